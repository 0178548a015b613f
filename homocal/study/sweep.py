"""``homocal sweep DATASET... -o DIR --horizon-shift -12:16:2``: one study per value of one parameter, and how
far each lands from the paper's Table 1.

    DIR/sweep.json                  the swept parameter, its values, the fixed parameters (format tag)
    DIR/runs/<param>=<value>/       one study results directory per value (homocal study's layout)
    DIR/sweep.csv                   every Table 1 number per method per value, and D (metrics.paper_distance)
    DIR/sweep.png                   the Table 1 metrics against the swept value, the paper's as dashed lines

Resumable: --resume continues every unfinished run (each is a study run with --resume) and rewrites the
CSV and the figure from the finished runs, so a sweep killed at any moment ends with the same files.
"""
from __future__ import annotations

import argparse
import csv
import io
import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from homocal.files import output_folder, read_json, write_json_atomic, write_text_atomic
from homocal.progress import show_progress
from homocal.study.cli import add_study_options, params_from_args
from homocal.study.engine import run_study
from homocal.study.inputs import OPTIONS
from homocal.study.figures import save
from homocal.study.metrics import D_KEYS, METHODS, METRICS, PAPER, build_table, load_study, paper_distance, shard_files

FORMAT = "homocal-sweep"  # sweep.json's "format": marks a sweep folder (homocal.files.output_folder)
SWEEPABLE = {opt.name: field for field, opt in OPTIONS.items() if opt.sweep}  # sweep's parameter name -> StudyParams field
CSV_KEYS = ("n", *D_KEYS, "median_cal", "iqr_cal", "std_cal")


def expand_values(text: str) -> list[str]:
    """'a:b:step' (numbers, b included when reached) and comma-separated items -> the list of value strings;
    an item with a letter before its first ':' (normal:6:2) is one value. ValueError if empty or malformed."""
    values = []
    for item in (x.strip() for x in text.split(",")):
        parts = item.split(":")
        if len(parts) == 3 and not any(c.isalpha() for c in parts[0]):
            try:
                a, b, step = (float(x) for x in parts)
            except ValueError:
                raise ValueError(f"{item!r}: a range is START:STOP:STEP in numbers") from None
            if not (math.isfinite(a) and math.isfinite(b) and step > 0 and b >= a and (b - a) / step <= 1000):
                raise ValueError(f"{item!r}: a range needs START <= STOP, STEP > 0 and at most 1000 values")
            n = int(math.floor((b - a) / step + 1e-9)) + 1
            values += [f"{a + i * step:g}" for i in range(n)]
        elif item:
            values.append(item)
        else:
            raise ValueError(f"{text!r}: an empty value")
    return values


def run_name(param: str, value: str) -> str:
    return f"{param}={value}".replace("/", "_")


def sweep_meta(paths: list[str], param: str, values: list[str], args: argparse.Namespace) -> dict:
    """sweep.json: the swept parameter (a SWEEPABLE name) and its values, the preset, the datasets, and "fixed",
    study.json's parameters (StudyParams.to_dict) without the swept one's field (descent_delta_max: descent)."""
    fixed = params_from_args(args).to_dict()
    fixed.pop(SWEEPABLE[param], None)  # absent: an omit_default option at its default
    return {"format": FORMAT, "param": param, "values": values, "preset": args.preset, "fixed": fixed,
            "datasets": [str(Path(p).resolve()) for p in paths]}


def run_sweep(paths: list[str], out: str | Path, param: str, values: list[str], args: argparse.Namespace,
              resume: bool = False, progress: bool = True) -> list[dict]:
    """Run (or resume) one study per value of param (a SWEEPABLE name) under out/runs; write sweep.csv and
    sweep.png; return the CSV rows. The other parameters come from args (homocal study's options)."""
    out = Path(out)
    meta = sweep_meta(paths, param, values, args)
    params = [params_from_args(args, **{SWEEPABLE[param]: _typed(param, v)}) for v in values]  # every value checked first
    with output_folder(out, FORMAT, resume, marker="sweep.json") as folder:
        if folder.resumed and read_json(out / "sweep.json") != meta:
            raise ValueError(f"{out} holds a sweep of other parameters; --resume needs the same datasets and options")
        folder.remove_temporaries(["sweep.json", "sweep.csv", "sweep.png"])
        write_json_atomic(out / "sweep.json", meta)
        for value, p in zip(values, params):
            run_dir = out / "runs" / run_name(param, value)
            run_study(paths, run_dir, p, preset=args.preset, resume=(run_dir / "study.json").is_file(), progress=progress)
        rows = []
        for value in values:
            run_dir = out / "runs" / run_name(param, value)
            table = build_table(shard_files(run_dir, load_study(run_dir)))
            D = paper_distance(table)
            rows += [{"param": param, "value": value, "method": m, "D": D,
                      **{k: table.value(m, k) for k in CSV_KEYS}} for m in METHODS]
        write_text_atomic(out / "sweep.csv", to_csv(rows))
        save(sweep_figure(rows, param), out / "sweep.png")
    return rows


