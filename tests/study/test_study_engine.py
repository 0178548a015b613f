"""homocal study end to end: the results directory contract, same seed -> same bytes, resume after a kill,
a real Dask LocalCluster, degenerate variants counted, bad input as one line."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import dask
import numpy as np
import pyarrow.parquet as pq
import pytest

from homocal.cli import main
from homocal.study.engine import run_study
from homocal.study.inputs import StudyParams, StudyScene
from homocal.study.shards import SHARD_SCHEMA, check_shard, compute_shard, study_key
from synthetic_dataset import write_dataset


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    root = tmp_path_factory.mktemp("datasets")
    return [str(write_dataset(root / "a", "scene_a", n_calibration=12, n_test=300)),
            str(write_dataset(root / "b", "scene_b", n_calibration=11, n_test=300, seed=1))]


def files(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*.parquet"))}


def study_cli(datasets, out, *extra):
    return [sys.executable, "-m", "homocal.cli", "study", *datasets, "--out", str(out), "--n-test", "200", *extra]


@pytest.fixture(scope="module")
def reference(datasets, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "study"
    assert main(["study", *datasets, "--out", str(out), "--variants", "40", "--n-test", "200"]) == 0
    return out


def test_results_directory_contract(reference):
    study = json.loads((reference / "study.json").read_text())
    assert study["complete"] and study["samples_total"] == study["samples_done"] == 41 * (220 + 165)
    assert study["n_variants"] == 40 and study["n_test"] == 200 and study["degenerate"] == []
    assert [d["scene"] for d in study["datasets"]] == ["scene_a", "scene_b"]
    shard = pq.read_table(reference / "shards" / "scene_a" / "variant_00007.parquet")
    assert shard.schema == SHARD_SCHEMA and shard.num_rows == 220
    assert shard.column("variant").to_pylist() == [7] * 220
    variants = pq.read_table(reference / "variants" / "scene_b.parquet")
    assert variants.num_rows == 41 and variants.column("n_perturbed").type.bit_width == 8
    assert {f"img_{c}" for c in range(8)} | {f"map_{c}" for c in range(8)} <= set(variants.column_names)
    d_spread = shard.column("d_spread").to_numpy()
    assert (d_spread > 0).all() and np.isfinite(shard.column("path_descent").to_numpy()).all()


@pytest.mark.slow  # end to end: studies in subprocesses
def test_same_seed_same_bytes_and_resume_after_kill(datasets, tmp_path):
    """A study killed (SIGKILL) as soon as its first shard is on disk, then resumed, gives the bytes of an
    uninterrupted run. 150 variants (302 shards, about a second of work once compiled) so the kill lands
    mid-run even when this process is slow to notice the first shard; if the run still finished first (a
    loaded machine), resuming the complete study must change nothing. The kill can land at any moment of
    the shard loop: test_resume_from_any_partial_state covers the states it leaves deterministically."""
    args = ["--variants", "150"]
    out = tmp_path / "killed"
    proc = subprocess.Popen(study_cli(datasets, out, *args), stderr=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
    shards = out / "shards"
    deadline = time.monotonic() + 300  # includes compiling the kernels if the cache is cold
    while proc.poll() is None and time.monotonic() < deadline and next(shards.rglob("variant_*.parquet"), None) is None:
        time.sleep(0.002)
    if proc.poll() is None:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    else:
        assert proc.returncode == 0
    study = json.loads((out / "study.json").read_text())
    done = len(list(shards.rglob("variant_*.parquet")))
    assert 0 < done <= 302 and study["complete"] == (done == 302 and proc.returncode == 0)
    assert main(["study", *datasets, "--out", str(out), "--n-test", "200", "--resume", *args]) == 0
    assert json.loads((out / "study.json").read_text())["complete"]
    uninterrupted = tmp_path / "uninterrupted"
    assert main(["study", *datasets, "--out", str(uninterrupted), "--n-test", "200", *args]) == 0
    assert files(out) == files(uninterrupted)


def test_resume_from_any_partial_state(datasets, reference, tmp_path):
    """What a kill leaves (some shards missing, a half-written temporary file, study.json not complete)
    resumes to the bytes of the uninterrupted run, nothing lost or duplicated."""
    out = tmp_path / "partial"
    shutil.copytree(reference, out)
    for scene, v in [("scene_a", 0), ("scene_a", 7), ("scene_a", 40), ("scene_b", 3), ("scene_b", 39)]:
        path = out / "shards" / scene / f"variant_{v:05d}.parquet"
        path.unlink()
        path.with_name(f"{path.stem}.tmp1234{path.suffix}").write_bytes(b"half a parquet file")  # our temporaries' names
    study = json.loads((out / "study.json").read_text())
    (out / "study.json").write_text(json.dumps({**study, "complete": False}))
    assert main(["study", *datasets, "--out", str(out), "--variants", "40", "--n-test", "200", "--resume"]) == 0
    assert files(out) == files(reference) and not list(out.rglob("*.tmp*"))
    resumed = json.loads((out / "study.json").read_text())
    assert resumed["complete"] and resumed["samples_done"] == study["samples_done"] == 41 * (220 + 165)


def test_resume_rejects_a_shard_without_its_degenerate_reason(datasets, reference, tmp_path, capsys):
    """A shard that does not record its variant's degenerate reason (not written by this version) is named,
    with a non-zero exit, before anything is computed."""
    out = tmp_path / "foreign"
    shutil.copytree(reference, out)
    shard = out / "shards" / "scene_b" / "variant_00005.parquet"
    pq.write_table(pq.read_table(shard).replace_schema_metadata(None), shard)
    (out / "shards" / "scene_a" / "variant_00002.parquet").unlink()
    assert main(["study", *datasets, "--out", str(out), "--variants", "40", "--n-test", "200", "--resume"]) == 2
    assert "variant_00005.parquet" in capsys.readouterr().err
    assert not (out / "shards" / "scene_a" / "variant_00002.parquet").exists()


@pytest.mark.slow  # end to end: a Dask LocalCluster
def test_dask_local_cluster_matches_in_process(datasets, reference, tmp_path):
    out = tmp_path / "dask"
    assert main(["study", *datasets, "--out", str(out), "--variants", "40", "--n-test", "200", "--workers", "2"]) == 0
    assert files(out) == files(reference)


def test_a_dataset_regenerated_at_the_same_path_is_read_afresh(tmp_path):
    """Two studies in one process of a dataset rewritten in between at the same path: the second one's shards are
    those of a study of the new dataset at another path, not the first one's."""
    def study(dataset: Path, out: str) -> dict[str, bytes]:
        assert main(["study", str(dataset), "--out", str(tmp_path / out), "--variants", "1", "--n-test", "50", "--no-progress"]) == 0
        return files(tmp_path / out)

    before = study(write_dataset(tmp_path / "same", "scene_a", seed=1), "first")
    after = study(write_dataset(tmp_path / "same", "scene_a", seed=2), "second")
    assert after == study(write_dataset(tmp_path / "elsewhere", "scene_a", seed=2), "fresh") != before


