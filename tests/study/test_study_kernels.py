"""The study's compiled kernels against the public correctors (a second implementation of the same maths):
corrected positions to 1e-9 m, the same descent trapezoid and evaluation count, the same hybrid choice."""
import itertools

import numpy as np
import pytest

from homocal.correctors import (DescentCorrector, HorizonCorrector, HybridCorrector, LeastChangeCorrector, RegressionCorrector,
                               radial_correction)
from homocal.geometry import ViewTransformer, apply_homography
from homocal.keyed_rng import packed_order, seed_from_key, shuffled_order, splitmix64
from homocal.study import kernels, metrics
from homocal.study.perturb import draw_variant
from homocal.study.inputs import StudyParams, StudyScene
from homocal.study.rows import make_test_table
from homocal.study.shards import prepare_variant, run_tables
from homocal.study.triples import n_samples, triples
from synthetic_dataset import write_dataset

pytestmark = pytest.mark.slow  # kernels against the readable correctors on many variants (minutes)

PARAMS = StudyParams(n_test=300)
# the base error and the range metric on top: every kernel path is compared with the correctors
SHIFTED = StudyParams(n_test=300, horizon_shift="normal:6:4", click_noise=1.0, metric="range")
MASK64 = 2**64 - 1


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    path = write_dataset(tmp_path_factory.mktemp("ds") / "scene", "kernel-scene", n_calibration=14, n_test=400)
    return StudyScene.from_dataset(path, PARAMS)


def fitted(scene, variant, triple, params=PARAMS):
    """The public correctors fitted on one sample, as the study defines it."""
    image, map_quad = scene.variant_quads(params, variant)
    vt = ViewTransformer(image, scene.site_map.to_metres(map_quad))
    sel = list(triple)
    args = (vt, scene.cal_image[sel], scene.cal_ground[sel], scene.origin)
    seed = seed_from_key(PARAMS.seed, scene.name, variant, *map(int, triple))
    return (vt, RegressionCorrector().fit(*args), RegressionCorrector(signed=True).fit(*args),
            DescentCorrector(seed=seed).fit(*args), HybridCorrector(seed=seed).fit(*args),
            RegressionCorrector(signed=True, intercept=True).fit(*args), HorizonCorrector().fit(*args),
            LeastChangeCorrector(**params.least_change).fit(*args))


def errors(points, truth, origin, metric):
    """(N,) errors of points (N, 2) against truth (N, 2): Euclidean, or range | ||g - o|| - ||p - o|| |."""
    if metric == "range":
        return np.abs(np.linalg.norm(truth - origin, axis=1) - np.linalg.norm(points - origin, axis=1))
    return np.linalg.norm(points - truth, axis=1)


def improvement(before, after, truth, origin, metric):
    e0 = errors(before, truth, origin, metric).mean()
    return 100 * (e0 - errors(after, truth, origin, metric).mean()) / e0


@pytest.mark.parametrize("params", [PARAMS, SHIFTED], ids=["default", "shifted-range"])
@pytest.mark.parametrize("variant", [0, 3, 17, 256, 999])
def test_kernel_agrees_with_correctors(scene, variant, params):
    rng = np.random.default_rng(variant)
    idx = scene.triples[rng.choice(len(scene.triples), 3, replace=False)]
    tables = prepare_variant(scene, params, variant)
    res = run_tables(scene, tables, params, variant, idx)
    out = res.out
    q, g, o = scene.test_image, scene.test_ground, scene.origin
    for s, triple in enumerate(idx):
        vt, reg, sig, dsc, hyb, icp, hor, lch = fitted(scene, variant, triple, params)
        base = vt.transform_points(q)
        # regression: the kernel's (a, b), clamping included, give the corrector's positions
        np.testing.assert_allclose(radial_correction(base, scene.origin, *res.faithful_ab[s]), reg.transform_points(q), rtol=0, atol=1e-9)
        np.testing.assert_allclose(radial_correction(base, scene.origin, *res.signed_ab[s]), sig.transform_points(q), rtol=0, atol=1e-9)
        assert tuple(res.faithful_ab[s]) == pytest.approx((reg.a_, reg.b_), rel=1e-9, abs=1e-15)
        # descent: the same final trapezoid (every accepted move) and the same number of evaluations
        np.testing.assert_array_equal(res.quads[s], dsc.transformer_.source.ravel())
        assert res.evaluations[s] == dsc.evaluations_
        kernel_positions = ViewTransformer(res.quads[s].reshape(4, 2), vt.target).transform_points(q)
        np.testing.assert_allclose(kernel_positions, dsc.transform_points(q), rtol=0, atol=1e-9)
        # calibration and path improvements in the study's metric (paths: float32 residual form); the hybrid
        # applies its threshold to the metric's calibration improvement of regression
        cq, cg = scene.cal_image[list(triple)], scene.cal_ground[list(triple)]
        cal_base = vt.transform_points(cq)
        col = {m: 1 + 2 * c for c, m in enumerate(kernels.METHODS)}
        for col, corrector in ((col["regression"], reg), (col["regression_signed"], sig), (col["descent"], dsc),
                               (col["regression_intercept"], icp), (col["horizon"], hor), (col["least_change"], lch)):
            ref = improvement(cal_base, corrector.transform_points(cq), cg, o, params.metric)
            # least change: its corners agree to 1e-6 px (its stopping accuracy, test_method_kernels)
            assert out[s, col] == pytest.approx(ref, abs=1e-5 if corrector is lch else 1e-9)
            ref = improvement(base, corrector.transform_points(q), g, o, params.metric)
            assert out[s, col + 1] == pytest.approx(ref, abs=1e-3)
        reg_col, des_col, hyb_col = kernels.CAL["regression"], kernels.CAL["descent"], kernels.CAL["hybrid"]
        chose_regression = out[s, reg_col] >= params.threshold
        assert bool(out[s, kernels.CHOSE]) == chose_regression
        if params.metric == "euclidean":
            assert chose_regression == (hyb.chosen_ == "regression")
            assert out[s, hyb_col] == pytest.approx(hyb.calibration_improvement_, abs=1e-9)
        chosen = reg_col if chose_regression else des_col
        assert tuple(out[s, hyb_col:hyb_col + 2]) == tuple(out[s, chosen:chosen + 2])
        assert out[s, kernels.BEFORE] == pytest.approx(errors(cal_base, cg, o, params.metric).mean(), rel=1e-12)


