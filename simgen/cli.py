"""The ``simgen`` command: generate a dataset, preview a scene, list the shipped scenes, import an external
detector's output, export a dataset for MOTChallenge tools.

Each subcommand has a handler ``fn(args) -> str`` (``parser.set_defaults(handler=fn)``) that returns its
one-line summary; ``main`` prints it as ``simgen COMMAND: ...``. Every subcommand that writes takes
``-o/--out``. A scene is a folder or the name of a shipped scene (``simgen scenes``).

Every command fails with one line on stderr (``simgen: error: ...``) naming the flag or file at fault, and
exit code 2 (3 when no OpenGL backend works): bad numbers are refused where they are parsed, file-system
errors (a full disk, a read-only folder) are reported with the file they hit.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import simgen
from homocal.arguments import SEED, number as _number
from homocal.files import OutputFolderError, os_message, output_folder
from homocal.progress import add_progress_option, show_progress
from homocal.names import check_name
from simgen.scene import DETECTORS, MAX_FPS, MAX_SECONDS, QUALITIES, detectors_problem

FILE_COMMANDS = ("import-mot", "export-mot")  # their errors name the command (generate's and preview's name the file or field)


def _fail(message: str, code: int = 2) -> int:
    print(f"simgen: error: {message}", file=sys.stderr)
    return code


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (no usage block)."""

    def error(self, message: str):
        command = self.prog.removeprefix("simgen").strip()
        sys.exit(_fail(f"{command}: {message}" if command else f"{message} (see simgen --help)"))


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="simgen", description="MuJoCo synthetic traffic datasets (data_schema.md).")
    p.add_argument("--version", action="version", version=f"simgen {simgen.__version__}",
                   help="print simgen's version (the installed homocal distribution's) and exit")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    g = sub.add_parser("generate", help="render a scene into a dataset folder")
    _add_scene(g)
    _add_out(g, "dataset folder to write (new or empty; with --resume, a killed run's)")
    g.add_argument("--seconds", type=_number(float, 0, MAX_SECONDS, low_open=True), help="simulated duration (default: the scene's run.seconds)")
    g.add_argument("--seed", type=SEED, default=0, help="random seed, an integer >= 0 (default 0)")
    g.add_argument("--fps", type=_number(int, 1, MAX_FPS), help="video frame rate (default: the scene's run.fps)")
    g.add_argument("--detectors", type=_detectors, help=f"comma-separated, from: {','.join(DETECTORS)} (default: the scene's)")
    g.add_argument("--quality", choices=QUALITIES, help="render preset (default: the scene's render.quality, else default)")
    g.add_argument("--workers", type=_number(int, 1), default=1, help="render chunks in this many processes (default 1)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="render chunks on the Dask cluster at ADDRESS (tcp://host:8786); its workers need the same "
                        "simgen, libraries and MUJOCO_GL as this process (a worker that differs stops the run)")
    g.add_argument("--resume", action="store_true", help="continue a killed run in --out")
    add_progress_option(g)
    g.set_defaults(handler=handle_generate)

    v = sub.add_parser("preview", help="render one annotated frame (boxes, foot points, trapezoid, horizon)")
    _add_scene(v)
    _add_out(v, "PNG to write")
    v.add_argument("--t", type=_number(float, 0, MAX_SECONDS), default=0.0, help="simulated time, seconds (default 0)")
    v.add_argument("--seed", type=SEED, default=0, help="random seed of the walks, an integer >= 0 (default 0)")
    v.add_argument("--quality", choices=QUALITIES, help="render preset (default: the scene's)")
    v.set_defaults(handler=handle_preview)

    s = sub.add_parser("scenes", help="list the shipped scenes (a name is a scene for generate and preview)")
    s.set_defaults(handler=handle_scenes)

    m = sub.add_parser("import-mot", help="add an external detector's MOTChallenge file to a dataset",
                       usage="simgen import-mot [-h] MOT_TXT --name NAME -o DATASET [--min-iou MIN_IOU]\n"
                             "       simgen import-mot [-h] DATASET MOT_TXT --name NAME [--min-iou MIN_IOU]")
    m.add_argument("files", type=Path, nargs="+", metavar="[DATASET] MOT_TXT",
                   help="the MOTChallenge det.txt or gt.txt to import (data_schema.md); the dataset folder before it "
                        "when -o/--out is not given")
    _add_out(m, "the complete simgen dataset folder whose detections.parquet gains the rows", required=False)
    m.add_argument("--name", required=True, type=_detector_name,
                   help="detector name for the detections.parquet rows and det/NAME.txt of export-mot: 1-64 letters, "
                        "digits, '.', '_' or '-', not starting with '.' (not segmentation, rgb or hog)")
    m.add_argument("--min-iou", type=_number(float, 0, 1, low_open=True), default=0.5,
                   help="box IoU in (0, 1] needed to associate a box with an agent (default 0.5)")
    m.set_defaults(handler=handle_import_mot)

    e = sub.add_parser("export-mot", help="write a dataset as a MOTChallenge sequence folder (TrackEval, motmetrics)")
    e.add_argument("dataset_dir", type=Path, help="a complete simgen dataset folder")
    _add_out(e, "sequence folder to write: seqinfo.ini, gt/gt.txt, det/<detector>.txt (new, empty or an earlier export)")
    e.set_defaults(handler=handle_export_mot)
    return p


def _add_scene(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", help="a scene folder (scene.toml, the MJCF and its ground texture) or the name of a "
                                      "shipped scene (simgen scenes)")


def _add_out(parser: argparse.ArgumentParser, help: str, required: bool = True) -> None:  # noqa: A002  (argparse's name)
    """-o/--out, the one output flag of every subcommand that writes (a folder or an image: never ``-``)."""
    parser.add_argument("-o", "--out", type=_output_path, required=required, help=help)


def _detectors(text: str) -> list[str]:
    names = text.split(",")
    if problem := detectors_problem(names):
        raise argparse.ArgumentTypeError(problem)
    return names


def _detector_name(text: str) -> str:
    try:
        return check_name(text, "detector name")
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _output_path(text: str) -> Path:
    if text == "-":
        raise argparse.ArgumentTypeError("simgen writes files, not a table to stdout: give a path")
    return Path(text)


def handle_generate(args: argparse.Namespace) -> str:
    from simgen.dataset import generate
    from simgen.scene import load_scene, scene_folder

    scene = load_scene(scene_folder(args.scene)).with_run(seconds=args.seconds, fps=args.fps, detectors=args.detectors,
                                                         quality=args.quality)
    t0 = time.perf_counter()
    generate(scene, args.seed, args.out, resume=args.resume, progress=show_progress(args), workers=args.workers,
             scheduler=args.scheduler)
    return (f"{args.out}: {scene.name}, seed {args.seed}, {scene.frames_total} frames at {scene.fps} fps, "
            f"detectors {','.join(scene.detectors)}, quality {scene.quality}, complete ({time.perf_counter() - t0:.1f} s)")


def handle_preview(args: argparse.Namespace) -> str:
    from simgen.preview import preview
    from simgen.scene import load_scene, scene_folder

    scene = load_scene(scene_folder(args.scene)).with_run(quality=args.quality)
    agents = preview(scene, args.seed, args.t, args.out)
    return f"{args.out}: {scene.name} at t = {args.t:g} s, seed {args.seed}, {agents} agents in view"


def handle_scenes(args: argparse.Namespace) -> str:
    from simgen.scene import SHIPPED, describe, load_scene, shipped_scenes

    names = shipped_scenes()
    for name in names:
        print(f"{name}: {describe(load_scene(SHIPPED / name))}")
    return f"{len(names)} shipped scenes in {SHIPPED.resolve()} (copy one to edit it)"


def handle_import_mot(args: argparse.Namespace) -> str:
    from simgen.dataset import FORMAT
    from simgen.detection import import_into_dataset

    if len(args.files) != (1 if args.out else 2):
        raise ValueError("give the dataset folder once: -o/--out DATASET MOT_TXT, or DATASET MOT_TXT")
    *dataset, mot_txt = args.files
    out = args.out or dataset[0]
    with output_folder(out, FORMAT, resume=True):  # the dataset's lock: one writer at a time
        n = import_into_dataset(out, mot_txt, args.name, args.min_iou)
    return f"{n} detections of {args.name!r} added to {out / 'detections.parquet'}"


def handle_export_mot(args: argparse.Namespace) -> str:
    from simgen.export import export_mot

    lines = export_mot(args.dataset_dir, args.out)
    return f"{args.out}: " + ", ".join(f"{name} {n} lines" for name, n in lines.items())


def main(argv: list[str] | None = None) -> int:
    """Run one subcommand; on success print its one-line summary (``simgen COMMAND: ...``) and return 0."""
    try:
        args = _parser().parse_args(argv)
    except SystemExit as e:  # --help, --version, or a refused argument (already printed)
        return e.code
    try:
        from simgen.backend import BackendError  # first: the guarded mujoco import
    except Exception as e:  # noqa: BLE001  (BackendError raised while importing simgen.backend)
        return _fail(str(e), 3)
    from simgen.dataset import DatasetError

    try:
        print(f"simgen {args.command}: {args.handler(args)}")
        return 0
    except BackendError as e:
        return _fail(str(e), 3)
    except (ValueError, KeyError, OSError, DatasetError, OutputFolderError) as e:  # ConfigError is a ValueError
        message = os_message(e) if isinstance(e, OSError) else str(e)
        return _fail(f"{args.command}: {message}" if args.command in FILE_COMMANDS else message)


if __name__ == "__main__":
    sys.exit(main())
