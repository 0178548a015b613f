"""simgen export-mot: the dataset as a MOTChallenge sequence folder, read back by motmetrics (a real MOT reader),
by configparser (seqinfo.ini) and by simgen import-mot."""
import configparser
import json
import shutil

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from simgen.cli import main

pytestmark = pytest.mark.generate  # renders datasets with simgen

mm = pytest.importorskip("motmetrics")


def export(capsys, dataset, out) -> str:
    assert main(["export-mot", str(dataset), "-o", str(out)]) == 0
    return capsys.readouterr().out


def rows(dataset, detector: str):
    det = pq.read_table(dataset / "detections.parquet")
    return det.filter(pc.equal(det.column("detector"), detector))


def test_the_folder_reads_with_motmetrics(tiny_dataset, tmp_path, capsys):
    out = tmp_path / "scene1-seq"
    summary = export(capsys, tiny_dataset, out)
    manifest = json.loads((tiny_dataset / "manifest.json").read_text())
    camera = json.loads((tiny_dataset / "camera.json").read_text())
    ini = configparser.ConfigParser()
    ini.read(out / "seqinfo.ini")
    assert dict(ini["Sequence"]) == {"name": manifest["scene"], "framerate": str(manifest["fps"]),
                                     "seqlength": str(manifest["frames_total"]), "imwidth": str(camera["width"]),
                                     "imheight": str(camera["height"])}  # fmt: skip
    assert (out / "gt" / "gt.txt").read_bytes() == (tiny_dataset / "mot" / "gt.txt").read_bytes()

    # ground truth: at 20 fps frame n is step n - 1; motmetrics puts a box's left edge at bb_left - 1 = x1 + 0.5
    gt = mm.io.loadtxt(out / "gt" / "gt.txt", fmt="mot16").reset_index()
    truth = pq.read_table(tiny_dataset / "gt.parquet")
    truth = truth.filter(pc.greater(truth.column("visible_pixels"), 0)).to_pandas()
    assert manifest["fps"] == 20 and len(gt) == len(truth) > 0
    np.testing.assert_array_equal(gt["FrameId"], truth["step"] + 1)
    np.testing.assert_array_equal(gt["Id"], truth["agent_id"])
    np.testing.assert_allclose(gt[["X", "Y"]], truth[["x1", "y1"]] + 0.5, atol=1e-9)
    np.testing.assert_allclose(gt["Width"], truth["x2"] - truth["x1"], atol=1e-9)
    np.testing.assert_allclose(gt["Visibility"], truth["visible_fraction"], rtol=1e-5)

    for detector in manifest["detectors"]:
        det = mm.io.loadtxt(out / "det" / f"{detector}.txt", fmt="mot15-2D").reset_index()
        mine = rows(tiny_dataset, detector).to_pandas()
        assert f"det/{detector}.txt {len(mine)} lines" in summary and len(det) == len(mine) > 0
        np.testing.assert_array_equal(det["FrameId"], mine["frame"] + 1)
        assert (det["Id"] == -1).all()
        np.testing.assert_allclose(det[["X", "Y"]], mine[["x1", "y1"]] + 0.5, atol=1e-6)
        np.testing.assert_allclose(det["Height"], mine["y2"] - mine["y1"], atol=1e-6)
        np.testing.assert_allclose(det["Confidence"], mine["score"], rtol=1e-9)


def test_motmetrics_matches_the_segmentation_detector_to_every_ground_truth_box(tiny_dataset, tmp_path, capsys, monkeypatch):
    """The segmentation detector's boxes are the ground truth's boxes (data_schema.md): recall and precision 1."""
    monkeypatch.setattr(np, "asfarray", lambda a, dtype=np.float64: np.asarray(a, dtype=dtype), raising=False)  # numpy 2
    export(capsys, tiny_dataset, tmp_path / "seq")
    gt = mm.io.loadtxt(tmp_path / "seq" / "gt" / "gt.txt", fmt="mot16")
    det = mm.io.loadtxt(tmp_path / "seq" / "det" / "segmentation.txt", fmt="mot15-2D").reset_index()
    det["Id"] = np.arange(len(det))  # detections have no track id (-1): one per row for the accumulator
    acc = mm.utils.compare_to_groundtruth(gt, det.set_index(["FrameId", "Id"]), "iou", distth=0.5)
    summary = mm.metrics.create().compute(acc, metrics=["recall", "precision", "num_misses", "num_false_positives"])
    assert summary.iloc[0].tolist() == [1.0, 1.0, 0, 0]


