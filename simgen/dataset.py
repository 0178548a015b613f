"""Writing a dataset folder (data_schema.md): the run. ``simgen.static`` writes the static files and the
calibration table, ``simgen.chunks`` the chunks of frames, ``simgen.executors`` spreads chunks over processes or a
Dask cluster; the final files are made here.

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

import shutil
from contextlib import nullcontext
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from tqdm import tqdm

from homocal.files import output_folder, OutputFolder, read_json, write_atomic, write_json_atomic
from simgen.backend import backend
from simgen.chunks import PARTS, DatasetError, chunk_count, chunk_frames, part_names, versions, render_chunks, source_digest
from simgen.detection import match_to_gt, write_mot_gt
from simgen.executors import dask_client, render_in_processes, render_on_dask
from simgen.parquet import write_parquet
from simgen.scene import GT_DT, Scene
from simgen.stage import Stage
from simgen.static import calibration_table, write_static
from simgen.truth import camera_pose_table
from simgen.video import concat

FORMAT = "simgen-dataset"  # manifest.json's format tag: the folder is a simgen dataset
FINAL = ("manifest.json", "camera.json", "trapezoids.json", "site_map.png", "site_map.json", "calibration.parquet",
         "gt.parquet", "detections.parquet", "mot/gt.txt", "video.mp4", "camera_pose.parquet")  # fmt: skip
# camera_pose.parquet: only when the camera moves (Scene.moving)


def manifest(scene: Scene, seed: int, frames_done: int, complete: bool) -> dict:
    return {
        "format": FORMAT, "scene": scene.name, "seed": seed, "config_hash": scene.config_hash(),
        "versions": versions(),
        "frames_total": scene.frames_total, "frames_done": frames_done, "complete": complete,
        "fps": scene.fps, "gt_dt": GT_DT, "seconds": scene.seconds, "detectors": list(scene.detectors),
        "steps_total": scene.steps_total, "chunk_seconds": scene.chunk_seconds,
        "rgb_reset_every_frames": chunk_frames(scene), "rgb_warmup_frames": scene.rgb_warmup_frames,
        "backend": backend(), "quality": scene.quality,
    }  # fmt: skip


# ---- the final files -------------------------------------------------------------------------
def _finalize(scene: Scene, out: Path) -> None:
    parts, n = out / PARTS, chunk_count(scene)
    gt = pa.concat_tables([pq.read_table(parts / f"{c:05d}.gt.parquet") for c in range(n)])
    det = pa.concat_tables([pq.read_table(parts / f"{c:05d}.det.parquet") for c in range(n)])
    rank = {name: i for i, name in enumerate(scene.detectors)}
    det_rank = np.array([rank[x] for x in det.column("detector").to_pylist()], dtype=np.int64)
    det = det.take(np.lexsort((det.column("frame").to_numpy(), det_rank)))
    write_parquet(out / "gt.parquet", gt)
    write_parquet(out / "detections.parquet", match_to_gt(det, gt))
    write_mot_gt(gt, scene.fps, out / "mot" / "gt.txt")
    if scene.moving:
        write_parquet(out / "camera_pose.parquet", camera_pose_table(scene))
    write_atomic(out / "video.mp4", lambda p: concat([parts / f"{c:05d}.mp4" for c in range(n)], p))


# ---- the run -------------------------------------------------------------------------------
class Run:
    """One ``generate`` run on a held output folder: which chunks are left, progress in the manifest."""

    def __init__(self, scene: Scene, seed: int, folder: OutputFolder) -> None:
        self.scene, self.seed, self.out = scene, seed, folder.path
        self.n, self.recorded = chunk_count(scene), None

    def frames(self, chunks: list[int]) -> int:
        per = chunk_frames(self.scene)
        return sum(min(per, self.scene.frames_total - c * per) for c in chunks)

    def done(self, c: int) -> bool:
        return all((self.out / name).is_file() for name in part_names(c))

    def todo(self) -> list[int]:
        return [c for c in range(self.n) if not self.done(c)]

    def record(self) -> None:
        """manifest.json's frames_done: the frames of the chunks done without a gap from the start."""
        first_missing = next((c for c in range(self.n) if not self.done(c)), self.n)
        frames = min(first_missing * chunk_frames(self.scene), self.scene.frames_total)
        if frames != self.recorded:
            write_json_atomic(self.out / "manifest.json", manifest(self.scene, self.seed, frames, False))
            self.recorded = frames


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
    with dask_client(scheduler) if scheduler else nullcontext() as client, output_folder(out, FORMAT, resume) as folder:
        m = _check_resumable(scene, seed, folder)
        if m is not None and m.get("complete"):
            shutil.rmtree(folder.path / PARTS, ignore_errors=True)
            return folder.path
        run = Run(scene, seed, folder)
        folder.remove_temporaries([*FINAL, *(name for c in range(run.n) for name in part_names(c))])
        with Stage(scene, seed) as stage:  # fails (backend) before anything but the lock is written
            run.record()  # the marker, first
            write_static(scene, folder.path)
            if not (folder.path / "calibration.parquet").is_file():
                write_parquet(folder.path / "calibration.parquet", calibration_table(stage))
        (folder.path / PARTS).mkdir(exist_ok=True)
        todo = run.todo()
        with tqdm(total=scene.frames_total, initial=scene.frames_total - run.frames(todo),
                  unit="frame", desc=scene.name, disable=not progress, smoothing=0.05) as bar:
            if client is not None:
                render_on_dask(run, todo, client, bar)
            elif workers > 1:
                render_in_processes(run, todo, workers, bar)
            else:
                render_chunks(scene, seed, folder.path, todo, tick=bar.update, on_chunk=lambda c: run.record())
        _finalize(scene, folder.path)
        write_json_atomic(folder.path / "manifest.json", manifest(scene, seed, scene.frames_total, True))
        shutil.rmtree(folder.path / PARTS)
        return folder.path
