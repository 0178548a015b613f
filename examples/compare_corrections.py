"""Compare the corrections on random trapezoid errors of the paper's camera (1280x720, 95 deg, 4 m, 15 deg).

Each sample: the exact trapezoid (ground 7 m x 22 m, 8-30 m ahead) with a tilt-like error of its top corners'
rows (up to +/-10 px) plus 0-3 px on every coordinate; three reference points at 10, 20 and 35 m straight
ahead; the path error is the mean error over a 7 x 23 grid (x -6..6 m, y 6..50 m). Also measured: a second
horizon parameter (a row scale about the horizon, which changes K of eq. (7)), fitted by Gauss-Newton from the
one-parameter fit. Run:  python examples/compare_corrections.py [samples, default 300]  (about 3 minutes on
2 shared cores, most of it descent)
"""
import sys

import numpy as np

from homocal import DescentCorrector, HorizonCorrector, PinholeCamera, RegressionCorrector, ViewTransformer
from homocal.geometry import apply_homography

CAM = PinholeCamera()
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])
REF_G = np.array([[0.0, 10.0], [0.0, 20.0], [0.0, 35.0]])
TEST_G = np.stack(np.meshgrid(np.linspace(-6, 6, 7), np.linspace(6, 50, 23)), -1).reshape(-1, 2)


def two_parameter_horizon(vt, eps0):
    """(eps, k) minimising the squared calibration residuals of q -> H(u, v_h + (1 + k)(v - v_h) + eps)."""
    def mapped(p, q):
        v_h = vt.horizon_row(q[:, 0])
        return apply_homography(vt.m, np.column_stack([q[:, 0], v_h + (1 + p[1]) * (q[:, 1] - v_h) + p[0]]))

    ref_q = CAM.project_ground(REF_G)
    p = np.array([eps0, 0.0])
    for _ in range(20):
        r = (mapped(p, ref_q) - REF_G).ravel()
        J = np.column_stack([((mapped(p + h, ref_q) - mapped(p - h, ref_q)) / 2e-7).ravel() for h in np.eye(2) * 1e-7])
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        if not np.isfinite(mapped(p + step, ref_q)).all():
            break
        p = p + step
    return lambda q: mapped(p, q)


def main(samples: int) -> None:
    rng = np.random.default_rng(1)
    ref_q, test_q = CAM.project_ground(REF_G), CAM.project_ground(TEST_G)
    methods = {
        "regression": lambda vt: RegressionCorrector().fit(vt, ref_q, REF_G, (0, 0)).transform_points,
        "regression-signed": lambda vt: RegressionCorrector(signed=True).fit(vt, ref_q, REF_G, (0, 0)).transform_points,
        "regression-intercept": lambda vt: RegressionCorrector(signed=True, intercept=True).fit(
            vt, ref_q, REF_G, (0, 0)).transform_points,
        "horizon": lambda vt: HorizonCorrector().fit(vt, ref_q, REF_G, (0, 0)).transform_points,
        "horizon, 2 parameters": lambda vt: two_parameter_horizon(
            vt, HorizonCorrector().fit(vt, ref_q, REF_G, (0, 0)).horizon_shift_),
        "descent": lambda vt: DescentCorrector().fit(vt, ref_q, REF_G, (0, 0)).transform_points,
    }
    improvement = {name: [] for name in methods}
    for _ in range(samples):
        offsets = rng.uniform(-3, 3, (4, 2))
        offsets[:2, 1] += rng.choice([-1, 1]) * rng.uniform(0, 10)
        vt = ViewTransformer(CAM.project_ground(GROUND) + offsets, GROUND)
        before = np.linalg.norm(vt.transform_points(test_q) - TEST_G, axis=1).mean()
        for name, fit in methods.items():
            after = np.linalg.norm(fit(vt)(test_q) - TEST_G, axis=1).mean()
            improvement[name].append(100 * (before - after) / before)
    print(f"path improvement over {samples} samples: median, 1st percentile, positive share")
    for name, imp in improvement.items():
        imp = np.array(imp)
        print(f"  {name:22s} {np.median(imp):6.1f} %  {np.percentile(imp, 1):7.1f} %  {100 * np.mean(imp > 0):5.1f} %")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 300)
