"""The ``simgen`` command: generate a dataset, preview a scene, import an external detector's output."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _fail(message: str, code: int = 2) -> int:
    print(f"simgen: error: {message}", file=sys.stderr)
    return code


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="simgen", description="MuJoCo synthetic traffic datasets (data_schema.md).")
    sub = p.add_subparsers(dest="command", required=True)

    g = sub.add_parser("generate", help="render a scene into a dataset folder")
    g.add_argument("scene_dir", type=Path)
    g.add_argument("--out", type=Path, required=True, help="dataset folder to write")
    g.add_argument("--seconds", type=float, help="simulated duration (default: the scene's run.seconds)")
    g.add_argument("--seed", type=int, required=True)
    g.add_argument("--fps", type=int, help="video frame rate (default: the scene's run.fps)")
    g.add_argument("--detectors", help="comma-separated, from: segmentation,rgb (default: the scene's)")
    g.add_argument("--resume", action="store_true", help="continue a killed run in --out")
    g.add_argument("--no-progress", action="store_true")

    v = sub.add_parser("preview", help="render one annotated frame (boxes, foot points, trapezoid, horizon)")
    v.add_argument("scene_dir", type=Path)
    v.add_argument("-o", "--output", type=Path, required=True, help="PNG to write")
    v.add_argument("--t", type=float, default=0.0, help="simulated time, seconds")
    v.add_argument("--seed", type=int, default=0)

    m = sub.add_parser("import-mot", help="add an external detector's MOTChallenge file to a dataset")
    m.add_argument("dataset_dir", type=Path)
    m.add_argument("mot_txt", type=Path)
    m.add_argument("--name", required=True, help="detector name for the detections.parquet rows (not segmentation or rgb)")
    m.add_argument("--min-iou", type=float, default=0.5, help="box IoU needed to associate a box with an agent (default 0.5)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        from simgen.render import BackendError  # first: guards the mujoco import
    except Exception as e:  # noqa: BLE001  (BackendError raised while importing simgen.render)
        return _fail(str(e), 3)
    from simgen.dataset import DatasetError, generate
    from simgen.scene import ConfigError, load_scene

    try:
        if args.command == "import-mot":
            from simgen.detection import import_into_dataset

            try:
                n = import_into_dataset(args.dataset_dir, args.mot_txt, args.name, args.min_iou)
            except (ValueError, OSError, KeyError) as e:
                return _fail(f"import-mot: {e}")
            print(f"simgen import-mot: {n} detections of {args.name!r} added to {args.dataset_dir / 'detections.parquet'}")
            return 0
        scene = load_scene(args.scene_dir)
        if args.command == "preview":
            from simgen.preview import preview

            preview(scene, args.seed, args.t, args.output)
            return 0
        detectors = args.detectors.split(",") if args.detectors else None
        scene = scene.with_run(seconds=args.seconds, fps=args.fps, detectors=detectors)
        generate(scene, args.seed, args.out, resume=args.resume, progress=not args.no_progress)
        return 0
    except (ConfigError, DatasetError) as e:
        return _fail(str(e))
    except BackendError as e:
        return _fail(str(e), 3)


if __name__ == "__main__":
    sys.exit(main())
