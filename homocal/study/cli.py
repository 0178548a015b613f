"""`homocal study DATASET... --out DIR`: the paper's evaluation (Sections 5-6) over simgen datasets."""
from __future__ import annotations

import argparse

from homocal.arguments import number
from homocal.dataset import calibration_source
from homocal.progress import add_progress_option, show_progress
from homocal.study.engine import dry_run_counts, run_study
from homocal.study.inputs import OPTIONS, StudyParams, preset_params
from homocal.study.options import DEFAULT_PRESET, PRESETS, OptionError, flag_type, preset_values


def add_study_options(p: argparse.ArgumentParser, sweep: bool = False) -> None:
    """--preset and one flag per study option (StudyParams' declarations; shared by study and sweep). Absent
    options are left out of the namespace (argparse.SUPPRESS), so the preset's values apply unless an option
    is given. sweep: the sweepable ones are read as text (a list of values, see sweep.expand_values)."""
    p.add_argument("--preset", choices=list(PRESETS), default=DEFAULT_PRESET, help=preset_help())
    for name, opt in OPTIONS.items():
        words = getattr(opt.kind, "words", ())
        metavar = "{" + ",".join(words) + "}" if words else opt.metavar
        p.add_argument(opt.flag, dest=name, metavar=metavar, default=argparse.SUPPRESS,
                       type=str if sweep and opt.sweep else flag_type(opt), help=option_help(name))
    add_progress_option(p)


def preset_help() -> str:
    """--preset's help: each preset, what it is and the option values it sets."""
    parts = []
    for name, preset in PRESETS.items():
        values = " ".join(f"{opt.flag} {opt.presets[name]}" for opt in OPTIONS.values() if name in opt.presets)
        parts.append(f"{name}: {preset.label}{' (default)' if name == DEFAULT_PRESET else ''}: {preset.details} ({values})")
    return "; ".join(parts)


def option_help(name: str) -> str:
    """A study option's help: its declaration's, its unit, its value in the default preset and what 'none' means."""
    opt = OPTIONS[name]
    default = opt.to_text(getattr(preset_params(DEFAULT_PRESET), name))
    return (f"{opt.help} ({opt.unit + '; ' if opt.unit else ''}default: the preset's, {default} in {DEFAULT_PRESET}"
            f"{'; none: ' + opt.none if opt.none else ''})")


def params_from_args(args: argparse.Namespace, **override) -> StudyParams:
    """StudyParams of the preset, then the options given, then override (field names); a ValueError naming the
    flag of a bad value."""
    values = {**preset_values(StudyParams, args.preset), **{n: getattr(args, n) for n in OPTIONS if hasattr(args, n)},
              **override}
    try:
        return StudyParams(**values)
    except OptionError as e:
        raise ValueError(f"argument {OPTIONS[e.name].flag}: {e.expected}, got {e.value!r}") from None


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "study", help="run the correction study (every trapezoid variant x every calibration triple)",
        description="Per scene: the clicked base trapezoid and N perturbed variants, every combination of three "
                    "calibration points, the seven corrections (the paper's two, their hybrid and four more: "
                    "docs/study.md); per-sample results as Parquet shards in --out. --preset paper runs the paper's protocol "
                    "as the paper states it, --preset table1-fit the configuration fitted to its Table 1.")
    p.add_argument("datasets", nargs="+", metavar="DATASET", help="simgen dataset folders (one per scene)")
    p.add_argument("-o", "--out", required=True, help="results directory")
    add_study_options(p)
    group = p.add_mutually_exclusive_group()
    group.add_argument("--workers", type=number(int, 1, 1024), help="start a local Dask cluster of N worker processes")
    group.add_argument("--scheduler", help="address of a running Dask scheduler")
    p.add_argument("--resume", action="store_true", help="continue the study in --out, skipping finished shards")
    p.add_argument("--dry-run", action="store_true", help="print the sample counts and exit")
    p.set_defaults(handler=handle_study)


def point_counts(entry: dict, params: StudyParams) -> str:
    """What a dataset gives the study: its calibration and test points (entry: study.json's datasets item), and
    whether it has fewer test points than --n-test (a detector that finds few people, a short dataset)."""
    source = params.foot_source
    text = (f"{entry['n_calibration']} calibration points ({calibration_source(source)}), "
            f"{entry['n_test']:,} test points ({source})")
    if entry["n_test"] < params.n_test:
        limits = [f"within {params.max_test_distance:g} m" if params.max_test_distance else "",
                  f"within {params.test_lateral_max:g} m of x = 0" if params.test_lateral_max else ""]
        where = " and ".join(x for x in limits if x)
        text += f": fewer than --n-test {params.n_test}, all the dataset has{' ' + where if where else ''}"
    return text


def handle_study(args: argparse.Namespace) -> int:
    params = params_from_args(args)
    if args.dry_run:
        counts = dry_run_counts(args.datasets, params)
        for entry in counts:
            print(f"{entry['scene']}: {entry['samples']:,} samples; {point_counts(entry, params)}")
        print(f"total: {sum(e['samples'] for e in counts):,} samples ({params.n_variants + 1} trapezoids per scene)")
        return 0
    study = run_study(args.datasets, args.out, params, preset=args.preset, resume=args.resume,
                      workers=args.workers, scheduler=args.scheduler, progress=show_progress(args))
    for entry in study["datasets"]:
        print(f"{entry['scene']}: {point_counts(entry, params)}")
    rate = study["samples_done"] / max(study["elapsed_seconds"], 1e-9)
    print(f"{study['samples_done']:,} of {study['samples_total']:,} samples in {args.out} "
          f"({study['elapsed_seconds']:.1f} s, {rate:,.0f} samples/s); complete: {study['complete']}")
    print(f"degenerate variants: {study['n_degenerate']}")
    for d in study["degenerate"]:
        print(f"  {d['scene']} variant {d['variant']}: {d['reason']}")
    return 0
