"""homocal watch with the roll (OnlineCalibrator(estimate_roll=True)) on render-free streams of a scene's walkers
(simgen.boxstream.box_stream: boxes from their bodies' geometry seen by the moving camera, each person's id given).

Per seed, --minutes at FPS, the camera steady or, at --at seconds, rolled by 1 or 2 degrees or tilted 1 degree
further down (a step). Printed per case: the alarms before the move (false), the detection delay (s: the first
alarm after the move of a test that sees it, the roll test for a roll and the row or drift test for a tilt, on the side
it moved) median and per seed, the missed moves, the people and their columns' interquartile range (px: the roll is
fitted when it spans ROLL_SPREAD of the width) and the roll estimate at the end against the camera's.

    python research/watch_roll.py --scene scene1 --seeds 3 --minutes 10 [--drift-test no]
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.watch import OnlineCalibrator  # noqa: E402
from homocal.watch.calibrator import ROLL_SPREAD  # noqa: E402
from simgen.boxstream import box_stream  # noqa: E402
from simgen.scene import CameraMove, load_scene  # noqa: E402

HEIGHT = (1.71, 0.09)  # simgen's people (data_schema.md), as research/watch.py's
FPS = 5.0  # the stream's frame rate: research/watch.py's default
CASES = {  # name: (the move at ``at`` s, the test that sees it, the side it moves: Move.direction)
    "steady": (lambda at: (), None, 0),
    "roll 1 degree": (lambda at: (CameraMove(at, roll_deg=1.0),), ("roll",), -1),
    "roll 2 degrees": (lambda at: (CameraMove(at, roll_deg=2.0),), ("roll",), -1),
    "tilt 1 degree": (lambda at: (CameraMove(at, tilt_deg=1.0),), ("row", "drift"), -1),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="scene1")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--at", type=float, default=300.0, help="the move's time, s")
    ap.add_argument("--drift-test", choices=("yes", "no"), default="yes", help="homocal watch's --drift-test")
    args = ap.parse_args()
    scene = load_scene(Path(__file__).resolve().parents[1] / "simgen" / "scenes" / args.scene)
    cam = scene.camera
    print(f"{args.scene}: {args.seeds} seeds x {args.minutes:g} min at {FPS:g} fps, the move at {args.at:g} s; "
          f"the roll is fitted when the people's columns' IQR spans {ROLL_SPREAD * cam.width:.0f} px")
    for name, (moves, test, side) in CASES.items():
        moving = dataclasses.replace(scene, moves=moves(args.at))
        delays, false, lines = [], 0, []
        for seed in range(args.seeds):
            cal = OnlineCalibrator(cam.K, cam.mount_height_m, FPS, (cam.width, cam.height), *HEIGHT,
                                   estimate_roll=True, drift_test=args.drift_test == "yes")
            columns, found, state = [], None, None
            for frame, xyxy, ids in box_stream(moving, seed, args.minutes * 60, FPS):
                state = cal.update(frame, xyxy, ids)
                columns += state.person_columns
                m = state.move
                if m and (test is None or m.detected_s < args.at):
                    false += 1
                elif m and found is None and m.test in test and m.direction == side:
                    found = m.detected_s - args.at
            delays.append(found)
            iqr = np.subtract(*np.percentile(columns, [75, 25]))
            truth = moving.camera_at(state.t_s).roll_deg
            lines.append(f"seed {seed}: {len(columns)} people, columns' IQR {iqr:.0f} px, delay "
                         f"{'-' if found is None else f'{found:.1f} s'}, roll at the end {state.roll_deg:.2f} +- "
                         f"{state.roll_sigma_deg:.2f} degrees (the camera's {truth:g})")
        seen = [d for d in delays if d is not None]
        summary = "" if test is None else (f"; delay median {np.median(seen):.1f} s" if seen else "; delay -") + \
            f", missed {len(delays) - len(seen)} of {len(delays)}"
        print(f"\n{name}: {false} false alarms in {args.seeds * (args.at if test else args.minutes * 60) / 3600:.2f} h"
              + summary)
        for line in lines:
            print("  " + line)


if __name__ == "__main__":
    main()
