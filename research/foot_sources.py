"""Table 1 per foot source: what a detector's foot points change in the study (docs/reproduction.md,
"Detection noise").

Run: python research/foot_sources.py STUDY [STUDY ...]
     (each STUDY a results folder of `homocal study DATASET... -o STUDY --foot-source F`)
     python research/foot_sources.py --calibration exact|segmentation DATASET OUT
     (OUT: DATASET with every calibration object's foot point, exact and detected alike, taken from the exact
     projection or from the segmentation detector, the other files linked: a study on it with --foot-source
     exact then has segmentation calibration points and exact test points, one with a detector exact
     calibration points and that detector's test points; this separates the calibration points' noise from
     the test points'; with --exact-detections, every matched detection moved to its agent's exact foot point:
     the detector's choice of test points without its foot-point error)

Prints three markdown tables:
1. Per dataset of the studies and per foot source (exact, each detector in detections.parquet, and the
   calibration objects' segmentation foot points): the points, those within the studies' test distance, and
   the foot point's error against the exact one: in the image (px, against gt.parquet's exact projection of
   the same agent at gt_t) and on the ground (m, the foot point mapped by the exact trapezoid against the true
   ground point), median and 90th percentile; and its bias: the median of how many rows it lies below the
   exact one and of its signed range error (mapped distance from the camera minus the true one, m).
2. Per study: its foot source, calibration and test points per scene (study.json), the test points' median
   distance from the camera (m), their ground error under the exact trapezoid's mapping (what their own error
   adds with a perfect trapezoid, mean over the study's test points, m) and the base trapezoid's path error (mean over its test points, m: the shards' path_before of
   variant 0).
3. Per study: Table 1's numbers of the paper's two methods (homocal.study.metrics.build_table) beside the
   paper's, and D, the RMS distance to the paper's 14 numbers (metrics.paper_distance); then the other methods.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from homocal.dataset import EXACT, load_dataset
from homocal.geometry import ViewTransformer
from homocal.study.metrics import D_METHODS, METHODS, METRICS, OVERALL, PAPER, build_table, load_study, paper_distance, shard_files

KEYS = ("pos_path", "mean_path", "median_path", "p1_path", "std_path", "corr", "pos_cal", "median_cal")


def exact_mapping(ds) -> ViewTransformer:
    exact = ds.trapezoids["exact"]
    return ViewTransformer(np.asarray(exact["image"], float), ds.site_map.to_metres(np.asarray(exact["map"], float)))


def with_exact_feet(ds):
    """detections.parquet as a DataFrame with u_exact, v_exact: gt.parquet's exact projection of the matched
    agent's foot point at gt_t (NaN for unmatched detections)."""
    gt = ds.table("gt.parquet").to_pandas()[["t", "agent_id", "u", "v"]]
    d = ds.table("detections.parquet").to_pandas()
    key = lambda t: np.round(t.fillna(-1.0) * 1e6).astype(np.int64)  # noqa: E731
    gt = gt.assign(key=key(gt["t"])).drop(columns="t").rename(columns={"u": "u_exact", "v": "v_exact"})
    return d.assign(key=key(d["gt_t"])).merge(gt, on=["agent_id", "key"], how="left", validate="many_to_one").drop(columns="key")


def foot_errors(ds, max_distance: float | None) -> list[list[str]]:
    """Rows (scene, source, points, within max_distance, px median / p90, m median / p90) of table 1."""
    vt = exact_mapping(ds)
    rows = []

    def row(source, image, exact_image, ground):
        near = np.ones(len(ground), bool) if max_distance is None else np.hypot(*(ground - ds.camera_origin).T) <= max_distance
        px = np.hypot(*(image - exact_image).T)[near]
        mapped = vt.transform_points(image)
        m = np.hypot(*(mapped - ground).T)[near]
        low = (image[:, 1] - exact_image[:, 1])[near]  # px, positive: below the exact foot point
        nearer = (np.hypot(*(mapped - ds.camera_origin).T) - np.hypot(*(ground - ds.camera_origin).T))[near]
        q = lambda x: f"{np.median(x):.2f} / {np.percentile(x, 90):.2f}" if len(x) else "-"  # noqa: E731
        signed = lambda x: f"{np.median(x):+.2f}" if len(x) else "-"  # noqa: E731
        rows.append([ds.name, source, f"{len(image):,}", f"{near.sum():,}", q(px), q(m), signed(low), signed(nearer)])

    detections = with_exact_feet(ds)
    for detector, d in detections.groupby("detector", sort=False):
        d = d[(d["agent_id"] >= 0) & np.isfinite(d[["u", "v", "gt_x", "gt_y"]]).all(axis=1)]
        row(detector, d[["u", "v"]].to_numpy(float), d[["u_exact", "v_exact"]].to_numpy(float), d[["gt_x", "gt_y"]].to_numpy(float))
    cal = ds.table("calibration.parquet").to_pandas()
    row("calibration objects, segmentation", cal[["u", "v"]].to_numpy(float), cal[["u_exact", "v_exact"]].to_numpy(float),
        cal[["x", "y"]].to_numpy(float))
    return rows


