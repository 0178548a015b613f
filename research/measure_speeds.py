"""Speeds and positions of people measured with homocal measure's filter against simgen's ground truth, beside
supervision's speed recipe (issue 34 item 4; docs/measure-accuracy.md).

    python research/measure_speeds.py DATASET [DATASET ...] [--detectors segmentation,rgb] [--shift 16]
    python research/measure_speeds.py DATASET [DATASET ...] --spread [--split | --box-sigma | --correlated] [--feet soles]
    python research/measure_speeds.py DATASET [DATASET ...] --spread --detectors rgb --box-margin 2
    python research/measure_speeds.py DATASET [DATASET ...] --exact --spread [--split | --box-sigma | --correlated] [--feet soles]
    python research/measure_speeds.py DATASET [DATASET ...] --steadiness [--spread] [--mappings pedestrians] [--exact] [--box-sigma | --correlated] [--feet soles] [--accel-psd fitted|imm]
    python research/measure_speeds.py DATASET [DATASET ...] --fit-imm
    python research/measure_speeds.py DATASET [DATASET ...] --fit-foot-scale [--box-sigma | --correlated] [--feet soles]
    python research/measure_speeds.py DATASET [DATASET ...] --fit-foot-tails [--box-sigma]
    python research/measure_speeds.py DATASET [DATASET ...] --spread --steadiness --accel-psd imm --foot-scale C
    python research/measure_speeds.py DATASET [DATASET ...] --spread --steadiness --foot-noise-tails student
    python research/measure_speeds.py DATASET [DATASET ...] --horizons 10
    python research/measure_speeds.py DATASET [DATASET ...] --draws 2000 [--correlated] [--feet soles] [--accel-psd fitted]
    python research/measure_speeds.py DATASET --throughput 10 [--correlated]

Per dataset and detector, the clicked trapezoid is the dataset's exact one moved as a tilt error moves it so
that its horizon lies --shift px above the true one (homocal.study.perturb.base_quad; 16 px is the study's
table1-fit base error). Its boxes (detections.parquet, homocal's pixels, foot point the bottom edge's centre)
are linked into tracks by IoU (homocal's link_tracks) and measured with:
  - "recipe": supervision's speed-estimation example, reimplemented from its steps: the clicked trapezoid's
    homography by cv2.getPerspectiveTransform (float32), each track's foot points mapped with
    cv2.perspectiveTransform, the last fps positions kept (a deque of maxlen fps), speed = |newest - oldest| /
    (len / fps), shown once the track has fps / 2 positions (the example uses the road's y only; here the 2D
    distance, as people do not walk along one axis);
  - with a lens (camera.json's distortion: the lens known, as homocal fit --camera-json has it) the foot points,
    the clicked trapezoid and the reference points are those of the undistorted image, for the recipe too,
    and a rolled camera's pedestrians fit estimates the roll (estimate_roll);
  - for each mapping, the clicked trapezoid uncorrected, least change from three reference points (the
    calibration objects nearest 10, 20 and 35 m straight ahead, their segmentation foot points: what a user
    clicks), pedestrians (no point; the default height prior, K and the camera height given), each by
    homocal's filter forward only ("filter", causal) and with the RTS smoother ("smoother") at
    homocal.measure.ACCEL_PSD, and by the recipe's 1 s difference on that mapping ("1 s diff").
The truth of a box: its detection's agent (detections.parquet agent_id; boxes of no agent are left out) at
the box's frame in gt.parquet (step = frame / fps / gt_dt): the true foot point, and the true velocity by a
central difference over +-1 ground-truth step (+-50 ms) of that agent's track (0 at its first and last step).
Range: the true point's distance from the camera's ground point; a column gives the 5-50 m errors of the
boxes at least 1 s from their track's first and last frame. Speed errors |est - true| in m/s, and in
percent of the true speed over boxes whose true speed is at least WALKING_MPS (a waiting person's percent is
undefined). Coverage: the share of boxes whose error is inside 1 and 2 times the 1-sigma (positions: |mapped -
true| <= k sigma_m, the 2D error against the semi-major axis; speeds: |speed - true| <= k speed_sigma_mps).

--spread: each dataset evaluated on its own, its figures (band medians, the 5-50 m 90th percentile, coverage)
given as mean [min, max] over the datasets.
--split: the filter's measurement noise the foot point's own only, the shared mapping error added to the
speed's bar (homocal.measure.measure_tracks(split_mapping_error=True)).
--box-sigma: the split with each foot point's own (u, v) sigmas FOOT_SIGMA_PER_BOX_HEIGHT x its box's height
(homocal.measure.tracks.box_height_sigma_px; research/foot_noise.py) instead of 1 px.
--correlated: --box-sigma with the foot point's error an AR(1) of correlation time FOOT_CORRELATION_S in the
filter's state (measure_tracks(foot_correlation_s=...); homocal measure --foot-noise correlated).
--accel-psd Q|fitted|imm: the filter's process noise (homocal measure --accel-psd; default homocal.measure.ACCEL_PSD);
fitted: per dataset, detector and mapping by maximum likelihood of the filter's innovations on the boxes'
tracks (homocal.measure.tracks.fit_tracks_accel_psd; no ground truth), printed to stderr; imm: the two-regime
model (homocal.measure.kalman.IMM), its IMM filter and smoother.
--exact: the part of the error that is the track's own, apart from the mapping's: the dataset's true mapping
(its exact trapezoid, the ground rectangle's projection, undistorted; ``exact_transformer``) alone, measured at
click sigma 0, so the bars hold the foot point's noise (each --split/--box-sigma/--correlated model's) and the
motion model's, no mapping error; no recipe row.
--feet soles: homocal's filter measures only the foot points whose bottom edge is the sole (homocal measure
--feet soles: not a box whose feet a nearer box may hide, nor one whose bottom or side the image border cuts,
homocal.measure.tracks.foot_status; their shares printed to stderr); the recipe and the 1 s differences take
every box.
--steadiness: instead, the smoothed speeds' 1/2-sigma coverage at 5-50 m pooled over the datasets per bin of the
true velocity's change over STEADY_S about the box (STEADINESS_BINS_MPS; ``steadiness_table``): a walker at a
steady pace or standing against one who turns, starts or stops; per range band the coverage and the quantiles
of |error| / sigma at 68.27 and 95.45 %; and the positions' 1/2-sigma coverage within sigma_m and within the
error ellipse. With --spread both tables, from the same evaluations.
--mappings NAMES: only these of MAPPINGS (comma-separated; the recipe is always measured).
--fit-imm: instead, the two-regime motion model's constants (homocal.measure.kalman.fit_imm: IMM_ACCEL_PSD,
IMM_SWITCH_PER_S) by maximum likelihood over the datasets' and --detectors' tracks pooled (``imm_inputs``).
--fit-foot-scale: instead, the scale c of the filter's measurement noise R (R -> c^2 R) that makes the tracks most
likely under the IMM (homocal.measure.kalman.fit_noise_scale at IMM_ACCEL_PSD, IMM_SWITCH_PER_S), per detector and
(of more than one) the detectors pooled, with the foot noise model of --box-sigma / --correlated (default fixed)
and --feet.
--fit-foot-tails: instead, the Student-t foot noise (its scale c on R and degrees of freedom) that makes the
tracks most likely under the IMM (homocal.measure.kalman.fit_student_noise), the detectors' tracks pooled, with
the foot noise model of --box-sigma (default fixed), every box: homocal.measure.tracks.STUDENT_FOOT_NOISE.
--foot-noise-tails normal|student: the foot noise's distribution (homocal measure --foot-noise-tails; student with
the models STUDENT_FOOT_NOISE has: its scale and degrees of freedom, the scale times --foot-scale).
--box-margin PX: the boxes' known excess height over the people's, as homocal fit --box-margin and homocal
measure take it (PedestrianCorrector(box_margin_px), homocal.geometry.boxes.trim_boxes: PX / 2 px off each box's top
and bottom edge in the camera's pixels, for every mapping's foot points; a box no taller an outlier of the fit
and its foot not measured, "short"); with --spread a dataset whose pedestrians' fit refuses the trimmed boxes is
left out (its refusal printed to stderr). The speed tables only: refused with --draws, --fit-*, --horizons and
--throughput, which read the boxes as detected.
--foot-scale C: the filter's measurement noise R times C^2 (measure_tracks(noise_scale=C)); the positions' sigma_m
stay the mapping's.
--horizons SECONDS: instead, the pedestrians' correction (as the tables fit it) on every disjoint window of
SECONDS of each dataset, its fitted horizon's error over its sigma (``horizon_table``; each fit printed to stderr).
--draws N: instead, the pedestrians' smoothed speeds' 1/2-sigma coverage pooled over the datasets (the split
model: box-height, or --correlated) against what it would be were the bars honest, each box's error its
camera's shared mapping error (``bar_parts``' a, times the camera's z) plus its own normal error: at the cameras'
realised horizon z, and over N draws of them (``pooled_coverage_table``).
--throughput MINUTES: the first dataset's segmentation boxes repeated (frames and track ids shifted) into a
CSV of MINUTES minutes, then `homocal measure` on it as a subprocess (with --correlated: --foot-noise
correlated; with --accel-psd, --feet, those): boxes per second and the child's peak resident memory (ru_maxrss).
"""
from __future__ import annotations