def test_degenerate_variant_is_counted_not_dropped(datasets, tmp_path, monkeypatch):
    # a scene whose hand-placed image trapezoid is nearly degenerate: 3 px moves make some variants invalid
    scene = StudyScene.from_dataset(datasets[0], StudyParams(n_test=200))
    quad = scene.image_quad.copy()
    quad[1] = quad[0] + 0.5 * (quad[2] - quad[0]) + [0.0, -1.0]  # TR almost on the TL-BR diagonal
    monkeypatch.setattr(StudyScene, "from_dataset", classmethod(lambda cls, p, prm: _with_quad(p, prm, quad)))
    study = run_study(datasets[:1], tmp_path / "deg", StudyParams(n_variants=30, n_test=200), progress=False)
    assert study["complete"] and study["n_degenerate"] > 0
    assert study["samples_done"] + study["samples_degenerate"] == study["samples_total"]
    variants = pq.read_table(tmp_path / "deg" / "variants" / "scene_a.parquet").to_pydict()
    assert [v for v, r in zip(variants["variant"], variants["reason"]) if r] == [d["variant"] for d in study["degenerate"]]
    scene_key = study_key(StudyParams(n_variants=30, n_test=200).to_dict(), "scene_a", scene.config_hash)
    for d in study["degenerate"]:
        shard = tmp_path / "deg" / "shards" / d["scene"] / f"variant_{d['variant']:05d}.parquet"
        assert d["reason"] and pq.read_table(shard).num_rows == 0
        assert check_shard(shard, d["scene"], d["variant"], scene_key, 0) == variants["reason"][d["variant"]] == d["reason"]


_original = StudyScene.from_dataset.__func__


def _with_quad(path, params, quad):
    scene = _original(StudyScene, path, params)
    scene.image_quad = quad
    return scene


