"""Writing a dataset folder (data_schema.md): static files, calibration, chunks of frames, final files.

Work is done in chunks of ``chunk_seconds``; each chunk's video segment and tables go to ``_parts/``
under temporary names and are renamed, then ``manifest.json`` records ``frames_done``. A killed run
resumed with ``resume=True`` redoes the unfinished chunk and ends with the same bytes as an
uninterrupted run: every draw is keyed by (seed, scene, slot), renders are deterministic, the rgb
detector restarts at every chunk from the ``rgb_warmup_frames`` frames before it (re-rendered on
resume), and the final files are written once from the parts.

The folder is held with ``homocal.files.output_folder`` (manifest.json with ``"format": FORMAT`` marks it as
a dataset; ``.lock`` while a run writes it). Chunks are independent, so ``workers`` processes (or the
workers of a Dask cluster) render contiguous blocks of them into ``_parts/``; each block starts with a fresh
Stage and rgb detector warmed up as on resume, so the parts are the bytes a serial run writes.
"""
from __future__ import annotations

import functools
import hashlib
import os
import platform
import shutil
import time
from collections import Counter
from contextlib import nullcontext
from concurrent.futures import ProcessPoolExecutor
from fractions import Fraction
from multiprocessing import get_context
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from tqdm import tqdm

import homocal.geometry
import simgen
from homocal.files import output_folder, OutputFolder, read_json, write_atomic, write_json_atomic
from simgen.backend import backend, mujoco
from simgen.detection import (
    BackgroundSubtractionDetector,
    HogDetector,
    SegmentationDetector,
    detections_table,
    match_to_gt,
    write_mot_gt,
)
from simgen.parquet import write_parquet
from simgen.scene import GT_DT, GT_RATE, Scene
from simgen.stage import Stage
from simgen.truth import GT_SCHEMA, gt_columns
from simgen.video import SegmentWriter, concat

PARTS = "_parts"
FORMAT = "simgen-dataset"  # manifest.json's format tag: the folder is a simgen dataset
FINAL = ("manifest.json", "camera.json", "trapezoids.json", "site_map.png", "site_map.json", "calibration.parquet",
         "gt.parquet", "detections.parquet", "mot/gt.txt", "video.mp4")  # fmt: skip

CALIBRATION_SCHEMA = pa.schema([
    ("index", pa.int32()), ("distance_m", pa.float64()), ("x", pa.float64()), ("y", pa.float64()),
    ("u", pa.float64()), ("v", pa.float64()), ("u_exact", pa.float64()), ("v_exact", pa.float64()),
    ("x1", pa.float64()), ("y1", pa.float64()), ("x2", pa.float64()), ("y2", pa.float64()),
])  # fmt: skip


class DatasetError(RuntimeError):
    """The output folder cannot be (re)used; one-line message."""


def _versions() -> dict:
    return {"python": platform.python_version(), "numpy": np.__version__, "mujoco": mujoco.__version__,
            "opencv": cv2.__version__, "simgen": simgen.__version__}


@functools.cache
def source_digest() -> str:
    """sha256 of the simgen sources and homocal.geometry (which simgen uses) as they are on disk at the first call
    (a run's start): a worker process reads them afresh, so if they changed in between (a checkout or merge under a
    running process, or a Dask worker with another install) its chunks would silently differ from this process's."""
    root = Path(simgen.__file__).parents[1]
    files = [*sorted(Path(simgen.__file__).parent.rglob("*.py")), *sorted(Path(homocal.geometry.__file__).parent.glob("*.py"))]
    return hashlib.sha256(b"".join(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() for p in files)).hexdigest()


def build_id() -> dict:
    """What a chunk's bytes depend on besides the scene and seed: library versions, the rendering backend
    and the digest of the code (``source_digest``). ``render_chunks`` in a worker checks it against the
    run's, so a worker with other code fails with one line instead of writing different bytes."""
    return {**_versions(), "backend": backend(), "source": source_digest()}


# ---- the static files ----------------------------------------------------------------------
def camera_json(scene: Scene) -> dict:
    cam = scene.camera
    lists = lambda a: np.asarray(a, dtype=float).tolist()  # noqa: E731
    return {
        "K": lists(cam.K), "R": lists(cam.R), "t": lists(cam.t), "width": cam.width, "height": cam.height,
        "hfov_deg": cam.hfov_deg, "vfov_deg": cam.vfov_deg, "mount_height_m": cam.mount_height_m,
        "tilt_deg": cam.tilt_deg, "image_to_ground": lists(cam.image_to_ground),
        "ground_to_image": lists(cam.ground_to_image), "horizon": lists(cam.horizon),
        "horizon_row": cam.horizon_row, "camera_origin": [0.0, 0.0],
    }  # fmt: skip


