"""Median and mean ms per frame of each simgen detector at 1280x720 on synthetic frames.

A static textured background with 30 textured rectangles ("pedestrians", 6x20 to 40x120 px)
moving over it, and their agent-id map. Run: python benchmarks/bench_detection.py [--frames N]
"""
from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from simgen.detection import BackgroundSubtractionDetector, SegmentationDetector

WIDTH, HEIGHT, AGENTS = 1280, 720, 30


def frames(n: int, seed: int = 0):
    """Yield (frame, rgb (H, W, 3) uint8, agent_ids (H, W) int32) for n frames."""
    rng = np.random.default_rng(seed)
    background = cv2.GaussianBlur(rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8), (0, 0), 2.0)
    size = rng.uniform(0.15, 1.0, AGENTS)[:, None] * [40, 120]
    start = rng.uniform([0, 150], [WIDTH - 40, HEIGHT - 120], (AGENTS, 2))
    velocity = rng.uniform(-4, 4, (AGENTS, 2))
    colour = rng.integers(0, 256, (AGENTS, 3))
    for frame in range(n):
        rgb, ids = background.copy(), np.full((HEIGHT, WIDTH), -1, np.int32)
        corner = np.abs((start + velocity * frame) % (2 * (np.array([WIDTH, HEIGHT]) - size)) - (np.array([WIDTH, HEIGHT]) - size))
        for agent, ((c, r), (w, h)) in enumerate(zip(corner.astype(int), size.astype(int))):
            rgb[r : r + h, c : c + w] = colour[agent] // 2 + background[r : r + h, c : c + w] // 4
            ids[r : r + h, c : c + w] = agent
        yield frame, rgb, ids


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    args = parser.parse_args()
    data = list(frames(args.frames))
    print(f"{args.frames} frames {WIDTH}x{HEIGHT}, {AGENTS} agents, cv2 threads {cv2.getNumThreads()}")
    for detector in (SegmentationDetector(), BackgroundSubtractionDetector()):
        times, count = [], 0
        for frame, rgb, ids in data:
            start = time.perf_counter()
            count += len(detector.detect(frame, frame / 20, rgb, ids))
            times.append(time.perf_counter() - start)
        times = np.array(times[10:]) * 1e3
        print(
            f"{detector.name:>12}: median {np.median(times):.2f} ms/frame, mean {times.mean():.2f}, "
            f"max {times.max():.2f}; {count / len(data):.1f} detections/frame"
        )


if __name__ == "__main__":
    main()
