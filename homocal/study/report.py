"""``homocal report RESULTS_DIR [RESULTS_DIR ...]``: the study's table and figures gathered on one self-contained
HTML page; several studies of one configuration at other seeds add each Table 1 number and D as mean and range.

Writes into the first RESULTS_DIR/report (or --out): report.json (the folder's marker, homocal.files.output_folder),
report.html (figures embedded as data URIs, linked to their files beside it), table.md, table.csv (the first
study's), table_spread.csv (Table 1's numbers and D over all the studies given) and figures/*.png; prints the
table and the page's path. A folder that is not empty and has no report.json is
refused untouched; a report folder of ours is written again (its own files replaced).
"""
from __future__ import annotations

import argparse
import base64
import csv
import html
import io
import re
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from homocal.files import output_folder, write_json_atomic, write_text_atomic
from homocal.progress import add_progress_option, show_progress
from homocal.study.figures import HEADLINE, FigureFile, figure_names, make_figures
from homocal.dataset import load_dataset
from homocal.geometry import ViewTransformer
from homocal.study.ceiling import QUADRATIC, variant_ceilings, weighted_median
from homocal.study.inputs import OPTIONS, StudyParams, StudyScene, changed_options, option_text, preset_params
from homocal.study.law import horizon_shift_law, perturbation_law
from homocal.study.options import PRESETS
from homocal.study.metrics import (D_KEYS, D_METHODS, METRICS, PAPER, Table, build_table, complete_shard_files, load_study,
                                   paper_distance, table_cells, to_csv, to_markdown, to_text, verified_shard_files)
from homocal.study.perturb import MAX_PIXELS

STYLE = """body{font-family:sans-serif;max-width:1400px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #ccc;padding:2px 8px}
td.num{text-align:right;font-variant-numeric:tabular-nums}.grid{display:grid;grid-template-columns:1fr 1fr;gap:1.5em}
figure{margin:0 0 2em}figure img{width:100%;max-width:1400px}figcaption{font-size:0.95em;color:#444}.warn{color:#a00}
nav ol{columns:2}code{background:#f3f3f3;padding:0 3px}"""
FORMAT = "homocal-report"  # report.json's "format": marks a report folder


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``report`` on the homocal command's subparsers."""
    parser = subparsers.add_parser(
        "report",
        help="gather a study's table and figures into one HTML page",
        description="Compute the paper's Table 1 (and more) from a study's results directory, draw the figures and "
        "write one HTML page with all of it; print the table and the page's path.",
    )
    parser.add_argument("results_dir", metavar="RESULTS_DIR", type=Path, nargs="+",
                        help="a folder written by `homocal study`; several: studies of one configuration at other seeds, "
                             "whose Table 1 numbers and D the report gives as mean and range (table_spread.csv)")
    parser.add_argument("-o", "--out", type=Path, default=None, help="folder for the page, table and figures (default: RESULTS_DIR/report)")
    parser.add_argument("--compare", type=Path, action="append", default=[], metavar="RESULTS_DIR",
                        help="another study to show beside this one in the Reproduction table (repeatable)")
    parser.add_argument("--sweep", type=Path, default=None, metavar="SWEEP_DIR",
                        help="a `homocal sweep` folder whose figure and closest value the Reproduction section shows")
    add_progress_option(parser)
    parser.set_defaults(handler=handle_report)


def handle_report(args: argparse.Namespace) -> int:
    """Handler of ``homocal report``: print the table and the page's path; ValueError on bad input."""
    first, *replicates = args.results_dir
    page, text, missing = write_report(first, args.out, args.compare, args.sweep, show_progress(args), replicates)
    print(text)
    print(page)
    if missing:
        print(f"homocal report: the study is not complete: {missing} shard(s) missing; the page shows the others "
              f"(finish it with homocal study ... --resume)", file=sys.stderr)
        return 1
    return 0


