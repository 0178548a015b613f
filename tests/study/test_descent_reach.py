"""Descent's reach rule (correctors.descent.within_reach): a stated tolerance, not rounding, decides whether a
coordinate may move exactly to delta_max, and the study's kernel takes the same decisions as the corrector."""
import numpy as np
import pytest

from homocal.correctors import DescentCorrector
from homocal.correctors.descent import REACH_TOLERANCE, within_reach
from homocal.geometry import ViewTransformer
from homocal.keyed_rng import seed_from_key
from homocal.study.inputs import StudyParams, StudyScene, descent_settings
from homocal.study.shards import prepare_variant, run_tables
from synthetic_dataset import write_dataset

REACH = descent_settings(18.0)  # the paper preset's reach, with its horizon 16 px off: most fits end on the reach
PARAMS = StudyParams(n_test=200, horizon_shift="16", descent=REACH)
NUDGE = 1e-12  # px


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    path = write_dataset(tmp_path_factory.mktemp("ds") / "scene", "reach-scene", n_calibration=10, n_test=200)
    return StudyScene.from_dataset(path, PARAMS)


@pytest.mark.parametrize("offset, delta_max, expected", [
    (1.0, 1.0, True), (-1.0, 1.0, True), (1.0 + 2e-13, 1.0, True), (-(1.0 + 2e-13), 1.0, True),
    (1.0 + REACH_TOLERANCE, 1.0, True), (1.0 + 2 * REACH_TOLERANCE, 1.0, False), (1.0625, 1.0, False),
    (18.0, 18.0, True), (18.0 + 1e-12, 18.0, True), (18.0625, 18.0, False), (0.0, 8.0, True), (np.nan, 8.0, False),
])
def test_within_reach(offset, delta_max, expected):
    assert within_reach(offset, delta_max) == expected


def nudged(quad, seed):
    """quad with every coordinate moved by +/-NUDGE px."""
    return quad + NUDGE * np.random.default_rng(seed).choice([-1.0, 1.0], quad.shape)


@pytest.mark.parametrize("seed", range(8))
def test_rounding_decides_no_move(seed):
    """Phase 2 under a loss that every +step lowers walks each coordinate to exactly delta_max (18 steps of 1 px,
    each sum rounded): from the clicked trapezoid and from it moved by 1e-12 px, every coordinate ends on the
    reach, after the same evaluations."""
    descent = DescentCorrector(**REACH)
    v0 = np.random.default_rng(seed).uniform(100.0, 1200.0, 8)
    ends = []
    for start in (v0, nudged(v0, seed)):
        v, _, evaluations = descent._coordinate_descent(start, start.copy(), lambda v: -float(v.sum()))
        np.testing.assert_allclose(v - start, REACH["delta_max"], rtol=0, atol=1e-9)
        ends.append(evaluations)
    assert ends[0] == ends[1]


def test_kernel_and_corrector_agree_at_the_reach(scene):
    """The kernel's descent (run_tables) on the clicked trapezoid moved by 1e-12 px takes the corrector's decisions
    (the same final trapezoid and evaluations) at the paper preset's reach, where most fits end on it."""
    at_limit = 0
    for variant in (1, 2):
        image, map_quad = scene.variant_quads(PARAMS, variant)
        target = scene.site_map.to_metres(map_quad)
        quad = nudged(image, variant)
        tables = prepare_variant(scene, PARAMS, variant)._replace(v0=quad.ravel())
        idx = scene.triples[::40]
        res = run_tables(scene, tables, PARAMS, variant, idx)
        for s, triple in enumerate(idx):
            sel = list(triple)
            seed = seed_from_key(PARAMS.seed, scene.name, variant, *map(int, triple))
            fit = DescentCorrector(seed=seed, **REACH).fit(ViewTransformer(quad, target), scene.cal_image[sel],
                                                            scene.cal_ground[sel], scene.origin)
            np.testing.assert_array_equal(res.quads[s], fit.transformer_.source.ravel())
            assert res.evaluations[s] == fit.evaluations_
            at_limit += np.any(np.abs(np.abs(res.quads[s] - quad.ravel()) - REACH["delta_max"]) < 1e-9)
    assert at_limit > 0
