"""A dataset's frames, rendered in chunks of ``chunk_seconds`` into ``_parts/`` (dataset.py's module docstring
tells how they make a resumable run): each chunk's video segment, ground truth and detections.
"""
from __future__ import annotations

import functools
import hashlib
import os
import platform
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa

import homocal.geometry
import simgen
from homocal.files import write_atomic
from simgen.backend import backend, mujoco
from simgen.detection import BackgroundSubtractionDetector, HogDetector, SegmentationDetector, detections_table
from simgen.parquet import write_parquet
from simgen.scene import GT_RATE, Scene
from simgen.stage import Stage
from simgen.truth import GT_SCHEMA, gt_columns
from simgen.video import SegmentWriter

PARTS = "_parts"


class DatasetError(RuntimeError):
    """The output folder cannot be (re)used; one-line message."""


def versions() -> dict:
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
    return {**versions(), "backend": backend(), "source": source_digest()}


def chunk_frames(scene: Scene) -> int:
    return round(scene.chunk_seconds * scene.fps)


def chunk_count(scene: Scene) -> int:
    return -(-scene.frames_total // chunk_frames(scene))


def _timeline(scene: Scene, c: int) -> list[tuple[float, int | None, int | None]]:
    """Chunk c's instants in time order: (pose time s, frame or None, gt step or None); exact merge."""
    per_f, per_s = chunk_frames(scene), round(scene.chunk_seconds * GT_RATE)
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
        "rgb": lambda: BackgroundSubtractionDetector(reset_every=chunk_frames(scene), warmup=scene.rgb_warmup_frames),
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


def part_names(c: int) -> list[str]:
    """Chunk c's files in the dataset folder, in the order they are written (the last one marks it done)."""
    return [f"{PARTS}/{c:05d}.mp4", f"{PARTS}/{c:05d}.gt.parquet", f"{PARTS}/{c:05d}.det.parquet"]


def run_chunk(stage: Stage, detectors: list, c: int, parts: Path, tick=lambda frames: None) -> None:
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
                    gt.append(gt_columns(step, stage.camera, state, ids))
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
    parts, per = Path(out) / PARTS, chunk_frames(scene)
    with Stage(scene, seed) as stage:
        detectors, previous = [], None
        for c in chunks:
            if previous is None or c != previous + 1:
                detectors = make_detectors(scene)
                _warm_up(stage, detectors, c * per)
            run_chunk(stage, detectors, c, parts, tick)
            on_chunk(c)
            previous = c
    return chunks
