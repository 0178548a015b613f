"""Probe of bad inputs and faults (issue 12), run by hand: every command and every input it reads, tried as a
careless user and a real fault would (wrong order, duplicates, NaN, inf, huge, empty, UTF-16, binary, a folder
that is not ours, a file where a folder is expected, two runs at once, a full disk, a read-only folder, a
symlink to a user's file, a killed run), and the library's public entry points.

    python benchmarks/probe_bad_inputs.py [--repo PATH] [--only WORD] [--keep]

--repo: the checkout to probe (default: this one; e.g. an older tree unpacked with git archive, for a count
before a fix). Every command runs as a real process (``python -m simgen.cli`` / ``homocal.cli``) in a fresh
folder; full disks and read-only folders are real tmpfs mounts (needs root; those cases are skipped otherwise).

Prints one row per case: case, command, expected, got (exit code, first line of stderr, files changed outside
the command's own outputs), PASS/FAIL; then the counts. A refused input must give exit 2, exactly one line
``<tool>: error: ...`` and change no file at all; an accepted one exit 0 and no file changed but its outputs.
A full disk or read-only folder must be named (the file under the mount). Library cases expect a ValueError
(one line) but where named "allowed". Slow (a few minutes: about
3 s per process); the fast tests of the same classes are in tests/ (see README, the promises under faults).
"""
from __future__ import annotations

import argparse
import hashlib
import http.client
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

TIMEOUT = 180
REF = "u,v,x,y\n639.5,429.4,0.0,10.0\n648.1,321.7,0.3,20.0\n636.1,272.1,-0.2,35.0\n"
TRAP = {"image": [[573, 282], [707, 285], [875, 480], [404, 479]], "map": [[365, 300], [435, 300], [435, 520], [365, 520]],
        "site_map": {"scale_px_per_m": 10.0, "origin_px": [400, 600]}}
MOT = "1,-1,100,60,10,20,0.9,-1,-1,-1\n"  # a detection inside the 320x180 frames of the small scene


@dataclass
class Case:
    """argv: the tool ("simgen" or "homocal") and its arguments; {F} is the shared fixtures folder, other paths
    are relative to the case's own folder. setup(case_dir): what the user left there. expect: "refused" (exit 2,
    one error line containing message, nothing changed) or "ok" (exit 0, nothing changed outside writes).
    fault: "full" / "readonly" (a tmpfs mounted at <case>/mnt, full or read-only, after setup filled it),
    "concurrent" (the command `first` started, then stopped with SIGSTOP once wait_for exists, so it holds its
    folder for as long as the case runs), "killed" (argv killed with SIGKILL once wait_for exists, then run
    again with --resume)."""

    name: str
    argv: list[str]
    expect: str = "refused"
    message: str = ""
    setup: Callable[[Path], object] | None = None
    writes: tuple[str, ...] = ()
    fault: str | None = None
    wait_for: str = ""
    first: list[str] | None = None
    timeout: float = 180


def put(**files: str | bytes) -> Callable[[Path], None]:
    """A setup writing files (name -> text or bytes; '/' in names makes folders; '@target' makes a symlink)."""
    def setup(d: Path) -> None:
        for name, data in files.items():
            p = d / name.replace("__", "/")
            p.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(data, str) and data.startswith("@"):
                p.symlink_to(d / data[1:])
            elif isinstance(data, bytes):
                p.write_bytes(data)
            else:
                p.write_text(data)
    return setup


def copy(src: str, dst: str, then: Callable[[Path], object] | None = None) -> Callable[[Path], None]:
    """A setup copying a fixture (src under {F}) to dst in the case folder, then running `then`."""
    def setup(d: Path) -> None:
        shutil.copytree(FIXTURES / src, d / dst, symlinks=True) if (FIXTURES / src).is_dir() else shutil.copy(FIXTURES / src, d / dst)
        if then:
            then(d)
    return setup


def edit_json(path: str, edit: Callable[[dict], object]) -> Callable[[Path], None]:
    def setup(d: Path) -> None:
        data = json.loads((d / path).read_text())
        edit(data)
        (d / path).write_text(json.dumps(data))
    return setup


def toml(edit: Callable[[str], str]) -> Callable[[Path], None]:
    """Copy the small scene to ./scene and edit its scene.toml's text."""
    def setup(d: Path) -> None:
        shutil.copytree(FIXTURES / "scene", d / "scene")
        t = d / "scene" / "scene.toml"
        t.write_text(edit(t.read_text()))
    return setup


def both(*setups: Callable[[Path], object]) -> Callable[[Path], None]:
    def setup(d: Path) -> None:
        for s in setups:
            s(d)
    return setup


USER = put(**{"out/video.mp4": b"a user's video", "out/notes.tmp1.txt": b"a user's notes"})
UTF16 = "u,v,x,y\n639.5,429.4,0.0,10.0\n".encode("utf-16")
BINARY = bytes(range(256)) * 4
GEN = ["simgen", "generate", "{F}/scene", "--seconds", "0.5", "--no-progress", "--out"]
STUDY = ["homocal", "study", "{F}/synth", "--variants", "2", "--n-test", "100", "--no-progress", "-o"]


def fit(*extra: str, t: str = "{F}/trap.json", r: str = "{F}/ref.csv", o: str = "c.json") -> list[str]:
    return ["homocal", "fit", "--trapezoid", t, "--points", r, "-o", o, *extra]


def apply(*extra: str, c: str = "{F}/correction.json", f: str = "{F}/feet.csv", o: str = "o.csv") -> list[str]:
    return ["homocal", "apply", c, "--points", f, "-o", o, *extra]


MEASURE = ["homocal", "measure", "{F}/trap.json", "--boxes", "{F}/boxes.csv", "--fps", "10", "--no-progress", "-o"]
WATCH = ["homocal", "watch", "--trapezoid", "{F}/trap.json", "--boxes", "{F}/boxes.csv", "--fps", "10", "--camera-height", "4",
         "--camera-json", "{F}/lens.json", "-o"]
LENS = ["homocal", "lens", "--lines", "{F}/lines.json", "-o"]
ADVISE = ["homocal", "advise", "--trapezoid", "{F}/trap.json", "--distances", "10,20,30,40", "--samples", "2"]
REPORT = ["homocal", "report", "--no-progress"]
SWEEP = ["homocal", "sweep", "{F}/synth", "--variants", "1", "--n-test", "50", "--no-progress", "-o"]