def trapezoids_json(scene: Scene) -> dict:
    return {
        "order": "TL,TR,BR,BL",
        "hand_placed": {"image": scene.hand_placed_image.tolist(), "map": scene.hand_placed_map.tolist()},
        "exact": {"image": scene.trapezoid_exact_image.tolist(), "map": scene.trapezoid_exact_map.tolist()},
        "ground_m": scene.trapezoid_ground.tolist(),
    }


def site_map(scene: Scene) -> np.ndarray:
    """(H, W, 3) uint8 BGR top-down map at ``scene.map_scale`` px per metre: the ground texture, with the
    footprints of the scene's static boxes (buildings) in grey."""
    x0, x1, y0, y1 = scene.ground.extent
    size = (round((x1 - x0) * scene.map_scale), round((y1 - y0) * scene.map_scale))
    image = cv2.resize(cv2.imread(str(scene.ground.texture), cv2.IMREAD_COLOR), size, interpolation=cv2.INTER_AREA)
    model = mujoco.MjModel.from_xml_path(str(scene.model_path))
    for g in np.flatnonzero((model.geom_type == mujoco.mjtGeom.mjGEOM_BOX) & (model.geom_bodyid == 0)):
        corners = np.array([[sx, sy, 0.0] for sx, sy in ((1, 1), (1, -1), (-1, -1), (-1, 1))]) * model.geom_size[g]
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, model.geom_quat[g])
        xy = (corners @ rot.reshape(3, 3).T + model.geom_pos[g])[:, :2]
        cv2.fillPoly(image, [np.round(scene.site_map.to_pixels(xy) * 16).astype(np.int32)], (150, 150, 150), cv2.LINE_AA, 4)
    return image


def manifest(scene: Scene, seed: int, frames_done: int, complete: bool) -> dict:
    return {
        "format": FORMAT, "scene": scene.name, "seed": seed, "config_hash": scene.config_hash(),
        "versions": _versions(),
        "frames_total": scene.frames_total, "frames_done": frames_done, "complete": complete,
        "fps": scene.fps, "gt_dt": GT_DT, "seconds": scene.seconds, "detectors": list(scene.detectors),
        "steps_total": scene.steps_total, "chunk_seconds": scene.chunk_seconds,
        "rgb_reset_every_frames": _chunk_frames(scene), "rgb_warmup_frames": scene.rgb_warmup_frames,
        "backend": backend(), "quality": scene.quality,
    }  # fmt: skip


def _write_static(scene: Scene, out: Path) -> None:
    write_json_atomic(out / "camera.json", camera_json(scene))
    write_json_atomic(out / "trapezoids.json", trapezoids_json(scene))
    image = site_map(scene)
    write_atomic(out / "site_map.png", lambda p: p.write_bytes(cv2.imencode(".png", image)[1].tobytes()))
    write_json_atomic(out / "site_map.json", {"file": "site_map.png", "scale_px_per_m": scene.map_scale,
                                       "origin_px": list(scene.site_map.origin_px), "width": image.shape[1], "height": image.shape[0]})


# ---- calibration ---------------------------------------------------------------------------
def calibration_table(stage: Stage) -> pa.Table:
    """One row per calibration distance: the object alone at its point (scene.calibration_xy), detected by the segmentation detector."""
    scene, detector = stage.scene, SegmentationDetector()
    xy = scene.calibration_xy
    d = np.hypot(xy[:, 0], xy[:, 1])  # the distances themselves with layout "line"
    box = np.full((len(d), 4), np.nan)
    for i, point in enumerate(xy):
        stage.set_calibration(point)
        batch = detector.detect(-1, 0.0, None, stage.agent_ids())
        if len(batch):
            box[i] = batch.xyxy[np.flatnonzero(batch.agent_id == 0)[0]]
    exact = scene.camera.project_ground(xy)
    cols = [np.arange(len(d), dtype=np.int32), d, xy[:, 0], xy[:, 1], (box[:, 0] + box[:, 2]) / 2, box[:, 3],
            exact[:, 0], exact[:, 1], box[:, 0], box[:, 1], box[:, 2], box[:, 3]]
    return pa.Table.from_arrays([pa.array(c) for c in cols], schema=CALIBRATION_SCHEMA)


