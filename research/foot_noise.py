"""The foot point's noise against the truth, as a function of the box's height (issue 34; docs/measure-accuracy.md).

    python research/foot_noise.py DATASET [DATASET ...] [--feet soles] [--max-lag FRAMES]

Per detector, over the datasets' boxes with an agent (detections.parquet agent_id): the error of the box's foot
point (homocal's bottom-edge centre, homocal.geometry.box_bottom_points) against the agent's true foot point
projected (gt.parquet u, v at the box's frame), px. Per box-height bin (BIN_EDGES_PX) its robust 1-sigma per
coordinate, 1.4826 x the median absolute deviation from the median (u, v), and the median (the bias); the
fit sigma_px = a + b x box height (weighted least squares of the bins' sigmas of both coordinates, each bin
weighted by its box count); and the errors' autocorrelation at lags 1..MAX_LAG frames (Pearson, over pairs of
the same agent's boxes that many frames apart, each error less its agent's median): near 0 at lag 1 means
white at the video rate; and the correlation time tau of an AR(1) fitted to them (``correlation_time``). Both
of the error in pixels (where the large boxes' large errors weigh most) and of the error over the box's height,
in units of the sigma the model gives it (FOOT_SIGMA_PER_BOX_HEIGHT x height), each box weighing alike: the
process the filter's AR(1) is (homocal.measure.tracks.FOOT_CORRELATION_S).
--feet soles: only the boxes homocal measure --feet soles measures (homocal.measure.tracks.foot_status over all of
the detector's boxes: not a box whose feet a nearer box may hide, nor one the image border cuts at its bottom or a
side). --max-lag: the autocorrelation's last lag, frames (default MAX_LAG).
"""
from __future__ import annotations

import argparse

import numpy as np

from homocal.dataset import load_dataset
from homocal.geometry import box_bottom_points
from homocal.measure.tracks import FEET, foot_status

BIN_EDGES_PX = (0, 20, 30, 40, 60, 80, 120, 160, 240, 400, 10_000)
MAX_LAG = 5
MIN_BIN_BOXES = 30
MAD_TO_SIGMA = 1.4826