import argparse
import collections
import inspect
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.special import ndtr
from scipy.stats import chi2

from homocal.arguments import number
from homocal.boxes import read_boxes
from homocal.correctors import LeastChangeCorrector, PedestrianCorrector
from homocal.dataset import load_dataset
from homocal.geometry import ViewTransformer, box_bottom_points
from homocal.geometry.boxes import MAX_BOX_MARGIN_PX, link_tracks, trim_boxes
from homocal.measure import ACCEL_PSD, measure_tracks
from homocal.measure.kalman import IMM, fit_imm, fit_noise_scale, fit_student_noise, speed_and_sigma
from homocal.measure.tracks import (FEET, FOOT, FOOT_TAILS, TrapezoidMapping, as_mapping, map_points, first_batch_inputs, fit_tracks_accel_psd, foot_noise_options,
                                    foot_status, mapping_velocity_covariance, measured_feet)
from homocal.study.perturb import base_quad

BANDS = ((5.0, 15.0), (15.0, 30.0), (30.0, 50.0), (5.0, 50.0))
WALKING_MPS = 0.5
STEADY_S = 1.0
"""--steadiness: the span, s, over which a box's true velocity change is taken."""
STEADINESS_BINS_MPS = (0.0, 0.1, 0.3, 1.0, np.inf)
"""--steadiness: the bins of the true velocity change over STEADY_S, m/s (under 0.1: a steady walker or one
standing)."""
REFERENCE_RANGES_M = (10.0, 20.0, 35.0)
MAPPINGS = ("uncorrected", "least change", "pedestrians")
"""The mappings measured (``mappings``; --mappings)."""


def recipe_speeds(positions: np.ndarray, frames: np.ndarray, ids: np.ndarray, fps: float) -> np.ndarray:
    """supervision's speed: per track (rows in frame order), |newest - oldest| / (len / fps) over a deque of the
    last int(fps) positions, NaN until it holds fps / 2 of them."""
    out = np.full(len(frames), np.nan)
    queues: dict[int, collections.deque] = {}
    for i in np.lexsort((frames, ids)):
        q = queues.setdefault(int(ids[i]), collections.deque(maxlen=int(fps)))
        q.append(positions[i])
        if len(q) >= fps / 2:
            out[i] = np.linalg.norm(q[-1] - q[0]) / (len(q) / fps)
    return out


