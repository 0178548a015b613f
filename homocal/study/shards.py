"""The study's shards: the per-variant tables hoisted out of the sample loop and the shard (every
calibration triple of one trapezoid variant) that both engine paths compute, with its identity and check."""
from __future__ import annotations

import hashlib
import json
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from homocal.geometry import ViewTransformer, apply_homography
from homocal.keyed_rng import seed_from_key
from homocal.study import kernels
from homocal.study.inputs import StudyParams, StudyScene
from homocal.study.rows import make_cal_table, make_test_table

SHARD_SCHEMA = pa.schema(
    [("variant", pa.int32()), ("i", pa.int16()), ("j", pa.int16()), ("k", pa.int16()),
     ("d_sum", pa.float32()), ("d_spread", pa.float32()), ("path_before", pa.float32())]
    + [(name, pa.bool_() if name == "hybrid_regression" else pa.float32()) for name in kernels.OUT_COLUMNS]
)
REASON_KEY = "degenerate_reason"  # a shard's Parquet schema metadata: why its variant is degenerate, "" if it is not


def variant_mapping(scene: StudyScene, params: StudyParams, variant: int):
    """(v0 (8,), t0 (8,), Bt (3, 3), H0 (3, 3), p (M, 2), pt (N, 2)): the variant's image quad (its base quad plus
    its offsets), map quad (metres), its basis, homography and mapped calibration and test points; or the reason (str) the
    variant is degenerate: a quad validate_quad rejects, a homography that cannot be formed, or a
    calibration or test point beyond the horizon."""
    image, map_quad = scene.variant_quads(params, variant)
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
    return v0, target.ravel(), Bt, H0, p, pt


def path_errors(mapped: np.ndarray, ground: np.ndarray, origin: np.ndarray, metric: str) -> np.ndarray:
    """The study's error (N,) m of each mapped test point (N, 2) m against its true ground point (N, 2) m:
    | ||g - o|| - ||p - o|| | with metric "range" (o the camera origin (2,) m), ||p - g|| otherwise; NaN where
    a point was mapped beyond the horizon (NaN)."""
    if metric == "range":
        return np.abs(np.linalg.norm(ground - origin, axis=1) - np.linalg.norm(mapped - origin, axis=1))
    return np.linalg.norm(mapped - ground, axis=1)


def prepare_variant(scene: StudyScene, params: StudyParams, variant: int) -> kernels.Variant | str:
    """The variant's kernels.Variant, or the reason (str) it is degenerate (see variant_mapping)."""
    mapping = variant_mapping(scene, params, variant)
    if isinstance(mapping, str):
        return mapping
    v0, t0, Bt, H0, p, pt = mapping
    o, g, gt = scene.origin, scene.cal_ground, scene.test_ground
    F = kernels.ground_frames(Bt, g)
    before = path_errors(pt, gt, o, params.metric)
    return kernels.Variant(v0, np.ascontiguousarray(t0), Bt, H0, F, np.ascontiguousarray(scene.cal_image),
                           np.ascontiguousarray(g), o, make_cal_table(p, g, o), make_test_table(scene.test_image, H0, pt, gt, o),
                           float(before.mean()))


def settings(params: StudyParams) -> kernels.Settings:
    """The methods' settings of a study (kernels.Settings)."""
    dp, lc = params.descent, params.least_change
    descent = kernels.DescentSettings(np.asarray(dp["grid_offsets"], dtype=np.float64), float(dp["delta_max"]),
                                      float(dp["initial_step"]), float(dp["min_step"]), int(dp["max_evals"]))
    least_change = kernels.LeastChangeSettings(float(lc["click_sigma_px"]), float(lc["map_sigma_m"]),
                                               float(lc["point_sigma_m"]), int(lc["iterations"]))
    return kernels.Settings(descent, least_change, float(params.threshold), params.metric == "range")


def run_tables(scene: StudyScene, tables: kernels.Variant, params: StudyParams, variant: int, idx: np.ndarray) -> kernels.Results:
    """kernels.run_variant on triples idx (S, 3) of the variant's tables (prepare_variant): its kernels.Results."""
    results = kernels.Results.empty(len(idx))
    I, J, K = (np.ascontiguousarray(idx[:, c].astype(np.int64)) for c in range(3))
    samples = kernels.Samples(I, J, K, np.uint64(seed_from_key(params.seed, scene.name, variant)))
    kernels.run_variant(tables, samples, settings(params), results)
    return results


def compute_shard(scene: StudyScene, params: StudyParams, variant: int) -> tuple[pa.Table, str]:
    """One shard: the Parquet table of every triple of variant (empty if degenerate) and the degenerate
    reason ("" if none). Its schema metadata says what it is: the reason (REASON_KEY), scene, variant,
    study_key and rows (checked by check_shard). The one shard function of both engine paths."""
    tables = prepare_variant(scene, params, variant)
    identity = {"scene": scene.name, "variant": str(variant), "study_key": study_key(params.to_dict(), scene.name, scene.config_hash)}
    if isinstance(tables, str):
        return SHARD_SCHEMA.empty_table().replace_schema_metadata({REASON_KEY: tables, **identity, "rows": "0"}), tables
    out = run_tables(scene, tables, params, variant, scene.triples).out
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