def foot_errors(path: str, detector: str, soles: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Of one dataset's boxes of ``detector`` with an agent (soles: whose foot_status is "used"): foot-point error
    (N, 2) px (box - truth), box height (N,) px, agent id (N,) and frame (N,)."""
    ds = load_dataset(path)
    det = ds.table("detections.parquet").to_pandas()
    det = det[det.detector == detector].reset_index(drop=True)
    if soles:
        det = det[foot_status(det[["x1", "y1", "x2", "y2"]].to_numpy(float), det.frame.to_numpy(),
                              ds.camera.image_size) == "used"]
    det = det[det.agent_id >= 0].reset_index(drop=True)
    gt = ds.table("gt.parquet").to_pandas()[["agent_id", "step", "u", "v"]]
    step = np.round(det.frame.to_numpy() / float(ds.manifest["fps"]) / float(ds.manifest["gt_dt"])).astype(np.int64)
    g = det[["agent_id"]].assign(step=step).astype({"agent_id": gt.agent_id.dtype}).merge(
        gt, on=["agent_id", "step"], how="left")
    xyxy = det[["x1", "y1", "x2", "y2"]].to_numpy(float)
    err = box_bottom_points(xyxy, convention="homocal") - g[["u", "v"]].to_numpy(float)
    ok = np.isfinite(err).all(axis=1)
    return err[ok], (xyxy[:, 3] - xyxy[:, 1])[ok], det.agent_id.to_numpy()[ok], det.frame.to_numpy(np.int64)[ok]


def robust_sigma(e: np.ndarray) -> np.ndarray:
    """1.4826 x the median absolute deviation from the median, along axis 0 ((n, ...) -> (...))."""
    return MAD_TO_SIGMA * np.median(np.abs(e - np.median(e, axis=0)), axis=0)


def binned_sigma(err: np.ndarray, height: np.ndarray) -> list[tuple[float, int, np.ndarray, np.ndarray]]:
    """Per BIN_EDGES_PX bin of at least MIN_BIN_BOXES boxes: (median height px, boxes, robust sigma (2,) of
    (u, v), median (2,))."""
    out = []
    for lo, hi in zip(BIN_EDGES_PX[:-1], BIN_EDGES_PX[1:]):
        inside = (height >= lo) & (height < hi)
        if inside.sum() >= MIN_BIN_BOXES:
            out.append((float(np.median(height[inside])), int(inside.sum()), robust_sigma(err[inside]),
                        np.median(err[inside], axis=0)))
    return out


def fit_linear(heights: np.ndarray, sigmas: np.ndarray, weights: np.ndarray, ratio: bool = False
               ) -> tuple[float, float]:
    """(a, b) minimising sum w (a + b h - sigma)^2: weighted least squares of sigma_px = a + b x height (ratio:
    a = 0, the pure ratio)."""
    A = np.column_stack([np.ones_like(heights), heights])[:, 1 if ratio else 0:] * np.sqrt(weights)[:, None]
    coef = np.linalg.lstsq(A, sigmas * np.sqrt(weights), rcond=None)[0]
    return (0.0, float(coef[0])) if ratio else (float(coef[0]), float(coef[1]))


def autocorrelation(e: np.ndarray, agents: np.ndarray, frames: np.ndarray, lag: int) -> float:
    """Pearson correlation of errors e (N,) of the same agent's boxes ``lag`` frames apart, each error less its
    agent's median."""
    order = np.lexsort((frames, agents))
    a, f = agents[order], frames[order]
    _, inverse = np.unique(a, return_inverse=True)
    medians = np.array([np.median(e[order][inverse == k]) for k in range(inverse.max() + 1)])
    r = e[order] - medians[inverse]
    index = {(x, y): i for i, (x, y) in enumerate(zip(a, f))}
    pairs = np.array([(i, index[(x, y + lag)]) for i, (x, y) in enumerate(zip(a, f)) if (x, y + lag) in index])
    return float(np.corrcoef(r[pairs[:, 0]], r[pairs[:, 1]])[0, 1])


def correlation_time(acf: np.ndarray, dt: float) -> float:
    """tau (s) of an AR(1), rho_k = exp(-k dt / tau), fitted to autocorrelations acf (K,) at lags 1..K frames dt
    seconds apart: least squares of ln rho_k = -(k dt) / tau through the origin."""
    lag = dt * np.arange(1, len(acf) + 1)
    return float(-np.sum(lag * lag) / np.sum(lag * np.log(acf)))


def report(paths: list[str], detector: str, soles: bool = False, max_lag: int = MAX_LAG) -> str:
    parts = [foot_errors(p, detector, soles) for p in paths]
    err, height, frames = (np.concatenate([p[i] for p in parts]) for i in (0, 1, 3))
    agents = np.concatenate([p[2] + 1_000_000 * k for k, p in enumerate(parts)])  # an agent of each dataset
    bins = binned_sigma(err, height)
    h = np.array([b[0] for b in bins])
    s = np.array([b[2] for b in bins])
    w = np.array([b[1] for b in bins], float)
    a, b = fit_linear(np.r_[h, h], np.r_[s[:, 0], s[:, 1]], np.r_[w, w])
    ratio = fit_linear(np.r_[h, h], np.r_[s[:, 0], s[:, 1]], np.r_[w, w], ratio=True)[1]
    per_axis = [fit_linear(h, s[:, c], w, ratio=True)[1] for c in (0, 1)]
    lines = [f"{detector}: {len(err):,} boxes of {len(paths)} datasets; foot-point error (box - truth), px",
             "| box height px (median) | boxes | sigma u | sigma v | median u | median v | fit a + b h |",
             "|---:|---:|---:|---:|---:|---:|---:|"]
    for (hm, n, sig, med) in bins:
        lines.append(f"| {hm:.0f} | {n:,} | {sig[0]:.2f} | {sig[1]:.2f} | {med[0]:+.2f} | {med[1]:+.2f} | "
                     f"{a + b * hm:.2f} |")
    lines.append(f"fitted (u and v together): sigma_px = {a:.3f} + {b:.4f} x box height (px); pure ratio {ratio:.4f} x "
                 f"box height (u alone {per_axis[0]:.4f}, v alone {per_axis[1]:.4f})")
    dt = 1.0 / float(load_dataset(paths[0]).manifest["fps"])
    for what, scale in (("error, px", 1.0), ("error / box height (in units of its modelled sigma)", height)):
        acfs = []
        for c, name in ((0, "u"), (1, "v")):
            acfs.append([autocorrelation(err[:, c] / scale, agents, frames, lag) for lag in range(1, max_lag + 1)])
            lines.append(f"autocorrelation of the {name} {what}, at lags 1..{max_lag} frames: "
                         + ", ".join(f"{x:.2f}" for x in acfs[-1]) + f" (AR(1) correlation time "
                         f"{correlation_time(np.array(acfs[-1]), dt):.2f} s)")
        lines.append(f"AR(1) correlation time of u and v together: {correlation_time(np.mean(acfs, axis=0), dt):.2f} s")
    return "\n".join(lines)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("datasets", nargs="+")
    parser.add_argument("--detectors", default="segmentation,rgb")
    parser.add_argument("--feet", choices=FEET, default=FEET[0], help="homocal measure --feet: the boxes taken")
    parser.add_argument("--max-lag", type=int, default=MAX_LAG, help="the autocorrelation's last lag, frames")
    args = parser.parse_args()
    for detector in args.detectors.split(","):
        print(report(args.datasets, detector, args.feet == "soles", args.max_lag) + "\n")
