"""homocal: homography ground-plane mapping, its error model and corrections (Szulc & Iwanowski).

The flat public API (supervision's style): geometry, the Section 3 error model, the Section 4
correctors (and the pedestrian correction with its box reader) and the dataset loader. The study lives in homocal.study.
"""
from homocal.correctors import (
    Corrector,
    DescentCorrector,
    HorizonCorrector,
    HybridCorrector,
    LeastChangeCorrector,
    PedestrianCorrector,
    RegressionCorrector,
    load_corrector,
)
from homocal.boxes import PersonBoxes, read_boxes
from homocal.dataset import Dataset, load_dataset
from homocal.error_model import ColumnModel, column_model, first_order_error, horizon_shift, quadratic_error
from homocal.geometry import (
    Lens,
    PinholeCamera,
    SiteMap,
    ViewTransformer,
    box_bottom_points,
    homography_from_quads,
    validate_quad,
)
from homocal.uncertainty import ground_uncertainty, max_trustworthy_range, sigma_radius

__all__ = [
    "ColumnModel",
    "Corrector",
    "Dataset",
    "DescentCorrector",
    "HorizonCorrector",
    "HybridCorrector",
    "LeastChangeCorrector",
    "Lens",
    "PedestrianCorrector",
    "PersonBoxes",
    "PinholeCamera",
    "RegressionCorrector",
    "SiteMap",
    "ViewTransformer",
    "box_bottom_points",
    "column_model",
    "first_order_error",
    "ground_uncertainty",
    "homography_from_quads",
    "horizon_shift",
    "load_corrector",
    "load_dataset",
    "max_trustworthy_range",
    "quadratic_error",
    "read_boxes",
    "sigma_radius",
    "validate_quad",
]