def truth(ds, detector: str):
    """Boxes of ``detector`` with an agent: frames (N,), xyxy (N, 4), true xy (N, 2), true speed (N,), range (N,),
    and the change (N,) m/s of the true velocity over STEADY_S about the box (the mean velocity of the STEADY_S / 2
    after it less that of the STEADY_S / 2 before it; NaN within STEADY_S / 2 of the agent's ends)."""
    det = ds.table("detections.parquet").to_pandas()
    det = det[det.detector == detector].reset_index(drop=True)
    gt = ds.table("gt.parquet").to_pandas()[["agent_id", "step", "x", "y"]]
    dt, fps = float(ds.manifest["gt_dt"]), float(ds.manifest["fps"])
    step = np.round(det.frame.to_numpy() / fps / dt).astype(np.int64)

    def at(offset: int) -> np.ndarray:  # the agent's true foot point offset steps away (NaN: none)
        keys = det[["agent_id"]].assign(step=step + offset).astype({"agent_id": gt.agent_id.dtype})
        return keys.merge(gt, on=["agent_id", "step"], how="left")[["x", "y"]].to_numpy(float)

    xy, before, after = at(0), at(-1), at(1)
    span = dt * (np.isfinite(before[:, 0]).astype(int) + np.isfinite(after[:, 0]))
    with np.errstate(invalid="ignore", divide="ignore"):
        vel = (np.where(np.isnan(after), xy, after) - np.where(np.isnan(before), xy, before)) / span[:, None]
    vel[span == 0] = 0.0
    xyxy = det[["x1", "y1", "x2", "y2"]].to_numpy(float)
    half = int(round(STEADY_S / 2 / dt))
    change = np.linalg.norm(at(half) - 2 * xy + at(-half), axis=1) / (half * dt)
    return (det.frame.to_numpy(np.int64), xyxy, xy, np.linalg.norm(vel, axis=1),
            np.linalg.norm(xy - ds.camera_origin, axis=1), change)


def undistorted(ds, points: np.ndarray) -> np.ndarray:
    """Image points (N, 2) of the dataset (its camera's pixels) in the undistorted image (as given for a pinhole)."""
    lens = ds.camera.lens
    return points if lens.is_identity else lens.undistort_points(points)


def exact_transformer(ds) -> ViewTransformer:
    """The dataset's true ground mapping: its exact trapezoid (the ground rectangle's projection) from the
    undistorted image to metres."""
    exact = ds.trapezoids["exact"]
    return ViewTransformer(undistorted(ds, np.asarray(exact["image"], float)),
                           ds.site_map.to_metres(np.asarray(exact["map"], float)))


def clicked_transformer(ds, shift: float) -> ViewTransformer:
    """The clicked trapezoid: the exact one moved as a tilt error moves it, its horizon shift px above the true one."""
    K, exact = ds.camera.K, exact_transformer(ds)
    row = float(exact.horizon_row(K[0, 2]))
    return ViewTransformer(base_quad(exact.source, K, row, ds.camera.horizon_row, shift, np.zeros(8)), exact.target)


def mappings(ds, shift: float, frames: np.ndarray, xyxy: np.ndarray, ids: np.ndarray, box_margin_px: float = 0.0) -> dict:
    clicked = clicked_transformer(ds, shift)
    q, g, distance = ds.calibration_points("segmentation")
    ahead = np.abs(g[:, 0] - ds.camera_origin[0]) < 1.0
    pick = [np.flatnonzero(ahead)[np.argmin(np.abs(distance[ahead] - r))] for r in REFERENCE_RANGES_M]
    least = LeastChangeCorrector().fit(clicked, undistorted(ds, q[pick]), g[pick], ds.camera_origin)
    return {MAPPINGS[0]: clicked, MAPPINGS[1]: least,
            MAPPINGS[2]: pedestrians(ds, clicked, frames, xyxy, ids, box_margin_px)}, clicked


def pedestrians(ds, clicked: ViewTransformer, frames: np.ndarray, xyxy: np.ndarray, ids: np.ndarray,
                box_margin_px: float = 0.0) -> PedestrianCorrector:
    """The pedestrians' correction of the clicked mapping from boxes xyxy (N, 4) homocal px of frames (N,) and
    tracks ids (N,): the default height prior, K, the camera height and the lens given, the roll estimated on a
    rolled camera, box_margin_px the boxes' margin (PedestrianCorrector's)."""
    rolled = bool(abs(ds.camera.horizon[0]) > 1e-9)  # a horizon that is not a row
    return PedestrianCorrector(estimate_roll=rolled, box_margin_px=box_margin_px).fit(
        clicked, xyxy, convention="homocal", frames=frames, track_ids=ids, K=ds.camera.K,
        camera_height_m=ds.camera.mount_height_m, image_size=ds.camera.image_size, camera_origin=ds.camera_origin,
        lens=None if ds.camera.lens.is_identity else ds.camera.lens)


def imm_inputs(path: str, detector: str, shift: float, foot_noise: str = "box-height", soles: bool = False) -> tuple:
    """kalman_filter's (t, z, R, foot) of a dataset's tracks of ``detector`` boxes as the tables measure them with
    the pedestrians' correction and a FOOT_NOISE model, feet all or the soles (first_batch_inputs: BATCH_CELLS)."""
    ds = load_dataset(path)
    frames, xyxy = truth(ds, detector)[:2]
    ids = link_tracks(frames, xyxy)
    feet = undistorted(ds, box_bottom_points(xyxy, convention="homocal"))
    peds = pedestrians(ds, clicked_transformer(ds, shift), frames, xyxy, ids)
    foot = foot_status(xyxy, frames, ds.camera.image_size) if soles else None
    noise = foot_noise_options(foot_noise, xyxy, 1.0)
    noise.pop("student_dof")  # normal: the fits take the tails as their own parameters
    return first_batch_inputs(peds, frames, feet, ids, float(ds.manifest["fps"]), **noise, foot=foot)


