"""Frames per second of the whole ``simgen generate`` pipeline beside MuJoCo's raw render passes.

    python benchmarks/bench_simgen.py [--scene scenes/scene1] [--seconds 10] [--seed 0]

In one process: the raw passes (``mujoco.Renderer``: update_scene + RGB render + segmentation
render, nothing else) are timed frame by frame on the same scene, seed and frame times as the
pipeline, before and after one full ``generate`` run (kinematics, renders, ground truth, both
detectors, MP4 encoding, Parquet writing). Prints medians and the ratio pipeline / raw; the
target is <= 1.25. The machine's other load shows up in both; run it on a quiet machine.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import simgen.dataset as dataset
from simgen.model import CAMERA
from simgen.render import backend, mujoco
from simgen.scene import load_scene
from simgen.stage import Stage


def raw_ms(scene, seed: int, frames: range) -> list[float]:
    """Per-frame ms of update_scene + RGB render + segmentation render with a bare mujoco.Renderer."""
    out = []
    with Stage(scene, seed) as stage:
        r = mujoco.Renderer(stage.model, scene.camera.height, scene.camera.width)
        try:
            for k in frames:
                stage.set_time(k / scene.fps)  # kinematics: not a render pass, not timed
                t0 = time.perf_counter()
                r.update_scene(stage.data, camera=CAMERA)
                r.render()
                r.enable_segmentation_rendering()
                r.render()
                r.disable_segmentation_rendering()
                out.append((time.perf_counter() - t0) * 1e3)
        finally:
            r.close()
    return out


def pipeline(scene, seed: int) -> tuple[float, float]:
    """(seconds in the chunk loop, seconds end to end) of one generate run."""
    chunk_s = []
    run_chunk = dataset._run_chunk

    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        run_chunk(*args, **kwargs)
        chunk_s.append(time.perf_counter() - t0)

    dataset._run_chunk = timed
    try:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            dataset.generate(scene, seed, Path(tmp) / "out", progress=False)
            total = time.perf_counter() - t0
    finally:
        dataset._run_chunk = run_chunk
    return sum(chunk_s), total


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", type=Path, default=Path(__file__).resolve().parents[1] / "scenes" / "scene1")
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    scene = load_scene(a.scene).with_run(seconds=a.seconds)
    n = scene.frames_total
    cam = scene.camera
    print(f"scene {scene.name}, {cam.width}x{cam.height}, {n} frames at {scene.fps} fps, {scene.agent_count} agents, "
          f"detectors {','.join(scene.detectors)}, MUJOCO_GL={backend()}")

    raw = raw_ms(scene, a.seed, range(0, n, 2))
    loop_s, total_s = pipeline(scene, a.seed)
    raw += raw_ms(scene, a.seed, range(1, n, 2))
    raw_med = statistics.median(raw)
    loop_ms, total_ms = loop_s / n * 1e3, total_s / n * 1e3
    print(f"raw render passes (RGB + segmentation): median {raw_med:.1f} ms/frame = {1e3 / raw_med:.2f} frames/s")
    print(f"pipeline, frame loop (steady state):    {loop_ms:.1f} ms/frame = {1e3 / loop_ms:.2f} frames/s, "
          f"ratio {loop_ms / raw_med:.2f}")
    print(f"pipeline, end to end (calibration, final files included): {total_ms:.1f} ms/frame = "
          f"{1e3 / total_ms:.2f} frames/s, ratio {total_ms / raw_med:.2f}")
    print(f"target: ratio <= 1.25 -> {'met' if loop_ms / raw_med <= 1.25 else 'NOT met'} (steady state)")


if __name__ == "__main__":
    main()
