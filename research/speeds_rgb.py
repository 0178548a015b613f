"""Why the rgb detector's speeds are worse than the segmentation detector's (issue 34; docs/measure-accuracy.md).

    python research/speeds_rgb.py DATASET [DATASET ...] [--grid]

Per dataset and detector (boxes with an agent, as research/measure_speeds.py takes them):
  - the boxes against the truth: the foot row's error (the box's bottom edge minus the row of the agent's true
    foot point projected, gt.parquet u, v) and the box height's error (against the agent's mask box in
    gt.parquet), median and interquartile range per range band, px;
  - the IoU linker's tracks: how many, their median length (frames), the share holding more than one agent,
    tracks per agent;
  - the pedestrians' fitted horizon (research/measure_speeds.py's fit: the clicked trapezoid's horizon 16 px
    off, the default prior) against camera.json's, with its sigma; its move per pixel of box height (every box
    a quarter px taller at each edge, then shorter, each fitted anew: px / px) and the box margin its error amounts to
    (the error over that move: boxes that many px taller than the people give it);
  - the foot points mapped through the exact trapezoid (no horizon error) against the agents' true positions,
    along the line of sight from the camera's ground point (m, + beyond the person), median and interquartile
    range per range band: the foot point's bias as a position's;
  - the speed error of homocal measure's smoother (median at 5-50 m, % of the true speed; 1/2-sigma
    coverage) with each cause taken away in turn: the pedestrians' mapping or the exact one (the dataset's
    exact trapezoid: no horizon error), the linker's tracks or the agents' own (no fragments, no swaps), and
    the median of |speed - true| / speed_sigma_mps (0.67 for honest Gaussian error bars).
--grid: the smoother on the pedestrians' corrected mapping with the filter's measurement noise the foot
point's alone (point_sigma_px through the mapping, no clicking error: the mapping's own error is shared by
every frame of a track, not white) for a grid of process noise q and point_sigma_px: the median speed error
at 5-50 m, the 1/2-sigma coverage, and the mean Gaussian log-likelihood of the filter's innovations (after each
track's first box) per box, what a maximum-likelihood choice of (q, point_sigma_px) from the data maximises.
"""
from __future__ import annotations

import argparse

import numpy as np

from homocal.dataset import load_dataset
from homocal.geometry import ViewTransformer, box_bottom_points
from homocal.geometry.boxes import link_tracks, trim_boxes
from homocal.measure import TrapezoidMapping, measure_tracks
from homocal.measure.kalman import kalman_filter
from homocal.measure.tracks import map_points, track_batches
from measure_speeds import BANDS, WALKING_MPS, clicked_transformer, mappings, pedestrians, truth, undistorted


GRID_Q = (0.01, 0.1, 0.5)
GRID_POINT_SIGMA_PX = (0.5, 1.0, 2.0, 4.0)


def smoother_errors(mapping, frames, feet, tracks, fps, true_speed, rng, **settings) -> str:
    """Median |speed - true| in % at 5-50 m, the 1/2-sigma coverage and the median |speed - true| / sigma of
    homocal measure's smoother (measure_tracks' settings) over the boxes whose track id is >= 0."""
    keep = np.flatnonzero(tracks >= 0)
    speed, sigma = np.full(len(frames), np.nan), np.full(len(frames), np.nan)
    index = {(f, k): i for i, f, k in zip(keep, frames[keep], tracks[keep])}
    for batch in measure_tracks(mapping, frames[keep], feet[keep], tracks[keep], fps, **settings):
        at = np.array([index[(f, k)] for f, k in zip(batch["frame"], batch["track_id"])])
        speed[at], sigma[at] = batch["speed_mps"], batch["speed_sigma_mps"]
    ok = np.isfinite(speed) & np.isfinite(true_speed) & (rng >= BANDS[-1][0]) & (rng < BANDS[-1][1])
    err = np.abs(speed - true_speed)
    walking = ok & (true_speed >= WALKING_MPS)
    return (f"{np.median(100 * err[walking] / true_speed[walking]):.1f} %, "
            f"{100 * np.mean(err[ok] <= sigma[ok]):.0f} / {100 * np.mean(err[ok] <= 2 * sigma[ok]):.0f} %, "
            f"{np.median(err[ok] / sigma[ok]):.2f}")


