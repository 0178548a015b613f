"""simgen generate end to end on a small copy of scene1: contents, 50 ms ground truth, determinism, resume."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute  # noqa: F401  (pa.compute)
import pyarrow.parquet as pq
import pytest

from simgen.cli import main

from scene_copies import copy_scene

pytestmark = [pytest.mark.generate, pytest.mark.slow]  # renders datasets with simgen

SECONDS, SEED = "2", "5"
FILES = ["manifest.json", "camera.json", "trapezoids.json", "site_map.png", "site_map.json", "calibration.parquet",
         "gt.parquet", "detections.parquet", "video.mp4", "mot/gt.txt"]  # fmt: skip


def _generate_args(scene: Path, out: Path, *extra: str) -> list[str]:
    return ["generate", str(scene), "--out", str(out), "--seconds", SECONDS, "--seed", SEED, "--no-progress", *extra]


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, Path]:
    """(scene folder, dataset folder) of one uninterrupted run."""
    tmp = tmp_path_factory.mktemp("run")
    scene = copy_scene(tmp)
    assert main(_generate_args(scene, tmp / "a")) == 0
    return scene, tmp / "a"


def test_dataset_has_exactly_the_documented_files(run):
    _, out = run
    assert sorted(_files(out)) == sorted(FILES)
    m = json.loads((out / "manifest.json").read_text())
    assert m["complete"] and m["frames_done"] == m["frames_total"] == 40 and m["gt_dt"] == 0.05 and m["fps"] == 20
    assert m["detectors"] == ["segmentation", "rgb"] and set(m["versions"]) == {"python", "numpy", "mujoco", "opencv", "simgen"}
    cam = json.loads((out / "camera.json").read_text())
    H = np.array(cam["image_to_ground"]) @ np.array(cam["ground_to_image"])
    np.testing.assert_allclose(H / H[2, 2], np.eye(3), atol=1e-9)
    assert (cam["width"], cam["height"]) == (320, 180)


def test_gt_every_50_ms(run):
    _, out = run
    gt = pq.read_table(out / "gt.parquet")
    step, t = gt.column("step").to_numpy(), gt.column("t").to_numpy()
    assert np.array_equal(t, step * 0.05)  # exactly k * 0.05, not accumulated
    assert np.array_equal(np.unique(step), np.arange(40))
    agent = gt.column("agent_id").to_numpy()
    for a in np.unique(agent):  # each agent: consecutive steps, 50 ms apart, no gaps
        assert np.all(np.diff(step[agent == a]) == 1)
    assert gt.schema.field("agent_id").type == "int32" and gt.schema.field("in_frame").type == "bool"


def test_gt_projection_and_boxes_agree(run):
    _, out = run
    gt = pq.read_table(out / "gt.parquet")
    cam = json.loads((out / "camera.json").read_text())
    x, y, u, v = (gt.column(c).to_numpy() for c in "xyuv")
    uvw = np.column_stack([x, y, np.ones_like(x)]) @ np.array(cam["ground_to_image"]).T
    front = y > 0.5
    np.testing.assert_allclose(uvw[front, :2] / uvw[front, 2:], np.column_stack([u, v])[front], atol=1e-6)
    x1, x2, y2, frac = (gt.column(c).to_numpy() for c in ("x1", "x2", "y2", "visible_fraction"))
    clear = frac > 0.8  # barely occluded: the box bottom is the nearer foot's sole
    assert clear.sum() > 50
    width = x2[clear] - x1[clear]
    assert np.all(np.abs((x1[clear] + x2[clear]) / 2 - u[clear]) < 0.5 * width + 1)
    # the foot point is the feet's midpoint: the nearer sole reaches at most 0.6 m (a quarter stride + half a foot) nearer
    r = np.hypot(x[clear], y[clear])
    near = np.column_stack([x[clear], y[clear], np.ones(clear.sum())]) * np.column_stack([1 - 0.6 / r, 1 - 0.6 / r, np.ones_like(r)])
    near = near @ np.array(cam["ground_to_image"]).T
    assert np.all(y2[clear] >= v[clear] - 1.0) and np.all(y2[clear] <= near[:, 1] / near[:, 2] + 1.0)
    assert np.all(np.isnan(x1[frac == 0]))


def test_calibration_and_detections(run):
    _, out = run
    cal = pq.read_table(out / "calibration.parquet")
    assert cal.column("index").to_pylist() == list(range(40))
    np.testing.assert_allclose(cal.column("distance_m").to_numpy(), np.arange(5.0, 45.0))
    du = cal.column("u").to_numpy() - cal.column("u_exact").to_numpy()
    dv = cal.column("v").to_numpy() - cal.column("v_exact").to_numpy()
    # the toes reach 0.125 m nearer than the foot point (1.8 px at 5 m at 320x180); beyond 38 m the legs are
    # thinner than a pixel at this resolution and the box ends above the ground
    near = cal.column("distance_m").to_numpy() <= 38.0
    assert np.all(np.abs(du) <= 1.0) and np.all(np.abs(dv[near]) <= 2.0) and np.all(np.abs(dv) <= 2.5)
    det = pq.read_table(out / "detections.parquet")
    names = det.column("detector").to_numpy(zero_copy_only=False)
    assert set(names) == {"segmentation", "rgb"} and list(dict.fromkeys(names)) == ["segmentation", "rgb"]
    seg = names == "segmentation"
    agent, t, gt_t = (det.column(c).to_numpy() for c in ("agent_id", "t", "gt_t"))
    assert np.all(agent[seg] >= 0) and np.all(np.abs(gt_t[seg] - t[seg]) <= 0.025 + 1e-9)
    assert (agent[~seg] >= 0).sum() > 0  # the rgb detector's blobs are associated with agents


def test_same_seed_same_bytes(run, tmp_path):
    scene, out = run
    assert main(_generate_args(scene, tmp_path / "b")) == 0
    assert _files(tmp_path / "b") == _files(out)


# kill points: during calibration, between chunks, while a video segment is written, while the final files are
@pytest.mark.parametrize("kill_when", ["manifest.json", "_parts/00001.gt.parquet", "_parts/00002.tmp*.mp4", "gt.parquet"])
def test_resume_after_kill_gives_the_same_bytes(run, tmp_path, kill_when):
    scene, reference = run
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "simgen.cli", *_generate_args(scene, out)]
    proc = subprocess.Popen(cmd, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not any(out.glob(kill_when)) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        assert not json.loads((out / "manifest.json").read_text())["complete"]
    else:  # the final files were written faster than we could look: resuming a complete run changes nothing
        assert kill_when == "gt.parquet" and proc.returncode == 0
    assert main(_generate_args(scene, out, "--resume")) == 0
    assert _files(out) == _files(reference)


def test_existing_output_needs_resume_and_the_same_seed(run, capsys):
    scene, out = run
    assert main(_generate_args(scene, out)) == 2
    assert "--resume" in capsys.readouterr().err
    assert main(["generate", str(scene), "--out", str(out), "--seconds", SECONDS, "--seed", "6", "--resume"]) == 2
    assert "seed" in capsys.readouterr().err


def test_import_mot_adds_an_external_detector(run, tmp_path):
    _, reference = run
    out = tmp_path / "copy"
    shutil.copytree(reference, out)
    assert main(["import-mot", str(out), str(out / "mot" / "gt.txt"), "--name", "oracle"]) == 0
    det = pq.read_table(out / "detections.parquet")
    names = det.column("detector").to_numpy(zero_copy_only=False)
    oracle = names == "oracle"
    assert oracle.sum() == len((out / "mot" / "gt.txt").read_text().splitlines())
    assert np.all(det.column("agent_id").to_numpy()[oracle] >= 0)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["detectors"][-1] == "oracle"
    assert main(["import-mot", str(out), str(out / "mot" / "gt.txt"), "--name", "oracle"]) == 0  # re-import replaces
    assert (pq.read_table(out / "detections.parquet").column("detector").to_numpy(zero_copy_only=False) == "oracle").sum() == oracle.sum()
    assert json.loads((out / "manifest.json").read_text())["detectors"].count("oracle") == 1


MOT_LINE = "1,-1,100,60,10,20,0.9,-1,-1,-1\n"  # a valid detection in the 320x180, 40-frame dataset
MOT_BAD = [
    # (id, file content (bytes) or None for no file, --name, extra flags, message)
    ("reserved name", MOT_LINE.encode(), "rgb", [], "reserved"),
    *((f"--name {name!r:.20}", MOT_LINE.encode(), name, [], f"argument --name: detector name {name!r:.30}")
      for name in ("../x", "a/b", ".", "..", ".hidden", "a\nb", "x" * 300, "", "a b", "é")),
    ("-o and a dataset", MOT_LINE.encode(), "yolo", ["-o", "OUT"], "give the dataset folder once"),
    ("a line of a megabyte", b"1," * 500_000 + b"\n", "yolo", [], "det.txt: line 1: longer than 1024 characters"),
    ("/dev/zero", "/dev/zero", "yolo", [], "/dev/zero: line 1: longer than 1024 characters"),
    ("over 256 MiB", "sparse", "yolo", [], "det.txt: larger than 256 MiB (the most a boxes file holds)"),
    ("bad line", (MOT_LINE + "2,-1,ten,10,5,20,0.9,-1,-1,-1\n").encode(), "yolo", [], "det.txt: line 2: not a number"),
    ("no file", None, "yolo", [], "missing.txt: No such file"),
    ("empty file", b"", "yolo", [], "det.txt: no detections"),
    ("blank lines only", b"\n \n", "yolo", [], "det.txt: no detections"),
    ("frame beyond the video", b"41,-1,100,60,10,20,0.9,-1,-1,-1\n", "yolo", [], "det.txt: line 1: frame 41 is beyond the video (40 frames)"),
    ("conf 5", b"1,-1,100,60,10,20,5.0,-1,-1,-1\n", "yolo", [], "det.txt: line 1: conf must be in [0, 1]"),
    ("conf -0.1", b"1,-1,100,60,10,20,-0.1,-1,-1,-1\n", "yolo", [], "det.txt: line 1: conf must be in [0, 1]"),
    ("box right of the image", b"1,-1,400,60,10,20,0.9,-1,-1,-1\n", "yolo", [], "det.txt: line 1: box 400,60,10,20 does not overlap"),
    ("box above the image", b"1,-1,100,-100,10,20,0.9,-1,-1,-1\n", "yolo", [], "does not overlap the 320x180 image"),
    ("huge box", b"1,-1,1,1,1e308,1e308,0.9,-1,-1,-1\n", "yolo", [], "reaches more than one image size beyond it"),
    ("wide box", b"1,-1,1,1,1000,20,0.9,-1,-1,-1\n", "yolo", [], "reaches more than one image size beyond it"),
    ("inf box", b"1,-1,1,1,inf,20,0.9,-1,-1,-1\n", "yolo", [], "det.txt: line 1: non-finite value"),
    ("not UTF-8", b"1,-1,100,60,10,20,0.9,-1,-1,-1\n\xff\xfe\x00bad\n", "yolo", [], "det.txt: not UTF-8 text"),
    ("--min-iou 2", MOT_LINE.encode(), "yolo", ["--min-iou", "2"], "argument --min-iou: must be a finite number in (0, 1], got 2"),
    ("--min-iou nan", MOT_LINE.encode(), "yolo", ["--min-iou", "nan"], "argument --min-iou: must be a finite number in (0, 1]"),
    ("--min-iou -1", MOT_LINE.encode(), "yolo", ["--min-iou", "-1"], "argument --min-iou"),
    ("--min-iou 0", MOT_LINE.encode(), "yolo", ["--min-iou", "0"], "argument --min-iou"),
    ("incomplete", MOT_LINE.encode(), "yolo", [], "not complete"),
    ("not a simgen dataset", MOT_LINE.encode(), "yolo", [], "not a simgen-dataset output folder"),
]  # fmt: skip


@pytest.mark.parametrize("how, content, name, extra, message", MOT_BAD, ids=[b[0] for b in MOT_BAD])
def test_import_mot_refuses_bad_input(run, tmp_path, capsys, how, content, name, extra, message):
    _, reference = run
    out = tmp_path / "copy"
    shutil.copytree(reference, out)
    mot = tmp_path / ("missing.txt" if content is None else "det.txt")
    if content == "/dev/zero":
        mot = Path(content)
    elif content == "sparse":  # a valid first line, then holes: 300 MiB on disk in no time
        with open(mot, "wb") as f:
            f.write(MOT_LINE.encode())
            f.truncate(300 << 20)
    elif content is not None:
        mot.write_bytes(content)
    extra = [str(out) if flag == "OUT" else flag for flag in extra]
    if how == "incomplete":
        manifest = json.loads((out / "manifest.json").read_text())
        (out / "manifest.json").write_text(json.dumps({**manifest, "complete": False}, indent=2) + "\n")
    if how == "not a simgen dataset":  # a manifest.json without our format tag (a user's, another tool's)
        manifest = json.loads((out / "manifest.json").read_text())
        (out / "manifest.json").write_text(json.dumps({k: v for k, v in manifest.items() if k != "format"}))
    before = _files(out)
    assert main(["import-mot", str(out), str(mot), "--name", name, *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("simgen: error: import-mot:") and message in err and len(err.splitlines()) == 1, err
    assert _files(out) == before


@pytest.mark.parametrize("files", [["det.txt"], ["data", "data", "det.txt"], ["data", "det.txt", "det.txt"]])
def test_import_mot_needs_the_dataset_once(tmp_path, capsys, monkeypatch, files):
    """No dataset, or a third file: refused before any file is read."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "det.txt").write_text(MOT_LINE)
    assert main(["import-mot", *files, "--name", "yolo"]) == 2
    assert capsys.readouterr().err == "simgen: error: import-mot: give the dataset folder once: -o/--out DATASET MOT_TXT, or DATASET MOT_TXT\n"
    assert [p.name for p in tmp_path.iterdir()] == ["det.txt"]