def test_descent_budget_and_bounds(scene):
    """A small budget stops at exactly max_evals; a small delta_max keeps every coordinate within it."""
    variant, triple = 5, scene.triples[[10]]
    tables = prepare_variant(scene, PARAMS, variant)
    for descent in (dict(max_evals=7), dict(delta_max=0.5, grid_offsets=(0.0,)), dict(grid_offsets=(-2.0, 0.0, 2.0))):
        params = StudyParams(n_test=300, descent={**PARAMS.descent, **descent})
        res = run_tables(scene, tables, params, variant, triple)
        vt, *_ = fitted(scene, variant, triple[0])
        sel = list(triple[0])
        seed = seed_from_key(PARAMS.seed, scene.name, variant, *map(int, triple[0]))
        ref = DescentCorrector(seed=seed, **{**PARAMS.descent, **descent}).fit(vt, scene.cal_image[sel], scene.cal_ground[sel], scene.origin)
        np.testing.assert_array_equal(res.quads[0], ref.transformer_.source.ravel())
        assert res.evaluations[0] == ref.evaluations_


def test_invalid_candidates_are_infinite():
    """frame() rejects what validate_quad rejects: collinear, self-intersecting and non-convex quads."""
    good = (0.0, 0.0, 10.0, 0.0, 10.0, 10.0, 0.0, 10.0)
    bad = [(0.0, 0.0, 5.0, 0.0, 10.0, 0.0, 0.0, 10.0),  # three collinear
           (0.0, 0.0, 10.0, 10.0, 10.0, 0.0, 0.0, 10.0),  # self-intersecting
           (0.0, 0.0, 10.0, 0.0, 3.0, 3.0, 0.0, 10.0)]  # non-convex
    assert kernels.frame(*good)[-1]
    assert not any(kernels.frame(*b)[-1] for b in bad)


def test_grid_best_is_first_argmin_of_means():
    """Phase 1's choice is np.argmin of the three losses' means (first on ties, cell 0 if all are +inf), on
    tables with repeated values, exact ties and invalid cells."""
    rng = np.random.default_rng(5)
    means = np.empty(625)
    for trial in range(300):
        table = rng.choice([0.0, 0.25, 0.5, 1 / 3, 2.0, np.inf], size=(6, 625)) if trial % 2 else rng.random((6, 625))
        if trial % 7 == 0:
            table[:, :] = np.inf
        i, j, k = rng.choice(6, 3, replace=False)
        expected = table[[i, j, k]].mean(axis=0)
        best, cell = kernels.grid_best(table, i, j, k, means)
        assert cell == np.argmin(expected) and best == expected[cell]


def test_sample_seed_matches_seed_from_key():
    base = np.uint64(seed_from_key(7, "scene", 12))
    for i, j, k in [(0, 1, 2), (3, 17, 38)]:
        assert int(kernels.sample_seed_kernel(base, i, j, k)) == seed_from_key(7, "scene", 12, i, j, k)


def test_variants_are_seeded_and_in_range():
    a, n = draw_variant(3, "s", 11)
    b, _ = draw_variant(3, "s", 11)
    np.testing.assert_array_equal(a, b)
    assert 2 <= n <= 16 and np.count_nonzero(a) <= n and np.all(np.abs(a) <= 3) and np.all(a == np.round(a))
    assert not draw_variant(3, "s", 0)[0].any()


def test_paper_sample_count():
    assert n_samples(40, 1000) + n_samples(39, 1000) == 19_038_019
    t = triples(6)
    assert [tuple(r) for r in t] == list(itertools.combinations(range(6), 3)) and t.dtype == np.int16
    with pytest.raises(ValueError, match="at least 3"):
        triples(2)


