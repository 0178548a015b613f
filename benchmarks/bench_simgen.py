"""Frames per second of the whole ``simgen generate`` pipeline beside MuJoCo's raw render passes.

    python benchmarks/bench_simgen.py [--scene scenes/scene1] [--seconds 20] [--seed 0] [--quality default]
    python benchmarks/bench_simgen.py --presets [--frames 60]       # RGB render cost of each quality preset
    python benchmarks/bench_simgen.py --parallel 2 [--repeats 3]    # generate serial vs --workers 2
    python benchmarks/bench_simgen.py --rgb-vs-segmentation DATASET ...  # what the rgb detector sees, per dataset
    python benchmarks/bench_simgen.py --lp-threads 0 1 2 [--frames 20]   # CPU per frame by llvmpipe threads

In one process, one ``generate`` run (kinematics, renders, ground truth, both detectors, MP4
encoding, Parquet writing) is timed chunk by chunk; before each chunk, the raw passes of the same
frames (every other one) are timed with a bare ``mujoco.Renderer`` on the same scene and seed:
update_scene + RGB render + segmentation render, nothing else. Interleaving them this way lets
both see the same machine load. Prints, per chunk, pipeline ms/frame over the median raw ms/frame
of the same chunk's frames, and the medians (target ratio <= 1.25). On a machine shared with
other jobs the raw time itself moves by +-30 % from chunk to chunk, so it also prints the time the
pipeline spends inside its own render calls against everything else it does in the same frames
(encoding runs in ffmpeg's process; its CPU shows up as slower renders there).

``--presets``: one renderer per quality preset (simgen.render.QUALITY) on the same Stage; each frame is
rendered (RGB) by every preset in turn, so all see the same load; prints the median ms/frame of each.
``--parallel N``: whole ``simgen generate`` runs (separate processes, as a user types them), serial and
with ``--workers N`` alternately, ``--repeats`` times each; prints each wall time and CPU time (all the
run's processes), the medians and their ratio (the speed-up), and checks that the datasets are
byte-identical. On a machine shared with other jobs the wall-time ratio measures the share of the cores
each run got as much as the code; the CPU times say whether the workers waste any.
"""
from __future__ import annotations

import argparse
import filecmp
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

import simgen.chunks as chunks
import simgen.dataset as dataset
from simgen.model import CAMERA
from simgen.backend import backend, mujoco
from simgen.render import QUALITY, FrameRenderer, apply_quality
from simgen.scene import load_scene
from simgen.stage import Stage


class RawPasses:
    """The render passes alone, on a Stage of its own; ``time(frames)`` -> ms per frame."""

    def __init__(self, scene, seed: int) -> None:
        self.stage = Stage(scene, seed)
        self.renderer = mujoco.Renderer(self.stage.model, scene.camera.height, scene.camera.width)

    def time(self, frames) -> list[float]:
        out, r = [], self.renderer
        for k in frames:
            self.stage.set_time(k / self.stage.scene.fps)  # kinematics: not a render pass, not timed
            t0 = time.perf_counter()
            r.update_scene(self.stage.data, camera=CAMERA)
            r.render()
            r.enable_segmentation_rendering()
            r.render()
            r.disable_segmentation_rendering()
            out.append((time.perf_counter() - t0) * 1e3)
        return out

    def close(self) -> None:
        self.renderer.close()
        self.stage.close()


def presets(scene, seed: int, frames: int) -> None:
    """Median RGB render ms/frame of each quality preset, interleaved frame by frame."""
    with Stage(scene, seed) as stage:
        renderers = {}
        for q in QUALITY:
            apply_quality(stage.model, q)  # read when the renderer (its GL buffers) is made, and by update_scene
            renderers[q] = mujoco.Renderer(stage.model, scene.camera.height, scene.camera.width)
        ms = {q: [] for q in QUALITY}
        for k in range(frames):
            stage.set_time(k / scene.fps)
            for q, r in renderers.items():
                apply_quality(stage.model, q)  # castshadow is read per update_scene
                t0 = time.perf_counter()
                r.update_scene(stage.data, camera=CAMERA)
                r.render()
                ms[q].append((time.perf_counter() - t0) * 1e3)
        for r in renderers.values():
            r.close()
    for q, samples in QUALITY.items():
        print(f"quality {q:8s} (offsamples {samples[0]}, shadow map {samples[1]} px): RGB median {statistics.median(ms[q]):.1f} ms/frame "
              f"over {frames} frames")