# ---- chunks --------------------------------------------------------------------------------
def _chunk_frames(scene: Scene) -> int:
    return round(scene.chunk_seconds * scene.fps)


def _chunk_count(scene: Scene) -> int:
    return -(-scene.frames_total // _chunk_frames(scene))


def _timeline(scene: Scene, c: int) -> list[tuple[float, int | None, int | None]]:
    """Chunk c's instants in time order: (pose time s, frame or None, gt step or None); exact merge."""
    per_f, per_s = _chunk_frames(scene), round(scene.chunk_seconds * GT_RATE)
    events: dict[Fraction, list] = {}
    for k in range(c * per_f, min((c + 1) * per_f, scene.frames_total)):
        events.setdefault(Fraction(k, scene.fps), [None, None])[0] = k
    for j in range(c * per_s, min((c + 1) * per_s, scene.steps_total)):
        events.setdefault(Fraction(j, GT_RATE), [None, None])[1] = j
    return [(float(t), *events[t]) for t in sorted(events)]


def make_detectors(scene: Scene) -> list:
    """The scene's detectors, in order; the rgb one restarts at every chunk."""
    make = {
        "segmentation": SegmentationDetector,
        "rgb": lambda: BackgroundSubtractionDetector(reset_every=_chunk_frames(scene), warmup=scene.rgb_warmup_frames),
        "hog": HogDetector,
    }
    return [make[name]() for name in scene.detectors]


def _warm_up(stage: Stage, detectors: list, frame: int) -> None:
    """Before resuming at ``frame``: feed the rgb detector the frames its state depends on."""
    for det in detectors:
        if isinstance(det, BackgroundSubtractionDetector):
            for k in range(det.resume_start(frame), frame):
                stage.set_time(k / stage.scene.fps)
                det.feed(k, stage.rgb())


def _part_names(c: int) -> list[str]:
    """Chunk c's files in the dataset folder, in the order they are written (the last one marks it done)."""
    return [f"{PARTS}/{c:05d}.mp4", f"{PARTS}/{c:05d}.gt.parquet", f"{PARTS}/{c:05d}.det.parquet"]


def _run_chunk(stage: Stage, detectors: list, c: int, parts: Path, tick=lambda frames: None) -> None:
    """Render chunk c into ``parts`` (its video segment, gt and detections); ``tick(1)`` after each frame."""
    scene = stage.scene
    gt, batches = [], []
    cam = scene.camera

    def render(tmp: Path) -> None:
        with SegmentWriter(tmp, cam.width, cam.height, scene.fps) as writer:
            for t, frame, step in _timeline(scene, c):
                state = stage.set_time(t)
                ids = stage.agent_ids()
                if step is not None:
                    gt.append(gt_columns(step, cam, state, ids))
                if frame is not None:
                    rgb = stage.rgb()
                    writer.append(rgb)
                    batches.extend(d.detect(frame, frame / scene.fps, rgb, ids) for d in detectors)
                    tick(1)

    write_atomic(parts / f"{c:05d}.mp4", render)
    columns = {name: np.concatenate([g[name] for g in gt]) for name in GT_SCHEMA.names}
    write_parquet(parts / f"{c:05d}.gt.parquet", pa.Table.from_pydict(columns, schema=GT_SCHEMA))
    write_parquet(parts / f"{c:05d}.det.parquet", detections_table(batches))


def render_chunks(scene: Scene, seed: int, out: str | Path, chunks: list[int], lp_threads: int | None = None,
                  tick=lambda frames: None, on_chunk=lambda c: None, expect: dict | None = None) -> list[int]:
    """Render the given chunks (ascending) of ``scene`` with ``seed`` into ``out/_parts``; returns ``chunks``.

    What a worker process runs (and the serial run, in its own process). ``lp_threads``: Mesa llvmpipe's
    rendering threads (``LP_NUM_THREADS``) for this process, set before its GL context is made, so that
    N workers on N cores do not oversubscribe them. The rgb detector is warmed up before each chunk that
    does not follow the previous one, as on resume: the bytes do not depend on how chunks are split.
    ``tick(1)`` after each frame, ``on_chunk(c)`` after each chunk. ``expect``: the run's ``build_id()``
    (given to workers); DatasetError if this process's differs.
    """
    if expect is not None and build_id() != expect:
        mine = build_id()
        diff = ", ".join(f"{k} {mine.get(k)!s:.12} (run: {expect.get(k)!s:.12})"
                         for k in sorted(expect) if mine.get(k) != expect.get(k))
        raise DatasetError(f"worker {platform.node()} pid {os.getpid()} has other code than the run ({diff}): "
                           "it would render other bytes; use the same simgen, libraries and MUJOCO_GL everywhere")
    if lp_threads is not None:
        os.environ["LP_NUM_THREADS"] = str(lp_threads)
    parts, per = Path(out) / PARTS, _chunk_frames(scene)
    with Stage(scene, seed) as stage:
        detectors, previous = [], None
        for c in chunks:
            if previous is None or c != previous + 1:
                detectors = make_detectors(scene)
                _warm_up(stage, detectors, c * per)
            _run_chunk(stage, detectors, c, parts, tick)
            on_chunk(c)
            previous = c
    return chunks


def _blocks(chunks: list[int], n: int) -> list[list[int]]:
    """``chunks`` cut into at most n contiguous blocks of nearly equal length."""
    n = min(n, len(chunks))
    return [chunks[len(chunks) * i // n : len(chunks) * (i + 1) // n] for i in range(n)]


# ---- the final files -------------------------------------------------------------------------
def _finalize(scene: Scene, out: Path) -> None:
    parts, n = out / PARTS, _chunk_count(scene)
    gt = pa.concat_tables([pq.read_table(parts / f"{c:05d}.gt.parquet") for c in range(n)])
    det = pa.concat_tables([pq.read_table(parts / f"{c:05d}.det.parquet") for c in range(n)])
    rank = {name: i for i, name in enumerate(scene.detectors)}
    det_rank = np.array([rank[x] for x in det.column("detector").to_pylist()], dtype=np.int64)
    det = det.take(np.lexsort((det.column("frame").to_numpy(), det_rank)))
    write_parquet(out / "gt.parquet", gt)
    write_parquet(out / "detections.parquet", match_to_gt(det, gt))
    write_mot_gt(gt, scene.fps, out / "mot" / "gt.txt")
    write_atomic(out / "video.mp4", lambda p: concat([parts / f"{c:05d}.mp4" for c in range(n)], p))


# ---- the run -------------------------------------------------------------------------------
class Run:
    """One ``generate`` run on a held output folder: which chunks are left, progress in the manifest."""

    def __init__(self, scene: Scene, seed: int, folder: OutputFolder) -> None:
        self.scene, self.seed, self.out = scene, seed, folder.path
        self.n, self.recorded = _chunk_count(scene), None

    def frames(self, chunks: list[int]) -> int:
        per = _chunk_frames(self.scene)
        return sum(min(per, self.scene.frames_total - c * per) for c in chunks)

    def done(self, c: int) -> bool:
        return all((self.out / name).is_file() for name in _part_names(c))

    def todo(self) -> list[int]:
        return [c for c in range(self.n) if not self.done(c)]

    def record(self) -> None:
        """manifest.json's frames_done: the frames of the chunks done without a gap from the start."""
        first_missing = next((c for c in range(self.n) if not self.done(c)), self.n)
        frames = min(first_missing * _chunk_frames(self.scene), self.scene.frames_total)
        if frames != self.recorded:
            write_json_atomic(self.out / "manifest.json", manifest(self.scene, self.seed, frames, False))
            self.recorded = frames


class _ParentWatch:
    """A worker's ``tick``: exit when the process that started it is gone (a killed run leaves no writer)."""

    def __init__(self) -> None:
        self.parent = os.getpid()

    def __call__(self, frames: int) -> None:
        if os.getppid() != self.parent:
            os._exit(1)


def _follow(run: Run, todo: list[int], futures: list, bar: tqdm) -> None:
    """Wait for the futures (concurrent or Dask), moving the bar and manifest.json as chunks land; the first
    failure cancels the rest and is raised."""
    shown = 0
    try:
        while True:
            frames = run.frames([c for c in todo if run.done(c)])
            bar.update(frames - shown)
            shown = frames
            failed = next((f for f in futures if f.done() and f.exception() is not None), None)
            if failed is not None:
                failed.result()
            run.record()
            if all(f.done() for f in futures):
                return
            time.sleep(0.5)
    finally:
        for f in futures:
            f.cancel()


def _render_in_processes(run: Run, todo: list[int], workers: int, bar: tqdm) -> None:
    """Blocks of chunks in ``workers`` spawned processes, LP_NUM_THREADS = cores // workers (at least 1) each."""
    threads = max(1, (os.cpu_count() or 1) // workers)
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
        futures = [pool.submit(render_chunks, run.scene, run.seed, run.out, block, threads, _ParentWatch(),
                               expect=build_id())
                   for block in _blocks(todo, workers)]
        _follow(run, todo, futures, bar)


def _dask_client(address: str):
    """A Dask client of the scheduler at ``address``; DatasetError (one line) if it cannot connect."""
    from distributed import Client  # noqa: PLC0415  (optional: only --scheduler needs it)

    try:
        return Client(address, timeout="10s")
    except (OSError, ValueError) as e:
        raise DatasetError(f"--scheduler {address}: cannot connect ({str(e).splitlines()[0]})") from None


def _render_on_dask(run: Run, todo: list[int], client, bar: tqdm) -> None:
    """One block of chunks per worker of the Dask cluster (another worker takes it over if that one is lost);
    each worker's LP_NUM_THREADS is its host's cores over the workers on that host (at least 1). Workers
    should run one thread each (``dask worker ADDRESS --nthreads 1``)."""
    workers = sorted(client.scheduler_info()["workers"].items())
    cores, hosts = client.run(os.cpu_count), Counter(info["host"] for _, info in workers)
    futures = [client.submit(render_chunks, run.scene, run.seed, str(run.out), block,
                             max(1, cores[address] // hosts[info["host"]]), expect=build_id(), workers=[address],
                             allow_other_workers=True, pure=False)
               for (address, info), block in zip(workers, _blocks(todo, len(workers)))]  # fmt: skip
    _follow(run, todo, futures, bar)


def _check_resumable(scene: Scene, seed: int, folder: OutputFolder) -> dict | None:
    """The manifest of the run being resumed (None for a new folder); DatasetError if it is another run's."""
    if not folder.resumed:
        return None
    m = read_json(folder.marker)
    if m.get("config_hash") != scene.config_hash() or m.get("seed") != seed:
        raise DatasetError(f"{folder.path}: --resume: it was made with another scene config, run options or seed")
    if m.get("backend") != backend():
        raise DatasetError(f"{folder.path}: --resume: it was rendered with MUJOCO_GL={m.get('backend')}; resume with the same backend")
    return m


def generate(scene: Scene, seed: int, out: str | Path, resume: bool = False, progress: bool = True,
             workers: int = 1, scheduler: str | None = None) -> Path:
    """Write (or with ``resume`` continue) the dataset of ``scene`` with ``seed`` into ``out``.

    ``workers`` > 1 renders blocks of chunks in that many processes; ``scheduler`` (a Dask scheduler
    address) on the workers of that cluster (one block per worker; they must see ``out`` at the same path).
    The bytes are the same either way. Raises DatasetError or OutputFolderError (one line) when ``out``
    cannot be used; nothing of a folder that is not a simgen dataset is touched.
    """
    source_digest()  # the code this run starts with, which its workers must have (a process kept open across a
    # change of the sources should be restarted: the digest is taken at its first run, not when it imported simgen)
    with _dask_client(scheduler) if scheduler else nullcontext() as client, output_folder(out, FORMAT, resume) as folder:
        m = _check_resumable(scene, seed, folder)
        if m is not None and m.get("complete"):
            shutil.rmtree(folder.path / PARTS, ignore_errors=True)
            return folder.path
        run = Run(scene, seed, folder)
        folder.remove_temporaries([*FINAL, *(name for c in range(run.n) for name in _part_names(c))])
        with Stage(scene, seed) as stage:  # fails (backend) before anything but the lock is written
            run.record()  # the marker, first
            _write_static(scene, folder.path)
            if not (folder.path / "calibration.parquet").is_file():
                write_parquet(folder.path / "calibration.parquet", calibration_table(stage))
        (folder.path / PARTS).mkdir(exist_ok=True)
        todo = run.todo()
        with tqdm(total=scene.frames_total, initial=scene.frames_total - run.frames(todo),
                  unit="frame", desc=scene.name, disable=not progress, smoothing=0.05) as bar:
            if client is not None:
                _render_on_dask(run, todo, client, bar)
            elif workers > 1:
                _render_in_processes(run, todo, workers, bar)
            else:
                render_chunks(scene, seed, folder.path, todo, tick=bar.update, on_chunk=lambda c: run.record())
        _finalize(scene, folder.path)
        write_json_atomic(folder.path / "manifest.json", manifest(scene, seed, scene.frames_total, True))
        shutil.rmtree(folder.path / PARTS)
        return folder.path
