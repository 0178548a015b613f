"""research/roll_budget.py's linearised error of the people's roll fit against the fit itself (fit_tilt_roll's
nonlinear root) on people seen by a rolled camera, one box each."""
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from homocal.correctors.pedestrians import fit_tilt, fit_tilt_roll
from homocal.geometry import PinholeCamera

SCRIPT = Path(__file__).resolve().parents[2] / "research" / "roll_budget.py"
spec = importlib.util.spec_from_file_location("roll_budget", SCRIPT)
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)
CAM = PinholeCamera(tilt_deg=15.0, roll_deg=1.0)
POSE = np.array([15.0, 1.0])


def fit_error(boxes: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, dict]:
    """fit_tilt_roll on the boxes (n, 4) of CAM, people labels (n,), the prior 1.71 m, 0.09 m: its (tilt, roll) error
    (2,) degrees and its result."""
    pp = tuple(CAM.K[:2, 2])
    start = fit_tilt(boxes[:, 3], boxes[:, 1], labels, CAM.focal_px, pp[1], 4.0, 1.71, 0.09)
    fit = fit_tilt_roll(boxes, labels, CAM.focal_px, pp, 4.0, 1.71, 0.09, start)
    return np.degrees([fit["tilt"], fit["roll"]]) - POSE, fit


def test_linearised_error_is_the_fits():
    """People whose heights scatter about the prior mean (their boxes exact): the roll and tilt errors the budget
    predicts at the true pose are the fit's own, to second order (a tenth of them, or 0.01 degrees: 0.45 and 0.41
    degrees of roll here); the boxes' part is nil, to rounding (each box's middle column is the sole's and the
    crown's mean, as the fit takes it: upright_columns) and the heights' carries it; the roll's sigma is the fit's."""
    rng = np.random.default_rng(4)
    xy = np.column_stack([rng.uniform(-8, 8, 120), rng.uniform(8, 40, 120)])
    height = rng.normal(1.71, 0.09, 120)
    sole, crown = CAM.project(np.column_stack([xy, np.zeros(120)])), CAM.project(np.column_stack([xy, height]))
    boxes = np.column_stack([np.minimum(sole[:, 0], crown[:, 0]) - 4, crown[:, 1], np.maximum(sole[:, 0], crown[:, 0]) + 4,
                             sole[:, 1]])
    labels = np.arange(120)
    parts = script.linearised(*script.at_pose(script.people_heights, boxes, labels, CAM.K, POSE, 4.0)[::-1], height, 1.71, 0.09)
    predicted = parts["share"].sum(0)  # degrees: tilt, roll
    actual, fit = fit_error(boxes, labels)
    assert abs(actual[1]) > 0.05  # an error worth predicting
    np.testing.assert_allclose(predicted, actual, rtol=0.1, atol=0.01)
    assert abs(parts["boxes"][1]) < 1e-9 and abs(parts["heights"][1]) > 0.1  # the boxes': 5e-15 degrees, rounding
    np.testing.assert_allclose(parts["roll_sigma"], math.degrees(math.sqrt(fit["cov"][1, 1])), rtol=0.1)


def test_linearised_error_with_walks_is_the_fits():
    """People of varied heights each walking 8 m across a rolled camera, 12 boxes each, their edges 0.5 px off: the
    roll error the budget predicts with the walks (their residuals about each person's mean, their weight the
    fit's walk_weight) is the fit's own within a quarter of the roll's sigma (the fit holds each person's median
    box from roll 0, the budget takes the median at the true pose: 0.1-0.2 sigma apart on seeds 1, 2, 3, 6; the
    tilt, from those medians alone, differs by their boxes' noise); the people's heights' part is under half of
    what they give with no walks (0.02 against 0.83 degrees here); the roll's sigma is the fit's."""
    rng = np.random.default_rng(6)
    n, k = 40, 12
    start = np.column_stack([rng.uniform(-10, 2, n), rng.uniform(10, 35, n)])
    feet = np.repeat(start, k, axis=0) + np.column_stack([np.tile(np.linspace(0, 8, k), n), np.zeros(n * k)])
    height = rng.normal(1.71, 0.09, n)
    sole, crown = CAM.project(np.column_stack([feet, np.zeros(n * k)])), CAM.project(np.column_stack([feet, np.repeat(height, k)]))
    boxes = np.column_stack([sole[:, 0] - 4, crown[:, 1], sole[:, 0] + 4, sole[:, 1]]) + rng.normal(0, 0.5, (n * k, 4))
    labels = np.repeat(np.arange(n), k)
    H, J = script.at_pose(script.people_heights, boxes, labels, CAM.K, POSE, 4.0)
    walk = (*script.at_pose(script.walk_residuals, boxes, labels, CAM.K, POSE, 4.0), labels)
    walks, alone = script.linearised(J, H, height, 1.71, 0.09, walk), script.linearised(J, H, height, 1.71, 0.09)
    actual, fit = fit_error(boxes, labels)
    assert abs(walks["share"].sum(0)[1] - actual[1]) < walks["roll_sigma"] / 4
    assert abs(walks["heights"][1]) < abs(alone["heights"][1]) / 2
    np.testing.assert_allclose(walks["roll_sigma"], math.degrees(math.sqrt(fit["cov"][1, 1])), rtol=0.1)


@pytest.mark.parametrize("share", [0.5, 0.75])
def test_middle_share_is_where_the_box_was_centred(share):
    """Boxes 10 px wide centred ``share`` of the way from a person's foot's column to the head's (both by
    PinholeCamera.project of the ground point and of the point the person's height above it, CAM rolled 1 degree):
    middle_share gives ``share`` to rounding, over the boxes whose axis leans over LEAN_PX."""
    rng = np.random.default_rng(2)
    ground, height = np.column_stack([rng.uniform(-12, 12, 200), rng.uniform(6, 30, 200)]), rng.uniform(1.5, 1.9, 200)
    sole, crown = CAM.project(np.column_stack([ground, np.zeros(200)])), CAM.project(np.column_stack([ground, height]))
    middle = sole[:, 0] + share * (crown[:, 0] - sole[:, 0])
    boxes = np.column_stack([middle - 5, crown[:, 1], middle + 5, sole[:, 1]])
    got, n = script.middle_share(boxes, ground, height, CAM)
    assert got == pytest.approx(share, abs=1e-9) and n == (np.abs(crown[:, 0] - sole[:, 0]) > script.LEAN_PX).sum() > 50
