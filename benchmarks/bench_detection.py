"""Cost of each simgen detector at 1280x720, and the HOG detector's quality on rendered scenes.

1. Cost: median and mean ms per frame on synthetic frames: a static textured background with 30
   textured rectangles ("pedestrians", 6x20 to 40x120 px) moving over it, and their agent-id map.
2. Quality (``--scene``): frames of a scene rendered every ``--every`` seconds for ``--seconds`` s;
   the reference is the segmentation detector's boxes of agents whose visible fraction is at least
   0.7 (hardly occluded); per upscale factor of the HOG detector: recall by reference box height,
   precision (boxes associated with any agent, IoU >= 0.3, over all boxes), the foot-point error
   against the segmentation foot point of the same agent (px, and in % of the box height), and ms/frame.

Run: python benchmarks/bench_detection.py [--frames N] [--scene scenes/scene1 --seconds 30 --every 0.5]
"""
from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from simgen.detection import BackgroundSubtractionDetector, HogDetector, SegmentationDetector

HEIGHT_BINS = (0, 50, 75, 100, 150, 200, 10_000)  # px, reference box height

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


def hog_quality(scene_dir: str, seconds: float, every: float, upscales: list[float]) -> None:
    """Print the HOG detector's recall by box height, precision, foot-point error and cost on rendered frames."""
    from simgen.scene import load_scene  # noqa: PLC0415  (mujoco only for this part)
    from simgen.stage import Stage  # noqa: PLC0415
    from simgen.truth import gt_columns  # noqa: PLC0415

    scene = load_scene(scene_dir)
    times = np.arange(0.0, seconds, every)
    detectors = [HogDetector(upscale=f) for f in upscales]
    ref, found, boxes, matched, errors, cost = [], {f: [] for f in upscales}, dict.fromkeys(upscales, 0), dict.fromkeys(upscales, 0), {f: [] for f in upscales}, {f: [] for f in upscales}
    with Stage(scene, seed=0, t_end=seconds) as stage:
        for t in times:
            state = stage.set_time(float(t))
            rgb, ids = stage.rgb(), stage.agent_ids()
            gt = gt_columns(0, scene.camera, state, ids)
            keep = gt["visible_fraction"] >= 0.7
            agents, height = gt["agent_id"][keep], (gt["y2"] - gt["y1"])[keep]
            foot = np.column_stack([(gt["x1"] + gt["x2"]) / 2, gt["y2"]])[keep]
            ref.append(height)
            for f, det in zip(upscales, detectors):
                start = time.perf_counter()
                batch = det.detect(0, float(t), rgb, ids)
                cost[f].append((time.perf_counter() - start) * 1e3)
                boxes[f] += len(batch)
                matched[f] += int((batch.agent_id >= 0).sum())
                hit = np.isin(agents, batch.agent_id)
                found[f].append(hit)
                where = [int(np.flatnonzero(batch.agent_id == a)[0]) for a in agents[hit]]
                errors[f] += [(np.hypot(*(batch.foot[w] - foot[i])), h) for w, i, h in zip(where, np.flatnonzero(hit), height[hit])]
    height = np.concatenate(ref)
    bins = np.digitize(height, HEIGHT_BINS) - 1
    print(f"HOG on {scene.name}: {len(times)} frames ({every} s apart over {seconds} s), {len(height)} reference boxes "
          f"(segmentation, visible fraction >= 0.7)")
    labels = [f"{lo}-{hi}" if hi < 10_000 else f">={lo}" for lo, hi in zip(HEIGHT_BINS[:-1], HEIGHT_BINS[1:])]
    print(f"  {'box height px':>14}: " + " ".join(f"{label:>8}" for label in labels))
    print(f"  {'references':>14}: " + " ".join(f"{(bins == b).sum():>8d}" for b in range(len(labels))))
    for f in upscales:
        hit = np.concatenate(found[f])
        recall = [f"{hit[bins == b].mean() * 100:7.1f}%" if (bins == b).any() else f"{'-':>8}" for b in range(len(labels))]
        print(f"  {'recall x' + str(f):>14}: " + " ".join(recall))
    for f in upscales:
        err = np.array(errors[f]).reshape(-1, 2)
        print(f"  upscale {f}: recall {np.concatenate(found[f]).mean() * 100:.1f}% overall, precision "
              f"{matched[f] / max(boxes[f], 1) * 100:.1f}% ({boxes[f]} boxes), foot-point error vs segmentation median "
              f"{np.median(err[:, 0]) if len(err) else float('nan'):.1f} px = {np.median(err[:, 0] / err[:, 1]) * 100 if len(err) else float('nan'):.1f}% "
              f"of the box height (p90 {np.percentile(err[:, 0], 90) if len(err) else float('nan'):.1f} px); "
              f"{np.median(cost[f]):.0f} ms/frame (median)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--scene", help="also measure the HOG detector's quality on this scene's rendered frames")
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--every", type=float, default=0.5)
    parser.add_argument("--upscale", default="1,2", help="comma-separated HOG upscale factors to compare")
    args = parser.parse_args()
    if args.scene:
        hog_quality(args.scene, args.seconds, args.every, [float(f) for f in args.upscale.split(",")])
    data = list(frames(args.frames))
    print(f"{args.frames} frames {WIDTH}x{HEIGHT}, {AGENTS} agents, cv2 threads {cv2.getNumThreads()}")
    for detector in (SegmentationDetector(), BackgroundSubtractionDetector(), HogDetector()):
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
