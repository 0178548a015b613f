"""The paper's correction methods (Section 4) and the hybrid of Section 7, with JSON save/load."""
from homocal.correctors.base import Corrector, load_corrector
from homocal.correctors.descent import DescentCorrector, calibration_loss
from homocal.correctors.hybrid import HybridCorrector
from homocal.correctors.regression import RegressionCorrector, fit_quadratic_error, radial_correction

__all__ = [
    "Corrector",
    "DescentCorrector",
    "HybridCorrector",
    "RegressionCorrector",
    "calibration_loss",
    "fit_quadratic_error",
    "load_corrector",
    "radial_correction",
]