def horizon_errors(path: str, detector: str, shift: float, seconds: float) -> list[dict]:
    """The pedestrians' fitted horizon against the true one, one dict per disjoint window of ``seconds`` of the
    dataset's boxes of ``detector`` (those ``truth`` keeps, as the speed tables fit them): start (s), error
    (fitted minus true row at the principal column, px), sigma (horizon_sigma_px_: the people's and the prior
    mean's) and sigma_people (horizon_sigma_people_px_), px; NaN and refusal (its message) where the fit refuses."""
    ds = load_dataset(path)
    fps = float(ds.manifest["fps"])
    frames, xyxy = truth(ds, detector)[:2]
    clicked = clicked_transformer(ds, shift)
    out = []
    for k in range(int(float(ds.manifest["seconds"]) // seconds)):
        sel = (frames >= k * seconds * fps) & (frames < (k + 1) * seconds * fps)
        row = {"dataset": Path(path).name, "detector": detector, "start": k * seconds}
        try:
            c = pedestrians(ds, clicked, frames[sel], xyxy[sel], link_tracks(frames[sel], xyxy[sel]))
        except ValueError as e:  # the fit refuses the window's boxes
            out.append(row | {"error": np.nan, "sigma": np.nan, "sigma_people": np.nan, "refusal": str(e)})
            continue
        out.append(row | {"error": c.horizon_row_ - ds.camera.horizon_row, "sigma": c.horizon_sigma_px_,
                          "sigma_people": c.horizon_sigma_people_px_})
    return out


def per_box(mapping, frames: np.ndarray, feet: np.ndarray, ids: np.ndarray, fps: float, **options) -> dict:
    """``measure_tracks``' columns (N,) in the boxes' order (frames, feet, ids (N,) as it takes them; options its
    keywords)."""
    index = {(f, k): i for i, (f, k) in enumerate(zip(frames, ids))}
    out: dict = {}
    for batch in measure_tracks(mapping, frames, feet, ids, fps, **options):
        at = np.array([index[(f, k)] for f, k in zip(batch["frame"], batch["track_id"])])
        for key, values in batch.items():
            out.setdefault(key, np.full(len(frames), np.nan, dtype=values.dtype if key == "foot" else np.float64))[at] = values
    return out


def evaluate(paths: list[str], detector: str, shift: float, split: bool = False, box_sigma: bool = False,
             correlated: bool = False, accel_psd: float | str = ACCEL_PSD, soles: bool = False,
             exact: bool = False, only: tuple[str, ...] = MAPPINGS, foot_scale: float = 1.0,
             foot_tails: str = FOOT_TAILS[0], box_margin_px: float = 0.0) -> dict:
    """{(mapping, estimator): dict of pooled arrays err (m/s), rel (%, NaN below WALKING_MPS), range, cover1/2
    (speeds), pos1/2 (positions within k sigma_m), ellipse1/2 (positions within the k-sigma ellipse: the squared
    Mahalanobis distance of the error under the mapped point's covariance within chi-square(2)'s quantile of the
    1-D k sigma's share, 68.3 / 95.4 %)} over the datasets; exact: the true mapping alone, bars of no mapping error;
    foot_scale: the filter's measurement noise times its square (--foot-scale); foot_tails a FOOT_TAILS;
    box_margin_px: the boxes' margin, px (--box-margin: the fit's, and every mapping's foot points as homocal
    measure's)."""
    pooled: dict = collections.defaultdict(lambda: collections.defaultdict(list))
    for path in paths:
        ds = load_dataset(path)
        fps = float(ds.manifest["fps"])
        frames, xyxy, true_xy, true_speed, rng, change = truth(ds, detector)
        ids = link_tracks(frames, xyxy)
        people = trim_boxes(xyxy, box_margin_px)  # homocal measure's, as is for no margin
        feet = undistorted(ds, box_bottom_points(people, convention="homocal"))
        foot = measured_feet(xyxy, frames, ds.camera.image_size, FEET[1] if soles else FEET[0], box_margin_px)
        if soles or box_margin_px:
            print(f"{Path(path).name}, {detector}: of {len(foot):,} boxes, " + ", ".join(
                  f"{k} {np.sum(foot == k):,} ({100 * np.mean(foot == k):.1f} %)" for k in FOOT[1:]), file=sys.stderr)
        if exact:
            maps, rows = {"exact": TrapezoidMapping(exact_transformer(ds), ds.camera.lens)}, {}
        else:
            maps, clicked = mappings(ds, shift, frames, xyxy, ids, box_margin_px)
            maps = {k: v for k, v in maps.items() if k in only}
            H = cv2.getPerspectiveTransform(clicked.source.astype(np.float32), clicked.target.astype(np.float32))
            sv_xy = cv2.perspectiveTransform(feet.reshape(-1, 1, 2).astype(np.float32), H).reshape(-1, 2).astype(float)
            rows = {"recipe": (recipe_speeds(sv_xy, frames, ids, fps), None, None, None, None)}
        first, last = (np.array([f(frames[ids == k]) for k in range(ids.max() + 1)]) for f in (np.min, np.max))
        inner = (frames - first[ids] >= fps) & (last[ids] - frames >= fps)  # at least 1 s from its track's ends
        for name, mapping in maps.items():
            noise = foot_noise_options("correlated" if correlated else "box-height" if box_sigma else "fixed", people, 1.0,
                                       foot_tails)
            noise["split_mapping_error"] |= split
            noise["noise_scale"] *= foot_scale
            if exact:
                noise["click_sigma_px"] = 0.0
            q = accel_psd
            if q == "fitted":
                q = fit_tracks_accel_psd(mapping, frames, feet, ids, fps, **noise, foot=foot)
                print(f"{Path(path).name}, {detector}, {name}: q fitted {q:.3g} m^2/s^3", file=sys.stderr)
            click = noise.get("click_sigma_px", inspect.signature(measure_tracks).parameters["click_sigma_px"].default)
            xy, cov = map_points(as_mapping(mapping), feet, click, noise["point_sigma_px"])
            e = xy - true_xy
            pos_d2 = np.einsum("ni,ni->n", e, np.linalg.solve(cov, e[..., None])[..., 0])  # squared Mahalanobis
            for estimator, smooth in (("filter", False), ("smoother", True)):
                m = per_box(mapping, frames, feet, ids, fps, smooth=smooth, accel_psd=q, **noise, foot=foot)
                pos_err = np.hypot(m["x"] - true_xy[:, 0], m["y"] - true_xy[:, 1])
                rows[f"{name}, {estimator}"] = (m["speed_mps"], m["speed_sigma_mps"], pos_err, m["sigma_m"], pos_d2)
            rows[f"{name}, 1 s diff"] = (recipe_speeds(mapping.transform_points(feet), frames, ids, fps), None, None, None, None)
        for key, (speed, sigma, pos_err, pos_sigma, pos_d2) in rows.items():
            ok = np.isfinite(true_speed) & np.isfinite(speed)
            err = np.abs(speed - true_speed)
            p = pooled[key]
            p["err"].append(err[ok])
            walking = true_speed[ok] >= WALKING_MPS
            p["rel"].append(np.where(walking, 100 * err[ok] / np.where(walking, true_speed[ok], 1.0), np.nan))
            p["range"].append(rng[ok])
            p["inner"].append(inner[ok])
            p["change"].append(change[ok])
            p["sigma"].append(sigma[ok] if sigma is not None else np.full(ok.sum(), np.nan))
            for k in (1, 2):
                p[f"cover{k}"].append(err[ok] <= k * sigma[ok] if sigma is not None else np.full(ok.sum(), np.nan))
                p[f"pos{k}"].append(pos_err[ok] <= k * pos_sigma[ok] if pos_err is not None else np.full(ok.sum(), np.nan))
                p[f"ellipse{k}"].append(pos_d2[ok] <= chi2.ppf(ndtr(k) - ndtr(-k), 2) if pos_d2 is not None
                                        else np.full(ok.sum(), np.nan))
    return {key: {k: np.concatenate(v) for k, v in p.items()} for key, p in pooled.items()}


def cells(p: dict) -> dict:
    """The table's figures of one method's pooled arrays: per band (median %, median m/s, p90 %, p90 m/s), the
    inner boxes' (median %, p90 %) and the 1/2-sigma coverage of speeds and positions (%, NaN: none)."""
    out = {}
    for lo, hi in BANDS:
        band = (p["range"] >= lo) & (p["range"] < hi)
        rel, err = p["rel"][band], p["err"][band]
        out[(lo, hi)] = ((np.nanmedian(rel), np.median(err), np.nanpercentile(rel, 90), np.percentile(err, 90))
                         if np.isfinite(rel).any() else None)
    inside = (p["range"] >= BANDS[-1][0]) & (p["range"] < BANDS[-1][1])
    rel = p["rel"][inside & p["inner"]]
    out["inner"] = (np.nanmedian(rel), np.nanpercentile(rel, 90))
    for name in ("cover", "pos"):
        hits = [p[f"{name}{k}"][inside] for k in (1, 2)]
        out[name] = (np.nan, np.nan) if np.isnan(hits[0]).all() else tuple(100 * np.nanmean(h) for h in hits)
    return out


def table(results: dict, detector: str, shift: float) -> str:
    head = " | ".join(f"{lo:g}-{hi:g} m median, p90" for lo, hi in BANDS)
    lines = [f"Speed error, {detector} boxes, horizon {shift:g} px off: |est - true| in % of the true speed "
             f"(m/s in brackets)", "", f"| method | {head} | 5-50 m, 1 s or more from a track's ends | "
             "1/2-sigma speeds | 1/2-sigma positions |", "|---|" + "---:|" * (len(BANDS) + 3)]
    for key, p in results.items():
        c = cells(p)
        row = ["-" if c[b] is None else f"{c[b][0]:.1f} % ({c[b][1]:.2f}), {c[b][2]:.1f} % ({c[b][3]:.2f})"
               for b in BANDS]
        row.append(f"{c['inner'][0]:.1f} %, {c['inner'][1]:.1f} %")
        row += ["-" if np.isnan(c[name][0]).all() else f"{c[name][0]:.0f} / {c[name][1]:.0f} %" for name in ("cover", "pos")]
        lines.append(f"| {key} | " + " | ".join(row) + " |")
    return "\n".join(lines)


def spread_table(per_dataset: list[dict], detector: str, shift: float) -> str:
    """The main figures of each dataset's own table as mean [min, max] over the datasets."""
    def stat(values) -> str:
        v = np.asarray(values, float)
        return "-" if np.isnan(v).all() else f"{np.nanmean(v):.1f} [{np.nanmin(v):.1f}, {np.nanmax(v):.1f}]"

    head = " | ".join(f"{lo:g}-{hi:g} m median" for lo, hi in BANDS)
    lines = [f"Speed error over {len(per_dataset)} datasets, {detector} boxes, horizon {shift:g} px off: % of the true "
             "speed, mean [min, max] of the datasets' own figures", "",
             f"| method | {head} | 5-50 m p90 | 1-sigma speeds | 2-sigma speeds | 1-sigma positions | 2-sigma positions |",
             "|---|" + "---:|" * (len(BANDS) + 5)]
    for key in per_dataset[0]:
        c = [cells(results[key]) for results in per_dataset]
        row = [stat([np.nan if d[b] is None else d[b][0] for d in c]) for b in BANDS]
        row.append(stat([np.nan if d[BANDS[-1]] is None else d[BANDS[-1]][2] for d in c]))
        row += [stat([d[name][k] for d in c]) for name in ("cover", "pos") for k in (0, 1)]
        lines.append(f"| {key} | " + " | ".join(row) + " |")
    return "\n".join(lines)


def steadiness_table(pooled: dict, detector: str) -> str:
    """The smoothed speeds' 1/2-sigma coverage at 5-50 m by how steady the true velocity is (its change over
    STEADY_S, STEADINESS_BINS_MPS): per bin its share of the boxes, the coverage, the median error and bar, m/s;
    per range band (BANDS) the coverage and the quantiles of |error| / sigma at a normal's 1 and 2 sigma shares
    (the bar's scale that would cover what it says); the positions' coverage."""
    lines = [f"{detector} boxes, 5-50 m, by the true velocity's change over {STEADY_S:g} s", "",
             "| method | change, m/s | boxes | 1/2-sigma speeds | median error, m/s | median sigma, m/s |",
             "|---|---|---:|---:|---:|---:|"]
    for key, p in pooled.items():
        if not key.endswith("smoother"):
            continue
        band = (p["range"] >= BANDS[-1][0]) & (p["range"] < BANDS[-1][1])
        for lo, hi in zip(STEADINESS_BINS_MPS[:-1], STEADINESS_BINS_MPS[1:]):
            sel = band & (p["change"] >= lo) & (p["change"] < hi)
            if sel.any():
                lines.append(f"| {key} | {lo:g}-{hi:g} | {100 * sel.sum() / band.sum():.1f} % | "
                             f"{100 * p['cover1'][sel].mean():.1f} / {100 * p['cover2'][sel].mean():.1f} % | "
                             f"{np.median(p['err'][sel]):.3f} | {np.median(p['sigma'][sel]):.3f} |")
    shares = [ndtr(k) - ndtr(-k) for k in (1, 2)]
    lines += ["", "Speeds by range: the 1/2-sigma coverage and the share 68.27 / 95.45 % of the boxes' |error| / sigma "
              "reaches (honest normal bars: 1 / 2)", "", "| method | range, m | 1/2-sigma speeds | |error| / sigma |",
              "|---|---|---:|---:|"]
    for key, p in pooled.items():
        if key.endswith("smoother"):
            for lo, hi in BANDS:
                b = (p["range"] >= lo) & (p["range"] < hi)
                if not b.any():
                    continue
                with np.errstate(invalid="ignore", divide="ignore"):
                    q = np.nanquantile(p["err"][b] / p["sigma"][b], shares)
                lines.append(f"| {key} | {lo:g}-{hi:g} | {100 * p['cover1'][b].mean():.1f} / {100 * p['cover2'][b].mean():.1f} % "
                             f"| {q[0]:.2f} / {q[1]:.2f} |")
    lines += ["", "Positions at 5-50 m: within k sigma_m (the semi-major axis) and within the k-sigma ellipse", "",
              "| method | 1/2 sigma_m | 1/2-sigma ellipse |", "|---|---:|---:|"]
    for key, p in pooled.items():
        if key.endswith("smoother"):
            band = (p["range"] >= BANDS[-1][0]) & (p["range"] < BANDS[-1][1])
            lines.append(f"| {key} | " + " | ".join(f"{100 * p[f'{name}1'][band].mean():.1f} / {100 * p[f'{name}2'][band].mean():.1f} %"
                                                    for name in ("pos", "ellipse")) + " |")
    return "\n".join(lines)


def bar_parts(path: str, detector: str, shift: float, foot_noise: str, accel_psd: float | str, soles: bool) -> dict:
    """The pedestrians' correction's smoothed speeds at the 5-50 m boxes with a true speed, as the tables measure
    them with a split FOOT_NOISE model (box-height or correlated): err (M,) speed - true, m/s; S (M,) its
    1-sigma; a (M,) the shared mapping error's part of it (the speed's delta-method sigma of
    ``mapping_velocity_covariance``, m/s; the track's own part is sqrt(S^2 - a^2)); z, the fit's horizon error
    over its sigma (horizon_sigma_px_)."""
    ds = load_dataset(path)
    fps = float(ds.manifest["fps"])
    frames, xyxy, _, true_speed, rng, _ = truth(ds, detector)
    ids = link_tracks(frames, xyxy)
    feet = undistorted(ds, box_bottom_points(xyxy, convention="homocal"))
    peds = pedestrians(ds, clicked_transformer(ds, shift), frames, xyxy, ids)
    foot = foot_status(xyxy, frames, ds.camera.image_size) if soles else None
    noise = foot_noise_options(foot_noise, xyxy, 1.0)
    q = fit_tracks_accel_psd(peds, frames, feet, ids, fps, **noise, foot=foot) if accel_psd == "fitted" else accel_psd
    click = inspect.signature(measure_tracks).parameters["click_sigma_px"].default  # the tables' click sigma
    m = per_box(peds, frames, feet, ids, fps, accel_psd=q, click_sigma_px=click, **noise, foot=foot)
    speed, S, v = m["speed_mps"], m["speed_sigma_mps"], np.column_stack([m["vx"], m["vy"]])
    a = speed_and_sigma(v, mapping_velocity_covariance(peds, feet, v, click))[1]
    keep = np.isfinite(speed) & np.isfinite(true_speed) & (rng >= BANDS[-1][0]) & (rng < BANDS[-1][1])
    return {"err": (speed - true_speed)[keep], "S": S[keep], "a": a[keep],
            "z": (peds.horizon_row_ - ds.camera.horizon_row) / peds.horizon_sigma_px_}


def expected_coverage(S: np.ndarray, a: np.ndarray, z: np.ndarray, k: float) -> np.ndarray:
    """The share of boxes whose speed error lies within k S if each box's error is a z + e, e ~ N(0, S^2 - a^2)
    (the track's own part honest and normal), for each of the mapping error's draws z (D,) (a camera's error
    in its sigmas, shared by its boxes): (D,) fractions (boxes S, a (M,) m/s)."""
    b = np.sqrt(np.maximum(S**2 - a**2, 1e-12))
    shift = np.outer(z, a)
    return (ndtr((k * S - shift) / b) - ndtr((-k * S - shift) / b)).mean(axis=1)


def pooled_coverage_table(parts: list[dict], draws: int, seed: int = 0) -> str:
    """The 1/2-sigma speed coverage pooled over the datasets of ``bar_parts``: measured; expected with both
    parts honest at each camera's realised horizon z; and over ``draws`` draws of the cameras' z ~ N(0, 1)
    (mean, 5th and 95th percentile): how far a pooled coverage over these cameras moves with part (a) alone."""
    rng = np.random.default_rng(seed)
    Z = rng.standard_normal((draws, len(parts)))
    n = np.array([len(p["S"]) for p in parts])
    lines = ["| k sigma | measured | expected at the realised z | expected over draws of z: mean [5th, 95th pct] | "
             "a camera alone at z = 0 |", "|---|---:|---:|---:|---:|"]
    for k in (1, 2):
        measured = 100 * np.mean(np.concatenate([np.abs(p["err"]) <= k * p["S"] for p in parts]))
        realised = 100 * np.average([expected_coverage(p["S"], p["a"], np.array([p["z"]]), k)[0] for p in parts], weights=n)
        drawn = 100 * np.average(np.column_stack([expected_coverage(p["S"], p["a"], Z[:, j], k)
                                                  for j, p in enumerate(parts)]), axis=1, weights=n)
        centre = 100 * np.average([expected_coverage(p["S"], p["a"], np.zeros(1), k)[0] for p in parts], weights=n)
        lines.append(f"| {k} | {measured:.1f} % | {realised:.1f} % | {drawn.mean():.1f} % [{np.percentile(drawn, 5):.1f}, "
                     f"{np.percentile(drawn, 95):.1f}] | {centre:.1f} % |")
    return "\n".join(lines)


def horizon_table(rows: list[dict]) -> str:
    """Per detector, the fitted horizons' z = error / sigma over ``horizon_errors``' rows (each an independent
    fit; those refused counted apart): the errors' RMS, mean and sd (px), the share of |z| < 1 and < 2 (68 / 95 %
    if the sigma is honest), the RMS and mean of z (1 and 0), for the whole sigma and the people's alone."""
    lines = ["| detector | fits (refused) | error RMS, px | error mean, sd, px | sigma median, px | whole sigma: |z| < 1, "
             "< 2, RMS z, mean z | people's sigma: median px; |z| < 1, < 2, RMS z |", "|---|---:|---:|---:|---:|---:|---:|"]
    for detector in dict.fromkeys(r["detector"] for r in rows):
        mine = [r for r in rows if r["detector"] == detector]
        e, s, sp = (np.array([r[k] for r in mine if "refusal" not in r]) for k in ("error", "sigma", "sigma_people"))
        z, zp = e / s, e / sp
        share = lambda z, k: 100 * np.mean(np.abs(z) < k)  # noqa: E731
        lines.append(f"| {detector} | {len(e)} ({len(mine) - len(e)}) | {np.sqrt(np.mean(e**2)):.2f} | {np.mean(e):+.2f}, {np.std(e, ddof=1):.2f} | {np.median(s):.2f} | {share(z, 1):.0f} %, "
                     f"{share(z, 2):.0f} %, {np.sqrt(np.mean(z**2)):.2f}, {np.mean(z):+.2f} | {np.median(sp):.2f}; "
                     f"{share(zp, 1):.0f} %, {share(zp, 2):.0f} %, {np.sqrt(np.mean(zp**2)):.2f} |")
    return "\n".join(lines)


def throughput(path: str, minutes: float, foot_noise: str = "fixed", accel_psd: float | str = ACCEL_PSD,
               feet: str = FEET[0], foot_tails: str = FOOT_TAILS[0]) -> str:
    ds = load_dataset(path)
    boxes = read_boxes(Path(path) / "detections.parquet", "segmentation")
    fps = float(ds.manifest["fps"])
    ids = link_tracks(boxes.frames, boxes.xyxy)
    length = int(boxes.frames.max()) + 1
    copies = int(np.ceil(minutes * 60 * fps / length))
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "boxes.csv"
        with open(csv, "w") as f:
            f.write("frame,track_id,x1,y1,x2,y2\n")
            for c in range(copies):
                xyxy = boxes.xyxy + 0.5  # homocal edges -> the CSV's pixel corners
                block = np.column_stack([boxes.frames + c * length, ids + c * (ids.max() + 1), xyxy])
                np.savetxt(f, block, fmt=["%d", "%d", "%.3f", "%.3f", "%.3f", "%.3f"], delimiter=",")
        trap = Path(path) / "trapezoids.json"  # its hand-placed trapezoid, uncorrected
        n = copies * len(ids)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "homocal.cli", "measure", str(trap), "--boxes", str(csv), "--fps",
                        f"{fps:g}", "--out", str(Path(tmp) / "tracks.parquet"), "--foot-noise", foot_noise,
                        "--accel-psd", str(accel_psd), "--feet", feet, "--foot-noise-tails", foot_tails, "--no-progress"],
                       check=True)
        seconds = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return (f"throughput: {n:,} boxes in the file ({copies} copies of {ds.name}'s {length} frames of segmentation boxes, "
            f"{copies * length / fps / 60:.1f} min at {fps:g} fps) in {seconds:.1f} s: {n / seconds:,.0f} boxes/s "
            f"(the whole command: start, read, write); peak memory {peak:.0f} MB")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("datasets", nargs="+")
    parser.add_argument("--detectors", default="segmentation,rgb")
    parser.add_argument("--shift", type=float, default=16.0, help="the clicked horizon above the true one, px")
    parser.add_argument("--throughput", type=float, metavar="MINUTES")
    parser.add_argument("--split", action="store_true", help="measure_tracks(split_mapping_error=True)")
    parser.add_argument("--box-sigma", action="store_true",
                        help="the split with each foot point's (u, v) sigmas FOOT_SIGMA_PER_BOX_HEIGHT x its box's height")
    parser.add_argument("--correlated", action="store_true",
                        help="--box-sigma with the foot point's error an AR(1) of correlation time FOOT_CORRELATION_S")
    parser.add_argument("--accel-psd", type=lambda s: s if s in ("fitted", IMM) else float(s), default=ACCEL_PSD,
                        help="the filter's process noise q, m^2/s^3, fitted (per dataset, detector and mapping) or imm")
    parser.add_argument("--feet", choices=FEET, default=FEET[0], help="homocal measure --feet")
    parser.add_argument("--spread", action="store_true", help="each dataset on its own: mean [min, max] over them")
    parser.add_argument("--exact", action="store_true",
                        help="the true mapping (the exact trapezoid) alone, bars of no mapping error (click sigma 0)")
    parser.add_argument("--mappings", default=",".join(MAPPINGS), help="the mappings measured, of " + ", ".join(MAPPINGS))
    parser.add_argument("--steadiness", action="store_true",
                        help="the smoothed speeds' coverage by the true velocity's change over STEADY_S, pooled")
    parser.add_argument("--fit-imm", action="store_true",
                        help="the IMM's two q and switching rates by maximum likelihood over the datasets' tracks")
    parser.add_argument("--fit-foot-scale", action="store_true",
                        help="the scale of the filter's measurement noise by maximum likelihood under the IMM")
    parser.add_argument("--foot-noise-tails", choices=FOOT_TAILS, default=FOOT_TAILS[0], help="homocal measure --foot-noise-tails")
    parser.add_argument("--fit-foot-tails", action="store_true",
                        help="the Student-t foot noise's scale and degrees of freedom by maximum likelihood under the IMM")
    parser.add_argument("--box-margin", type=number(float, 0.0, MAX_BOX_MARGIN_PX), default=0.0, metavar="PX",
                        help="the boxes' known excess height: PX / 2 off each box's top and bottom edge")
    parser.add_argument("--foot-scale", type=float, default=1.0, metavar="C",
                        help="the filter's measurement noise times C^2")
    parser.add_argument("--horizons", type=float, metavar="SECONDS",
                        help="the pedestrians' fitted horizon's error over its sigma on disjoint windows of SECONDS")
    parser.add_argument("--draws", type=int, metavar="N",
                        help="the pooled speed coverage against what honest parts give over N draws of the cameras' mapping errors")
    args = parser.parse_args(argv)
    if args.box_margin and (args.draws or args.fit_imm or args.fit_foot_scale or args.fit_foot_tails or args.horizons
                            or args.throughput):
        parser.error("--box-margin: for the speed tables only, not --draws, --fit-*, --horizons or --throughput")
    if args.draws:
        for detector in args.detectors.split(","):
            parts = [bar_parts(d, detector, args.shift, "correlated" if args.correlated else "box-height",
                               args.accel_psd, args.feet == "soles") for d in args.datasets]
            for d, p in zip(args.datasets, parts):
                share = np.median(p["a"] / p["S"])
                print(f"{Path(d).name}, {detector}: horizon z {p['z']:+.2f}, mapping part a / S median {share:.2f}", file=sys.stderr)
            print(f"{detector} boxes, pedestrians, smoother, {len(parts)} datasets pooled\n\n" + pooled_coverage_table(parts, args.draws) + "\n")
        return 0
    if args.fit_imm:
        qs, rates = fit_imm([imm_inputs(d, detector, args.shift) for d in args.datasets for detector in args.detectors.split(",")])
        print(f"IMM fitted on {len(args.datasets)} datasets, {args.detectors} boxes: q {qs[0]:.3g}, {qs[1]:.3g} m^2/s^3; "
              f"switching rates {rates[0]:.3g}, {rates[1]:.3g} per s")
        return 0
    if args.fit_foot_scale:
        noise = "correlated" if args.correlated else "box-height" if args.box_sigma else "fixed"
        inputs = {detector: [imm_inputs(d, detector, args.shift, noise, args.feet == "soles") for d in args.datasets]
                  for detector in args.detectors.split(",")}
        pooled = [(args.detectors, [x for v in inputs.values() for x in v])] if len(inputs) > 1 else []
        for name, group in list(inputs.items()) + pooled:
            print(f"{name} boxes, {noise}, feet {args.feet}, IMM: foot noise scale c {fit_noise_scale(group):.3f}")
        return 0
    if args.fit_foot_tails:
        noise = "box-height" if args.box_sigma else "fixed"
        c, dof = fit_student_noise([imm_inputs(d, detector, args.shift, noise) for d in args.datasets
                                    for detector in args.detectors.split(",")])
        print(f"{args.detectors} boxes, {noise}, IMM: Student-t foot noise scale c {c:.3f}, degrees of freedom {dof:.3g}")
        return 0
    if args.horizons:
        rows = [r for detector in args.detectors.split(",") for d in args.datasets
                for r in horizon_errors(d, detector, args.shift, args.horizons)]
        for r in rows:
            print(f"{r['dataset']}, {r['detector']}, {r['start']:g} s: " + (f"refused: {r['refusal']}" if "refusal" in r else
                  f"error {r['error']:+.2f} px, sigma {r['sigma']:.2f} (people {r['sigma_people']:.2f})"), file=sys.stderr)
        print(horizon_table(rows))
        return 0
    if args.throughput:
        print(throughput(args.datasets[0], args.throughput, "correlated" if args.correlated else "fixed", args.accel_psd,
                         args.feet, args.foot_noise_tails))
        return 0
    only = tuple(args.mappings.split(","))
    for detector in args.detectors.split(","):
        def run(paths: list[str]) -> dict:
            return evaluate(paths, detector, args.shift, args.split, args.box_sigma, args.correlated, args.accel_psd,
                            args.feet == "soles", args.exact, only, args.foot_scale, args.foot_noise_tails,
                            args.box_margin)

        def fitted(path: str) -> dict | None:  # a dataset's evaluation, None where a fit refuses the trimmed boxes
            try:
                return run([path])
            except ValueError as e:
                if not args.box_margin:
                    raise
                print(f"{Path(path).name}, {detector}: left out, refused: {e}", file=sys.stderr)
                return None

        if args.spread:
            each = [e for e in map(fitted, args.datasets) if e is not None]
            print(spread_table(each, detector, args.shift) + "\n")
            if args.steadiness:  # the same evaluations pooled
                print(steadiness_table({key: {k: np.concatenate([e[key][k] for e in each]) for k in each[0][key]}
                                        for key in each[0]}, detector) + "\n")
        elif args.steadiness:
            print(steadiness_table(run(args.datasets), detector) + "\n")
        else:
            print(table(run(args.datasets), detector, args.shift) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
