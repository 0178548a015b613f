"""LeastChangeCorrector (issue 10): its optimum against scipy's, a known perturbation recovered, exact fits,
the Gauss-Newton step against a least-squares solve, the safeguard, JSON and bad input."""
import json
import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from homocal import Corrector, LeastChangeCorrector, PinholeCamera, ViewTransformer, load_corrector
from homocal.correctors import least_change
from homocal.correctors.least_change import gauss_newton_step, mapped_jacobian, safeguarded_step
from homocal.uncertainty import _quad_jacobian

CAM = PinholeCamera()
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])
EXACT = CAM.project_ground(GROUND)
CLICKED = EXACT + [[2.0, -3.0], [-1.0, 2.0], [1.5, 1.0], [-0.5, -1.0]]
MAP_CLICKED = GROUND + [[0.1, -0.2], [0.0, 0.1], [-0.1, 0.0], [0.05, 0.05]]
LINE_G = np.array([[0.0, 10.0], [0.0, 20.0], [0.0, 35.0]])
SPREAD_G = np.array([[-4.0, 9.0], [4.0, 12.0], [-3.0, 25.0], [3.0, 32.0], [0.0, 18.0]])
TEST_G = np.stack(np.meshgrid(np.linspace(-6, 6, 7), np.linspace(6, 50, 12)), -1).reshape(-1, 2)


def fit(g, vt=None, **kw):
    vt = vt or ViewTransformer(CLICKED, MAP_CLICKED)
    return LeastChangeCorrector(**kw).fit(vt, CAM.project_ground(g), g, (0.0, 0.0))