def innovation_loglik(mapping, frames, feet, tracks, fps, q: float, point_sigma_px: float) -> float:
    """Mean Gaussian log-likelihood per box of the forward filter's innovations (each track's first box left out),
    the measurement noise the foot point's alone (no clicking error)."""
    total, count = 0.0, 0
    for batch in track_batches(tracks, frames):
        rows = np.concatenate(batch)
        xy, cov = map_points(mapping, feet[rows], 0.0, point_sigma_px)
        n, L = len(batch), max(map(len, batch))
        t, z, R = np.empty((n, L)), np.full((n, L, 2), np.nan), np.full((n, L, 2, 2), np.nan)
        at = np.concatenate([[0], np.cumsum([len(r) for r in batch])])
        for i, r in enumerate(batch):
            t[i, :len(r)], t[i, len(r):] = frames[r] / fps, frames[r[-1]] / fps
            z[i, :len(r)], R[i, :len(r)] = xy[at[i]:at[i + 1]], cov[at[i]:at[i + 1]]
        f = kalman_filter(t, z, R, q)
        nu, S = z - f["x_pred"][..., :2], f["P_pred"][..., :2, :2] + R
        ok = np.isfinite(nu).all(-1) & np.isfinite(S).all((-1, -2))
        ok[:, 0] = False  # a track's first innovation is against the all but unknown start
        d = np.einsum("ni,ni->n", nu[ok], np.linalg.solve(S[ok], nu[ok][..., None])[..., 0])
        total += float(np.sum(-0.5 * (np.log(np.linalg.det(S[ok])) + d + 2 * np.log(2 * np.pi))))
        count += int(ok.sum())
    return total / count


def margin_slope(ds, frames: np.ndarray, xyxy: np.ndarray, ids: np.ndarray) -> float:
    """The pedestrians' fitted horizon row's move per px of box height (px / px): the fit (measure_speeds'
    pedestrians on its clicked trapezoid) of boxes xyxy (N, 4) homocal px a quarter px taller at each edge less that
    of boxes a quarter px shorter, over the 1 px between them (a segmentation fragment can be 1 px tall); NaN where
    either fit refuses."""
    clicked, rows = clicked_transformer(ds, 16.0), []
    for margin in (-0.5, 0.5):  # a negative margin: taller boxes
        try:
            rows.append(pedestrians(ds, clicked, frames, trim_boxes(xyxy, margin), ids).horizon_row_)
        except ValueError:
            return float("nan")
    return rows[0] - rows[1]


def line_of_sight_offsets(ds, mapped: np.ndarray, true_xy: np.ndarray) -> np.ndarray:
    """(N,) m: mapped ground points (N, 2) m less the true ones (N, 2) m along the line of sight from the
    camera's ground point to the true one (+: beyond it)."""
    sight = true_xy - np.asarray(ds.camera_origin, float)
    return np.einsum("ni,ni->n", mapped - true_xy, sight / np.linalg.norm(sight, axis=1)[:, None])


