"""The paper's correction methods (Section 4), the hybrid of Section 7, and beyond the paper the horizon
correction (Section 3's model fitted), regression with an intercept, the least-change trapezoid
correction and the pedestrian correction (no reference point: the camera's tilt from people's boxes); with JSON save/load, and their catalogue (each method's names, class and settings, once)."""
from homocal.correctors.base import MAX_REFERENCE_POINTS, Corrector, load_corrector
from homocal.correctors.descent import DescentCorrector, calibration_loss
from homocal.correctors.horizon import HorizonCorrector, fit_horizon_shift
from homocal.correctors.hybrid import HybridCorrector
from homocal.correctors.least_change import LeastChangeCorrector
from homocal.correctors.pedestrians import PedestrianCorrector
from homocal.correctors.regression import (
    RegressionCorrector,
    fit_quadratic_error,
    fit_quadratic_intercept,
    radial_correction,
)
from homocal.correctors.catalogue import DEFAULT_METHOD, METHODS, Method, get_method, method_of

__all__ = [
    "DEFAULT_METHOD",
    "MAX_REFERENCE_POINTS",
    "METHODS",
    "Corrector",
    "DescentCorrector",
    "HorizonCorrector",
    "HybridCorrector",
    "LeastChangeCorrector",
    "Method",
    "PedestrianCorrector",
    "RegressionCorrector",
    "calibration_loss",
    "fit_horizon_shift",
    "fit_quadratic_error",
    "fit_quadratic_intercept",
    "get_method",
    "load_corrector",
    "method_of",
    "radial_correction",
]