def parallel(scene_dir: Path, seconds: float, seed: int, workers: int, repeats: int) -> None:
    """Serial and ``--workers`` generate runs, alternately; wall-time medians and the speed-up."""
    walls: dict[int, list[float]] = {1: [], workers: []}
    cpus: dict[int, list[float]] = {1: [], workers: []}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(repeats):
            for w in (1, workers):
                out = Path(tmp) / f"w{w}_{r}"
                cmd = [sys.executable, "-m", "simgen.cli", "generate", str(scene_dir), "--out", str(out), "--seconds",
                       str(seconds), "--seed", str(seed), "--workers", str(w), "--no-progress"]  # fmt: skip
                t0, c0 = time.perf_counter(), _children_cpu()
                subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
                walls[w].append(time.perf_counter() - t0)
                cpus[w].append(_children_cpu() - c0)
                print(f"  repeat {r}, --workers {w}: {walls[w][-1]:.1f} s wall, {cpus[w][-1]:.1f} s CPU "
                      f"(load average {os.getloadavg()[0]:.1f})", flush=True)
        a, b = Path(tmp) / "w1_0", Path(tmp) / f"w{workers}_0"
        files = sorted(str(p.relative_to(a)) for p in a.rglob("*") if p.is_file())
        same = filecmp.cmpfiles(a, b, files, shallow=False)[0] == files
    frames = round(seconds * load_scene(scene_dir).fps)
    s, p = statistics.median(walls[1]), statistics.median(walls[workers])
    print(f"serial: median {s:.1f} s ({frames / s:.2f} frames/s); --workers {workers}: median {p:.1f} s "
          f"({frames / p:.2f} frames/s); speed-up {s / p:.2f}x (medians of {repeats}, interleaved, end to end); "
          f"datasets byte-identical: {same}; {os.cpu_count()} cores")
    print(f"CPU time (all processes of the run, ffmpeg included): serial median {statistics.median(cpus[1]):.1f} s, "
          f"--workers {workers} median {statistics.median(cpus[workers]):.1f} s")


def _children_cpu() -> float:
    """User + system CPU seconds of this process's finished descendants."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def rgb_vs_segmentation(datasets: list[Path], min_height: float = 20.0) -> None:
    """Per dataset (e.g. one per quality preset): the rgb detector's boxes against the segmentation boxes
    of the same frame and agent, on agents at least ``min_height`` px tall, after the first chunk's warm-up."""
    for d in datasets:
        a = {k: np.asarray(v) for k, v in pq.read_table(d / "detections.parquet").to_pydict().items()}
        warm = a["frame"] >= json.loads((d / "manifest.json").read_text())["rgb_warmup_frames"]
        seg = warm & (a["detector"] == "segmentation") & (a["y2"] - a["y1"] >= min_height)
        index = {(f, g): i for i, f, g in zip(np.flatnonzero(seg), a["frame"][seg], a["agent_id"][seg])}
        rgb = np.flatnonzero(warm & (a["detector"] == "rgb") & (a["agent_id"] >= 0))
        r, s = np.array([(i, index[a["frame"][i], a["agent_id"][i]]) for i in rgb if (a["frame"][i], a["agent_id"][i]) in index]).T
        width = lambda i: a["x2"][i] - a["x1"][i]  # noqa: E731
        print(f"{d.name}: quality {json.loads((d / 'manifest.json').read_text())['quality']}: rgb found {len(r)} of "
              f"{seg.sum()} agents >= {min_height:g} px tall ({len(r) / seg.sum():.1%}); foot point vs segmentation's: "
              f"|du| median {np.median(np.abs(a['u'][r] - a['u'][s])):.2f} px, dv median {np.median(a['v'][r] - a['v'][s]):+.2f} px; "
              f"box width / segmentation's: median {np.median(width(r) / width(s)):.2f}")


def lp_threads(scene_dir: Path, seed: int, counts: list[int], frames: int) -> None:
    """CPU and wall ms per frame of the RGB + segmentation passes with LP_NUM_THREADS = each count, each in
    a process of its own (the variable is read when the GL context is made), interleaved twice."""
    for _ in range(2):
        for n in counts:
            subprocess.run([sys.executable, __file__, "--scene", str(scene_dir), "--seed", str(seed), "--frames", str(frames),
                            "--one-lp", str(n)], check=True, env={**os.environ, "LP_NUM_THREADS": str(n)})  # fmt: skip


