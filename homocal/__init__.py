"""homocal: homography ground-plane mapping, its error model and corrections."""
from homocal.correctors import Corrector, DescentCorrector, HybridCorrector, RegressionCorrector, load_corrector
