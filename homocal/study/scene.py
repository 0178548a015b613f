"""One scene of the study: its inputs, the per-variant tables hoisted out of the sample loop, and the
shard (every calibration triple of one trapezoid variant) that both engine paths compute."""
from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import asdict, dataclass, field, fields

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from homocal.dataset import EXACT, load_dataset
from homocal.geometry import SiteMap, ViewTransformer, apply_homography
from homocal.keyed_rng import seed_from_key
from homocal.study import kernels
from homocal.study.perturb import ShiftSpec, base_quad, draw_base_error, draw_variant, perturbed_quads
from homocal.study.triples import distance_features, triples

SHARD_SCHEMA = pa.schema(
    [("variant", pa.int32()), ("i", pa.int16()), ("j", pa.int16()), ("k", pa.int16()),
     ("d_sum", pa.float32()), ("d_spread", pa.float32()), ("path_before", pa.float32())]
    + [(name, pa.bool_() if name == "hybrid_regression" else pa.float32()) for name in kernels.OUT_COLUMNS]
)
REASON_KEY = "degenerate_reason"  # a shard's Parquet schema metadata: why its variant is degenerate, "" if it is not
METRICS = ("euclidean", "range")


@dataclass(frozen=True)
class StudyParams:
    """Everything that determines a study's numbers (written to study.json by to_dict).

    horizon_shift: None (the hand-placed trapezoid as it is) or the clicked trapezoid's systematic error, a
    ShiftSpec string: its horizon is put that many px above the true one (positive: the mapping
    underestimates range). click_noise: standard deviation (px) of Gaussian noise on its 8 image coordinates.
    metric: "euclidean" (ground error ||p - g||) or "range" (| ||g - o|| - ||p - o|| |) for the calibration
    and path errors the improvements are computed from (the correctors themselves are unchanged).
    test_lateral_max: test points at most this many metres to the side of the calibration line x = o_x.
    """

    seed: int = 0
    n_variants: int = 1000
    foot_source: str = EXACT  # "exact", "segmentation" or another detector's name
    n_test: int = 2000
    max_test_distance: float | None = 50.0  # metres from the camera; the paper's operating range (Fig. 2); None: all
    test_lateral_max: float | None = None
    horizon_shift: str | None = None
    click_noise: float = 0.0
    metric: str = "euclidean"
    threshold: float = 75.0
    descent: dict = field(default_factory=lambda: dict(
        delta_max=8.0, grid_offsets=(-4.0, -2.0, 0.0, 2.0, 4.0), initial_step=1.0, min_step=0.0625, max_evals=400))

    def __post_init__(self) -> None:
        if self.horizon_shift is not None:
            object.__setattr__(self, "horizon_shift", str(ShiftSpec.parse(self.horizon_shift)))  # one spelling
        grid = tuple(float(x) for x in self.descent["grid_offsets"])
        object.__setattr__(self, "descent", {**self.descent, "grid_offsets": grid})
        if self.metric not in METRICS:
            raise ValueError(f"--metric {self.metric!r}: expected one of {', '.join(METRICS)}")
        if not (isinstance(self.click_noise, (int, float)) and 0 <= self.click_noise <= 100):
            raise ValueError(f"--click-noise {self.click_noise!r}: expected a number of pixels in [0, 100]")
        if not isinstance(self.seed, int) or not 0 <= self.seed < 2**63:
            raise ValueError(f"--seed {self.seed!r}: expected an integer in [0, 2**63)")
        for name in ("max_test_distance", "test_lateral_max"):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, (int, float)) and 0 < value < float("inf")):
                raise ValueError(f"--{name.replace('_', '-')} {value!r}: expected a positive number of metres or none")

    def to_dict(self) -> dict:
        """Every field, JSON-ready (study.json; what --resume compares)."""
        d = asdict(self)
        d["descent"]["grid_offsets"] = list(d["descent"]["grid_offsets"])
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "StudyParams":
        """The inverse of to_dict (unknown keys are ignored: study.json holds more)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


@dataclass
class Scene:
    """A scene's study inputs: hand-placed quads (4, 2), calibration q (M, 2) px, g (M, 2) m, distance (M,) m,
    test points (N, 2) px and (N, 2) m, camera origin (2,) m, and the triples (S, 3)."""

    name: str
    site_map: SiteMap
    image_quad: np.ndarray
    map_quad: np.ndarray
    origin: np.ndarray
    cal_image: np.ndarray
    cal_ground: np.ndarray
    distance: np.ndarray
    test_image: np.ndarray
    test_ground: np.ndarray
    triples: np.ndarray
    K: np.ndarray
    true_horizon_row: float
    config_hash: str = ""

    @functools.cached_property
    def horizon_row(self) -> float:
        """Horizon row (px) of the hand-placed trapezoid's mapping at the principal column."""
        return float(ViewTransformer(self.image_quad, self.site_map.to_metres(self.map_quad)).horizon_row(self.K[0, 2]))

    def base_image_quad(self, params: StudyParams, variant: int) -> np.ndarray:
        """The variant's clicked base image trapezoid (4, 2) px (perturb.base_quad): the hand-placed one, its
        horizon put the variant's horizon shift above the true one if params has a horizon shift, plus the
        variant's click noise; the hand-placed one itself by default."""
        eps, noise = draw_base_error(params.seed, self.name, variant, shift_spec(params), params.click_noise)
        return base_quad(self.image_quad, self.K, self.horizon_row, self.true_horizon_row, eps, noise)

    @functools.cached_property
    def distance_features(self) -> tuple[np.ndarray, np.ndarray]:
        """(d_sum, d_spread) (S,) float32 of every triple (triples.distance_features)."""
        return distance_features(self.distance, self.triples)

    @classmethod
    def from_dataset(cls, path, params: StudyParams) -> "Scene":
        """Load a dataset folder; calibration points from the exact or segmentation foot points (a detector's
        test points use segmentation calibration points, the only detector calibration objects carry)."""
        ds = load_dataset(path)
        cal_image, cal_ground, distance = ds.calibration_points(EXACT if params.foot_source == EXACT else "segmentation")
        if len(cal_image) < 3:
            raise ValueError(f"{path}: need at least 3 calibration points, got {len(cal_image)}")
        test_image, test_ground = ds.test_points(params.foot_source, n=params.n_test, seed=params.seed,
                                                  max_distance=params.max_test_distance,
                                                  max_lateral=params.test_lateral_max)
        return cls(ds.name, ds.site_map, ds.trapezoid_image, ds.trapezoid_map, np.asarray(ds.camera_origin, float),
                   cal_image, cal_ground, distance, test_image, test_ground, triples(len(cal_image)),
                   np.asarray(ds.camera["K"], dtype=np.float64), float(ds.camera["horizon_row"]),
                   str(ds.manifest.get("config_hash", "")))


