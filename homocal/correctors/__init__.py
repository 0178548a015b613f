"""The paper's correction methods (Section 4), the hybrid of Section 7, and beyond the paper the horizon
correction (Section 3's model fitted), regression with an intercept and the least-change trapezoid
correction; with JSON save/load."""
from homocal.correctors.base import Corrector, load_corrector
from homocal.correctors.descent import DescentCorrector, calibration_loss
from homocal.correctors.horizon import HorizonCorrector, fit_horizon_shift
from homocal.correctors.hybrid import HybridCorrector
from homocal.correctors.least_change import LeastChangeCorrector
from homocal.correctors.regression import (
    RegressionCorrector,
    fit_quadratic_error,
    fit_quadratic_intercept,
    radial_correction,
)

__all__ = [
    "Corrector",
    "DescentCorrector",
    "HorizonCorrector",
    "HybridCorrector",
    "LeastChangeCorrector",
    "RegressionCorrector",
    "calibration_loss",
    "fit_horizon_shift",
    "fit_quadratic_error",
    "fit_quadratic_intercept",
    "load_corrector",
    "radial_correction",
]