def write_report(results_dir: str | Path, out_dir: str | Path | None = None, compare: Sequence[Path] = (),
                 sweep_dir: Path | None = None, progress: bool = False, replicates: Sequence[Path] = ()) -> tuple[Path, str, int]:
    """Write table.md, table.csv, table_spread.csv, figures/ and report.html; return the page's path, the table
    as text and the number of shards missing.

    compare: other results directories shown beside this one in the Reproduction table; sweep_dir: a sweep
    folder whose figure and closest value it shows; replicates: studies of the same configuration at other
    seeds (check_replicates), over which with this one table_spread.csv and the page give every Table 1 number
    and D as mean and range; progress: a bar on stderr per pass over the shards that takes more than a second
    (the table's two passes, the figures' six). ValueError if a results directory is not one (no study.json)
    or holds no shard yet, or a replicate's configuration differs other than by seed.
    """
    results_dir = Path(results_dir)
    study = load_study(results_dir)
    shards, missing = verified_shard_files(results_dir, study)
    if not any(shards.values()):
        raise ValueError(f"{results_dir}: no finished shards under shards/<scene>/ yet")
    replicate_studies = [(Path(r), load_study(r)) for r in replicates]
    check_replicates([(results_dir, study), *replicate_studies])
    replicate_tables = []
    for path, replicate in replicate_studies:
        replicate_tables.append(build_table(complete_shard_files(path, replicate), progress))
    others = []
    for other in compare:
        other_study = load_study(other)
        others.append((other, other_study, build_table(verified_shard_files(other, other_study)[0], progress)))
    sweep = read_sweep(sweep_dir) if sweep_dir is not None else None
    table = build_table(shards, progress)  # every input read before anything is written: a failing report writes nothing
    out_dir = Path(out_dir) if out_dir is not None else results_dir / "report"
    with output_folder(out_dir, FORMAT, resume=True, marker="report.json") as folder:
        folder.remove_temporaries(["report.json", "report.html", "table.md", "table.csv", "table_spread.csv",
                                   *(f"figures/{name}" for name in figure_names(study))])
        write_json_atomic(folder.marker, {"format": FORMAT, "results_dir": str(results_dir.resolve())})
        write_text_atomic(out_dir / "table.md", to_markdown(table))
        write_text_atomic(out_dir / "table.csv", to_csv(table))
        spread = spread_rows([table, *replicate_tables])
        write_text_atomic(out_dir / "table_spread.csv", spread_csv(spread, [study, *(r for _, r in replicate_studies)]))
        figures, notes = make_figures(results_dir, study, shards, out_dir / "figures", progress)
        page = out_dir / "report.html"
        reproduction = reproduction_html([(results_dir, study, table), *others], sweep, out_dir)
        if replicate_tables:
            reproduction += spread_html(spread, [study, *(r for _, r in replicate_studies)])
        law = law_html(results_dir, study)
        write_text_atomic(page, render_html(study, table, figures, notes, out_dir, reproduction + law, missing))
    return page, to_text(table), missing


def check_replicates(studies: list[tuple[Path, dict]]) -> None:
    """ValueError (one line) unless the studies (path, study.json) share one configuration other than their seeds:
    every StudyParams field but seed, and the datasets' scenes and config hashes; and no seed twice."""
    def configuration(study: dict) -> dict:
        params = StudyParams.from_dict(study).to_dict()
        del params["seed"]
        return {**params, "datasets": [(d["scene"], d.get("config_hash")) for d in study["datasets"]]}

    (first_path, first), seeds = studies[0], {}
    for path, study in studies:
        mine, theirs = configuration(study), configuration(first)
        differ = [k for k in sorted(mine.keys() | theirs.keys()) if mine.get(k) != theirs.get(k)]
        if differ:
            raise ValueError(f"{path}: its configuration differs from {first_path}'s other than by seed ({', '.join(differ)}); "
                             "several studies in one report must be one configuration at other seeds")
        seed = StudyParams.from_dict(study).seed
        if seed in seeds:
            raise ValueError(f"{path}: the same seed ({seed}) as {seeds[seed]}; several studies in one report need other seeds")
        seeds[seed] = path


SpreadRow = tuple[str, str, str, list[float], float]  # method, metric, scope, its value in each study, the paper's