def test_import_mot_takes_the_dataset_as_out(run, tmp_path):
    """``import-mot MOT_TXT --name N -o DATASET`` adds what ``import-mot DATASET MOT_TXT --name N`` adds."""
    _, reference = run
    given, flagged = tmp_path / "given", tmp_path / "flagged"
    shutil.copytree(reference, given)
    shutil.copytree(reference, flagged)
    assert main(["import-mot", str(given), str(reference / "mot" / "gt.txt"), "--name", "oracle"]) == 0
    assert main(["import-mot", str(reference / "mot" / "gt.txt"), "--name", "oracle", "--out", str(flagged)]) == 0
    assert _files(flagged) == _files(given) != _files(reference)


def test_import_mot_accepts_the_limits(run, tmp_path):
    """The edges of what is accepted: last frame, conf 0 and 1, a box partly outside the image."""
    _, reference = run
    out = tmp_path / "copy"
    shutil.copytree(reference, out)
    (tmp_path / "det.txt").write_text("40,-1,100,60,10,20,1,-1,-1,-1\n1,-1,-5,170,30,40,0,-1,-1,-1\n")
    assert main(["import-mot", str(out), str(tmp_path / "det.txt"), "--name", "yolo", "--min-iou", "1"]) == 0
    det = pq.read_table(out / "detections.parquet")
    yolo = det.filter(pa.compute.equal(det.column("detector"), "yolo"))
    assert yolo.num_rows == 2 and np.isfinite(np.column_stack([yolo.column(c).to_numpy() for c in ("x1", "y1", "x2", "y2")])).all()


