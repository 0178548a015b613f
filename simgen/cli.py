"""The ``simgen`` command: generate a dataset, preview a scene, import an external detector's output.

Every command fails with one line on stderr (``simgen: error: ...``) naming the flag or file at fault, and
exit code 2 (3 when no OpenGL backend works): bad numbers are refused where they are parsed, file-system
errors (a full disk, a read-only folder) are reported with the file they hit.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from simgen.scene import DETECTORS, QUALITIES


def _fail(message: str, code: int = 2) -> int:
    print(f"simgen: error: {message}", file=sys.stderr)
    return code


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (no usage block)."""

    def error(self, message: str):
        sys.exit(_fail(f"{self.prog.removeprefix('simgen ')}: {message}"))


def _number(kind, low: float, high: float = math.inf, low_open: bool = False):
    """argparse type: a finite ``kind`` in [low, high] (``(low, high]`` if low_open)."""
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None
        if not (math.isfinite(value) and (value > low if low_open else value >= low) and value <= high):
            what = "an integer" if kind is int else "a finite number"
            bounds = f"in {'(' if low_open else '['}{low:g}, {high:g}]" if math.isfinite(high) else f"{'>' if low_open else '>='} {low:g}"
            raise argparse.ArgumentTypeError(f"must be {what} {bounds}, got {text}")
        return value
    return parse


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="simgen", description="MuJoCo synthetic traffic datasets (data_schema.md).")
    sub = p.add_subparsers(dest="command", required=True)

    g = sub.add_parser("generate", help="render a scene into a dataset folder")
    g.add_argument("scene_dir", type=Path)
    g.add_argument("--out", type=Path, required=True, help="dataset folder to write")
    g.add_argument("--seconds", type=_number(float, 0, low_open=True), help="simulated duration (default: the scene's run.seconds)")
    g.add_argument("--seed", type=_number(int, 0), default=0, help="random seed, an integer >= 0 (default 0)")
    g.add_argument("--fps", type=_number(int, 1), help="video frame rate (default: the scene's run.fps)")
    g.add_argument("--detectors", help=f"comma-separated, from: {','.join(DETECTORS)} (default: the scene's)")
    g.add_argument("--quality", choices=QUALITIES, help="render preset (default: the scene's render.quality, else default)")
    g.add_argument("--workers", type=_number(int, 1), default=1, help="render chunks in this many processes (default 1)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="render chunks on the Dask cluster at ADDRESS (tcp://host:8786); its workers need the same "
                        "simgen, libraries and MUJOCO_GL as this process (a worker that differs stops the run)")
    g.add_argument("--resume", action="store_true", help="continue a killed run in --out")
    g.add_argument("--no-progress", action="store_true")

    v = sub.add_parser("preview", help="render one annotated frame (boxes, foot points, trapezoid, horizon)")
    v.add_argument("scene_dir", type=Path)
    v.add_argument("-o", "--output", type=Path, required=True, help="PNG to write")
    v.add_argument("--t", type=_number(float, 0), default=0.0, help="simulated time, seconds")
    v.add_argument("--seed", type=_number(int, 0), default=0)
    v.add_argument("--quality", choices=QUALITIES, help="render preset (default: the scene's)")

    m = sub.add_parser("import-mot", help="add an external detector's MOTChallenge file to a dataset")
    m.add_argument("dataset_dir", type=Path)
    m.add_argument("mot_txt", type=Path)
    m.add_argument("--name", required=True, help="detector name for the detections.parquet rows (not segmentation or rgb)")
    m.add_argument("--min-iou", type=_number(float, 0, 1, low_open=True), default=0.5,
                   help="box IoU in (0, 1] needed to associate a box with an agent (default 0.5)")
    return p


def _os_message(e: OSError) -> str:
    """One line: the file and the system's reason (``out/gt.parquet: No space left on device``)."""
    if e.filename is not None and e.strerror:
        return f"{e.filename}: {e.strerror}"
    return (str(e).strip().splitlines() or [type(e).__name__])[0]


def main(argv: list[str] | None = None) -> int:
    try:
        args = _parser().parse_args(argv)
    except SystemExit as e:  # --help, --version, or a refused argument (already printed)
        return e.code
    try:
        from simgen.render import BackendError  # first: guards the mujoco import
    except Exception as e:  # noqa: BLE001  (BackendError raised while importing simgen.render)
        return _fail(str(e), 3)
    from homocal.files import OutputFolderError
    from simgen.dataset import DatasetError, generate
    from simgen.scene import ConfigError, load_scene

    try:
        if args.command == "import-mot":
            from simgen.detection import import_into_dataset

            try:
                n = import_into_dataset(args.dataset_dir, args.mot_txt, args.name, args.min_iou)
            except (ValueError, OSError, KeyError) as e:
                return _fail(f"import-mot: {_os_message(e) if isinstance(e, OSError) else e}")
            print(f"simgen import-mot: {n} detections of {args.name!r} added to {args.dataset_dir / 'detections.parquet'}")
            return 0
        scene = load_scene(args.scene_dir).with_run(quality=args.quality)
        if args.command == "preview":
            from simgen.preview import preview

            preview(scene, args.seed, args.t, args.output)
            return 0
        detectors = args.detectors.split(",") if args.detectors else None
        scene = scene.with_run(seconds=args.seconds, fps=args.fps, detectors=detectors)
        t0 = time.perf_counter()
        generate(scene, args.seed, args.out, resume=args.resume, progress=not args.no_progress,
                 workers=args.workers, scheduler=args.scheduler)
        print(f"simgen generate: {args.out}: {scene.name}, seed {args.seed}, {scene.frames_total} frames at {scene.fps} fps, "
              f"detectors {','.join(scene.detectors)}, quality {scene.quality}, complete ({time.perf_counter() - t0:.1f} s)")
        return 0
    except (ConfigError, DatasetError, OutputFolderError) as e:
        return _fail(str(e))
    except BackendError as e:
        return _fail(str(e), 3)
    except OSError as e:
        return _fail(_os_message(e))


if __name__ == "__main__":
    sys.exit(main())
