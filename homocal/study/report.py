"""``homocal report RESULTS_DIR``: the study's table and figures gathered on one self-contained HTML page.

Writes into RESULTS_DIR/report (or --out): report.html (figures embedded as data URIs, linked to their
files beside it), table.md, table.csv and figures/*.png; prints the table and the page's path.
"""
from __future__ import annotations

import argparse
import base64
import html
import json
from pathlib import Path

from tqdm import tqdm

from homocal.files import write_text_atomic
from homocal.study.figures import FigureFile, make_figures
from homocal.study.metrics import Table, build_table, load_study, shard_files, table_cells, to_csv, to_markdown, to_text

STYLE = """body{font-family:sans-serif;max-width:1400px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #ccc;padding:2px 8px}
td.num{text-align:right;font-variant-numeric:tabular-nums}.grid{display:grid;grid-template-columns:1fr 1fr;gap:1.5em}
figure{margin:0}figure img{width:100%}figcaption{font-size:0.9em;color:#444}.warn{color:#a00}"""


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``report`` on the homocal command's subparsers."""
    parser = subparsers.add_parser(
        "report",
        help="gather a study's table and figures into one HTML page",
        description="Compute the paper's Table 1 (and more) from a study's results directory, draw the figures and "
        "write one HTML page with all of it; print the table and the page's path.",
    )
    parser.add_argument("results_dir", metavar="RESULTS_DIR", type=Path, help="a folder written by `homocal study`")
    parser.add_argument("--out", type=Path, default=None, help="folder for the page, table and figures (default: RESULTS_DIR/report)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Handler of ``homocal report``: print the table and the page's path; ValueError on bad input."""
    page, text = write_report(args.results_dir, args.out)
    print(text)
    print(page)
    return 0


def write_report(results_dir: str | Path, out_dir: str | Path | None = None) -> tuple[Path, str]:
    """Write table.md, table.csv, figures/ and report.html; return the page's path and the table as text.

    ValueError if results_dir is not a results directory (no study.json) or holds no shard yet.
    """
    results_dir = Path(results_dir)
    study = load_study(results_dir)
    shards = shard_files(results_dir, study)
    if not any(shards.values()):
        raise ValueError(f"{results_dir}: no finished shards under shards/<scene>/ yet")
    out_dir = Path(out_dir) if out_dir is not None else results_dir / "report"
    out_dir.mkdir(parents=True, exist_ok=True)
    with tqdm(total=3, desc="homocal report", unit="step", disable=None) as bar:
        table = build_table(shards)
        write_text_atomic(out_dir / "table.md", to_markdown(table))
        write_text_atomic(out_dir / "table.csv", to_csv(table))
        bar.update()
        figures, notes = make_figures(results_dir, study, shards, out_dir / "figures")
        bar.update()
        page = out_dir / "report.html"
        write_text_atomic(page, render_html(study, table, figures, notes, out_dir))
        bar.update()
    return page, to_text(table)


def render_html(study: dict, table: Table, figures: list[FigureFile], notes: list[str], out_dir: Path) -> str:
    """The report page: study parameters and counts, the table per method, the figures two by two."""
    e = html.escape
    done, total = study.get("samples_done"), study.get("samples_total")
    degenerate = study.get("degenerate", [])
    rows_read = table.value("regression", "n") + table.value("regression", "nonfinite")
    parts = [
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>homocal study report</title><style>{STYLE}</style></head><body>",
        "<h1>homocal study report</h1>",
        "" if study.get("complete") else f"<p class='warn'>The study is not complete: {e(str(done))} of {e(str(total))} samples.</p>",
        "<h2>Study</h2>",
        _html_table(["parameter", "value"], [[k, _show(v)] for k, v in study.items() if k not in ("datasets", "degenerate", "versions")]),
        _html_table(["scene", "dataset", "config hash"], [[d["scene"], d.get("path", ""), d.get("config_hash", "")] for d in study["datasets"]]),
        f"<p>Samples done: {e(_show(done))} of {e(_show(total))} (study.json); rows read from the shards: {rows_read:,}. "
        f"Degenerate trapezoid variants: {len(degenerate)}.</p>",
        _html_table(["scene", "variant", "reason"], [[d.get("scene", ""), d.get("variant", ""), d.get("reason", "")] for d in degenerate]) if degenerate else "",
        f"<p>Versions: {e(_show(study.get('versions', {})))}</p>",
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
    parts.append("<div class='grid'>")
    for fig in figures:
        data = base64.b64encode(fig.path.read_bytes()).decode("ascii")
        rel = fig.path.relative_to(out_dir).as_posix()
        parts.append(f"<figure><img src='data:image/png;base64,{data}' alt='{e(rel)}'><figcaption><b>{e(fig.title)}.</b> "
                     f"{e(fig.caption)} <a href='{e(rel)}'>{e(rel)}</a></figcaption></figure>")
    parts.append("</div></body></html>")
    return "\n".join(p for p in parts if p)


def _html_table(header: list[str], rows: list[list], numeric: bool = False) -> str:
    """An HTML table; numeric: right-align every column but the first."""
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td{' class=num' if numeric and i else ''}>{html.escape(str(c))}</td>" for i, c in enumerate(row)) + "</tr>"
        for row in rows
    )
    return f"<table><tr>{head}</tr>{body}</table>"


def _show(value) -> str:
    return value if isinstance(value, str) else json.dumps(value)