def test_two_workers_give_the_serial_bytes(run, tmp_path, capsys):
    scene, reference = run
    assert main(_generate_args(scene, tmp_path / "w2", "--workers", "2")) == 0
    assert _files(tmp_path / "w2") == _files(reference)
    assert "simgen generate: " in capsys.readouterr().out


def test_a_worker_with_other_code_refuses_to_render(small_scene, tmp_path):
    """A worker whose code or libraries differ from the run's (build_id) fails in one line before rendering."""
    from simgen.chunks import DatasetError, build_id, render_chunks
    from simgen.scene import load_scene

    scene = load_scene(small_scene).with_run(seconds=1)
    (tmp_path / "_parts").mkdir()
    with pytest.raises(DatasetError, match=r"has other code than the run \(source [0-9a-f]{12} \(run: 000000000000\)\)") as e:
        render_chunks(scene, 5, tmp_path, [0], expect={**build_id(), "source": "0" * 64})
    assert len(str(e.value).splitlines()) == 1 and not any((tmp_path / "_parts").iterdir())


def test_killed_parallel_run_resumes_serially_to_the_same_bytes(run, tmp_path):
    """Chunks finished out of order by workers are kept; resume renders only the missing ones."""
    scene, reference = run
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "simgen.cli", *_generate_args(scene, out, "--workers", "2")]
    proc = subprocess.Popen(cmd, stderr=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not any(out.glob("_parts/*.det.parquet")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    time.sleep(1.0)  # the workers notice their parent is gone (at their next frame) and exit
    assert main(_generate_args(scene, out, "--resume")) == 0
    assert _files(out) == _files(reference)


def test_dask_local_cluster_gives_the_serial_bytes(run, tmp_path):
    distributed = pytest.importorskip("distributed")
    scene, reference = run
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        with distributed.Client(cluster) as client:
            assert len(client.scheduler_info()["workers"]) == 2
        assert main(_generate_args(scene, tmp_path / "dask", "--scheduler", cluster.scheduler_address)) == 0
    assert _files(tmp_path / "dask") == _files(reference)