def one_lp(scene, seed: int, frames: int) -> None:
    with Stage(scene, seed) as stage:
        stage.set_time(0.0)
        stage.rgb()  # the first renders compile llvmpipe's shaders: not timed
        stage.agent_ids()
        r0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        for k in range(frames):
            stage.set_time(5.0 + k / scene.fps)
            stage.rgb()
            stage.agent_ids()
        r1, t1 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
    cpu = (r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime) / frames * 1e3
    print(f"LP_NUM_THREADS={os.environ['LP_NUM_THREADS']}: RGB + segmentation {cpu:.0f} ms CPU, {(t1 - t0) / frames * 1e3:.0f} ms wall "
          f"per frame ({frames} frames, load average {os.getloadavg()[0]:.1f})", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", type=Path, default=Path(__file__).resolve().parents[1] / "scenes" / "scene1")
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quality", choices=list(QUALITY), help="render preset of the pipeline run (default: the scene's)")
    p.add_argument("--presets", action="store_true", help="time the RGB pass of each quality preset instead")
    p.add_argument("--frames", type=int, default=60, help="frames per preset with --presets, per process with --lp-threads")
    p.add_argument("--parallel", type=int, metavar="N", help="time generate serial vs --workers N instead")
    p.add_argument("--repeats", type=int, default=3, help="runs of each with --parallel")
    p.add_argument("--rgb-vs-segmentation", type=Path, nargs="+", metavar="DATASET", help="compare the detectors in datasets instead")
    p.add_argument("--lp-threads", type=int, nargs="+", metavar="N", help="CPU per frame with LP_NUM_THREADS = each N instead")
    p.add_argument("--one-lp", type=int, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.lp_threads:
        return lp_threads(a.scene, a.seed, a.lp_threads, a.frames)
    if a.one_lp is not None:
        return one_lp(load_scene(a.scene), a.seed, a.frames)
    if a.rgb_vs_segmentation:
        return rgb_vs_segmentation(a.rgb_vs_segmentation)
    if a.parallel:
        return parallel(a.scene, a.seconds, a.seed, a.parallel, a.repeats)
    scene = load_scene(a.scene).with_run(seconds=a.seconds, quality=a.quality)
    if a.presets:
        return presets(scene, a.seed, a.frames)
    cam, n = scene.camera, scene.frames_total
    print(f"scene {scene.name}, {cam.width}x{cam.height}, {n} frames at {scene.fps} fps, {scene.agent_count} agents, "
          f"detectors {','.join(scene.detectors)}, quality {scene.quality}, MUJOCO_GL={backend()}")

    raw, chunk_ms, ratios, inside_ms, chunk_inside = RawPasses(scene, a.seed), [], [], [0.0], []
    per_chunk, run_chunk = chunks.chunk_frames(scene), chunks.run_chunk
    raw_ms: list[float] = []

    def timed(stage, detectors, c, parts, tick):
        frames = range(c * per_chunk, min((c + 1) * per_chunk, n))
        raw_chunk = raw.time(frames[::2])
        raw_ms.extend(raw_chunk)
        t0, inside0 = time.perf_counter(), inside_ms[0]
        run_chunk(stage, detectors, c, parts, tick)
        chunk_ms.append((time.perf_counter() - t0) * 1e3 / len(frames))
        chunk_inside.append((inside_ms[0] - inside0) / len(frames))
        ratios.append(chunk_ms[-1] / statistics.median(raw_chunk))
        print(f"  chunk {c}: raw {statistics.median(raw_chunk):.1f} ms/frame, pipeline {chunk_ms[-1]:.1f} ms/frame, "
              f"ratio {ratios[-1]:.2f}", flush=True)

    def clocked(method):
        def wrapper(self):
            t0 = time.perf_counter()
            out = method(self)
            inside_ms[0] += (time.perf_counter() - t0) * 1e3
            return out
        return wrapper

    originals = FrameRenderer.rgb, FrameRenderer.segmentation
    chunks.run_chunk = timed
    try:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            FrameRenderer.rgb, FrameRenderer.segmentation = map(clocked, originals)
            dataset.generate(scene, a.seed, Path(tmp) / "out", progress=False)
            FrameRenderer.rgb, FrameRenderer.segmentation = originals
            total_s = time.perf_counter() - t0 - sum(raw_ms) / 1e3
    finally:
        chunks.run_chunk = run_chunk
        FrameRenderer.rgb, FrameRenderer.segmentation = originals
        raw.close()

    raw_med, loop_ms, total_ms = statistics.median(raw_ms), statistics.median(chunk_ms), total_s / n * 1e3
    print(f"raw render passes (RGB + segmentation): median {raw_med:.1f} ms/frame = {1e3 / raw_med:.2f} frames/s "
          f"({len(raw_ms)} frames)")
    print(f"pipeline, chunk loop (median over {len(chunk_ms)} chunks): {loop_ms:.1f} ms/frame = "
          f"{1e3 / loop_ms:.2f} frames/s; median of the per-chunk ratios {statistics.median(ratios):.2f}")
    print(f"pipeline, end to end (calibration and final files included): {total_ms:.1f} ms/frame = "
          f"{1e3 / total_ms:.2f} frames/s, ratio {total_ms / raw_med:.2f}")
    inside = statistics.median(chunk_inside)
    print(f"inside the pipeline: render calls {inside:.1f} ms/frame, everything else {loop_ms - inside:.1f} ms/frame, "
          f"ratio {loop_ms / inside:.2f}")
    print(f"target ratio <= 1.25: {'met' if statistics.median(ratios) <= 1.25 else 'NOT met'} (chunk loop), "
          f"{'met' if total_ms / raw_med <= 1.25 else 'NOT met'} (end to end)")


if __name__ == "__main__":
    main()