def report(path: str, grid: bool) -> None:
    ds = load_dataset(path)
    fps, dt = float(ds.manifest["fps"]), float(ds.manifest["gt_dt"])
    gt = ds.table("gt.parquet").to_pandas()[["agent_id", "step", "u", "v", "y1", "y2"]]
    det_all = ds.table("detections.parquet").to_pandas()
    exact = ds.trapezoids["exact"]
    exact_map = ViewTransformer(undistorted(ds, np.asarray(exact["image"], float)),
                                ds.site_map.to_metres(np.asarray(exact["map"], float)))
    print(f"{ds.name} (seed {ds.manifest['seed']}): true horizon row {ds.camera.horizon_row:.1f} px")
    for detector in ("segmentation", "rgb"):
        frames, xyxy, true_xy, true_speed, rng, _ = truth(ds, detector)
        det = det_all[det_all.detector == detector].reset_index(drop=True)
        agents = det.agent_id.to_numpy()
        step = np.round(det.frame.to_numpy() / fps / dt).astype(np.int64)
        g = det[["agent_id"]].assign(step=step).merge(gt, on=["agent_id", "step"], how="left")
        foot_err = det.y2.to_numpy() - g.v.to_numpy()
        height_err = (det.y2 - det.y1).to_numpy() - (g.y2 - g.y1).to_numpy()
        ids = link_tracks(frames, xyxy)
        has = agents >= 0
        pairs = np.unique(np.column_stack([ids[has], agents[has]]), axis=0)
        mixed = np.mean(np.bincount(pairs[:, 0]) > 1)
        per_agent = len(pairs) / len(np.unique(pairs[:, 1]))
        print(f"  {detector}: {len(frames):,} boxes ({np.sum(~has):,} of no agent); {ids.max() + 1} tracks, median "
              f"{np.median(np.bincount(ids)):.0f} frames, {100 * mixed:.0f} % of them hold more than one agent, "
              f"{per_agent:.1f} tracks per agent")
        for lo, hi in BANDS[:-1]:
            band = has & (rng >= lo) & (rng < hi)
            q = lambda e: f"{np.nanmedian(e[band]):+.1f} (IQR {np.subtract(*np.nanpercentile(e[band], [75, 25])):.1f})"  # noqa: E731
            print(f"    {lo:g}-{hi:g} m ({band.sum():,} boxes): foot row {q(foot_err)} px, box height {q(height_err)} px")
        maps, _ = mappings(ds, 16.0, frames, xyxy, ids)
        peds = maps["pedestrians"]
        error = peds.horizon_row_ - ds.camera.horizon_row
        slope = margin_slope(ds, frames, xyxy, ids)
        print(f"    pedestrians' horizon {peds.horizon_row_:.1f} +- {peds.horizon_sigma_px_:.1f} px "
              f"({error:+.1f} px from the true one); {slope:+.2f} px per px of box height, the error of boxes "
              f"{error / slope:+.1f} px taller than the people")
        feet = undistorted(ds, box_bottom_points(xyxy, convention="homocal"))
        along = line_of_sight_offsets(ds, exact_map.transform_points(feet), true_xy)
        for lo, hi in BANDS[:-1]:
            band = has & (rng >= lo) & (rng < hi) & np.isfinite(along)
            q25, q50, q75 = np.percentile(along[band], [25, 50, 75]) if band.any() else (np.nan,) * 3
            print(f"    {lo:g}-{hi:g} m: the exact mapping's foot point {q50:+.3f} m along the line of sight "
                  f"(IQR {q25:+.3f}, {q75:+.3f})")
        for mapping_name, mapping in (("pedestrians", peds), ("exact", exact_map)):
            for track_name, tracks in (("the linker's", ids), ("the agents' own", np.where(has, agents, -1))):
                print(f"    smoother, {mapping_name} mapping, {track_name} tracks: median speed error at 5-50 m, "
                      f"1/2-sigma speeds, median |error| / sigma: "
                      f"{smoother_errors(mapping, frames, feet, tracks, fps, true_speed, rng)}")
        if grid:
            foot_only = TrapezoidMapping(peds.transformer_)
            for q in GRID_Q:
                cells = [f"{sp:g} px: {smoother_errors(foot_only, frames, feet, ids, fps, true_speed, rng, accel_psd=q, click_sigma_px=0.0, point_sigma_px=sp)}, "
                         f"log-lik {innovation_loglik(foot_only, frames, feet, ids, fps, q, sp):.2f}"
                         for sp in GRID_POINT_SIGMA_PX]
                print(f"    grid, q {q:g}: " + " | ".join(cells))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("datasets", nargs="+")
    parser.add_argument("--grid", action="store_true", help="also the (q, point sigma) grid of the module docstring")
    args = parser.parse_args()
    for dataset in args.datasets:
        report(dataset, args.grid)
