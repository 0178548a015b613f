"""The study's figures as PNG files (matplotlib's object API with the Agg canvas; no pyplot state).

- the headline: each method's path improvement distribution per scene, side by side, the paper's Table 1 marked;
- error against distance with the fitted quadratic e = a d^2 + b d (paper Section 3), per scene;
- the distance distribution of the test points (paper Fig. 2);
- the calibration and path improvement distributions per method;
- mean path improvement against the sum and the spread of the three calibration distances (paper Fig. 4).

The first two need the datasets (study.json names them); the others read only the shards.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from homocal.correctors import fit_quadratic_error
from homocal.dataset import Dataset, calibration_source, load_dataset
from homocal.files import write_atomic
from homocal.geometry import ViewTransformer
from homocal.study.aggregate import Quantiles, scan
from homocal.study.metrics import D_METHODS, METHODS, PAPER
from homocal.study.perturb import base_trapezoid, perturbed_quads

DPI = 110
HEADLINE = "path_improvement.png"  # the report's first figure (headline_figure)


@dataclass(frozen=True)
class FigureFile:
    """A written figure: its PNG path, a title and a caption with the numbers worth knowing."""

    path: Path
    title: str
    caption: str


def figure_names(study: dict) -> list[str]:
    """The file names make_figures may write for a study (those of its scenes whose dataset is missing are not)."""
    return [HEADLINE, *(f"error_distance_{entry['scene']}.png" for entry in study["datasets"]), "test_distance.png",
            "improvement_histograms.png", "path_heatmaps.png"]


def save(fig: Figure, out: Path) -> None:
    """Write the figure as a PNG, atomically."""
    write_atomic(out, lambda tmp: fig.savefig(tmp, dpi=DPI))


def make_figures(results_dir: Path, study: dict, shards: dict[str, list[Path]], out_dir: Path, progress: bool = False
                 ) -> tuple[list[FigureFile], list[str]]:
    """Write every figure the results allow into out_dir; return them and notes on the ones left out.
    progress: a bar per pass over the shards on stderr for long reads."""
    out_dir.mkdir(parents=True, exist_ok=True)
    datasets, notes = [], []
    figures = [FigureFile(out_dir / HEADLINE, "Path improvement of each method, per scene",
                          headline_figure(shards, out_dir / HEADLINE, progress=progress))]
    source, n_test, seed = study.get("foot_source", "exact"), study.get("n_test"), study.get("seed", 0)
    max_distance = study.get("max_test_distance")
    for entry in study["datasets"]:
        scene, path = entry["scene"], out_dir / f"error_distance_{entry['scene']}.png"
        try:
            ds = load_dataset(_dataset_path(results_dir, entry.get("path", "")))
            caption = error_vs_distance(ds, Path(results_dir) / "variants" / f"{scene}.parquet", source, path,
                                        n_test=n_test, seed=seed, max_distance=max_distance)
        except ValueError as e:
            notes.append(f"scene {scene}: dataset not available, its error and distance figures are left out ({e})")
            continue
        datasets.append(ds)
        figures.append(FigureFile(path, f"Ground error against distance: {scene}", caption))
    if datasets:
        path = out_dir / "test_distance.png"
        caption = test_distance_distribution(datasets, source, path, n_test=n_test, seed=seed, max_distance=max_distance)
        figures.append(FigureFile(path, "Distance distribution of the test points", caption))
    figures += [
        FigureFile(out_dir / "improvement_histograms.png", "Improvement distributions",
                   improvement_histograms(shards, out_dir / "improvement_histograms.png", progress=progress)),
        FigureFile(out_dir / "path_heatmaps.png", "Mean path improvement against calibration distances",
                   path_heatmaps(shards, out_dir / "path_heatmaps.png", progress=progress)),
    ]
    return figures, notes


class ColumnHistogram:
    """Counts per bin (edges (B + 1,), the last bin closed), below the first and above the last edge, and the
    median of a float32 column, over batches seen twice (add every batch, second_pass(), add every batch again).
    A value that is not finite is a failed correction, as in the table (homocal.study.metrics): counted
    (``failures``), below the first edge and below every percentile."""

    def __init__(self, edges: np.ndarray):
        self.edges, self.counts, self.below, self.above = edges, np.zeros(len(edges) - 1, np.int64), 0, 0
        self.failures, self.median, self.first = 0, Quantiles((50,)), True

    def add(self, values: np.ndarray) -> None:
        failed = ~np.isfinite(values)
        values = np.where(failed, np.float32(-np.inf), values)
        self.median.add(values)
        if self.first:
            self.counts += np.histogram(values[~failed], self.edges)[0]
            self.below += np.count_nonzero(values < self.edges[0])
            self.above += np.count_nonzero(values > self.edges[-1])
            self.failures += np.count_nonzero(failed)

    def second_pass(self) -> None:
        self.first = False
        self.median.second_pass()


def column_histograms(shards: dict[str, list[Path]], columns: list[str], edges: np.ndarray, what: str,
                      progress: bool = False, per_scene: bool = False) -> dict:
    """A ColumnHistogram (edges (B + 1,)) of each column, all scenes pooled ({column: histogram}) or per scene
    ({(scene, column): histogram}); read in two passes one shard at a time (aggregate.scan)."""
    hists: dict = {}
    for n in (1, 2):
        for scene, batch in scan(shards, columns, f"{what}, pass {n} of 2", progress):
            for c in columns:
                key = (scene, c) if per_scene else c
                if n == 1 and key not in hists:
                    hists[key] = ColumnHistogram(edges)
                hists[key].add(batch[c])
        if n == 1:
            for h in hists.values():
                h.second_pass()
    return hists


def headline_figure(shards: dict[str, list[Path]], out: Path, lo: float = -100.0, hi: float = 100.0,
                    width: float = 2.0, progress: bool = False) -> str:
    """The report's first figure: per scene (a panel each), each method's path improvement distribution (percent)
    as a strip whose height follows the share of samples per bin, with its median; the paper's Table 1 median and
    mean path improvement marked on its two methods' strips. Returns the caption."""
    edges = np.arange(lo, hi + width / 2, width)
    columns = [f"path_{m}" for m in METHODS]
    hists = column_histograms(shards, columns, edges, "headline", progress, per_scene=True)
    scenes = list(dict.fromkeys(scene for scene, _ in hists))
    fig = Figure(figsize=(13, 0.1 + (0.55 * len(METHODS) + 0.9) * len(scenes)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(scenes), 1, sharex=True, squeeze=False).ravel())
    centres = (edges[:-1] + edges[1:]) / 2
    for ax, scene in zip(axes, scenes):
        notes = []
        for row, method in enumerate(METHODS):
            h = hists[(scene, f"path_{method}")]
            share = h.counts / max(h.median.n, 1)
            y = len(METHODS) - 1 - row
            half = 0.42 * share / max(share.max(), 1e-12)
            ax.fill_between(centres, y - half, y + half, step="mid", color="tab:blue", alpha=0.55, lw=0)
            median = h.median.values()[0]
            ax.plot([median] * 2, [y - 0.42, y + 0.42], color="k", lw=2)
            outside = 100 * (h.below + h.above) / max(h.median.n, 1)
            notes.append(f"median {median:.1f} %" + (f", {outside:.1f} % outside" if outside >= 0.05 else ""))
            if method in D_METHODS:
                ax.plot(PAPER[method]["median_path"], y, "D", color="tab:red", ms=8, mec="k")
                ax.plot(PAPER[method]["mean_path"], y, "^", color="tab:orange", ms=8, mec="k")
        ax.set_yticks(range(len(METHODS)), list(METHODS)[::-1], fontsize=10)
        ax.set_ylim(-0.6, len(METHODS) - 0.4)
        right = ax.twinx()  # each strip's median (and share outside the display) beside it
        right.set_ylim(ax.get_ylim())
        right.set_yticks(range(len(METHODS)), notes[::-1], fontsize=9)
        ax.set_xlim(lo, hi)
        ax.axvline(0, color="0.3", lw=0.8)
        ax.set_title(f"{scene}", fontsize=11, loc="left")
        ax.grid(axis="x", color="0.85", lw=0.6)
    axes[-1].set_xlabel("path improvement (%) = 100 (E_before - E_after) / E_before")
    axes[0].plot([], [], "D", color="tab:red", mec="k", label="paper's Table 1: median")
    axes[0].plot([], [], "^", color="tab:orange", mec="k", label="paper's Table 1: mean")
    axes[0].plot([], [], color="k", lw=2, label="ours: median")
    fig.legend(loc="outside upper center", fontsize=9, ncols=3)
    save(fig, out)
    return (f"Each method's path improvement per scene: the strip's height follows the share of samples per "
            f"{width:g} pp bin (each strip scaled to its own highest bin), the black bar is its median; shown on "
            f"[{lo:g}, {hi:g}] %, the share outside it given beside the median (failed corrections count below). The "
            f"paper's Table 1 median (diamond) and mean (triangle) path improvement are marked on its two methods, "
            f"{' and '.join(D_METHODS)}.")