@pytest.mark.parametrize("kw", [{}, {"map_sigma_m": 0.0}, {"point_sigma_m": 0.03, "click_sigma_px": 2.0}])
@pytest.mark.parametrize("g", [LINE_G, SPREAD_G], ids=["line", "spread"])
def test_same_optimum_as_scipy(g, kw):
    """scipy's Levenberg-Marquardt on the residuals (x, (g - f(x)) / point_sigma) from x = 0, with f from
    ViewTransformer, reaches the same corrected corners and objective."""
    c = fit(g, **kw)
    sigma = np.repeat([c.click_sigma_px, c.map_sigma_m], 8)
    z0 = np.concatenate([CLICKED.ravel(), MAP_CLICKED.ravel()])
    q = CAM.project_ground(g)

    def residuals(x):
        z = z0 + sigma * x
        f = ViewTransformer(z[:8].reshape(4, 2), z[8:].reshape(4, 2)).transform_points(q)
        return np.concatenate([x, (g - f).ravel() / c.point_sigma_m])

    ref = least_squares(residuals, np.zeros(16), method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    z = z0 + sigma * ref.x
    np.testing.assert_allclose(c.transformer_.source, z[:8].reshape(4, 2), atol=1e-5)
    np.testing.assert_allclose(c.transformer_.target, z[8:].reshape(4, 2), atol=1e-6)
    assert c.objective_final_ == pytest.approx(2 * ref.cost, rel=1e-8)
    assert c.objective_initial_ == pytest.approx(float(np.sum(residuals(np.zeros(16)) ** 2)), rel=1e-12)


@pytest.mark.parametrize("map_sigma_m", [0.0, 0.1])
def test_known_corner_perturbation_recovered_from_spread_points(map_sigma_m):
    """5 exact, well-spread points fix the homography: a pure corner error (2 px on TL) is undone everywhere."""
    vt = ViewTransformer(EXACT + [[2.0, -2.0], [0, 0], [0, 0], [0, 0]], GROUND)
    c = fit(SPREAD_G, vt, point_sigma_m=1e-5, map_sigma_m=map_sigma_m)
    before = np.abs(vt.transform_points(CAM.project_ground(TEST_G)) - TEST_G).max()
    assert before > 0.5
    np.testing.assert_allclose(c.transform_points(CAM.project_ground(TEST_G)), TEST_G, atol=1e-3)


@pytest.mark.parametrize("map_sigma_m", [0.0, 0.1])
def test_three_points_fitted_exactly(map_sigma_m):
    c = fit(LINE_G, point_sigma_m=1e-6, map_sigma_m=map_sigma_m)
    assert c.error_before_ > 0.1
    np.testing.assert_allclose(c.transform_points(CAM.project_ground(LINE_G)), LINE_G, atol=1e-6)
    if map_sigma_m == 0:
        np.testing.assert_array_equal(c.transformer_.target, MAP_CLICKED)


@pytest.mark.parametrize("source,target", [(CLICKED, MAP_CLICKED), (EXACT, GROUND * 10 + [400, 20])])
def test_analytic_jacobian_matches_central_differences(source, target):
    q = CAM.project_ground(np.vstack([SPREAD_G, TEST_G]))
    J = mapped_jacobian(source, target, q)
    h = 1e-6 * np.ptp(target, axis=0).max()  # homocal.uncertainty's map step
    np.testing.assert_allclose(J[:, :, :8], _quad_jacobian(source, target, q, 0, 1e-3), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(J[:, :, 8:], _quad_jacobian(source, target, q, 1, h), rtol=1e-6, atol=1e-7)
    assert np.abs(J).max() > 0.1


def test_gauss_newton_step_is_the_regularised_least_squares_solution():
    """x' minimises ||x'||^2 + ||b - J x'||^2 / s^2, b = r + J x: the stacked system [I; J / s] x' = [0; b / s]."""
    rng = np.random.default_rng(3)
    J, r, x, s = rng.normal(size=(6, 16)), rng.normal(size=6), rng.normal(size=16), 0.3
    stacked = np.vstack([np.eye(16), J / s])
    expected = np.linalg.lstsq(stacked, np.concatenate([np.zeros(16), (r + J @ x) / s]), rcond=None)[0]
    np.testing.assert_allclose(gauss_newton_step(x, J, r, s), expected, atol=1e-12)


def push_through_step(x, J, r, s):
    """The step as the earlier implementation formed it: J^T (J J^T + s^2 I)^-1 (r + J x), a (2N, 2N) solve."""
    return J.T @ np.linalg.solve(J @ J.T + s**2 * np.eye(len(r)), r + J @ x)


@pytest.mark.parametrize("rows", [6, 10, 40])
def test_normal_equations_step_equals_the_push_through_step(rows):
    rng = np.random.default_rng(rows)
    J, r, x, s = rng.normal(size=(rows, 16)), rng.normal(size=rows), rng.normal(size=16), 0.05
    np.testing.assert_allclose(gauss_newton_step(x, J, r, s), push_through_step(x, J, r, s), rtol=0, atol=1e-9)


@pytest.mark.parametrize("g", [LINE_G, SPREAD_G], ids=["line", "spread"])
def test_fit_equals_the_push_through_fit(monkeypatch, g):
    """The whole fit with the 16 x 16 normal equations ends where the (2N, 2N) push-through form ends, to 1e-6 px
    and 1e-6 m (the fit's stopping accuracy, ~1e-6 prior sigmas)."""
    ours = fit(g)
    monkeypatch.setattr(least_change, "gauss_newton_step", push_through_step)
    earlier = fit(g)
    np.testing.assert_allclose(ours.transformer_.source, earlier.transformer_.source, rtol=0, atol=1e-6)
    np.testing.assert_allclose(ours.transformer_.target, earlier.transformer_.target, rtol=0, atol=1e-6)
    assert ours.objective_final_ == pytest.approx(earlier.objective_final_, rel=1e-9, abs=1e-12)


def test_memory_is_linear_in_the_point_count():
    """20,000 reference points: the step's largest array is the (2N, 16) Jacobian, not a (2N, 2N) matrix."""
    import tracemalloc

    g = np.column_stack([np.tile(np.linspace(-6, 6, 100), 200), np.repeat(np.linspace(6, 50, 200), 100)])
    tracemalloc.start()
    c = fit(g)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert c.iterations_ >= 1 and peak < 200e6  # (2N, 2N) float64 would be 12.8 GB


def test_safeguard_halves_then_gives_up():
    x, step = np.zeros(2), np.array([8.0, 0.0])
    accept_below_3 = lambda c: None if c[0] > 3 else 1.0  # noqa: E731  full step and half refused, quarter accepted
    got = safeguarded_step(x, step, 2.0, accept_below_3)
    np.testing.assert_array_equal(got[0], [2.0, 0.0])
    assert got[1] == 1.0
    assert safeguarded_step(x, step, 0.5, accept_below_3) is None  # usable but Phi increased: refused
    assert safeguarded_step(x, step, 2.0, lambda c: None if c[0] > 0.4 else 1.0) is None  # 8/16 = 0.5: none left


def test_unusable_iterates_keep_the_clicked_quads(monkeypatch):
    """If every step is refused, the fit keeps x = 0: the clicked trapezoids, Phi unchanged."""
    monkeypatch.setattr(least_change, "predicted_points", lambda *a: None)
    c = fit(LINE_G)
    assert c.iterations_ == 0 and c.objective_final_ == c.objective_initial_
    np.testing.assert_array_equal(c.transformer_.source, CLICKED)
    np.testing.assert_array_equal(c.transformer_.target, MAP_CLICKED)


def test_wild_prior_stays_valid():
    """A huge click sigma and a reference point 3 m off: the full steps would break the quads; the safeguard keeps
    them valid, every reference point in front of the horizon and Phi below its start."""
    g = LINE_G.copy()
    c = LeastChangeCorrector(click_sigma_px=500.0, map_sigma_m=20.0, point_sigma_m=1e-4).fit(
        ViewTransformer(CLICKED, MAP_CLICKED), CAM.project_ground(g), g + [[0, 0], [3.0, 0], [0, -3.0]], (0.0, 0.0))
    assert np.isfinite(c.transformer_.transform_points(CAM.project_ground(g))).all()
    assert c.objective_final_ < c.objective_initial_


def test_save_load_round_trip(tmp_path):
    c = fit(LINE_G)
    c.save(tmp_path / "c.json")
    back = load_corrector(tmp_path / "c.json")
    assert isinstance(back, LeastChangeCorrector) and back.get_params() == c.get_params()
    q = CAM.project_ground(TEST_G)
    np.testing.assert_array_equal(back.transform_points(q), c.transform_points(q))
    np.testing.assert_array_equal(back.m, c.m)
    assert (back.iterations_, back.objective_final_) == (c.iterations_, c.objective_final_)


def _edited(edit):
    data = fit(LINE_G, map_sigma_m=0.0).to_dict()
    edit(data)
    return data


@pytest.mark.parametrize("edit,message", [
    (lambda d: d["params"].update(point_sigma_m=-0.1), "point_sigma_m must be a finite number > 0"),
    (lambda d: d["params"].update(map_sigma_m=math.nan), "map_sigma_m must be a finite number >= 0"),
    (lambda d: d["params"].update(iterations=0), "iterations must be an integer >= 1"),
    (lambda d: d["fitted"]["source"][0].__setitem__(0, math.nan), "field fitted.source/target"),
    (lambda d: d["fitted"].update(source=d["fitted"]["source"][:3]), "exactly 4 vertices"),
    (lambda d: d["fitted"].update(source=d["fitted"]["source"][::-1]), "goes round the other way"),
    (lambda d: d["fitted"]["target"][0].__setitem__(0, -3.3), "but map_sigma_m = 0"),
    (lambda d: d["fitted"].update(iterations=11), "fitted.iterations"),
    (lambda d: d["fitted"].update(objective_final=d["fitted"]["objective_initial"] + 1), "above objective_initial"),
    (lambda d: d["fitted"].update(objective_initial=math.inf), "finite number"),
], ids=["negative sigma", "nan sigma", "iterations", "nan corner", "3 corners", "reversed", "map moved",
        "too many iterations", "objective up", "inf objective"])
def test_hand_edited_json_refused(edit, message):
    with pytest.raises(ValueError, match="bad least-change correction") as e:
        Corrector.from_dict(_edited(edit), "c.json")
    assert message in str(e.value)


@pytest.mark.parametrize("kw,message", [
    ({"click_sigma_px": 0.0}, "click_sigma_px must be a finite number > 0"),
    ({"click_sigma_px": math.inf}, "click_sigma_px must be a finite number > 0"),
    ({"map_sigma_m": -0.1}, "map_sigma_m must be a finite number >= 0"),
    ({"point_sigma_m": 0}, "point_sigma_m must be a finite number > 0"),
    ({"point_sigma_m": "0.1"}, "point_sigma_m must be a finite number > 0"),
    ({"iterations": 2.5}, "iterations must be an integer >= 1"),
    ({"iterations": True}, "iterations must be an integer >= 1"),
])
def test_bad_parameters(kw, message):
    with pytest.raises(ValueError, match=message):
        LeastChangeCorrector(**kw)


@pytest.mark.parametrize("q,g,message", [
    (CAM.project_ground(LINE_G[:2]), LINE_G[:2], "need at least 3 reference points"),
    (np.vstack([CAM.project_ground(LINE_G[:2]), [[np.nan, 300.0]]]), LINE_G, r"image_points\[2\] is not finite"),
    (CAM.project_ground(LINE_G), LINE_G + [[0, 0], [0, 0], [np.nan, 0]], r"ground_points\[2\] is not finite"),
    (np.vstack([CAM.project_ground(LINE_G[:2]), [[640.0, 50.0]]]), LINE_G, "on or above the horizon"),
], ids=["two points", "nan image", "nan ground", "beyond horizon"])
def test_bad_calibration_input(q, g, message):
    with pytest.raises(ValueError, match=message):
        LeastChangeCorrector().fit(ViewTransformer(CLICKED, MAP_CLICKED), q, g, (0.0, 0.0))


def test_cli_summary_names_the_corner_moves(tmp_path, capsys):
    from homocal.cli import main
    (tmp_path / "t.json").write_text(json.dumps({"image": CLICKED.tolist(), "map": MAP_CLICKED.tolist()}))
    rows = np.column_stack([CAM.project_ground(LINE_G), LINE_G])
    (tmp_path / "r.csv").write_text("u,v,x,y\n" + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in rows))
    assert main(["fit", "--trapezoid", str(tmp_path / "t.json"), "--points", str(tmp_path / "r.csv"),
                 "--method", "least-change", "-o", str(tmp_path / "c.json")]) == 0
    c = fit(LINE_G)
    px, m = c.corner_moves()
    assert px > 0 and m > 0
    assert (f"the largest corner move is {px:.3f} px on the image and {m:.3f} m on the map "
            f"({c.iterations_} Gauss-Newton steps)") in capsys.readouterr().out