def spread_rows(tables: list[Table]) -> list[SpreadRow]:
    """Every Table 1 number (the metrics of metrics.PAPER but n, per paper method) and D (metrics.paper_distance,
    paper value 0), per scope (the scenes, then overall), with its value in each of the studies' tables."""
    rows = []
    for scope in tables[0].scopes:
        for method in D_METHODS:
            rows += [(method, key, scope, [t.value(method, key, scope) for t in tables], PAPER[method][key])
                     for key in METRICS if key in PAPER[method] and key != "n"]
        rows.append(("", "D", scope, [paper_distance(t, scope) for t in tables], 0.0))
    return rows


def spread_csv(rows: list[SpreadRow], studies: list[dict]) -> str:
    """table_spread.csv: method, metric, scope, mean, min, max (over the studies; D's metric is "D"), paper, then
    the value of each study in a column named by its seed (seed_N), at full precision."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["method", "metric", "scope", "mean", "min", "max", "paper", *(f"seed_{s.get('seed', 0)}" for s in studies)])
    for method, metric, scope, values, paper in rows:
        writer.writerow([method, metric, scope, *(repr(float(x)) for x in _spread(values)), repr(float(paper)),
                         *(repr(float(v)) for v in values)])
    return buf.getvalue()


def spread_html(rows: list[SpreadRow], studies: list[dict]) -> list[str]:
    """The page's section of the Table 1 numbers and D as mean (min-max) over the studies, one column per scope."""
    scopes = list(dict.fromkeys(scope for _, _, scope, _, _ in rows))
    cells: dict[tuple[str, str], dict[str, str]] = {}
    for method, metric, scope, values, paper in rows:
        fmt = METRICS[metric][1] if metric in METRICS else "{:.1f}"
        mean, low, high = _spread(values)
        cells.setdefault((method, metric), {"paper": fmt.format(paper)})[scope] = (
            f"{fmt.format(mean)} ({fmt.format(low)} to {fmt.format(high)})")
    seeds = ", ".join(str(s.get("seed", 0)) for s in studies)
    body = [[method, METRICS[metric][0] if metric in METRICS else "D, RMS distance to the paper (pp)", c["paper"],
             *(c[s] for s in scopes)] for (method, metric), c in cells.items()]
    return [f"<h2>Over {len(studies)} studies of this configuration (seeds {html.escape(seeds)})</h2>",
            "<p>Each Table 1 number and D as the mean over the studies and, in brackets, their range (least to "
            "greatest); also in <a href='table_spread.csv'>table_spread.csv</a> with each study's value.</p>",
            _html_table(["method", "metric", "paper", *scopes], body, numeric=True)]


def _spread(values: list[float]) -> tuple[float, float, float]:
    """(mean, min, max) of values; NaN if any is NaN."""
    a = np.asarray(values, dtype=np.float64)
    return float(a.mean()), float(a.min()), float(a.max())


def config_label(study: dict) -> str:
    """A study's configuration in its options' words: its preset and what it is (study.json's preset_label;
    none in a study.json written before presets were labelled, whose "paper" may name another configuration),
    its base error, click noise, metric and lens always, then every other study option that differs from homocal
    study's defaults (inputs.changed_options)."""
    params = StudyParams.from_dict(study)
    parts = ["hand-placed trapezoid as it is" if params.horizon_shift is None else option_text("horizon_shift", params.horizon_shift),
             option_text("click_noise", params.click_noise), option_text("metric", params.metric),
             option_text("lens", params.lens)]
    rest = tuple(n for n in OPTIONS if n not in ("n_variants", "horizon_shift", "click_noise", "metric", "lens"))
    parts += changed_options(params, StudyParams(), rest)  # the other options, where they differ from the defaults
    label = f" ({study['preset_label']})" if study.get("preset_label") else ""
    return f"preset {study.get('preset')}{label}, {params.n_variants} variants: " + " ".join(parts)


