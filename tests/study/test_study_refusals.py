"""Refusals that change nothing: names read from manifests and study.json never become paths unchecked, a report
that would fail writes nothing, a site map's numbers are numbers, a point is two finite numbers."""
import argparse
import json
import shutil
from pathlib import Path

import pytest

from homocal.arguments import xy_pair
from homocal.cli import main
from homocal.dataset import load_dataset
from homocal.geometry import SiteMap
from homocal.study.inputs import MAX_SEED
from synthetic_dataset import make_moving, write_dataset

BAD_NAMES = ["../../../../escaped", "../../../../../victim", "a/b", ".", "..", ".hidden", "x\ny", "x" * 300, "", 5, None]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_dataset(tmp_path_factory.mktemp("data") / "a", "scene_a", n_calibration=6, n_test=60)


@pytest.fixture(scope="module")
def study(dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("study") / "s"
    assert main(["study", str(dataset), "-o", str(out), "--variants", "1", "--n-test", "50", "--no-progress"]) == 0
    return out


def snapshot(root: Path) -> dict[str, bytes]:
    """Every file under root (recursively) and its bytes."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("homocal: error: "), err
    return err[0]


@pytest.mark.parametrize("name", BAD_NAMES, ids=repr)
def test_a_manifest_scene_that_is_not_a_name_is_refused_before_anything_is_written(dataset, tmp_path, capsys, name):
    """`homocal study DS -o OUT` with manifest.json's "scene" a path, a hidden or overlong name, a newline or not
    text: one line naming the manifest, exit 2, OUT not made and nothing written anywhere under tmp_path."""
    bad = tmp_path / "deep" / "er" / "ds"
    shutil.copytree(dataset, bad)
    manifest = json.loads((bad / "manifest.json").read_text())
    (bad / "manifest.json").write_text(json.dumps({**manifest, "scene": name}))
    before = snapshot(tmp_path)
    out = tmp_path / "deep" / "er" / "out"
    assert main(["study", str(bad), "-o", str(out), "--variants", "1", "--n-test", "20", "--no-progress"]) == 2
    assert "manifest.json: scene" in one_error_line(capsys)
    assert snapshot(tmp_path) == before and not out.exists()


@pytest.mark.parametrize("name", BAD_NAMES, ids=repr)
def test_a_study_json_scene_that_is_not_a_name_makes_report_touch_nothing(study, tmp_path, capsys, name):
    """`homocal report` of a study whose datasets[0].scene is not a name: one line naming study.json, exit 2, no
    report folder, the user's victim.png beside it untouched."""
    results = tmp_path / "a" / "b" / "c" / "d" / "s"
    shutil.copytree(study, results)
    meta = json.loads((results / "study.json").read_text())
    meta["datasets"][0]["scene"] = name
    (results / "study.json").write_text(json.dumps(meta))
    (tmp_path / "victim.png").write_bytes(b"the user's picture")
    before = snapshot(tmp_path)
    assert main(["report", str(results), "--no-progress"]) == 2
    assert "study.json: datasets[0].scene" in one_error_line(capsys)
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("sweep", ["missing", "empty folder", "empty csv", "no png"])
def test_a_report_that_would_fail_writes_nothing(study, tmp_path, capsys, sweep):
    """report --sweep of a folder that is not a finished sweep: one line, exit 2, no report folder made (the
    sweep is read before anything is written)."""
    folder = tmp_path / "sweep"
    if sweep != "missing":
        folder.mkdir()
    if sweep == "empty csv":
        (folder / "sweep.csv").write_text("param,value,method,D\n")
        (folder / "sweep.png").write_bytes(b"png")
    if sweep == "no png":
        (folder / "sweep.csv").write_text("param,value,method,D\nseed,0,regression,3.5\n")
    before = snapshot(study)
    out = tmp_path / "report"
    assert main(["report", str(study), "-o", str(out), "--sweep", str(folder), "--no-progress"]) == 2
    assert "not a finished homocal sweep folder" in one_error_line(capsys)
    assert main(["report", str(study), "--sweep", str(folder), "--no-progress"]) == 2
    capsys.readouterr()
    assert not out.exists() and snapshot(study) == before


@pytest.mark.parametrize("site", [{"scale_px_per_m": True, "origin_px": [0, 0]}, {"scale_px_per_m": False, "origin_px": [0, 0]},
                                  {"scale_px_per_m": "10", "origin_px": [0, 0]}, {"scale_px_per_m": None, "origin_px": [0, 0]},
                                  {"scale_px_per_m": [10], "origin_px": [0, 0]}, {"scale_px_per_m": 10, "origin_px": [True, 0]},
                                  {"scale_px_per_m": 10, "origin_px": [0]}, {"scale_px_per_m": 10, "origin_px": "00"},
                                  {"scale_px_per_m": 10}, {"scale_px_per_m": float("nan"), "origin_px": [0, 0]}],
                         ids=lambda d: json.dumps(d))
def test_site_map_numbers_are_numbers(dataset, tmp_path, site):
    """Booleans, text, null and lists are not a site map's numbers: one line naming site_map.json."""
    with pytest.raises(ValueError, match="site map"):
        SiteMap.from_dict(site)
    bad = tmp_path / "ds"
    shutil.copytree(dataset, bad)
    (bad / "site_map.json").write_text(json.dumps(site))
    with pytest.raises(ValueError, match="site_map.json") as raised:
        load_dataset(bad)
    assert "\n" not in str(raised.value)


def test_a_good_site_map_still_reads():
    assert SiteMap.from_dict({"scale_px_per_m": 10, "origin_px": [200.5, 600]}) == SiteMap(10.0, (200.5, 600.0))


@pytest.mark.parametrize("text", ["", "1", "1,2,3", "1;2", "x,1", "nan,1", "1,inf", "-inf,0", "1e400,0", ",", "1,,2"])
def test_a_bad_point_is_one_argparse_line(text):
    """homocal.arguments.xy_pair (advise's --camera-origin, fit's): anything but two finite numbers X,Y is refused
    as argparse's one line."""
    with pytest.raises(argparse.ArgumentTypeError, match="X,Y"):
        xy_pair(text)


@pytest.mark.parametrize("text, point", [("1,2", (1.0, 2.0)), (" -0.5 , 3e1 ", (-0.5, 30.0))])
def test_a_point_is_two_numbers(text, point):
    assert xy_pair(text) == point


@pytest.mark.parametrize("text", ["-1", str(MAX_SEED + 1), "1" + "0" * 400, "1.5", "nan", "", "x"])
def test_advise_refuses_a_seed_as_the_study_does(tmp_path, capsys, text):
    """homocal advise --seed takes the study's seeds (inputs.MAX_SEED): anything else is argparse's one line naming
    the flag, and nothing is written."""
    with pytest.raises(SystemExit) as raised:
        main(["advise", "--trapezoid", str(tmp_path / "t.json"), "--distances", "10,20,30", "--seed", text,
              "-o", str(tmp_path / "a.csv")])
    assert raised.value.code == 2 and "argument --seed" in one_error_line(capsys)
    assert not any(tmp_path.iterdir())


def test_a_dataset_whose_camera_moves_is_refused(dataset, tmp_path, capsys):
    """A dataset with camera_pose.parquet (simgen writes it only when [[camera.moves]] or [camera.sway] move the
    camera): its test points were seen by a moving camera, which the study's one trapezoid cannot map. One line
    naming the file, exit 2, nothing written."""
    moving = make_moving(shutil.copytree(dataset, tmp_path / "moving"))
    assert load_dataset(moving).moving and not load_dataset(dataset).moving
    before = snapshot(tmp_path)
    out = tmp_path / "out"
    assert main(["study", str(moving), "-o", str(out), "--variants", "1", "--n-test", "20", "--no-progress"]) == 2
    assert "its camera moves (camera_pose.parquet)" in one_error_line(capsys)
    assert snapshot(tmp_path) == before and not out.exists()