def cli_cases() -> list[Case]:
    trap = lambda **kw: json.dumps({**TRAP, **kw})  # noqa: E731
    image = TRAP["image"]
    return [
        # ---- simgen generate: flags, scene config, output folder, faults
        Case("seconds inf", [*GEN, "out", "--seconds", "inf"], message="--seconds"),
        Case("seconds nan", [*GEN, "out", "--seconds", "nan"], message="--seconds"),
        Case("seconds huge", [*GEN, "out", "--seconds", "1e12"], message="--seconds"),
        Case("seed -1", [*GEN, "out", "--seed", "-1"], message="--seed"),
        Case("seed huge", [*GEN, "out", "--seed", str(2**70)], message="--seed"),
        Case("fps huge", [*GEN, "out", "--fps", "100000"], message="fps"),
        Case("workers huge (as many as chunks)", [*GEN, "out", "--workers", "100000"], expect="ok", writes=("out",)),
        Case("detectors duplicated", [*GEN, "out", "--detectors", "segmentation,segmentation"], message="segmentation"),
        Case("detectors empty", [*GEN, "out", "--detectors", ","], message="detect"),
        Case("detectors ''", [*GEN, "out", "--detectors", ""], message="--detectors"),
        Case("scene missing", ["simgen", "generate", "nowhere", "--out", "out"], message="nowhere"),
        *[Case(f"scene name {name!r:.20}", ["simgen", "generate", name, "--out", "out"], message="shipped: scene1, scene2")
          for name in ("../x", "a/b", "..x", "a\nb", "x" * 300)],
        Case("scene is a file", ["simgen", "generate", "f", "--out", "out"], setup=put(f="x"), message="f"),
        Case("scene.toml UTF-16", [*GEN[:2], "scene", *GEN[3:], "out"], setup=both(toml(lambda t: t), _utf16("scene/scene.toml")), message="scene.toml"),
        Case("scene.toml binary", [*GEN[:2], "scene", *GEN[3:], "out"], setup=both(toml(lambda t: t), put(**{"scene__scene.toml": BINARY})), message="scene.toml"),
        Case("scene.toml empty", [*GEN[:2], "scene", *GEN[3:], "out"], setup=both(toml(lambda t: t), put(**{"scene__scene.toml": ""})), message="scene.toml"),
        Case("scene unknown key", [*GEN[:2], "scene", *GEN[3:], "out"], setup=toml(lambda t: t.replace("tilt_deg", "tlit_deg")), message="tlit_deg"),
        Case("scene key twice", [*GEN[:2], "scene", *GEN[3:], "out"], setup=toml(lambda t: t.replace("tilt_deg = 15.0", "tilt_deg = 15.0\ntilt_deg = 16.0")), message="scene.toml"),
        Case("scene height nan", [*GEN[:2], "scene", *GEN[3:], "out"], setup=toml(lambda t: t.replace("mount_height_m = 4.0", "mount_height_m = nan")), message="mount_height_m"),
        Case("scene height huge", [*GEN[:2], "scene", *GEN[3:], "out"], setup=toml(lambda t: t.replace("mount_height_m = 4.0", "mount_height_m = 1e308")), message="mount_height_m"),
        Case("scene agents -1", [*GEN[:2], "scene", *GEN[3:], "out"], setup=toml(lambda t: t.replace("count = 8", "count = -1")), message="count"),
        Case("scene route empty", [*GEN[:2], "scene", *GEN[3:], "out"], setup=toml(lambda t: t.replace("points = [[-5.5, -6.0], [-5.5, 70.0]]", "points = []", 1)), message="points"),
        Case("scene route repeated point", [*GEN[:2], "scene", *GEN[3:], "out"], setup=toml(lambda t: t.replace("points = [[-5.5, -6.0], [-5.5, 70.0]]", "points = [[-5.5, -6.0], [-5.5, -6.0]]", 1)), message="points"),
        Case("scene trapezoid mirrored", [*GEN[:2], "scene", *GEN[3:], "out"], setup=toml(_mirror_trapezoid), message="hand_placed_image"),
        Case("out: user's folder", [*GEN, "out"], setup=USER, message="not empty"),
        Case("out: user's folder, resume", [*GEN, "out", "--resume"], setup=USER, message="not a simgen-dataset"),
        Case("out: a file", [*GEN, "out", "--resume"], setup=put(out="x"), message="not a folder"),
        Case("out: symlink to user's folder", [*GEN, "link", "--resume"], setup=both(USER, put(link="@out")), message="not a simgen-dataset"),
        Case("out: full disk", [*GEN, "mnt/out"], fault="full", message="No space left on device"),
        Case("out: read-only", [*GEN, "mnt/out"], fault="readonly", message="Read-only file system"),
        Case("two generate at once", [*GEN, "out", "--resume"], fault="concurrent", first=[*GEN, "out"], wait_for="out/manifest.json", writes=("out",), message="locked by"),
        Case("generate killed, resumed", [*GEN, "out"], expect="ok", fault="killed", wait_for="out/_parts/*", writes=("out",)),
        # ---- simgen preview
        Case("preview t inf", ["simgen", "preview", "{F}/scene", "-o", "a.png", "--t", "inf"], message="--t"),
        Case("preview t huge", ["simgen", "preview", "{F}/scene", "-o", "a.png", "--t", "1e12"], message="--t"),
        Case("preview -o user's PNG", ["simgen", "preview", "{F}/scene", "-o", "a.png"], setup=put(**{"a.png": b"\x89PNG mine"}), message="a.png"),
        Case("preview -o symlink to user's file", ["simgen", "preview", "{F}/scene", "-o", "l.png"], setup=put(u="mine", **{"l.png": "@u"}), message="l.png"),
        Case("preview -o a folder", ["simgen", "preview", "{F}/scene", "-o", "d"], setup=put(d__x="x"), message="d"),
        Case("preview -o full disk", ["simgen", "preview", "{F}/scene", "-o", "mnt/a.png"], fault="full", message="No space left on device"),
        Case("preview -o read-only", ["simgen", "preview", "{F}/scene", "-o", "mnt/a.png"], fault="readonly", message="Read-only file system"),
        Case("preview twice", ["simgen", "preview", "{F}/scene", "-o", "a.png"], expect="ok", setup=_preview_once, writes=("a.png",)),
        # ---- simgen import-mot
        *[Case(f"import-mot {name}", ["simgen", "import-mot", "ds", "det.txt", "--name", "yolo", *extra],
               setup=copy("dataset", "ds", put(**{"det.txt": data})), message=msg)
          for name, data, extra, msg in [
              ("empty", "", [], "det.txt"), ("UTF-16", MOT.encode("utf-16"), [], "det.txt"), ("binary", BINARY, [], "det.txt"),
              ("NaN box", "1,-1,nan,60,10,20,0.9,-1,-1,-1\n", [], "det.txt"), ("inf box", "1,-1,100,60,inf,20,0.9,-1,-1,-1\n", [], "det.txt"),
              ("1e308 box", "1,-1,1,1,1e308,1e308,0.9,-1,-1,-1\n", [], "det.txt"), ("frame 0", "0,-1,100,60,10,20,0.9,-1,-1,-1\n", [], "det.txt"),
              ("frame beyond the video", "9999,-1,100,60,10,20,0.9,-1,-1,-1\n", [], "det.txt"),
              ("negative width", "1,-1,100,60,-10,20,0.9,-1,-1,-1\n", [], "det.txt"),
              ("conf nan", "1,-1,100,60,10,20,nan,-1,-1,-1\n", [], "det.txt"),
              ("min-iou nan", MOT, ["--min-iou", "nan"], "--min-iou"), ("min-iou 2", MOT, ["--min-iou", "2"], "--min-iou")]],
        *[Case(f"import-mot --name {name!r:.20}", ["simgen", "import-mot", "ds", "det.txt", "--name", name],
               setup=copy("dataset", "ds", put(**{"det.txt": MOT})), message="--name")
          for name in ("../x", "a/b", ".", "..", "a\nb", "x" * 300)],
        Case("import-mot /dev/zero", ["simgen", "import-mot", "ds", "/dev/zero", "--name", "yolo"], setup=copy("dataset", "ds"),
             message="/dev/zero"),
        Case("import-mot -o DATASET", ["simgen", "import-mot", "det.txt", "--name", "yolo", "-o", "ds"], expect="ok",
             setup=copy("dataset", "ds", put(**{"det.txt": MOT})), writes=("ds/detections.parquet", "ds/manifest.json")),
        Case("export-mot manifest scene ../../escaped", ["simgen", "export-mot", "ds", "-o", "seq"],
             setup=copy("dataset", "ds", edit_json("ds/manifest.json", lambda m: m.update(scene="../../escaped"))), message="scene"),
        Case("import-mot duplicate lines", ["simgen", "import-mot", "ds", "det.txt", "--name", "yolo"], expect="ok",
             setup=copy("dataset", "ds", put(**{"det.txt": MOT * 2})), writes=("ds/detections.parquet", "ds/manifest.json")),
        Case("import-mot frames in reverse order", ["simgen", "import-mot", "ds", "det.txt", "--name", "yolo"], expect="ok",
             setup=copy("dataset", "ds", put(**{"det.txt": MOT.replace("1,", "3,", 1) + MOT})), writes=("ds/detections.parquet", "ds/manifest.json")),
        Case("import-mot into user's folder", ["simgen", "import-mot", "out", "det.txt", "--name", "yolo"], setup=both(USER, put(**{"det.txt": MOT})), message="out"),
        Case("import-mot into a file", ["simgen", "import-mot", "f", "det.txt", "--name", "yolo"], setup=put(f="x", **{"det.txt": MOT}), message="f"),
        Case("import-mot while generate writes", ["simgen", "import-mot", "out", "{F}/det.txt", "--name", "yolo"], fault="concurrent",
             first=[*GEN, "out"], wait_for="out/manifest.json", writes=("out",), message="locked by"),
        # ---- homocal fit
        Case("fit trapezoid mirrored", fit(t="t.json"), setup=put(**{"t.json": trap(map=TRAP["map"][1::-1] + TRAP["map"][:1:-1])}), message="mirrored"),
        Case("fit trapezoid upside down", fit(t="t.json"), setup=put(**{"t.json": trap(map=TRAP["map"][2:] + TRAP["map"][:2])}), message="t.json"),
        Case("fit image corners out of order", fit(t="t.json"), setup=put(**{"t.json": trap(image=[image[1], image[0], image[3], image[2]])}), message="t.json"),
        Case("fit trapezoid vertex twice", fit(t="t.json"), setup=put(**{"t.json": trap(image=[image[0], image[0], image[2], image[3]])}), message="t.json"),
        Case("fit trapezoid NaN", fit(t="t.json"), setup=put(**{"t.json": trap(image=[[float("nan"), 282], *image[1:]])}), message="t.json"),
        Case("fit trapezoid 1e308", fit(t="t.json"), setup=put(**{"t.json": trap(image=[[1e308, 282], *image[1:]])}), message="t.json"),
        Case("fit trapezoid empty", fit(t="t.json"), setup=put(**{"t.json": ""}), message="t.json"),
        Case("fit trapezoid UTF-16", fit(t="t.json"), setup=put(**{"t.json": json.dumps(TRAP).encode("utf-16")}), message="t.json"),
        Case("fit trapezoid binary", fit(t="t.json"), setup=put(**{"t.json": BINARY}), message="t.json"),
        Case("fit trapezoid is a folder", fit(t="t.json"), setup=put(**{"t.json__x": "x"}), message="t.json"),
        Case("fit trapezoid 3 corners", fit(t="t.json"), setup=put(**{"t.json": trap(image=image[:3])}), message="t.json"),
        Case("fit site map scale 0", fit(t="t.json"), setup=put(**{"t.json": trap(site_map={"scale_px_per_m": 0, "origin_px": [0, 0]})}), message="t.json"),
        Case("fit points duplicated", fit(r="r.csv"), setup=put(**{"r.csv": REF + REF.splitlines()[1] + "\n"}), message="r.csv"),
        Case("fit points NaN", fit(r="r.csv"), setup=put(**{"r.csv": REF + "nan,300,0,15\n"}), message="r.csv"),
        Case("fit points inf", fit(r="r.csv"), setup=put(**{"r.csv": REF + "640,inf,0,15\n"}), message="r.csv"),
        Case("fit points 1e308", fit(r="r.csv"), setup=put(**{"r.csv": REF + "640,1e308,0,15\n"}), message="r.csv"),
        Case("fit points header only", fit(r="r.csv"), setup=put(**{"r.csv": "u,v,x,y\n"}), message="r.csv"),
        Case("fit points empty", fit(r="r.csv"), setup=put(**{"r.csv": ""}), message="r.csv"),
        Case("fit points UTF-16", fit(r="r.csv"), setup=put(**{"r.csv": UTF16}), message="r.csv"),
        Case("fit points binary", fit(r="r.csv"), setup=put(**{"r.csv": BINARY}), message="r.csv"),
        Case("fit points column twice", fit(r="r.csv"), setup=put(**{"r.csv": "u,v,x,y,u\n" + "\n".join(l + ",1" for l in REF.splitlines()[1:]) + "\n"}), message="r.csv"),
        Case("fit points behind the camera", fit(r="r.csv"), expect="ok", setup=put(**{"r.csv": REF + "640,700,0,-3\n"}), writes=("c.json",)),
        Case("fit camera-origin nan", fit("--camera-origin", "nan,0"), message="--camera-origin"),
        Case("fit seed -1", fit("--method", "descent", "--seed", "-1"), message="--seed"),
        Case("fit threshold nan", fit("--method", "hybrid", "--threshold", "nan"), message="--threshold"),
        Case("fit -o user's file", fit(o="mine.json"), setup=put(**{"mine.json": "{}"}), message="mine.json"),
        Case("fit -o symlink to user's file", fit(o="l.json"), setup=put(u="mine", **{"l.json": "@u"}), message="l.json"),
        Case("fit -o a folder", fit(o="d"), setup=put(d__x="x"), message="d"),
        Case("fit -o full disk", fit(o="mnt/c.json"), fault="full", message="No space left on device"),
        Case("fit -o read-only", fit(o="mnt/c.json"), fault="readonly", message="Read-only file system"),
        Case("fit twice", fit(), expect="ok", setup=copy("correction.json", "c.json"), writes=("c.json",)),
        # ---- homocal apply
        Case("apply correction a = -5", apply(c="c.json"), setup=copy("correction.json", "c.json", edit_json("c.json", lambda d: d["fitted"].update(a=-5.0))), message="c.json"),
        Case("apply correction b = NaN", apply(c="c.json"), setup=copy("correction.json", "c.json", _nan_b), message="c.json"),
        Case("apply correction UTF-16", apply(c="c.json"), setup=copy("correction.json", "c.json", _utf16("c.json")), message="c.json"),
        Case("apply correction binary", apply(c="c.json"), setup=put(**{"c.json": BINARY}), message="c.json"),
        Case("apply correction empty", apply(c="c.json"), setup=put(**{"c.json": ""}), message="c.json"),
        # a byte beyond homocal.files.MAX_JSON_BYTES
        Case("apply correction huge (sparse)", apply(c="c.json"), setup=_sparse("c.json", 16 * 2**20 + 1), message="larger than 16 MiB"),
        Case("apply feet NaN and inf (kept, marked)", apply(f="f.csv"), expect="ok", setup=put(**{"f.csv": "u,v\n640,400\nnan,400\n640,inf\n"}), writes=("o.csv",)),
        Case("apply feet UTF-16", apply(f="f.csv"), setup=put(**{"f.csv": "u,v\n640,400\n".encode("utf-16")}), message="f.csv"),
        Case("apply feet binary", apply(f="f.csv"), setup=put(**{"f.csv": BINARY}), message="f.csv"),
        Case("apply feet empty", apply(f="f.csv"), setup=put(**{"f.csv": ""}), message="f.csv"),
        Case("apply feet u twice", apply(f="f.csv"), setup=put(**{"f.csv": "u,v,u\n640,400,1\n"}), message="f.csv"),
        Case("apply -o its own input", apply(f="f.csv", o="f.csv"), setup=put(**{"f.csv": "u,v\n640,400\n"}), message="f.csv"),
        Case("apply -o user's file", apply(o="mine.csv"), setup=put(**{"mine.csv": "my,data\n"}), message="mine.csv"),
        Case("apply -o full disk", apply(o="mnt/o.csv"), fault="full", message="No space left on device"),
        Case("apply -o read-only", apply(o="mnt/o.csv"), fault="readonly", message="Read-only file system"),
        Case("apply click-sigma inf", apply("--click-sigma-px", "inf"), message="--click-sigma-px"),
        # ---- homocal study
        Case("study dataset missing", ["homocal", "study", "nowhere", "-o", "out"], message="nowhere"),
        Case("study dataset is a user's folder", ["homocal", "study", "mine", "-o", "out"], setup=put(mine__a="x"), message="mine"),
        Case("study dataset given twice", ["homocal", "study", "{F}/synth", "{F}/synth", "-o", "out"], message="synth"),
        Case("study dataset calibration NaN", ["homocal", "study", "ds", "-o", "out", "--variants", "1"], setup=copy("synth", "ds", _nan_calibration), message="calibration"),
        Case("study dataset camera.json UTF-16", ["homocal", "study", "ds", "-o", "out"], setup=copy("synth", "ds", _utf16("ds/camera.json")), message="camera.json"),
        Case("study dataset gt.parquet binary", ["homocal", "study", "ds", "-o", "out"], setup=copy("synth", "ds", put(**{"ds__gt.parquet": BINARY})), message="gt.parquet"),
        Case("study seed -1", [*STUDY, "out", "--seed", "-1"], message="--seed"),
        Case("study variants -1", [*STUDY, "out", "--variants", "-1"], message="--variants"),
        Case("study variants huge", [*STUDY, "out", "--variants", str(10**12)], message="--variants"),
        Case("study n-test huge", [*STUDY, "out", "--n-test", str(10**12)], message="--n-test"),
        Case("study max-test-distance nan", [*STUDY, "out", "--max-test-distance", "nan"], message="--max-test-distance"),
        Case("study click-noise nan", [*STUDY, "out", "--click-noise", "nan"], message="--click-noise"),
        Case("study horizon-shift inf", [*STUDY, "out", "--horizon-shift", "inf"], message="horizon"),
        Case("study map-scale 0", [*STUDY, "out", "--map-scale", "0"], message="--map-scale"),
        Case("study map-scale nan", [*STUDY, "out", "--map-scale", "nan"], message="--map-scale"),
        Case("study map-scale huge", [*STUDY, "out", "--map-scale", "1e400"], message="--map-scale"),
        Case("study out: user's folder", [*STUDY, "out"], setup=USER, message="not empty"),
        Case("study out: user's folder, resume", [*STUDY, "out", "--resume"], setup=USER, message="not a homocal-study"),
        Case("study out: a file", [*STUDY, "out"], setup=put(out="x"), message="not a folder"),
        Case("study out: full disk", [*STUDY, "mnt/out"], fault="full", message="No space left on device"),
        Case("study out: read-only", [*STUDY, "mnt/out"], fault="readonly", message="Read-only file system"),
        Case("two studies at once", [*STUDY, "out", "--resume"], fault="concurrent", first=[*STUDY, "out"], wait_for="out/study.json", writes=("out",), message="locked by"),
        Case("study killed, resumed", [*STUDY, "out", "--variants", "30"], expect="ok", fault="killed", wait_for="out/shards/*/*.parquet", writes=("out",)),
        Case("study manifest scene escapes", ["homocal", "study", "d/e/f/ds", "-o", "d/e/f/out"], setup=copy("synth", "d/e/f/ds", edit_json("d/e/f/ds/manifest.json", lambda m: m.update(scene="../../../../escaped"))), message="manifest.json: scene"),
        Case("study site_map scale true", ["homocal", "study", "ds", "-o", "out"], setup=copy("synth", "ds", edit_json("ds/site_map.json", lambda m: m.update(scale_px_per_m=True))), message="site_map.json"),
        Case("study scheduler unreachable", [*STUDY, "out", "--scheduler", "tcp://127.0.0.1:1"], message="scheduler"),
        Case("study resume, swapped shard", [*STUDY, "res", "--resume"], setup=copy("results", "res", _swapped_shard), message="variant_00001"),
        Case("study resume, truncated shard", [*STUDY, "res", "--resume"], setup=copy("results", "res", _truncated_shard), message="variant_00001"),
        Case("study preset unknown", [*STUDY, "out", "--preset", "paper-ish"], message="--preset"),
        Case("study descent-delta-max 0", [*STUDY, "out", "--descent-delta-max", "0"], message="--descent-delta-max"),
        Case("study perturbation empty", [*STUDY, "out", "--perturbation", ""], message="--perturbation"),
        # ---- homocal sweep
        Case("sweep value twice", [*SWEEP, "out", "--horizon-shift", "1,1"], message="1"),
        Case("sweep value nan", [*SWEEP, "out", "--horizon-shift", "nan,1"], message="nan"),
        Case("sweep empty value", [*SWEEP, "out", "--horizon-shift", "1,,2"], message="empty"),
        Case("sweep map-scale -1", [*SWEEP, "out", "--map-scale", "2,-1"], message="--map-scale"),
        Case("sweep descent-delta-max 0", [*SWEEP, "out", "--descent-delta-max", "8,0"], message="--descent-delta-max"),
        Case("sweep image-width true", [*SWEEP, "out", "--image-width", "1280,true"], message="--image-width"),
        Case("sweep seed 1.5", [*SWEEP, "out", "--seed", "0,1.5"], message="--seed"),
        Case("sweep out: user's folder, resume", [*SWEEP, "out", "--horizon-shift", "0,1", "--resume"], setup=USER, message="not a homocal-sweep"),
        Case("sweep out: a study folder", [*SWEEP, "out", "--horizon-shift", "0,1", "--resume"], setup=copy("results", "out"), message="not a homocal-sweep"),
        # ---- homocal report
        Case("report twice", [*REPORT, "res"], expect="ok", setup=_report_once, writes=("res/report",)),
        Case("report into user's folder", [*REPORT, "{F}/results", "-o", "out"], setup=USER, message="not a homocal-report"),
        Case("report into its study folder", [*REPORT, "res", "-o", "res"], setup=copy("results", "res"), message="not a homocal-report"),
        Case("report -o a file", [*REPORT, "{F}/results", "-o", "out"], setup=put(out="x"), message="not a folder"),
        Case("report -o full disk", [*REPORT, "{F}/results", "-o", "mnt/out"], fault="full", message="No space left on device"),
        Case("report -o read-only", [*REPORT, "{F}/results", "-o", "mnt/out"], fault="readonly", message="Read-only file system"),
        Case("report of a user's folder", [*REPORT, "out", "-o", "page"], setup=USER, message="out"),
        Case("report study.json UTF-16", [*REPORT, "res", "-o", "page"], setup=copy("results", "res", _utf16("res/study.json")), message="study.json"),
        Case("report shard binary", [*REPORT, "res", "-o", "page"], setup=copy("results", "res", _garbage_shard), message="variant_00001"),
        Case("report shard copied over another", [*REPORT, "res", "-o", "page"], setup=copy("results", "res", _swapped_shard), message="variant_00001"),
        Case("report study.json scene escapes", [*REPORT, "a/b/c/d/res"], setup=both(copy("results", "a/b/c/d/res", edit_json("a/b/c/d/res/study.json", lambda m: m["datasets"][0].update(scene="../../../../../victim"))), put(**{"victim.png": b"a user's picture"})), message="datasets[0].scene"),
        Case("report --sweep missing", [*REPORT, "{F}/results", "-o", "out", "--sweep", "MISSING"], message="MISSING"),
        Case("report --sweep a user's folder", [*REPORT, "{F}/results", "-o", "out", "--sweep", "mine"], setup=put(mine__a="x"), message="mine"),
        Case("two reports at once", [*REPORT, "{F}/results", "-o", "out"], fault="concurrent", first=[*REPORT, "{F}/results", "-o", "out"], wait_for="out/report.json", writes=("out",), message="locked by"),
        # ---- homocal advise
        Case("advise distances twice", [*ADVISE[:4], "--distances", "10,10,20"], message="--distances"),
        Case("advise distances nan", [*ADVISE[:4], "--distances", "10,nan,20"], message="--distances"),
        Case("advise samples huge", [*ADVISE, "--samples", str(10**12)], message="samples"),
        Case("advise lateral inf", [*ADVISE, "--lateral", "inf"], message="--lateral"),
        Case("advise test-points UTF-16", [*ADVISE, "--test-points", "g.csv"], setup=put(**{"g.csv": "x,y\n0,10\n".encode("utf-16")}), message="g.csv"),
        Case("advise test-points NaN", [*ADVISE, "--test-points", "g.csv"], setup=put(**{"g.csv": "x,y\n0,nan\n"}), message="g.csv"),
        Case("advise -o user's file", [*ADVISE, "-o", "mine.csv"], setup=put(**{"mine.csv": "my,data\n"}), message="mine.csv"),
        Case("advise -o full disk", [*ADVISE, "-o", "mnt/a.csv"], fault="full", message="No space left on device"),
        Case("advise --out writes", [*ADVISE, "--out", "a.csv"], expect="ok", writes=("a.csv",)),
        Case("advise --output (not a flag)", [*ADVISE, "--output", "a.csv"], message="--output"),
        Case("advise test-points 100,001 rows", [*ADVISE, "--test-points", "g.csv"], setup=_many_points("g.csv", 100_001, "x,y"), message="more than 100,000 points"),
        # ---- homocal fit: the bound on reference points, least change's memory
        Case("fit least-change 20,000 points", fit("--method", "least-change", r="ref.csv"), expect="ok", setup=_many_points("ref.csv", 20_000), writes=("c.json",), timeout=600),
        Case("fit 100,001 points", fit(r="ref.csv"), setup=_many_points("ref.csv", 100_001), message="more than 100,000 points"),
        # ---- output folders: a user's .lock
        Case("study out: a user's empty .lock", [*STUDY, "out"], setup=put(**{"out__.lock": ""}), message="not a lock of ours"),
        Case("study out: a user's empty .lock, resume", [*STUDY, "out", "--resume"], setup=copy("results", "out", put(**{"out__.lock": ""})), message="not a lock of ours"),
        # ---- homocal measure
        Case("measure writes, then replaces its own", [*MEASURE, "t.parquet"], expect="ok", setup=_measure_once, writes=("t.parquet",)),
        *[Case(f"measure fps {fps}", [*MEASURE[:5], "--fps", fps, "-o", "t.parquet"], message="--fps") for fps in ("0", "nan", "inf", "1e9", "-10")],
        *[Case(f"measure box-margin {m}", [*MEASURE, "t.parquet", "--box-margin", m], message="--box-margin") for m in ("nan", "-1", "65", "1e308")],
        Case("measure boxes UTF-16", [*MEASURE[:3], "--boxes", "b.csv", *MEASURE[5:], "t.parquet"], setup=put(**{"b.csv": "frame,track_id,x1,y1,x2,y2\n0,1,1,2,3,4\n".encode("utf-16")}), message="b.csv"),
        Case("measure boxes binary", [*MEASURE[:3], "--boxes", "b.csv", *MEASURE[5:], "t.parquet"], setup=put(**{"b.csv": BINARY}), message="b.csv"),
        Case("measure boxes empty", [*MEASURE[:3], "--boxes", "b.csv", *MEASURE[5:], "t.parquet"], setup=put(**{"b.csv": ""}), message="b.csv"),
        Case("measure boxes NaN", [*MEASURE[:3], "--boxes", "b.csv", *MEASURE[5:], "t.parquet"], setup=put(**{"b.csv": "frame,track_id,x1,y1,x2,y2\n0,1,600,300,nan,360\n1,1,600,300,620,360\n"}), message="b.csv"),
        Case("measure boxes upside down", [*MEASURE[:3], "--boxes", "b.csv", *MEASURE[5:], "t.parquet"], setup=put(**{"b.csv": "frame,track_id,x1,y1,x2,y2\n0,1,600,360,620,300\n1,1,600,360,620,300\n"}), message="b.csv"),
        Case("measure (frame, track) twice", [*MEASURE[:3], "--boxes", "b.csv", *MEASURE[5:], "t.parquet"], setup=put(**{"b.csv": "frame,track_id,x1,y1,x2,y2\n0,1,600,300,620,360\n0,1,600,300,620,360\n1,1,600,300,620,360\n"}), message="b.csv"),
        Case("measure tracks of one frame", [*MEASURE[:3], "--boxes", "b.csv", *MEASURE[5:], "t.parquet"], setup=put(**{"b.csv": "frame,track_id,x1,y1,x2,y2\n0,1,600,300,620,360\n1,2,600,300,620,360\n"}), message="no track has"),
        Case("measure boxes missing", [*MEASURE[:3], "--boxes", "nowhere.csv", *MEASURE[5:], "t.parquet"], message="nowhere.csv"),
        Case("measure correction binary", ["homocal", "measure", "c.json", *MEASURE[3:], "t.parquet"], setup=put(**{"c.json": BINARY}), message="c.json"),
        Case("measure correction of another image", ["homocal", "measure", "c.json", *MEASURE[3:], "t.parquet", "--camera-json", "{F}/lens.json"], setup=put(**{"c.json": json.dumps({**TRAP, "image": [[x + 2000, y] for x, y in TRAP["image"]]})}), message="outside the lens's 1280x720 frame"),
        Case("measure -o user's file", [*MEASURE, "mine.parquet"], setup=put(**{"mine.parquet": b"PAR1 mine"}), message="mine.parquet"),
        Case("measure -o its own input", [*MEASURE[:3], "--boxes", "b.csv", *MEASURE[5:], "b.csv"], setup=copy("boxes.csv", "b.csv"), message="b.csv"),
        Case("measure -o and --summary one file", [*MEASURE, "t.parquet", "--summary", "t.parquet"], message="its own file"),
        Case("measure -o a folder", [*MEASURE, "d"], setup=put(d__x="x"), message="d"),
        Case("measure -o full disk", [*MEASURE, "mnt/t.parquet"], fault="full", message="No space left on device"),
        Case("measure -o read-only", [*MEASURE, "mnt/t.parquet"], fault="readonly", message="Read-only file system"),
        Case("measure accel-psd nan", [*MEASURE, "t.parquet", "--accel-psd", "nan"], message="--accel-psd"),
        Case("measure student tails, box-height noise", [*MEASURE, "t.parquet", "--foot-noise-tails", "student", "--foot-noise", "box-height"], message="--foot-noise-tails student"),
        # ---- homocal watch
        Case("watch writes its folder", [*WATCH, "w"], expect="ok", writes=("w",)),
        Case("watch -o its own earlier folder", [*WATCH, "w"], setup=_watch_once, message="not empty"),
        Case("watch -o user's folder", [*WATCH, "out"], setup=USER, message="not empty"),
        Case("watch -o a file", [*WATCH, "out"], setup=put(out="x"), message="not a folder"),
        Case("watch -o full disk", [*WATCH, "mnt/w"], fault="full", message="No space left on device"),
        Case("watch -o read-only", [*WATCH, "mnt/w"], fault="readonly", message="Read-only file system"),
        Case("watch boxes out of time order", [*WATCH[:4], "--boxes", "b.csv", *WATCH[6:], "w"], setup=put(**{"b.csv": "frame,track_id,x1,y1,x2,y2\n1,1,600,300,620,360\n0,1,600,300,620,360\n"}), message="time order"),
        Case("watch boxes binary", [*WATCH[:4], "--boxes", "b.csv", *WATCH[6:], "w"], setup=put(**{"b.csv": BINARY}), message="b.csv"),
        Case("watch boxes UTF-16", [*WATCH[:4], "--boxes", "b.csv", *WATCH[6:], "w"], setup=put(**{"b.csv": "frame,track_id,x1,y1,x2,y2\n0,1,1,2,3,4\n".encode("utf-16")}), message="b.csv"),
        Case("watch boxes inf", [*WATCH[:4], "--boxes", "b.csv", *WATCH[6:], "w"], setup=put(**{"b.csv": "frame,track_id,x1,y1,x2,y2\n0,1,600,300,inf,360\n"}), message="b.csv"),
        Case("watch camera-json binary", [*WATCH[:-3], "--camera-json", "l.json", "-o", "w"], setup=put(**{"l.json": BINARY}), message="l.json"),
        Case("watch camera-json folds", [*WATCH[:-3], "--camera-json", "l.json", "-o", "w"], setup=copy("lens.json", "l.json", edit_json("l.json", lambda d: d.update(distortion=[0.9, -0.7, 0, 0, 0]))), message="l.json"),
        Case("watch trapezoid of another camera", ["homocal", "watch", "--trapezoid", "t.json", *WATCH[4:], "w"], setup=put(**{"t.json": json.dumps({**TRAP, "image": [[x + 2000, y] for x, y in TRAP["image"]]})}), message="outside the lens's 1280x720 frame"),
        *[Case(f"watch arl0-people {n}", [*WATCH, "w", "--arl0-people", n], message="--arl0-people") for n in ("0", "nan", "1e300")],
        Case("watch camera-height inf", [*WATCH, "w", "--camera-height", "inf"], message="--camera-height"),
        Case("watch fps nan", [*WATCH, "w", "--fps", "nan"], message="--fps"),
        *[Case(f"watch box-margin {m}", [*WATCH, "w", "--box-margin", m], message="--box-margin") for m in ("inf", "-0.5", "64.5")],
        Case("apply at a watch's refused stretch", apply("--at", "1", c="w"), setup=_watch_refused("the people disagree"), message="t = 1 s has no correction in w: the people disagree"),
        Case("apply at a watch's refusal not ours", apply("--at", "1", c="w"), setup=_watch_refused(5), message="field refused: expected text"),
        Case("two watches at once", [*WATCH, "w"], fault="concurrent", first=[*WATCH, "w"], wait_for="w/watch.json", writes=("w",), message="locked by"),
        # ---- homocal lens
        Case("lens writes, then replaces its own", [*LENS, "l.json"], expect="ok", setup=_lens_once, writes=("l.json",)),
        Case("lens lines binary", ["homocal", "lens", "--lines", "x.json", "-o", "l.json"], setup=put(**{"x.json": BINARY}), message="x.json"),
        Case("lens lines UTF-16", ["homocal", "lens", "--lines", "x.json", "-o", "l.json"], setup=copy("lines.json", "x.json", _utf16("x.json")), message="x.json"),
        Case("lens lines NaN", ["homocal", "lens", "--lines", "x.json", "-o", "l.json"], setup=copy("lines.json", "x.json", edit_json("x.json", lambda d: d["lines"][0][0].__setitem__(0, float("nan")))), message="x.json"),
        Case("lens lines empty list", ["homocal", "lens", "--lines", "x.json", "-o", "l.json"], setup=put(**{"x.json": json.dumps({"image_size": [1280, 720], "lines": []})}), message="x.json"),
        Case("lens line of one point", ["homocal", "lens", "--lines", "x.json", "-o", "l.json"], setup=put(**{"x.json": json.dumps({"image_size": [1280, 720], "lines": [[[1, 2]]] * 4})}), message="x.json"),
        Case("lens image size huge", ["homocal", "lens", "--lines", "x.json", "-o", "l.json"], setup=copy("lines.json", "x.json", edit_json("x.json", lambda d: d.update(image_size=[10**9, 720]))), message="x.json"),
        Case("lens -o user's file", [*LENS, "mine.json"], setup=put(**{"mine.json": "{}"}), message="mine.json"),
        Case("lens -o full disk", [*LENS, "mnt/l.json"], fault="full", message="No space left on device"),
        Case("lens frame binary", ["homocal", "lens", "--frame", "f.png", "-o", "l.json"], setup=put(**{"f.png": BINARY}), message="f.png"),
        Case("lens checkerboard matches nothing", ["homocal", "lens", "--checkerboard", "none/*.png", "--pattern", "9x6", "--square-m", "0.025", "-o", "l.json"], message="--checkerboard"),
        Case("lens checkerboard pattern 0x6", ["homocal", "lens", "--checkerboard", "{F}/map.png", "--pattern", "0x6", "--square-m", "0.025", "-o", "l.json"], message="--pattern"),
        Case("lens hfov nan", [*LENS, "l.json", "--hfov", "nan"], message="--hfov"),
        # ---- homocal ui (command line)
        Case("ui -o two missing folders", ["homocal", "ui", "--frame", "{F}/map.png", "--site-map", "{F}/map.png", "--scale", "10", "-o", "a/b"], timeout=30, message="its parent folder"),
        Case("ui frame UTF-16 text", ["homocal", "ui", "--frame", "f.png", "--site-map", "{F}/map.png", "--scale", "10", "-o", "."], setup=put(**{"f.png": "x".encode("utf-16")}), timeout=30, message="f.png"),
        Case("ui scale nan", ["homocal", "ui", "--frame", "{F}/map.png", "--site-map", "{F}/map.png", "--scale", "nan", "-o", "."], timeout=30, message="--scale"),
        Case("ui -o a file", ["homocal", "ui", "--frame", "{F}/map.png", "--site-map", "{F}/map.png", "--scale", "10", "-o", "f"], setup=put(f="x"), timeout=30, message="f"),
    ]