def closest(rows: list[dict]) -> dict:
    """The row (of method regression) of the value with the least D."""
    return min((r for r in rows if r["method"] == "regression" and not math.isnan(r["D"])), key=lambda r: r["D"])


def to_csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: (repr(float(v)) if isinstance(v, float) else v) for k, v in r.items()} for r in rows)
    return buf.getvalue()


def sweep_figure(rows: list[dict], param: str) -> Figure:
    """Table 1's metrics and D against the swept value, per method; the paper's values dashed."""
    values = list(dict.fromkeys(r["value"] for r in rows))
    try:
        x = np.array([float(v) for v in values])
        labels = None
    except ValueError:
        x, labels = np.arange(len(values), dtype=float), values
    keys = ("pos_path", "pos_cal", "mean_path", "median_path", "corr", "p1_path", "D")
    fig = Figure(figsize=(12, 7), layout="constrained")
    axes = fig.subplots(2, 4).ravel()
    for ax, key in zip(axes, keys):
        for n, method in enumerate(METHODS):
            color = f"C{n}"
            y = [r[key] for r in rows if r["method"] == method]
            ax.plot(x, y, "o-", color=color, ms=3, label=method)
            if key in PAPER.get(method, {}):
                ax.axhline(PAPER[method][key], color=color, ls="--", lw=1)
            if key == "D":
                break
        ax.set_title("D to the paper's Table 1 (pp)" if key == "D" else METRICS[key][0], fontsize=9)
        unit = OPTIONS[SWEEPABLE[param]].unit
        ax.set_xlabel(param.replace("_", " ") + (f" ({unit})" if unit else ""), fontsize=8)
        if labels is not None:
            ax.set_xticks(x, labels, rotation=30, fontsize=7)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    axes[-1].axis("off")
    axes[-1].text(0, 0.5, "dashed: the paper's value\n(regression as written against\nthe paper's regression, descent\n"
                  "against its descent)", fontsize=9, va="center")
    return fig


def _typed(param: str, value: str):
    """A swept value (text) of the SWEEPABLE parameter param as StudyParams takes it; a ValueError naming the flag."""
    opt = OPTIONS[SWEEPABLE[param]]
    try:
        return opt.from_text(value)
    except ValueError as e:
        raise ValueError(f"argument {opt.flag}: {e}") from None


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "sweep", help="one study per value of one parameter, and each one's distance to the paper's Table 1",
        description="Runs `homocal study` once per value of the swept parameter (give exactly one of "
                    f"{', '.join(OPTIONS[f].flag for f in SWEEPABLE.values())} as a list: 0,1,2 or START:STOP:STEP), "
                    "writes sweep.csv (Table 1 per method per value, and D, the RMS distance to the paper's 14 "
                    "numbers in pp) and sweep.png, and names the closest value.")
    p.add_argument("datasets", nargs="+", metavar="DATASET", help="simgen dataset folders (one per scene)")
    p.add_argument("-o", "--out", required=True, help="sweep directory")
    p.add_argument("--resume", action="store_true", help="continue the sweep in --out")
    add_study_options(p, sweep=True)
    p.set_defaults(handler=handle_sweep)


def handle_sweep(args: argparse.Namespace) -> int:
    given = [s for s, f in SWEEPABLE.items() if hasattr(args, f) and len(expand_values(getattr(args, f))) > 1]
    if len(given) != 1:
        raise ValueError(f"sweep exactly one parameter with two or more values (got {len(given)}: {', '.join(given) or 'none'})")
    param = given[0]
    text = getattr(args, SWEEPABLE[param])
    values = expand_values(text)
    typed = [_typed(param, v) for v in values]
    twice = list(dict.fromkeys(v for v, t in zip(values, typed) if typed.count(t) > 1))
    if twice:
        raise ValueError(f"{OPTIONS[SWEEPABLE[param]].flag} {text!r}: {', '.join(twice)} given more than once")
    delattr(args, SWEEPABLE[param])
    for name, field in SWEEPABLE.items():  # single values of the other sweepable options, as the study takes them
        if hasattr(args, field):
            setattr(args, field, _typed(name, getattr(args, field)))
    rows = run_sweep(args.datasets, args.out, param, values, args, resume=args.resume, progress=show_progress(args))
    best = closest(rows)
    print(f"homocal sweep: {len(values)} values of {param} in {args.out} (sweep.csv, sweep.png); closest to the paper's "
          f"Table 1: {param} = {best['value']} (D = {best['D']:.1f} pp)")
    return 0