def shift_spec(params: StudyParams) -> ShiftSpec | None:
    """The study's horizon-shift spec, None if it has none."""
    return None if params.horizon_shift is None else ShiftSpec.parse(params.horizon_shift)


@dataclass
class VariantTables:
    """Per-variant work hoisted out of the sample loop (inputs of kernels.run_variant)."""

    v0: np.ndarray
    Bt: np.ndarray
    H0: np.ndarray
    F: np.ndarray
    cal: np.ndarray
    test: np.ndarray
    path_before: float


def variant_mapping(scene: Scene, params: StudyParams, variant: int):
    """(v0 (8,), Bt (3, 3), H0 (3, 3), p (M, 2), pt (N, 2)): the variant's image quad (its base quad plus its
    offsets), target basis, homography and mapped calibration and test points; or the reason (str) the
    variant is degenerate: a quad validate_quad rejects, a homography that cannot be formed, or a
    calibration or test point beyond the horizon."""
    offsets, _ = draw_variant(params.seed, scene.name, variant)
    image, map_quad = perturbed_quads(scene.base_image_quad(params, variant), scene.map_quad, offsets)
    try:
        target = ViewTransformer(image, scene.site_map.to_metres(map_quad)).target
    except ValueError as e:
        return str(e)
    v0 = image.ravel()
    Bt = kernels.target_basis(target)
    H0 = kernels.homography(v0, Bt)
    p = apply_homography(H0, scene.cal_image)
    pt = apply_homography(H0, scene.test_image)
    for what, mapped in (("calibration", p), ("test", pt)):
        bad = np.flatnonzero(np.isnan(mapped).any(axis=1))
        if bad.size:
            return f"{what} point {bad[0]} maps beyond the horizon"
    return v0, Bt, H0, p, pt


def prepare_variant(scene: Scene, params: StudyParams, variant: int) -> VariantTables | str:
    """The variant's tables, or the reason (str) it is degenerate (see variant_mapping)."""
    mapping = variant_mapping(scene, params, variant)
    if isinstance(mapping, str):
        return mapping
    v0, Bt, H0, p, pt = mapping
    o, g, gt = scene.origin, scene.cal_ground, scene.test_ground
    d = np.linalg.norm(p - o, axis=1)
    r = p - g
    cal = np.vstack([d, r.T, ((p - o) / d[:, None]).T, np.linalg.norm(r, axis=1), np.linalg.norm(g - o, axis=1) - d])
    dt = np.linalg.norm(pt - o, axis=1)
    dgt = np.linalg.norm(gt - o, axis=1)
    rt = pt - gt
    ut = (pt - o) / dt[:, None]
    w0 = np.column_stack([scene.test_image, np.ones(len(pt))]) @ H0[2]
    s = np.column_stack([scene.test_image, np.ones(len(pt))]) / w0[:, None]
    f = kernels.FIXED  # lengths in units of 2^-26 m (see kernels.regression_paths)
    test = np.vstack([f * dt, f * f * (rt**2).sum(axis=1), f * 2 * (rt * ut).sum(axis=1), s.T, f * rt.T, f * gt.T,
                      f * (gt - o).T, f * dgt])
    test = test.astype(np.float32)
    F = kernels.ground_frames(Bt, g)
    before = np.abs(dgt - dt) if params.metric == "range" else np.linalg.norm(rt, axis=1)
    return VariantTables(v0, Bt, H0, F, np.ascontiguousarray(cal), np.ascontiguousarray(test), float(before.mean()))