def _many_points(name: str, n: int, columns: str = "u,v,x,y") -> Callable[[Path], None]:
    """A setup writing n distinct points below the fixture trapezoid's horizon (u,v,x,y: the ground position is
    the trapezoid's mapping moved by up to 5 cm; x,y: ground points 10-60 m ahead)."""
    def setup(d: Path) -> None:
        import numpy as np
        from homocal.geometry import SiteMap, ViewTransformer

        i = np.arange(n)
        q = np.column_stack([450 + (i % 400) * 1.0, 300 + (i // 400) * (170 / max(1, (n - 1) // 400))])
        site = SiteMap(10.0, (400.0, 600.0))
        g = ViewTransformer(np.array(TRAP["image"], float), site.to_metres(np.array(TRAP["map"], float))).transform_points(q)
        g += np.random.default_rng(0).uniform(-0.05, 0.05, g.shape)
        rows = np.column_stack([q, g]) if columns == "u,v,x,y" else np.column_stack([i % 7 - 3.0, 10 + i * 50 / n])
        (d / name).write_text(columns + "\n" + "".join(",".join(map(repr, r)) + "\n" for r in rows.tolist()))
    return setup


def _mirror_trapezoid(text: str) -> str:
    import re
    m = re.search(r"hand_placed_image = (.*)", text)
    tl, tr, br, bl = json.loads(m.group(1))
    return text.replace(m.group(0), f"hand_placed_image = {json.dumps([tr, tl, bl, br])}")


def _nan_b(d: Path) -> None:
    (d / "c.json").write_text((d / "c.json").read_text().replace('"b": ', '"b": NaN, "_b": ', 1))


def _utf16(name: str) -> Callable[[Path], None]:
    return lambda d: (d / name).write_bytes((d / name).read_text().encode("utf-16"))


def _nan_calibration(d: Path) -> None:
    import pyarrow.parquet as pq
    t = pq.read_table(d / "ds" / "calibration.parquet")
    x = t.column("x").to_numpy().copy()
    x[1] = float("nan")  # a calibration object without its true ground position
    pq.write_table(t.set_column(t.schema.get_field_index("x"), "x", [x]), d / "ds" / "calibration.parquet")


def _garbage_shard(d: Path) -> None:
    next((d / "res" / "shards").glob("*/variant_00001.parquet")).write_bytes(BINARY)


def _swapped_shard(d: Path) -> None:
    shards = sorted((d / "res" / "shards").glob("*/variant_0000*.parquet"))
    shutil.copy(shards[2], shards[1])


def _truncated_shard(d: Path) -> None:
    shard = next((d / "res" / "shards").glob("*/variant_00001.parquet"))
    shard.write_bytes(shard.read_bytes()[:300])


def _preview_once(d: Path) -> None:
    run(["simgen", "preview", str(FIXTURES / "scene"), "-o", "a.png"], d)


def _measure_once(d: Path) -> None:
    run([*MEASURE, "t.parquet"], d)


def _watch_once(d: Path) -> None:
    run([*WATCH, "w"], d)


def _sparse(name: str, size: int) -> Callable[[Path], None]:
    """A file of size bytes, all holes (nothing on disk)."""
    def setup(d: Path) -> None:
        with (d / name).open("wb") as f:
            f.truncate(size)
    return setup


def _watch_refused(why) -> Callable[[Path], None]:
    """A watch folder whose first stretch's correction is a refusal saying why (homocal watch writes it so where its
    people are mostly outliers)."""
    def setup(d: Path) -> None:
        _watch_once(d)
        (d / "w/corrections/0.00.json").write_text(json.dumps({"format": "homocal-watch-refused", "start_s": 0.0, "refused": why}))
    return setup


def _lens_once(d: Path) -> None:
    run([*LENS, "l.json"], d)


def _report_once(d: Path) -> None:
    shutil.copytree(FIXTURES / "results", d / "res")
    run([*REPORT, "res"], d)


# ---- library entry points -------------------------------------------------------------------------
def library_cases() -> list[tuple[str, str, Callable[[], object]]]:
    """(case, entry point, call): each is bad input, and the call must raise ValueError with one line, but for
    the cases named "allowed" (ViewTransformer maps any plane to any plane: a mirrored target is a valid
    homography there; homocal fit and ui, which know the frames, refuse it)."""
    import numpy as np
    from homocal.correctors import DescentCorrector, HorizonCorrector, RegressionCorrector, load_corrector
    from homocal.geometry import ViewTransformer

    image, ground = np.array(TRAP["image"], float), (np.array(TRAP["map"], float) - [400, 600]) / 10 * [1, -1]
    ref = np.loadtxt(REF.splitlines()[1:], delimiter=",")
    vt = ViewTransformer(image, ground)
    nan, big = float("nan"), 1e308

    def fit(corrector, q=ref[:, :2], g=ref[:, 2:], origin=(0.0, 0.0)):
        return lambda: corrector.fit(vt, np.asarray(q, float), np.asarray(g, float), origin).transform_points(q)

    def load(text: str | bytes):
        def call():
            p = Path(tempfile.mkdtemp()) / "c.json"
            p.write_bytes(text if isinstance(text, bytes) else text.encode())
            return load_corrector(p)
        return call

    from homocal.correctors import LeastChangeCorrector
    from homocal.correctors.catalogue import METHODS, get_method
    from homocal.files import read_points_csv
    from homocal.geometry import read_trapezoid_file

    def file(name: str, data: bytes | str, then: Callable[[Path], object]):
        def call():
            p = Path(tempfile.mkdtemp()) / name
            p.write_bytes(data if isinstance(data, bytes) else data.encode())
            return then(p)
        return call

    many = np.column_stack([450 + np.arange(100_001) % 400, 300 + np.arange(100_001) // 400 * 0.6])
    good = json.loads(Path(FIXTURES / "correction.json").read_text())
    return [
        ("least-change 100,001 points", "LeastChangeCorrector.fit", fit(LeastChangeCorrector(), q=many, g=vt.transform_points(many))),
        ("catalogue method a list", "get_method", lambda: get_method(["regression"])),
        ("catalogue descent threshold", "Method.make", lambda: METHODS["descent"].make(threshold=50.0)),
        ("read_trapezoid_file UTF-16", "read_trapezoid_file", file("t.json", json.dumps(TRAP).encode("utf-16"), read_trapezoid_file)),
        ("read_trapezoid_file binary", "read_trapezoid_file", file("t.json", BINARY, read_trapezoid_file)),
        ("read_points_csv binary", "read_points_csv", file("r.csv", BINARY, lambda p: read_points_csv(p, ("u", "v"), True))),
        ("read_points_csv over its bound", "read_points_csv", file("r.csv", "u,v\n" + "1,2\n" * 11, lambda p: read_points_csv(p, ("u", "v"), True, most=10))),
        ("ViewTransformer NaN vertex", "ViewTransformer", lambda: ViewTransformer(np.vstack([[nan, 1], image[1:]]), ground)),
        ("ViewTransformer inf vertex", "ViewTransformer", lambda: ViewTransformer(image, np.vstack([[np.inf, 1], ground[1:]]))),
        ("ViewTransformer 1e308 vertex", "ViewTransformer", lambda: ViewTransformer(np.vstack([[big, 1], image[1:]]), ground)),
        ("ViewTransformer vertex twice", "ViewTransformer", lambda: ViewTransformer(np.vstack([image[:1], image[:1], image[2:]]), ground)),
        ("ViewTransformer mirrored map (a plane homography: allowed)", "ViewTransformer", lambda: ViewTransformer(image, ground[[1, 0, 3, 2]])),
        ("ViewTransformer 3 vertices", "ViewTransformer", lambda: ViewTransformer(image[:3], ground[:3])),
        ("ViewTransformer empty", "ViewTransformer", lambda: ViewTransformer(np.zeros((0, 2)), np.zeros((0, 2)))),
        ("ViewTransformer text", "ViewTransformer", lambda: ViewTransformer("abcd", ground)),
        ("ViewTransformer collinear", "ViewTransformer", lambda: ViewTransformer([[0, 0], [1, 1], [2, 2], [3, 3]], ground)),
        ("regression NaN point", "RegressionCorrector.fit", fit(RegressionCorrector(), q=np.vstack([ref[:2, :2], [nan, 300]]))),
        ("regression inf ground", "RegressionCorrector.fit", fit(RegressionCorrector(), g=np.vstack([ref[:2, 2:], [0, np.inf]]))),
        ("regression point twice", "RegressionCorrector.fit", fit(RegressionCorrector(), q=ref[[0, 0, 1], :2], g=ref[[0, 0, 1], 2:])),
        ("regression 2 points", "RegressionCorrector.fit", fit(RegressionCorrector(), q=ref[:2, :2], g=ref[:2, 2:])),
        ("regression shapes differ", "RegressionCorrector.fit", fit(RegressionCorrector(), g=ref[:2, 2:])),
        ("regression origin nan", "RegressionCorrector.fit", fit(RegressionCorrector(), origin=(nan, 0))),
        ("descent 1e308 point", "DescentCorrector.fit", fit(DescentCorrector(), q=np.vstack([ref[:2, :2], [big, 300]]))),
        ("horizon points empty", "HorizonCorrector.fit", fit(HorizonCorrector(), q=np.zeros((0, 2)), g=np.zeros((0, 2)))),
        ("load_corrector UTF-16", "load_corrector", load(json.dumps(good).encode("utf-16"))),
        ("load_corrector binary", "load_corrector", load(BINARY)),
        ("load_corrector empty", "load_corrector", load("")),
        ("load_corrector a = -5", "load_corrector", load(json.dumps({**good, "fitted": {**good["fitted"], "a": -5.0}}))),
        ("load_corrector b = NaN", "load_corrector", load(json.dumps({**good, "fitted": {**good["fitted"], "b": nan}}))),
        ("load_corrector trapezoid 1e308", "load_corrector", load(json.dumps(good).replace("573", "1e308", 1))),
    ]


def run_library(name: str, call: Callable[[], object]) -> tuple[str, bool]:
    """Call a library case: PASS if it raises ValueError with a one-line message, or, for a case named
    "allowed", if it returns."""
    try:
        call()
    except ValueError as e:
        text = str(e)
        return f"ValueError: {text[:110]}", bool(text) and "\n" not in text and "allowed" not in name
    except Exception as e:  # noqa: BLE001  (any other exception is a broken promise)
        return f"{type(e).__name__}: {(str(e).splitlines() or [''])[0][:110]}", False
    return "returned (no error)", "allowed" in name


# ---- homocal ui's JSON API ---------------------------------------------------------------------------
def ui_api_rows(d: Path) -> list[tuple[str, str, str, str, bool]]:
    """Bad requests to a real ``homocal ui`` server: each must get its 4xx status (or 503) and {"error": one line},
    never 500 nor a dropped connection; Save into a folder holding a user's trapezoid.json must get 409 and leave
    it, Save over a symlink 409 and leave its target; a POST without the printed URL's token 403; the server must
    still answer afterwards, and print no traceback."""
    out = d / "uiout"
    out.mkdir(parents=True)
    (out / "trapezoid.json").write_text("a user's file")
    args = ["ui", "--frame", f"{FIXTURES}/map.png", "--site-map", f"{FIXTURES}/map.png", "--scale", "10", "-o", str(out)]
    server = subprocess.Popen([sys.executable, "-m", "homocal.cli", *args], cwd=d, env=ENV, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    try:
        printed = server.stdout.readline().split(" on ")[-1].split(" ")[0]
        url, token = printed.split("?token=")
        points = [[float(x) for x in line.split(",")] for line in REF.splitlines()[1:]]
        good = {"trapezoid": {"image": TRAP["image"], "map": TRAP["map"]}, "camera_origin": [0, 0], "points": points,
                "method": "regression-signed"}
        image = TRAP["image"]
        setup_many = Path(d / "many")
        setup_many.mkdir()
        _many_points("ref.csv", 20_000)(setup_many)
        many = [[float(x) for x in line.split(",")] for line in (setup_many / "ref.csv").read_text().splitlines()[1:]]
        cases = [
            ("NaN point", "fit", json.dumps({**good, "points": [[float("nan"), 300, 0, 15], *points]}).encode(), 400),
            ("1e308 point", "fit", json.dumps({**good, "points": [[1e308, 300, 0, 15], *points]}).encode(), 400),
            ("point twice", "fit", json.dumps({**good, "points": [points[0], *points]}).encode(), 400),
            ("mirrored map", "fit", json.dumps({**good, "trapezoid": {"image": image, "map": TRAP["map"][1::-1] + TRAP["map"][:1:-1]}}).encode(), 400),
            ("vertex twice", "fit", json.dumps({**good, "trapezoid": {"image": [image[0], *image[:3]], "map": TRAP["map"]}}).encode(), 400),
            ("UTF-16 body (JSON's encoding detection)", "fit", json.dumps(good).encode("utf-16"), 200),
            ("binary body", "fit", BINARY, 400),
            ("a list, not an object", "fit", b"[1, 2]", 400),
            ("JSON nested 100,000 deep", "fit", b"[" * 100_000 + b"]" * 100_000, 400),
            ("a 5,000-digit integer", "fit", json.dumps({**good, "seed": 0}).replace('"seed": 0', '"seed": ' + "9" * 5000).encode(), 400),
            ("seed 1e30", "fit", json.dumps({**good, "method": "descent", "seed": 1e30}).encode(), 400),
            ("method a list", "fit", json.dumps({**good, "method": ["regression"]}).encode(), 400),
            ("click_sigma_px 1e308", "view", json.dumps({**good, "click_sigma_px": 1e308}).encode(), 400),
            ("100,001 points", "fit", json.dumps({**good, "points": [[1.0, 2.0, 3.0, 4.0]] * 100_001}).encode(), 400),
            ("least-change 20,000 points", "fit", json.dumps({**good, "method": "least-change", "points": many}).encode(), 200),
            ("no token", "fit", json.dumps(good).encode(), 403),
            ("save over a user's file", "save", json.dumps(good).encode(), 409),
            ("still serving", "fit", json.dumps(good).encode(), 200),
        ]
        rows = []
        for name, endpoint, body, status in cases:
            headers = {"Content-Type": "application/json", "X-Homocal-Token": "" if name == "no token" else token}
            request = urllib.request.Request(url + "api/" + endpoint, data=body, headers=headers)
            got, error = _answer(request)
            ok = got == status and (status == 200 or (error and "\n" not in error and "internal error" not in error))
            rows.append((f"ui {name}", f"POST /api/{endpoint}", f"{status}", f"{got}: {error[:110]}", ok))
        port = url.rsplit(":", 1)[1].strip("/")
        with socket.create_connection(("127.0.0.1", int(port)), timeout=60) as conn:
            conn.sendall(f"POST /api/fit HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json\r\n"
                         f"X-Homocal-Token: {token}\r\nContent-Length: abc\r\n\r\n{{}}".encode())
            response = http.client.HTTPResponse(conn)
            response.begin()
            error = str(json.loads(response.read()).get("error", ""))
        rows.append(("ui Content-Length: abc", "POST /api/fit", "400", f"{response.status}: {error[:110]}", response.status == 400 and "Content-Length" in error))
        user_file_kept = (out / "trapezoid.json").read_text() == "a user's file"
        rows.append(("ui save left the user's file", "POST /api/save", "unchanged", "unchanged" if user_file_kept else "overwritten", user_file_kept))
        (out / "trapezoid.json").unlink()
        (out / "trapezoid.json").symlink_to(d / "victim.txt")
        (d / "victim.txt").write_text("a user's file")
        got, error = _answer(urllib.request.Request(url + "api/save", data=json.dumps({**good, "overwrite": True}).encode(),
                                                    headers={"Content-Type": "application/json", "X-Homocal-Token": token}))
        kept = (d / "victim.txt").read_text() == "a user's file" and (out / "trapezoid.json").is_symlink()
        rows.append(("ui save over a symlink", "POST /api/save", "409, target unchanged", f"{got}: {error[:90]}", got == 409 and kept))
    finally:
        server.kill()
        server.wait()
    traceback = "Traceback" in server.stderr.read()
    rows.append(("ui no traceback on the server's terminal", "homocal ui", "none", "a traceback" if traceback else "none", not traceback))
    return rows


def _answer(request: urllib.request.Request) -> tuple[int, str]:
    """(status, error message) of a request to the page's server."""
    try:
        with urllib.request.urlopen(request, timeout=120) as response:
            return response.status, str(json.loads(response.read()).get("error", ""))
    except urllib.error.HTTPError as e:
        return e.code, str(json.loads(e.read()).get("error", ""))


# ---- running the command cases ------------------------------------------------------------------
def run(argv: list[str], cwd: Path, wait: bool = True, timeout: float = TIMEOUT):
    tool, *args = [a.replace("{F}", str(FIXTURES)) for a in argv]
    cmd = [sys.executable, "-m", f"{tool}.cli", *args]
    if not wait:
        return subprocess.Popen(cmd, cwd=cwd, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return subprocess.run(cmd, cwd=cwd, env=ENV, capture_output=True, text=True, errors="replace", timeout=timeout)


def snapshot(*roots: Path) -> dict[str, str]:
    state = {}
    for root in roots:
        for p in sorted(root.rglob("*")):
            key = str(p)
            if p.is_symlink():
                state[key] = "link:" + os.readlink(p)
            elif p.is_file():
                state[key] = hashlib.sha256(p.read_bytes()).hexdigest()
            elif p.is_dir():
                state[key] = "dir"
    return state


def changed(before: dict, after: dict, allowed: list[Path]) -> list[str]:
    keys = {k for k in before.keys() | after.keys() if before.get(k) != after.get(k)}
    return sorted(k for k in keys if not any(k == str(a) or k.startswith(str(a) + "/") for a in allowed))


def mount(d: Path, kind: str) -> Path | None:
    """A tmpfs at d/mnt: 'full' (16 KiB, filled to the brim), 'readonly'; None if it cannot be mounted."""
    mnt = d / "mnt"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=16k", "tmpfs", str(mnt)], capture_output=True).returncode:
        return None
    if kind == "full":
        fd = os.open(mnt / ".filler", os.O_WRONLY | os.O_CREAT)
        try:
            while os.write(fd, b"\0" * 512):
                pass
        except OSError:  # ENOSPC: full
            pass
        finally:
            os.close(fd)
    else:
        subprocess.run(["mount", "-o", "remount,ro", str(mnt)], check=True)
    return mnt


def run_case(case: Case, d: Path) -> tuple[str, bool]:
    """Run one case in its folder d; return (what happened, passed)."""
    if case.setup:
        case.setup(d)
    mnt = mount(d, case.fault) if case.fault in ("full", "readonly") else None
    if case.fault in ("full", "readonly") and mnt is None:
        return "skipped (cannot mount a tmpfs: not root?)", True
    first, note = None, ""
    try:
        if case.fault in ("concurrent", "killed"):
            first = run(case.first or case.argv, d, wait=False)
            deadline = time.monotonic() + TIMEOUT
            while not list(d.glob(case.wait_for)) and first.poll() is None and time.monotonic() < deadline:
                time.sleep(0.002)
            if first.poll() is None:
                first.send_signal(signal.SIGKILL if case.fault == "killed" else signal.SIGSTOP)
            else:
                note = f" (the first run ended, exit {first.returncode}, before the {case.fault} moment)"
            if case.fault == "killed":
                first.wait()
                first = None
        before = snapshot(d, FIXTURES)
        argv = case.argv + (["--resume"] if case.fault == "killed" else [])
        try:
            result = run(argv, d, timeout=case.timeout)
        except subprocess.TimeoutExpired:
            return f"timeout after {case.timeout:g} s", False
        after = snapshot(d, FIXTURES)
    finally:
        if first is not None:
            first.kill()  # SIGKILL ends a stopped process too
            first.wait()
        if mnt is not None:
            subprocess.run(["umount", str(mnt)], check=False)
    lines = result.stderr.splitlines()
    allowed = [d / w for w in case.writes] if case.expect == "ok" else []
    outside = changed(before, after, allowed)
    tool = case.argv[0]
    if case.expect == "refused":
        ok = (result.returncode == 2 and len(lines) == 1 and lines[0].startswith(f"{tool}: error: ")
              and case.message in lines[0] and not outside and (mnt is None or "mnt/" in lines[0]))  # names the file
    else:
        ok = result.returncode == 0 and "Traceback" not in result.stderr and not outside
    got = note + (f"exit {result.returncode}, {len(lines)} stderr line(s): {(lines[0] if lines else '')[:110]}"
           + (f"; changed: {', '.join(str(Path(k).relative_to(d)) if k.startswith(str(d)) else k for k in outside[:3])}" if outside else ""))
    return got, ok


def write_people(root: Path) -> None:
    """The people's fixtures: boxes.csv (two walkers seen by the card's camera, 10 fps, in time order), lens.json
    (that camera's K, no distortion) and lines.json (straight lines seen through a barrel lens)."""
    import numpy as np
    from homocal.geometry import Lens, PinholeCamera

    camera, rows = PinholeCamera(), []
    for frame in range(40):
        for k, (x0, y0, vx, vy) in enumerate([(-2.0, 10.0, 0.3, 1.2), (2.0, 25.0, -0.5, -1.0)]):
            (u, v), = camera.project_ground(np.array([[x0 + vx * frame / 10, y0 + vy * frame / 10]]))
            rows.append(f"{frame},{k},{u - 10:.1f},{v - 60:.1f},{u + 10:.1f},{v:.1f}\n")
    (root / "boxes.csv").write_text("frame,track_id,x1,y1,x2,y2\n" + "".join(rows))
    (root / "lens.json").write_text(json.dumps({"K": camera.K.tolist(), "distortion": [0.0] * 5, "image_size": [1280, 720]}))
    barrel = Lens(camera.K, [-0.2, 0.03, 0.0, 0.0, 0.0], (1280, 720))
    lines = [barrel.distort_points(np.column_stack([np.linspace(60, 1220, 12), np.full(12, row)])).tolist() for row in (80, 200, 520, 640)]
    lines += [barrel.distort_points(np.column_stack([np.full(12, col), np.linspace(40, 680, 12)])).tolist() for col in (120, 300, 980, 1160)]
    (root / "lines.json").write_text(json.dumps({"image_size": [1280, 720], "lines": lines}))


def make_fixtures(root: Path) -> None:
    """The shared inputs: a small scene and its 0.5 s dataset (simgen generate), a synthetic dataset, a quick
    study of it, the street example's trapezoid, points and correction, a site-map image."""
    sys.path[:0] = [str(REPO / "tests" / "simgen"), str(REPO / "tests")]
    from scene_copies import copy_scene
    from synthetic_dataset import write_dataset

    copy_scene(root)
    (root / "scene1").rename(root / "scene")
    write_dataset(root / "synth", n_calibration=8, n_test=200)
    (root / "trap.json").write_text(json.dumps(TRAP))
    (root / "ref.csv").write_text(REF)
    (root / "feet.csv").write_text("u,v\n640,400\n700,350\n")
    (root / "det.txt").write_text(MOT)
    write_people(root)
    shutil.copy(REPO / "scenes" / "scene1" / "site_map.png", root / "map.png") if (REPO / "scenes" / "scene1" / "site_map.png").exists() else None
    for argv in (["simgen", "generate", str(root / "scene"), "--out", str(root / "dataset"), "--seconds", "0.5", "--no-progress"],
                 [*STUDY, str(root / "results")],
                 fit("--method", "regression", o=str(root / "correction.json"))):
        result = run(argv, root)
        if result.returncode:
            sys.exit(f"fixture {' '.join(argv[:2])} failed: {result.stderr.strip()}")
    if not (root / "map.png").exists():
        shutil.copy(root / "dataset" / "site_map.png", root / "map.png")


def main() -> int:
    global REPO, FIXTURES, ENV
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repo", type=Path, default=Path(__file__).resolve().parents[1])
    parser.add_argument("--only", default="", help="run the cases whose name or command contains this")
    parser.add_argument("--keep", action="store_true", help="keep the case folders (printed)")
    args = parser.parse_args()
    REPO = args.repo.resolve()
    ENV = {**os.environ, "PYTHONPATH": str(REPO), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    sys.path.insert(0, str(REPO))
    top = Path(tempfile.mkdtemp(prefix="probe_"))
    FIXTURES = top / "fixtures"
    FIXTURES.mkdir()
    make_fixtures(FIXTURES)
    rows = []
    for i, case in enumerate(c for c in cli_cases() if args.only in c.name or args.only in " ".join(c.argv[:2])):
        d = top / f"case{i:03d}"
        d.mkdir()
        got, ok = run_case(case, d)
        rows.append((case.name, " ".join(case.argv[:2]), case.expect + (f" ({case.message})" if case.message else ""), got, ok))
        print(f"{'PASS' if ok else 'FAIL'}  {case.name:<40} {' '.join(case.argv[:2]):<18} {rows[-1][2][:40]:<40} {got}", flush=True)
    if args.only in "ui":
        for row in ui_api_rows(top / "ui"):
            rows.append(row)
            print(f"{'PASS' if row[4] else 'FAIL'}  {row[0]:<40} {row[1]:<18} {row[2]:<40} {row[3]}", flush=True)
    for name, entry, call in library_cases():
        if args.only in name:
            got, ok = run_library(name, call)
            expected = "returns" if "allowed" in name else "ValueError"
            rows.append((name, entry, expected, got, ok))
            print(f"{'PASS' if ok else 'FAIL'}  {name:<40} {entry:<18} {expected:<40} {got}", flush=True)
    failed = [r for r in rows if not r[4]]
    print(f"\n{len(rows)} cases: {len(rows) - len(failed)} PASS, {len(failed)} FAIL")
    for r in failed:
        print(f"  FAIL {r[0]} ({r[1]}): {r[3]}")
    if args.keep:
        print(f"case folders: {top}")
    else:
        shutil.rmtree(top, ignore_errors=True)
    return 1 if failed else 0


REPO = FIXTURES = Path()
ENV: dict[str, str] = {}

if __name__ == "__main__":
    sys.exit(main())