def _splitmix64_reference(state: int) -> int:
    """splitmix64 in Python integers (Vigna's reference: add the golden gamma, then mix)."""
    z = (state + 0x9E3779B97F4A7C15) & MASK64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
    return z ^ (z >> 31)


def test_splitmix64_matches_reference_sequence():
    """The published splitmix64 outputs for seed 1234567 (state advanced by the gamma each step)."""
    expected = [6457827717110365317, 3203168211198807973, 9817491932198370423, 4593380528125082431,
                16408922859458223821]
    state = 1234567
    for value in expected:
        assert int(splitmix64(np.uint64(state))) == _splitmix64_reference(state) == value
        state = (state + 0x9E3779B97F4A7C15) & MASK64


def test_shuffled_order_is_lexicographic_permutation_of_one_draw():
    """shuffled_order (the correctors') and packed_order (the kernels') give permutation floor(z 8!/2^64) of
    itertools.permutations(range(8)), z = splitmix64(seed ^ pass * C), computed here in Python integers."""
    permutations = list(itertools.permutations(range(8)))
    out = np.empty(8, np.int64)
    for seed in [0, 1, 2**63 + 5, 2**64 - 1, seed_from_key(3, "x", 4, 5, 6, 7)]:
        for pass_index in range(40):
            z = _splitmix64_reference(seed ^ ((pass_index * 0xD1B54A32D192ED03) & MASK64))
            expected = permutations[(z * 40320) >> 64]
            shuffled_order(np.uint64(seed), pass_index, out)
            assert tuple(out) == expected
            packed = int(packed_order(np.uint64(seed), pass_index))
            assert tuple((packed >> (4 * c)) & 15 for c in range(8)) == expected
    with pytest.raises(ValueError, match="shape \\(8,\\)"):
        shuffled_order(np.uint64(9), 2, np.empty(5, np.int64))


def test_shuffled_orders_are_uniform():
    """Over 40,000 (seed, pass) draws every coordinate takes every position about 1/8 of the time."""
    counts = np.zeros((8, 8))
    out = np.empty(8, np.int64)
    for seed in range(1000):
        for pass_index in range(40):
            shuffled_order(np.uint64(seed_from_key(seed)), pass_index, out)
            counts[np.arange(8), out] += 1
    expected = 40_000 / 8
    assert np.all(np.abs(counts - expected) < 5 * np.sqrt(expected))  # 5 sigma, binomial

def test_a_test_point_beyond_the_corrected_horizon_is_a_counted_failure(scene):
    """A variant whose clicked horizon is 16 px too high, with one test point 0.05 px below it: the horizon correction
    lowers the horizon past it (the public corrector maps it to NaN), the kernel's path improvement is NaN, and the
    table's statistics count the sample as a failure, not positive, below every percentile."""
    params = StudyParams(n_test=300, horizon_shift="16")
    variant = 1
    clean = prepare_variant(scene, params, variant)
    H0 = clean.H0
    u = float(scene.test_image[:, 0].mean())
    point = np.array([[u, -(H0[2, 0] * u + H0[2, 2]) / H0[2, 1] + 0.05]])
    image = np.vstack([scene.test_image, point])
    p = apply_homography(H0, image)
    assert np.isfinite(p).all()
    g = np.vstack([scene.test_ground, p[-1:]])
    tables = clean._replace(test=make_test_table(image, H0, p, g, scene.origin),
                             path_before=float(np.linalg.norm(p - g, axis=1).mean()))
    idx = scene.triples[::7]
    out = run_tables(scene, tables, params, variant, idx).out
    path, cal = out[:, kernels.CAL["horizon"] + 1].astype(np.float32), out[:, kernels.CAL["horizon"]].astype(np.float32)
    failed = np.isnan(path)
    assert failed.sum() > len(idx) // 2
    image_quad, map_quad = scene.variant_quads(params, variant)
    vt = ViewTransformer(image_quad, scene.site_map.to_metres(map_quad))
    for s, triple in enumerate(idx):
        hor = HorizonCorrector().fit(vt, scene.cal_image[list(triple)], scene.cal_ground[list(triple)], scene.origin)
        assert np.isnan(hor.transform_points(point)).any() == failed[s]
    # beside the same samples without that test point (no failure)
    clean_out = run_tables(scene, clean, params, variant, idx).out
    path = np.concatenate([path, clean_out[:, kernels.CAL["horizon"] + 1].astype(np.float32)])
    cal = np.concatenate([cal, clean_out[:, kernels.CAL["horizon"]].astype(np.float32)])
    finite = np.isfinite(path)
    assert finite.sum() == 2 * len(idx) - failed.sum()
    stats = metrics.method_stats(path, cal)
    assert (stats["n"], stats["failures"], stats["finite"]) == (2 * len(idx), failed.sum(), finite.sum())
    assert stats["pos_path"] == pytest.approx(100 * np.count_nonzero(path[finite] > 0) / (2 * len(idx)))
    assert stats["mean_path"] == pytest.approx(path[finite].astype(np.float64).mean())
    assert stats["p1_path"] == -np.inf