def run_tables(scene: Scene, tables: VariantTables, params: StudyParams, variant: int, idx: np.ndarray):
    """kernels.run_variant on triples idx (S, 3): (out (S, len(OUT_COLUMNS)), ab (S, 4), vfinal (S, 9)), see there."""
    S = len(idx)
    out, ab, vfinal = np.empty((S, len(kernels.OUT_COLUMNS))), np.empty((S, 4)), np.empty((S, 9))
    dp = params.descent
    I, J, K = (np.ascontiguousarray(idx[:, c].astype(np.int64)) for c in range(3))
    kernels.run_variant(
        tables.v0, tables.Bt, tables.H0, tables.F, np.ascontiguousarray(scene.cal_image),
        np.ascontiguousarray(scene.cal_ground), tables.cal, tables.test,
        tables.path_before, I, J, K, np.uint64(seed_from_key(params.seed, scene.name, variant)),
        np.asarray(dp["grid_offsets"], dtype=np.float64), float(dp["delta_max"]), float(dp["initial_step"]),
        float(dp["min_step"]), int(dp["max_evals"]), float(params.threshold), params.metric == "range", scene.origin,
        out, ab, vfinal)
    return out, ab, vfinal


def compute_shard(scene: Scene, params: StudyParams, variant: int) -> tuple[pa.Table, str]:
    """One shard: the Parquet table of every triple of variant (empty if degenerate) and the degenerate
    reason ("" if none). Its schema metadata says what it is: the reason (REASON_KEY), scene, variant,
    study_key and rows (checked by check_shard). The one shard function of both engine paths."""
    tables = prepare_variant(scene, params, variant)
    identity = {"scene": scene.name, "variant": str(variant), "study_key": study_key(params.to_dict(), scene.name, scene.config_hash)}
    if isinstance(tables, str):
        return SHARD_SCHEMA.empty_table().replace_schema_metadata({REASON_KEY: tables, **identity, "rows": "0"}), tables
    out, _, _ = run_tables(scene, tables, params, variant, scene.triples)
    d_sum, d_spread = scene.distance_features
    S = len(scene.triples)
    f32 = lambda x: pa.array(np.asarray(x, dtype=np.float32))  # noqa: E731
    columns = [pa.array(np.full(S, variant, np.int32)), *(pa.array(scene.triples[:, c]) for c in range(3)),
               f32(d_sum), f32(d_spread), f32(np.full(S, tables.path_before))]
    columns += [pa.array(out[:, c] == 1.0) if name == "hybrid_regression" else f32(out[:, c])
                for c, name in enumerate(kernels.OUT_COLUMNS)]
    return pa.Table.from_arrays(columns, schema=SHARD_SCHEMA.with_metadata({REASON_KEY: "", **identity, "rows": str(S)})), ""


def study_key(params: dict, scene: str, config_hash: str) -> str:
    """What a shard belongs to, as 16 hex digits: sha256 of the study's parameters (StudyParams.to_dict), the
    scene's name and its dataset's config hash (all in study.json, so the report can recompute it)."""
    blob = json.dumps({"params": params, "scene": scene, "dataset": config_hash}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def check_shard(path, scene: str, variant: int, key: str, rows: int) -> str:
    """The degenerate reason ("" if none) of the shard file at path after checking that it is the shard
    expected there: readable Parquet, of this scene, variant and study (key: study_key), with rows rows (0 if
    degenerate). ValueError naming the file and what is wrong otherwise (a cut or garbage file, a shard of
    another study or variant copied there, an older homocal's shard)."""
    try:
        meta = pq.read_metadata(path)
    except (OSError, pa.ArrowInvalid) as e:
        raise ValueError(f"{path}: not a readable shard (cut or garbage: {e})") from None
    found = {k.decode(): v.decode() for k, v in (meta.metadata or {}).items() if k != b"ARROW:schema"}
    if REASON_KEY not in found or "study_key" not in found:
        raise ValueError(f"{path}: not a shard of this homocal version (no {REASON_KEY!r} or 'study_key' in its metadata)")
    expected = {"scene": scene, "variant": str(variant), "study_key": key}
    wrong = [f"{k} {found.get(k)!r} (expected {v!r})" for k, v in expected.items() if found.get(k) != v]
    if wrong:
        raise ValueError(f"{path}: a shard of another study or variant: {', '.join(wrong)}")
    reason = found[REASON_KEY]
    if meta.num_rows != (0 if reason else rows) or found.get("rows") != str(meta.num_rows):
        raise ValueError(f"{path}: {meta.num_rows} rows, expected {0 if reason else rows}")
    return reason