def improvement_histograms(shards: dict[str, list[Path]], out: Path, lo: float = -200.0, hi: float = 100.0, width: float = 2.0,
                           progress: bool = False) -> str:
    """Histograms of calibration and path improvement (percent) per method, all scenes pooled, shown on [lo, hi];
    read in two passes one shard at a time (aggregate.scan)."""
    edges = np.arange(lo, hi + width / 2, width)
    columns = [f"{kind}_{m}" for m in METHODS for kind in ("cal", "path")]
    hists = column_histograms(shards, columns, edges, "histograms", progress)
    fig = Figure(figsize=(10, 2.6 * len(METHODS)), layout="constrained")
    axes = fig.subplots(len(METHODS), 2, sharex=True)
    for row, method in zip(axes, METHODS):
        for ax, kind, h in zip(row, ("calibration", "path"), (hists[f"cal_{method}"], hists[f"path_{method}"])):
            n = max(h.median.n, 1)
            ax.stairs(100 * h.counts / n, edges, fill=True, color=f"tab:{'blue' if kind == 'path' else 'green'}")
            ax.axvline(0, color="k", lw=0.8)
            below, above = 100 * h.below / n, 100 * h.above / n
            median = h.median.values()[0]
            failed = f", {100 * h.failures / n:.2f} % failed" if h.failures else ""
            ax.text(0.02, 0.95, f"median {median:.1f} %\nbelow {lo:g} %: {below:.2f} % (not shown{failed})"
                    + (f"\nabove {hi:g} %: {above:.2f} %" if above else ""),
                    transform=ax.transAxes, va="top", fontsize=8)
            ax.set_title(f"{method}: {kind} improvement", fontsize=10)
            ax.set_ylabel(f"samples per {width:g} pp bin (%)")
    for ax in axes[-1]:
        ax.set_xlabel("improvement (%) = 100 (E_before - E_after) / E_before")
    save(fig, out)
    return (f"The improvement distributions of the paper's Section 6 (its text gives their medians, spreads and 1st "
            f"percentiles). Share of samples per {width:g} percentage-point bin, all scenes pooled; the display is clipped to "
            f"[{lo:g}, {hi:g}] % and each panel gives the share of samples outside it; failed corrections (path error "
            f"infinite) count below it and in the median, as in the table.")