def read_sweep(sweep_dir: Path) -> tuple[Path, dict, bytes]:
    """(sweep_dir, the regression row of sweep.csv with the least D, sweep.png's bytes) of a homocal sweep folder;
    ValueError naming what is missing or malformed."""
    try:
        with (Path(sweep_dir) / "sweep.csv").open(encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
        best = min((r for r in rows if r.get("method") == "regression"), key=lambda r: float(r["D"]))
        return sweep_dir, best, (Path(sweep_dir) / "sweep.png").read_bytes()
    except (OSError, UnicodeError, csv.Error, ValueError, KeyError, TypeError) as e:
        reason = e.strerror if isinstance(e, OSError) and e.strerror else "no regression rows with a number D in sweep.csv"
        raise ValueError(f"{sweep_dir}: not a finished homocal sweep folder ({reason})") from None


def reproduction_html(studies: list[tuple[Path, dict, Table]], sweep: tuple[Path, dict, bytes] | None,
                      out_dir: Path) -> list[str]:
    """The Reproduction section: the paper's Table 1 numbers (and the text's std and 1st percentile) beside
    each study's, with D (metrics.paper_distance); numbers more than 10 pp (0.10 for correlations) from the
    paper are marked; the sweep's figure if given (read_sweep)."""
    e = html.escape
    header = ["method", "metric", "paper"] + [f"{i + 1}: {p.name}" for i, (p, _, _) in enumerate(studies)]
    rows, far = [], []
    for method in D_METHODS:
        for key in D_KEYS:
            cells = [method, METRICS[key][0], METRICS[key][1].format(PAPER[method][key])]
            for i, (_, _, table) in enumerate(studies):
                value = table.value(method, key)
                gap = abs(value - PAPER[method][key]) * (100 if key == "corr" else 1)
                cells.append(("! " if gap > 10 else "") + METRICS[key][1].format(value))
                far += [f"{method} {METRICS[key][0]} (study {i + 1})"] if gap > 10 else []
            rows.append(cells)
    rows.append(["", "D, RMS distance to the paper over these 14 numbers (pp)", "0"]
                + [f"{paper_distance(t):.1f}" for _, _, t in studies])
    parts = ["<h2>Reproduction of the paper's Table 1</h2>",
             "<p>The paper's numbers (Table 1 and the text of its Section 6) beside ours: the paper's regression against "
             "ours as written (unsigned errors, a, b clamped), its gradient descent against our descent. D is the RMS of "
             "the 14 differences (percentages in pp, correlations x 100). '!' marks a number more than 10 pp (0.10) "
             "from the paper's. The studies:</p><ol>"]
    parts += [f"<li>{e(str(p))}: {e(config_label(st))}</li>" for p, st, _ in studies]
    parts += ["</ol>", _html_table(header, rows, numeric=True)]
    if far:
        counts = [sum(f.endswith(f"(study {i + 1})") for f in far) for i in range(len(studies))]
        parts.append(f"<p class='warn'>Numbers more than 10 pp from the paper's: "
                     f"{', '.join(f'{n} of 14 in study {i + 1}' for i, n in enumerate(counts))}. docs/reproduction.md gives the "
                     "measured reason for each.</p>")
    parts += ["<p>Measured on the studies' datasets: what the paper leaves open and drives the gap.</p><ul>"]
    parts += [f"<li>{e(line)}</li>" for _, st, _ in studies[:1] for line in gap_facts(st)]
    parts += [f"<li>Study {i + 1}: {e(line)}</li>" for i, (_, st, table) in enumerate(studies)
              if (line := ceiling_fact(st, table.value("regression", "median_path")))]
    parts.append("</ul>")
    if sweep is not None:
        sweep_dir, best, png = sweep
        data = base64.b64encode(png).decode("ascii")
        parts.append(f"<figure><img src='data:image/png;base64,{data}' alt='sweep'><figcaption><b>Sensitivity to "
                     f"{e(best['param'])}.</b> Table 1's metrics against the swept value ({e(str(sweep_dir))}); the "
                     f"paper's values dashed. Closest: {e(best['param'])} = {e(best['value'])}, D = {float(best['D']):.1f} "
                     "pp.</figcaption></figure>")
    return parts


def gap_facts(study: dict) -> list[str]:
    """Per dataset of a study: how far the hand-placed trapezoid's horizon lies from the exact one's (px, at the
    principal column; positive: above, the mapping underestimates range), the share of its test points
    within 2 m of the calibration line, and the size in metres of the 0-3 px map perturbations."""
    facts, params = [], StudyParams.from_dict(study)
    for entry in study["datasets"]:
        try:
            ds = load_dataset(entry["path"])
        except ValueError:
            continue
        K = ds.camera.K
        rows = [ViewTransformer(t["image"], ds.site_map.to_metres(t["map"])).horizon_row(K[0, 2])
                for t in (ds.trapezoids["exact"], ds.trapezoids["hand_placed"])]
        _, ground = ds.test_points(params.foot_source, n=params.n_test, seed=params.seed,
                                   max_distance=params.max_test_distance, max_lateral=params.test_lateral_max)
        near = np.mean(np.abs(ground[:, 0] - ds.camera_origin[0]) <= 2.0)
        shift = params.horizon_shift
        base = ("the study uses it as it is" if shift is None
                else f"the study moves it to lie {shift} px above the true horizon (--horizon-shift)")
        facts.append(f"{ds.name}: the hand-placed trapezoid's horizon lies {rows[0] - rows[1]:+.2f} px above the exact one's "
                     f"(negative: below; the mapping then overestimates range), and {base}; {100 * near:.1f} % of its "
                     f"{len(ground)} test points are within 2 m of the calibration line (the calibration objects stand on it); "
                     f"the map perturbations are px of {_map_scale_words(params.map_scale, ds.site_map.scale_px_per_m)}; "
                     f"the image perturbations are px of {_image_width_words(params.image_width, float(ds.camera.image_size[0]))}.")
    return facts


def ceiling_fact(study: dict, regression_median: float, variants: int = 50) -> str | None:
    """What regression's median path improvement (%) of a study could be at best: the median over the samples of
    the first ``variants`` variants of each scene of the best a d^2 + b d correction fitted to the test points
    themselves (study.ceiling; each variant weighted by its triples); None if a dataset is not available."""
    params = StudyParams.from_dict(study)
    try:
        scenes = [StudyScene.from_dataset(entry["path"], params) for entry in study["datasets"]]
    except ValueError:
        return None
    n = min(variants, params.n_variants + 1)
    ceilings = np.array([variant_ceilings(scene, params, v)[QUADRATIC] for scene in scenes for v in range(n)])
    weights = np.repeat([float(len(scene.triples)) for scene in scenes], n)
    return (f"the best a d^2 + b d correction there is, fitted to the test points themselves (an oracle), improves their "
            f"{params.metric} error by a median of {weighted_median(ceilings, weights):.1f} % over variants 0-{n - 1} of each scene "
            f"(research/radial_ceiling.py: over all): on them no correction of the paper's regression form has a "
            f"higher median path improvement; ours, as written, has {regression_median:.1f} % over all, the paper's "
            f"{PAPER['regression']['median_path']:.1f} %.")


def _map_scale_words(scale: float | None, own: float) -> str:
    """Which site map (scale: the study's map_scale) the 0-3 px map perturbations are in, and their largest size
    in metres."""
    which = (f"its own {own:g} px/m site map" if scale is None
             else f"a {scale:g} px/m site map (--map-scale; its own is {own:g})")
    return f"{which}, up to {MAX_PIXELS / (scale or own):.2f} m"


def _image_width_words(width: float | None, own: float) -> str:
    """Which camera image (width: the study's image_width) the 0-3 px image perturbations are in, and their
    largest size in its own px."""
    if width is None:
        return f"its own {own:g} px wide image"
    return (f"a {width:g} px wide image of the same field of view (--image-width; its own is {own:g} px wide), "
            f"up to {MAX_PIXELS * own / width:.2f} px of its own")


def law_html(results_dir: Path, study: dict) -> list[str]:
    """The quadratic law (paper Section 3) measured on each dataset's exact trapezoid (study.law)."""
    e = html.escape
    parts = ["<h2>The quadratic law, measured</h2>",
             "<p>Range error along the calibration line (10-44 m straight ahead) against the exact trapezoid. A horizon "
             "shift (the clicked image trapezoid moved as a tilt error moves it) gives the error eq. (17) describes: its "
             "exponent against range measured from the column model's Offset point is 2 to first order; higher-order "
             "terms lower it at large shifts. The study's random 0-3 px corner perturbations do not: their signed error "
             "changes sign along the line in most variants, and eq. (17) alone does not predict it, while the full "
             "first-order expansion (first_order_error) does.</p>"]
    for entry in study["datasets"]:
        try:
            ds = load_dataset(entry["path"])
        except ValueError as err:
            parts.append(f"<p class='warn'>{e(entry['scene'])}: dataset not available ({e(str(err))})</p>")
            continue
        exact = ds.trapezoids["exact"]
        vt = ViewTransformer(exact["image"], ds.site_map.to_metres(exact["map"]))
        K = ds.camera.K
        shift_rows = [[f"{r['shift_px']:g}", f"{r['exponent_Y']:.3f}", f"{r['exponent_Y_offset']:.3f}", f"{r['error_far_m']:.3f}",
                       f"{r['first_order_far_m']:.3f}", f"{r['eq17_far_m']:.3f}"] for r in horizon_shift_law(vt, K, ds.camera_origin)]
        parts += [f"<h3>{e(ds.name)}</h3>", _html_table(
            ["horizon shift (px)", "exponent vs Y", "exponent vs Y - Offset", "error at 44 m (m)", "first order (m)", "eq. (17) (m)"],
            shift_rows, numeric=True)]
        law = perturbation_law(vt, np.asarray(exact["map"], float), ds.site_map, ds.camera_origin, K[0, 2],
                               study.get("seed", 0), ds.name, reading=study.get("perturbation", "coordinate"))
        parts.append(f"<p>Random corner perturbations ({law['variants']} variants of the study's perturbation model on the "
                     f"exact trapezoid): median exponent {law['median_exponent']:.2f}; the signed error changes sign "
                     f"between 10 and 44 m in {100 * law['sign_change_share']:.0f} % of variants; median relative RMS "
                     f"residual of first_order_error {100 * law['median_residual_first_order']:.1f} %, of eq. (17) alone "
                     f"{100 * law['median_residual_eq17']:.0f} %.</p>")
    return parts


def render_html(study: dict, table: Table, figures: list[FigureFile], notes: list[str], out_dir: Path,
                first: Sequence[str] = (), missing: int = 0) -> str:
    """The report page: a table of contents, the incomplete-study warning, the headline figure (figures.HEADLINE),
    the sections given in first (Reproduction, the law), the study's settings (settings_html) and counts, the
    table per method, the other figures one under another at full width."""
    e = html.escape
    done, total = study.get("samples_done"), study.get("samples_total")
    degenerate = study.get("degenerate", [])
    rows_read = table.value("regression", "n")
    headline = [f for f in figures if f.path.name == HEADLINE]
    versions = ", ".join(f"{k} {v}" for k, v in study.get("versions", {}).items())
    parts = [
        "" if study.get("complete") and not missing else f"<p class='warn'>The study is not complete: {missing} shard(s) missing, {_count(done)} of {_count(total)} samples in study.json's count; the numbers below are of the shards finished so far.</p>",
        "<h2>The methods at a glance</h2>",
        *(_figure_html(f, out_dir) for f in headline),
        *first,
        "<h2>Study</h2>",
        *settings_html(study),
        _html_table(["scene", "dataset", "config hash"], [[d["scene"], d.get("path", ""), d.get("config_hash", "")] for d in study["datasets"]]),
        f"<p>Samples done: {_count(done)} of {_count(total)} (study.json); rows read from the shards: {rows_read:,}. "
        f"Degenerate trapezoid variants: {len(degenerate)}.</p>",
        _html_table(["scene", "variant", "reason"], [[d.get("scene", ""), d.get("variant", ""), d.get("reason", "")] for d in degenerate]) if degenerate else "",
        f"<p>Versions: {e(versions)}</p>" if versions else "",
        "<h2>Table 1 and more</h2>",
        "<p>Improvements in percent, 100 (E_before - E_after) / E_before of the mean ground error on the calibration "
        "points (calibration) and the test points (path); pp = percentage points. Also in <a href='table.md'>table.md</a> "
        "and <a href='table.csv'>table.csv</a>.</p>",
        "<div class='grid'>",
    ]
    for method, header, lines in table_cells(table):
        parts.append(f"<div><h3>{e(method)}</h3>{_html_table(header, lines, numeric=True)}</div>")
    parts.append("</div>")
    parts.append("<h2>Figures</h2>")
    parts += [f"<p class='warn'>{e(note)}</p>" for note in notes]
    parts += [_figure_html(f, out_dir) for f in figures if f.path.name != HEADLINE]
    body, contents = _numbered_sections("\n".join(p for p in parts if p))
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>homocal study report</title><style>{STYLE}</style>"
            f"</head><body>\n<h1>homocal study report</h1>\n{contents}\n{body}\n</body></html>")