def test_import_mot_reads_back_what_export_mot_writes(tiny_dataset, tmp_path, capsys):
    dataset = tmp_path / "dataset"
    shutil.copytree(tiny_dataset, dataset)
    export(capsys, dataset, tmp_path / "seq")
    assert main(["import-mot", str(dataset), str(tmp_path / "seq" / "det" / "rgb.txt"), "--name", "rgb_again"]) == 0
    before, again = rows(dataset, "rgb"), rows(dataset, "rgb_again")
    assert again.num_rows == before.num_rows > 0
    for column in ("frame", "t", "x1", "y1", "x2", "y2", "u", "v", "score"):
        np.testing.assert_allclose(again.column(column).to_numpy(), before.column(column).to_numpy(), rtol=1e-9, atol=1e-6)


def test_an_earlier_export_is_rewritten_and_loses_the_detectors_gone(tiny_dataset, tmp_path, capsys):
    dataset = tmp_path / "dataset"
    shutil.copytree(tiny_dataset, dataset)
    seq = tmp_path / "seq"
    export(capsys, tiny_dataset, seq)
    assert main(["import-mot", str(dataset), str(seq / "det" / "rgb.txt"), "--name", "yolo"]) == 0
    export(capsys, dataset, seq)
    assert (seq / "det" / "yolo.txt").read_bytes() == (seq / "det" / "rgb.txt").read_bytes()
    export(capsys, tiny_dataset, seq)
    assert sorted(p.name for p in (seq / "det").iterdir()) == ["rgb.txt", "segmentation.txt"]
    assert sorted(p.name for p in seq.iterdir()) == ["det", "export.json", "gt", "seqinfo.ini"]


@pytest.mark.parametrize("listed", ["notes.txt", "det/../notes.txt", "../outside.txt", "gt/mine.txt", "det/sub/x.txt", 7])
def test_a_hand_edited_marker_never_gets_a_user_file_removed(tiny_dataset, tmp_path, capsys, listed):
    """Only det/<name>.txt files an earlier export lists are removed as stale; anything else it lists stays."""
    seq = tmp_path / "seq"
    export(capsys, tiny_dataset, seq)
    user_files = [seq / "notes.txt", tmp_path / "outside.txt", seq / "gt" / "mine.txt", seq / "det" / "sub" / "x.txt"]
    for f in user_files:
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text("mine")
    marker = json.loads((seq / "export.json").read_text())
    (seq / "export.json").write_text(json.dumps({**marker, "files": [*marker["files"], listed]}))
    export(capsys, tiny_dataset, seq)
    assert all(f.read_text() == "mine" for f in user_files)


def _edit_manifest(dataset, **fields):
    manifest = json.loads((dataset / "manifest.json").read_text())
    (dataset / "manifest.json").write_text(json.dumps({**manifest, **fields}))


BAD = [
    ("a user's folder", lambda d, out: (out.mkdir(), (out / "notes.txt").write_text("mine")), "is not an export-mot folder"),
    ("not a dataset", lambda d, out: (d / "manifest.json").unlink(), "not a complete simgen dataset (no manifest.json)"),
    ("incomplete", lambda d, out: _edit_manifest(d, complete=False), "the run is not complete"),
    *((f"scene {name!r}", lambda d, out, name=name: _edit_manifest(d, scene=name), f"manifest.json: scene {name!r:.30}")
      for name in ("../../escaped", "a/b", "..", ".hidden", "a\nb", "x" * 65, "", None, 5)),
    *((f"detector {name!r}", lambda d, out, name=name: _edit_manifest(d, detectors=["segmentation", name]),
       f"manifest.json: detector {name!r:.30}") for name in ("../x", "det/x", ".", "a\nb", "x" * 300, 1.5)),
    ("detectors not a list", lambda d, out: _edit_manifest(d, detectors="segmentation"), "detectors: expected a list of names"),
    ("out is a file", lambda d, out: out.write_text("mine"), "exists and is not a folder"),
]  # fmt: skip


@pytest.mark.parametrize("how, spoil, message", BAD, ids=[b[0] for b in BAD])
def test_bad_input_is_one_line_and_touches_nothing(tiny_dataset, tmp_path, capsys, how, spoil, message):
    dataset, out = tmp_path / "dataset", tmp_path / "out"
    shutil.copytree(tiny_dataset, dataset)
    spoil(dataset, out)
    before = sorted((p.relative_to(tmp_path), p.read_bytes() if p.is_file() else None) for p in tmp_path.rglob("*"))
    assert main(["export-mot", str(dataset), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("simgen: error: export-mot: ") and message in err and len(err.splitlines()) == 1, err
    assert sorted((p.relative_to(tmp_path), p.read_bytes() if p.is_file() else None) for p in tmp_path.rglob("*")) == before