def test_point_facts(study: dict) -> dict[str, tuple[float, float]]:
    """Per scene: the mean ground error (m) of the study's test points mapped by the exact trapezoid, and their
    median true distance from the camera (m)."""
    out = {}
    for entry in study["datasets"]:
        ds = load_dataset(entry["path"])
        image, ground = ds.test_points(study.get("foot_source", EXACT), n=study.get("n_test"), seed=study.get("seed", 0),
                                       max_distance=study.get("max_test_distance"), max_lateral=study.get("test_lateral_max"))
        out[entry["scene"]] = (float(np.mean(np.hypot(*(exact_mapping(ds).transform_points(image) - ground).T))),
                               float(np.median(np.hypot(*(ground - ds.camera_origin).T))))
    return out


def table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" if i < 2 else "---:" for i in range(len(header))) + "|"]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def derive(dataset: Path, out: Path, calibration: str, exact_detections: bool = False) -> None:
    """OUT: dataset's files linked, calibration.parquet rewritten with (u, v) and (u_exact, v_exact) both from the
    exact projections (calibration "exact") or both from the segmentation detector ("segmentation"); with
    exact_detections, detections.parquet rewritten with every matched detection's (u, v) set to the exact
    projection of its agent's foot point (the detector's choice of test points without its foot-point error)."""
    ds = load_dataset(dataset)  # a complete dataset
    out.mkdir(parents=True)
    rewrite = {"calibration.parquet", *(["detections.parquet"] if exact_detections else [])}
    for f in sorted(dataset.iterdir()):
        if f.name not in rewrite:
            os.symlink(f.resolve(), out / f.name)
    cal = pq.read_table(dataset / "calibration.parquet")
    u, v = ("u_exact", "v_exact") if calibration == EXACT else ("u", "v")
    cols = {"u": cal.column(u), "v": cal.column(v), "u_exact": cal.column(u), "v_exact": cal.column(v)}
    for name, col in cols.items():
        cal = cal.set_column(cal.schema.get_field_index(name), name, col)
    pq.write_table(cal, out / "calibration.parquet")
    if exact_detections:
        d = with_exact_feet(ds)
        matched = d["u_exact"].notna().to_numpy()
        d.loc[matched, "u"], d.loc[matched, "v"] = d.loc[matched, "u_exact"], d.loc[matched, "v_exact"]
        pq.write_table(pa.Table.from_pandas(d.drop(columns=["u_exact", "v_exact"]), preserve_index=False),
                       out / "detections.parquet")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("studies", nargs="+", type=Path, help="results folders of homocal study (or DATASET OUT)")
    parser.add_argument("--calibration", choices=(EXACT, "segmentation"), help="write a dataset with these calibration points")
    parser.add_argument("--exact-detections", action="store_true",
                        help="with --calibration: matched detections at their agent's exact foot point")
    args = parser.parse_args(argv)
    if args.exact_detections and not args.calibration:
        parser.error("--exact-detections: only with --calibration (it rewrites the written dataset's detections)")
    if args.calibration:
        if len(args.studies) != 2:
            parser.error("--calibration needs DATASET OUT")
        derive(*args.studies, args.calibration, args.exact_detections)
        return 0
    studies = [(path, load_study(path)) for path in args.studies]
    datasets = dict.fromkeys(e["path"] for _, s in studies for e in s["datasets"])
    max_distance = studies[0][1].get("max_test_distance")
    rows = [r for path in datasets for r in foot_errors(load_dataset(path), max_distance)]
    within = f"within {max_distance:g} m" if max_distance else "all"
    print(table(["scene", "foot points", "matched points", within, "image error, px (median / p90)",
                 "ground error, m (median / p90)", "rows below, px (median)", "range error, m (median)"], rows))
    print()
    point_rows, tables = [], []
    for path, study in studies:
        shards = shard_files(path, study)
        before = {scene: pq.read_table(files[0], columns=["path_before"]).column(0)[0].as_py() if files else float("nan")
                  for scene, files in shards.items()}
        facts = test_point_facts(study)
        point_rows += [[str(path), study.get("foot_source", EXACT), e["scene"], f"{study['n_variants']}",
                        f"{e['n_calibration']}", f"{e['n_test']:,}", f"{facts[e['scene']][1]:.1f}",
                        f"{facts[e['scene']][0]:.3f}", f"{before[e['scene']]:.3f}"] for e in study["datasets"]]
        tables.append((path, study, build_table(shards)))
    print(table(["study", "foot source", "scene", "variants", "calibration points", "test points",
                 "test points' median distance (m)", "test points' error, exact mapping (m)", "base trapezoid's path error (m)"], point_rows))
    print()
    header = ["method", "metric", "paper", *(f"{s.get('foot_source', EXACT)} ({p.name})" for p, s, _ in tables)]
    fmt = lambda k, v: "" if v is None else METRICS[k][1].format(v)  # noqa: E731
    rows = [[m, METRICS[k][0], fmt(k, PAPER[m].get(k)), *(fmt(k, t.value(m, k, OVERALL)) for _, _, t in tables)]
            for m in D_METHODS for k in KEYS]
    print(table(header, rows + [["", "**D** (pp)", "0", *(f"{paper_distance(t):.1f}" for _, _, t in tables)]]))
    print()
    print(table(header, [[m, METRICS[k][0], "", *(fmt(k, t.value(m, k, OVERALL)) for _, _, t in tables)]
                         for m in METHODS if m not in D_METHODS for k in KEYS]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