def settings_html(study: dict) -> list[str]:
    """The study's settings as homocal study's command line gives them: each option's flag and value (with its
    unit) and what it sets, those that differ from the preset's values marked; then the settings no option sets
    (StudyParams' internal fields), in words."""
    params = StudyParams.from_dict(study)
    preset = study.get("preset")
    base = preset_params(preset) if preset in PRESETS else StudyParams()
    label = f" ({study['preset_label']})" if study.get("preset_label") else ""
    rows = []
    for name, opt in OPTIONS.items():
        value = getattr(params, name)
        text = opt.to_text(value) + (f" {opt.unit}" if opt.unit and value is not None else "")
        meaning = opt.none if value is None else opt.help
        changed = option_text(name, value) != option_text(name, getattr(base, name))
        rows.append([opt.flag, text, ("set; " if changed else "") + meaning])
    fixed = [f"the hybrid's threshold {params.threshold:g} % (the paper's Section 5.4)",
             "least change's settings " + ", ".join(f"{k} = {v:g}" for k, v in params.least_change.items()),
             "descent's other settings " + ", ".join(f"{k} = {_words(v)}" for k, v in params.descent.items()
                                                     if k != "delta_max")]
    return [f"<p>Preset <code>--preset {html.escape(str(preset))}</code>{html.escape(label)}; as its command line: "
            f"<code>{html.escape(' '.join(option_text(n, getattr(params, n)) for n in OPTIONS))}</code>.</p>",
            _html_table(["option", "value", "what it sets ('set': differs from the preset)"], rows),
            "<p>Fixed, no option: " + html.escape("; ".join(fixed)) + ".</p>"]