@pytest.mark.slow  # a study in a subprocess
def test_dry_run_and_bad_input(datasets, tmp_path, capsys):
    assert main(["study", *datasets, "--out", str(tmp_path / "x"), "--preset", "paper", "--dry-run"]) == 0
    assert "total: 385,385 samples" in capsys.readouterr().out
    assert not (tmp_path / "x").exists()
    broken = tmp_path / "broken"
    write_dataset(broken, "broken", n_calibration=12, n_test=50)
    os.remove(broken / "calibration.parquet")
    result = subprocess.run(study_cli([str(broken)], tmp_path / "y"), capture_output=True, text=True)
    assert result.returncode == 2 and result.stderr.strip().count("\n") == 0
    assert result.stderr.startswith("homocal: error:") and "calibration.parquet" in result.stderr
    assert not (tmp_path / "y").exists()
    few = write_dataset(tmp_path / "few", "few", n_calibration=2, n_test=50)
    assert main(["study", str(few), "--out", str(tmp_path / "z")]) == 2
    assert "at least 3 calibration points" in capsys.readouterr().err and not (tmp_path / "z").exists()


def test_dry_run_says_how_many_points_each_foot_source_gives(datasets, tmp_path, capsys):
    """A detector's calibration points are the segmentation detector's; fewer test points than --n-test is said,
    and a detector the dataset lacks is one line naming the ones it has."""
    assert main(["study", *datasets, "--out", str(tmp_path / "x"), "--foot-source", "segmentation", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert ("scene_a: 11,220 samples; 12 calibration points (segmentation), 300 test points (segmentation): "
            "fewer than --n-test 2000, all the dataset has within 50 m") in out
    assert main(["study", *datasets, "--out", str(tmp_path / "x"), "--n-test", "200", "--dry-run"]) == 0
    assert "scene_b: 8,415 samples; 11 calibration points (exact), 200 test points (exact)\n" in capsys.readouterr().out
    assert main(["study", *datasets, "--out", str(tmp_path / "x"), "--foot-source", "hog", "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no detections from detector 'hog' (have ['segmentation'])" in err
    assert not (tmp_path / "x").exists()


def test_existing_study_needs_resume(datasets, reference, capsys):
    assert main(["study", *datasets, "--out", str(reference), "--variants", "40", "--n-test", "200"]) == 2
    assert "--resume" in capsys.readouterr().err


def test_shard_function_is_deterministic(datasets):
    scene = StudyScene.from_dataset(datasets[1], StudyParams(n_test=100))
    a, _ = compute_shard(scene, StudyParams(n_test=100), 3)
    b, _ = compute_shard(scene, StudyParams(n_test=100), 3)
    assert a.equals(b)


@pytest.mark.parametrize("command", ["study", "sweep"])
def test_resume_refuses_a_folder_that_is_not_ours(datasets, tmp_path, capsys, command):
    """--resume on a user's folder: one line, exit 2, every file of the folder untouched (temporaries too)."""
    out = tmp_path / "mine"
    out.mkdir()
    user = {"video.mp4": b"the user's video", "notes.tmp1.txt": b"not ours", "study.json": b'{"format": "other"}'}
    for name, data in user.items():
        (out / name).write_bytes(data)
    sweep = ["--horizon-shift", "0,4"] if command == "sweep" else []
    assert main([command, *datasets, "-o", str(out), "--variants", "1", "--n-test", "50", *sweep, "--resume"]) == 2
    assert "not a homocal-" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == user


def test_a_second_writer_is_refused_with_who_holds_the_lock(datasets, tmp_path, capsys):
    from homocal.files import output_folder

    out = tmp_path / "busy"
    with output_folder(out, "homocal-study", resume=False, marker="study.json"):
        assert main(["study", *datasets, "-o", str(out), "--variants", "1", "--n-test", "50"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"pid {os.getpid()}" in err[0]
    assert main(["study", *datasets, "-o", str(out), "--variants", "1", "--n-test", "50"]) == 0  # free again


@pytest.mark.parametrize("fault", ["garbage", "cut", "other_variant", "swapped", "other_seed",
                                   pytest.param("deleted", marks=pytest.mark.slow)])  # deleted: a report drawn
def test_resume_and_report_check_every_shard(datasets, reference, tmp_path, capsys, fault):
    """A garbage or cut shard, a valid shard of another variant copied over one, two shards swapped, a shard of
    another study (seed 1): resume and report refuse it, naming the file, and the refused resume leaves
    study.json byte for byte as it was; a deleted shard: report says the study is not complete (exit 1, on the
    page and on stderr) and resume rewrites it."""
    out = tmp_path / "s"
    shutil.copytree(reference, out)
    target = out / "shards" / "scene_a" / "variant_00003.parquet"
    if fault == "garbage":
        target.write_bytes(b"not parquet at all")
    elif fault == "cut":
        target.write_bytes(target.read_bytes()[:200])
    elif fault == "other_variant":
        shutil.copy(out / "shards" / "scene_a" / "variant_00004.parquet", target)
    elif fault == "swapped":
        other = out / "shards" / "scene_a" / "variant_00002.parquet"
        a, b = target.read_bytes(), other.read_bytes()
        target.write_bytes(b)
        other.write_bytes(a)
    elif fault == "other_seed":
        other = tmp_path / "seed1"
        assert main(["study", *datasets, "--out", str(other), "--variants", "3", "--n-test", "200", "--seed", "1"]) == 0
        shutil.copy(other / "shards" / "scene_a" / "variant_00003.parquet", target)
    else:
        target.unlink()
    capsys.readouterr()
    before = (out / "study.json").read_bytes()
    report_code = main(["report", str(out), "--no-progress"])
    err = capsys.readouterr().err
    resume_code = main(["study", *datasets, "--out", str(out), "--variants", "40", "--n-test", "200", "--resume"])
    resume_err = capsys.readouterr().err
    if fault == "deleted":
        assert report_code == 1 and "not complete: 1 shard(s) missing" in err
        assert "1 shard(s) missing" in (out / "report" / "report.html").read_text()
        assert resume_code == 0 and files(out) == files(reference)
    else:
        assert report_code == 2 and "variant_0000" in err and not (out / "report").exists()
        assert resume_code == 2 and "variant_0000" in resume_err
        assert (out / "study.json").read_bytes() == before


BAD_FLAGS = [
    # (command and flags after the datasets and -o, the message)
    (["study", "--variants", "-1"], "argument --variants: expected an integer in [0, 100000], got '-1'"),
    (["study", "--variants", str(10**12)], "argument --variants: expected an integer in [0, 100000]"),
    (["study", "--n-test", "0"], "argument --n-test: expected an integer in [1, 1000000], got '0'"),
    (["study", "--n-test", str(10**12)], "argument --n-test: expected an integer in [1, 1000000]"),
    (["study", "--workers", "0"], "argument --workers: must be an integer in [1, 1024], got 0"),
    (["sweep", "--horizon-shift", "1,1"], "--horizon-shift '1,1': 1 given more than once"),
    (["sweep", "--seed", "0,1,0"], "--seed '0,1,0': 0 given more than once"),
    (["sweep", "--horizon-shift", "0,2", "--n-test", "-5"], "argument --n-test"),
    (["sweep", "--map-scale", "2,0"], "argument --map-scale: expected a number in (0, 1000] (px/m) or none, got '0'"),
    (["sweep", "--map-scale", "2,-1"], "argument --map-scale: expected a number in (0, 1000] (px/m) or none, got '-1'"),
    (["sweep", "--map-scale", "2,ten"], "argument --map-scale: expected a number in (0, 1000] (px/m) or none, got 'ten'"),
    (["sweep", "--map-scale", "2,nan"], "argument --map-scale: expected a number in (0, 1000] (px/m) or none, got 'nan'"),
    (["sweep", "--map-scale", "2,inf"], "argument --map-scale: expected a number in (0, 1000] (px/m) or none, got 'inf'"),
    (["sweep", "--descent-delta-max", "8,0"], "argument --descent-delta-max: expected a number in (0, 100] (px), got '0'"),
    (["study", "--scheduler", "tcp://127.0.0.1:1"], "scheduler 'tcp://127.0.0.1:1': cannot connect"),
]  # fmt: skip


@pytest.mark.parametrize("args, message", BAD_FLAGS, ids=[" ".join(a) for a, _ in BAD_FLAGS])
def test_bad_numbers_are_one_line_naming_the_flag(datasets, tmp_path, capsys, args, message):
    """One line naming the flag, exit 2, no output folder (a scheduler that cannot be reached is found before
    the folder is made)."""
    out = tmp_path / "out"
    try:
        with dask.config.set({"distributed.comm.timeouts.connect": "2s"}):
            code = main([args[0], *datasets, "-o", str(out), *args[1:]])
    except SystemExit as e:  # refused by argparse
        code = e.code
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("homocal: error: ") and message in err and err.count("\n") == 1, err
    assert not out.exists()