def heatmap_means(shards: dict[str, list[Path]], bins: int = 24, progress: bool = False
                  ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ma.MaskedArray], dict[str, int]]:
    """x edges (bins + 1,) over the triples' distance sum (m), y edges (bins + 1,) over their spread (max - min,
    m), and per method the mean path improvement (percent) per cell, (bins, bins) indexed [y, x], empty cells
    masked; all scenes pooled, read in two passes one shard at a time (aggregate.scan): the ranges, then the
    cells' counts and sums; and per method the failed corrections (path error infinite) left out of the means."""
    located = ["d_sum", "d_spread"]
    lows, highs = [np.inf, np.inf], [-np.inf, -np.inf]
    for _, batch in scan(shards, located, "heatmaps, pass 1 of 2", progress):
        for i, c in enumerate(located):
            values = batch[c][np.isfinite(batch[c])]
            if values.size:
                lows[i], highs[i] = min(lows[i], float(values.min())), max(highs[i], float(values.max()))
    x_edges, y_edges = (np.linspace(*_range(lo, hi), bins + 1) for lo, hi in zip(lows, highs))
    counts = {m: np.zeros(bins * bins, np.int64) for m in METHODS}
    sums = {m: np.zeros(bins * bins) for m in METHODS}
    failures = dict.fromkeys(METHODS, 0)
    for _, batch in scan(shards, [*located, *(f"path_{m}" for m in METHODS)], "heatmaps, pass 2 of 2", progress):
        cell = _bin(batch["d_sum"], x_edges) * bins + _bin(batch["d_spread"], y_edges)
        inside = np.isfinite(batch["d_sum"]) & np.isfinite(batch["d_spread"])
        for method in METHODS:
            path = batch[f"path_{method}"]
            ok = inside & np.isfinite(path)
            failures[method] += int(np.count_nonzero(inside & ~np.isfinite(path)))
            counts[method] += np.bincount(cell[ok], minlength=bins * bins)
            sums[method] += np.bincount(cell[ok], weights=path[ok], minlength=bins * bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = {m: np.ma.masked_invalid(sums[m] / counts[m]).reshape(bins, bins).T for m in METHODS}
    return x_edges, y_edges, means, failures


def path_heatmaps(shards: dict[str, list[Path]], out: Path, bins: int = 24, vmin_floor: float = -100.0,
                  progress: bool = False) -> str:
    """Mean path improvement (percent) per bin of the sum (m) and the spread (max - min, m) of the three
    calibration distances, per method, all scenes pooled (paper Fig. 4; heatmap_means). Returns the caption."""
    x_edges, y_edges, means, failures = heatmap_means(shards, bins, progress)
    fig, vmin, clipped = heatmap_figure(x_edges, y_edges, means, vmin_floor)
    save(fig, out)
    return (f"Counterpart of the paper's Fig. 4 (a: regression, b: descent). Mean path improvement per cell of {bins} x {bins} bins of the calibration triple's distance sum and "
            f"spread (max - min), all scenes and variants pooled; empty cells are blank"
            + (f"; cell means below {vmin:g} % share the lowest colour" if clipped else "")
            + (f"; failed corrections (path error infinite) are left out of the means: "
               f"{', '.join(f'{m} {n:,}' for m, n in failures.items() if n)}." if any(failures.values()) else "."))


def heatmap_figure(x_edges: np.ndarray, y_edges: np.ndarray, means: dict, vmin_floor: float = -100.0):
    """(figure, vmin, clipped): one panel per method of means (heatmap_means), four a row, on one diverging colour
    scale centred on 0 (red: worse than no correction, blue: better), cell means below vmin_floor clipped."""
    filled = [m for m in means.values() if m.count()]
    lowest = float(min((m.min() for m in filled), default=0.0))
    vmin = max(lowest, vmin_floor)
    vmax = max(float(max((m.max() for m in filled), default=100.0)), vmin)
    span = max(abs(vmin), abs(vmax), 1e-9)
    norm = Normalize(-span, span)
    rows = -(-len(means) // 4)
    fig = Figure(figsize=(16, 4.2 * rows), layout="constrained")
    axes = fig.subplots(rows, 4, sharex=True, sharey=True).ravel()
    for ax in axes[len(means):]:
        ax.remove()
    axes = axes[:len(means)]
    for ax, (method, mean) in zip(axes, means.items(), strict=True):
        mesh = ax.pcolormesh(x_edges, y_edges, mean, cmap="RdBu", norm=norm)
        ax.set_title(method)
        ax.set_xlabel("sum of the three calibration distances (m)")
        ax.set_ylabel("spread of the three calibration distances (m)")
    fig.colorbar(mesh, ax=axes.tolist(), label="mean path improvement (%)", extend="min" if lowest < vmin else "neither")
    return fig, vmin, lowest < vmin


def ground_error(image_quad: np.ndarray, map_quad: np.ndarray, ds: Dataset, image: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """Euclidean ground error (N,), metres, of image points (N, 2) px mapped through the trapezoid pair
    (image px, map px) and the site map, against their true ground positions (N, 2) m; NaN beyond the horizon."""
    mapped = ds.site_map.to_metres(ViewTransformer(image_quad, map_quad).transform_points(image))
    return np.linalg.norm(mapped - ground, axis=1)


def error_vs_distance(ds: Dataset, variants_file: Path, source: str, out: Path, n_variants: int = 3,
                      n_test: int | None = 2000, seed: int = 0, max_distance: float | None = None) -> str:
    """Ground error (m) against true distance from the camera (m) for the variant-0 base trapezoid (calibration
    and test points) and the first n_variants perturbed, non-degenerate variants (calibration points), each
    with the least-squares fit e = a d^2 + b d over its calibration points (paper eqs. (17), (19); the
    counterpart of the paper's Fig. 3)."""
    cal_img, cal_ground, _ = ds.calibration_points(calibration_source(source))
    test_img, test_ground = ds.test_points(source, n=n_test, seed=seed, max_distance=max_distance)
    fig = Figure(figsize=(8, 5.5), layout="constrained")
    ax = fig.subplots()
    quads = _variant_quads(ds, variants_file, n_variants)
    e_test = ground_error(*quads[0][1], ds, test_img, test_ground)
    ax.scatter(_distance(ds, test_ground), e_test, s=3, color="0.7", label=f"test points ({len(e_test)}), {quads[0][0]}")
    d_cal = _distance(ds, cal_ground)
    d_line = np.linspace(0, max(d_cal.max(), np.nanmax(_distance(ds, test_ground))), 200)
    negative = []
    for (name, (image, map_quad)), color in zip(quads, ["k", "tab:red", "tab:orange", "tab:purple", "tab:cyan"]):
        try:
            e_cal = ground_error(image, map_quad, ds, cal_img, cal_ground)
        except ValueError:
            continue
        ok = np.isfinite(e_cal)
        a, b, _ = fit_quadratic_error(d_cal[ok], e_cal[ok])
        negative += [name] if a < 0 else []
        ax.scatter(d_cal, e_cal, s=18, color=color, marker="o" if name == quads[0][0] else "x")
        ax.plot(d_line, a * d_line**2 + b * d_line, color=color, ls="-" if name == quads[0][0] else "--",
                label=f"{name}: e = {a:.2e} d² {b:+.2e} d")
    ax.set_xlabel("true distance from the camera (m)")
    ax.set_ylabel("ground error of the mapped point (m)")
    ax.set_title(f"{ds.name}: ground error against distance ({source} foot points)")
    ax.legend(fontsize=8)
    save(fig, out)
    return (f"Counterpart of the paper's Fig. 3. Euclidean ground error of the calibration points (markers) and the test "
            f"points (grey) mapped through the base trapezoid of variant 0 and the first {len(quads) - 1} perturbed "
            f"variant(s), with the least-squares fit e = a d² + b d over all {len(d_cal)} calibration points of each."
            + (f" The fitted quadratic term is negative for {', '.join(negative)}: there the error does not grow as the "
               f"square of the range (Section 3), and the paper's Method 1 clamps a to 0." if negative else ""))


def test_distance_distribution(datasets: list[Dataset], source: str, out: Path, n_test: int | None = None, seed: int = 0,
                               width: float = 1.0, max_distance: float | None = None) -> str:
    """Histogram of the test points' true distance from the camera (m) per scene, calibration distances as ticks."""
    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.subplots()
    sizes = []
    for ds, color in zip(datasets, ["tab:blue", "tab:orange", "tab:green", "tab:red"]):
        d = _distance(ds, ds.test_points(source, n=n_test, seed=seed, max_distance=max_distance)[1])
        sizes.append(f"{ds.name}: {len(d)}")
        ax.hist(d, bins=np.arange(0, d.max() + width, width), histtype="step", color=color, lw=1.5, label=f"{ds.name} test points")
        cal = ds.calibration_points(calibration_source(source))[2]
        ax.plot(cal, np.zeros_like(cal), "|", color=color, ms=14, mew=1.5, label=f"{ds.name} calibration distances")
    ax.set_xlabel("distance from the camera (m)")
    ax.set_ylabel(f"test points per {width:g} m bin")
    ax.set_title("Distance distribution of the test points")
    ax.legend(fontsize=8)
    save(fig, out)
    return (f"Counterpart of the paper's Fig. 2. True distance from the camera of the test points ({', '.join(sizes)}); "
            f"ticks on the axis: calibration distances.")


def _variant_quads(ds: Dataset, variants_file: Path, n: int) -> list[tuple[str, tuple[np.ndarray, np.ndarray]]]:
    """(name, (image quad, map quad)) of variant 0 and the first n non-degenerate perturbed variants, each its
    base trapezoid (the variants table's horizon_shift_px and click_0..7; the hand-placed one if the table is
    missing) plus its offsets (img_0..7, map_0..7)."""
    hand = ("hand-placed", (ds.trapezoid_image, ds.trapezoid_map))
    if not variants_file.is_file():
        return [hand]
    t = pq.read_table(variants_file).to_pydict()
    target = ds.site_map.to_metres(ds.trapezoid_map)
    out = []
    for row in range(len(t["variant"])):
        if len(out) == n + 1:
            break
        offsets = np.array([t[f"{side}_{k}"][row] for side in ("img", "map") for k in range(8)])
        if t["degenerate"][row] or (row > 0 and not offsets.any()):
            continue
        noise = np.array([t[f"click_{k}"][row] for k in range(8)])
        base = base_trapezoid(ds.trapezoid_image, target, ds.camera.K, ds.camera.horizon_row, t["horizon_shift_px"][row], noise)
        name = "base trapezoid (variant 0)" if row == 0 else f"variant {t['variant'][row]}"
        out.append((name, perturbed_quads(base, ds.trapezoid_map, offsets)))
    return out or [hand]


def _distance(ds: Dataset, ground: np.ndarray) -> np.ndarray:
    return np.linalg.norm(ground - ds.camera_origin, axis=1)


def _dataset_path(results_dir: Path, path: str) -> Path:
    """A dataset path from study.json: as given, or relative to the results directory."""
    p = Path(path)
    return p if p.is_absolute() or p.exists() else Path(results_dir) / p


def _range(lo: float, hi: float) -> tuple[float, float]:
    """The axis range of values whose finite extremes are lo, hi (inf, -inf if there are none)."""
    if lo > hi:
        return 0.0, 1.0
    return (lo, hi) if hi > lo else (lo - 0.5, hi + 0.5)


def _bin(values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Bin index (N,) of values in edges (bins + 1,), the last bin closed."""
    return np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)