def _words(value) -> str:
    """A setting's value as text: numbers with %g, lists joined by commas."""
    if isinstance(value, (list, tuple)):
        return ", ".join(_words(v) for v in value)
    return f"{value:g}" if isinstance(value, (int, float)) and not isinstance(value, bool) else str(value)


def _count(value) -> str:
    """A count of study.json, or "?" if it has none."""
    return f"{value:,}" if isinstance(value, int) else "?"


def _figure_html(fig: FigureFile, out_dir: Path) -> str:
    """A figure embedded as a data URI at full width, its caption and a link to its file."""
    e = html.escape
    data = base64.b64encode(fig.path.read_bytes()).decode("ascii")
    rel = fig.path.relative_to(out_dir).as_posix()
    return (f"<figure><img src='data:image/png;base64,{data}' alt='{e(fig.title)}'><figcaption><b>{e(fig.title)}.</b> "
            f"{e(fig.caption)} <a href='{e(rel)}'>{e(rel)}</a></figcaption></figure>")


_H2 = re.compile(r"<h2>(.*?)</h2>")


def _numbered_sections(body: str) -> tuple[str, str]:
    """(body with an id on each h2, the table of contents linking to them)."""
    titles: list[str] = []

    def anchor(match: re.Match) -> str:
        titles.append(match.group(1))
        return f"<h2 id='section-{len(titles)}'>{match.group(1)}</h2>"

    body = _H2.sub(anchor, body)
    items = "".join(f"<li><a href='#section-{i + 1}'>{t}</a></li>" for i, t in enumerate(titles))
    return body, f"<nav><b>Contents</b><ol>{items}</ol></nav>"


def _html_table(header: list[str], rows: list[list], numeric: bool = False) -> str:
    """An HTML table; numeric: right-align every column but the first."""
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td{' class=num' if numeric and i else ''}>{html.escape(str(c))}</td>" for i, c in enumerate(row)) + "</tr>"
        for row in rows
    )
    return f"<table><tr>{head}</tr>{body}</table>"

