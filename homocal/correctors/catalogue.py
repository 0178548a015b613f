"""The catalogue of correction methods: each method declared once, and read by fit, apply, advise, the page
(and the study, through ``STUDY_COLUMNS``).

An entry names the method everywhere it appears: ``name`` (``homocal fit --method``, ``homocal advise
--method``, the page's method list), ``column`` (the study's kernel and shard columns ``cal_<column>``,
``path_<column>``; None for a method the study's triple kernels do not run), the JSON "method" key (the
class's ``Corrector.method``; several entries may share one class, told apart by ``fixed``), the class,
the constructor arguments a user may set (``settings``: fit's flags, the page's fields), what it is fitted
from (``evidence``: "points", reference points u,v,x,y; "boxes", people's boxes), a one-line description and
the note fit prints after its summary. To add a method: write its Corrector subclass and add
one ``Method`` to ``CATALOGUE``; with a study column, its kernel too (homocal.study.kernels.column_kernel).

>>> METHODS["regression-signed"].make()
RegressionCorrector(signed=True, intercept=False)
>>> METHODS["descent"].make(seed=3).seed
3
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

from homocal.correctors.base import Corrector
from homocal.correctors.descent import DescentCorrector
from homocal.correctors.horizon import HorizonCorrector
from homocal.correctors.hybrid import HybridCorrector
from homocal.correctors.least_change import LeastChangeCorrector
from homocal.correctors.pedestrians import SETTINGS as PEDESTRIAN_SETTINGS
from homocal.correctors.pedestrians import PedestrianCorrector
from homocal.correctors.regression import RegressionCorrector


def _regression_note(c: RegressionCorrector) -> str:
    note = " (fallback of lower order: the reference distances are nearly equal)" if c.degenerate_ else ""
    constant = f" {'-' if c.c_ < 0 else '+'} {abs(c.c_):.6g}" if c.intercept else ""
    return f" Error law e(d) = {c.a_:.6g} d^2 + {c.b_:.6g} d{constant}{note}."


def _horizon_note(c: HorizonCorrector) -> str:
    eps = c.horizon_shift_
    return (f" Horizon shift epsilon = {eps:.3f} px (the clicked trapezoid's horizon lies that far below the "
            f"fitted one; corrected trapezoid: the clicked one moved {eps:.3f} px up).")


def _least_change_note(c: LeastChangeCorrector) -> str:
    px, m = c.corner_moves()
    return (f" Least change: the largest corner move is {px:.3f} px on the image and {m:.3f} m on the map "
            f"({c.iterations_} Gauss-Newton steps).")


def _descent_note(c: DescentCorrector) -> str:
    return f" Descent used {c.evaluations_} phase-2 evaluations."


def _hybrid_note(c: HybridCorrector) -> str:
    relation = ">=" if c.chosen_ == "regression" else "<"
    return (f" The hybrid chose {c.chosen_}: regression's improvement {c.regression_.calibration_improvement_:.1f} % "
            f"{relation} threshold {c.threshold:g} %.")


def _pedestrians_note(c: PedestrianCorrector) -> str:
    hidden = {"dropped": f", {c.n_hidden_} with feet a nearer person may hide" + (
                  f" (left out: with them {c.first_refusal_})" if c.first_refusal_ else ""),
              "no frames": ", none looked at for hidden feet (--drop-hidden-feet auto: no frames)",
              "kept": ", none left out for hidden feet (--drop-hidden-feet auto: the fit with every box passed the "
                      "outlier check)"
              if c.drop_hidden_feet == "auto" else ""}[c.hidden_feet_]
    margin = f" (each less a {c.box_margin_px:g} px box margin)" if c.box_margin_px else ""
    return (f" Boxes: {c.n_boxes_} read{margin}, {c.n_border_} cut by the image border{hidden}, {c.n_outliers_} outliers; people "
            f"(tracks): {c.n_people_used_} of {c.n_people_} used. Horizon row {c.horizon_row_:.2f} +- "
            f"{c.horizon_sigma_px_:.2f} px (1 sigma: the people's {c.horizon_sigma_people_px_:.2f} px and "
            f"{c.mean_sensitivity_px_per_cm_:.2f} px per cm of the prior mean's {100 * c.height_mean_sigma_m:g} cm; "
            f"clicked {c.clicked_horizon_row_:.2f}).")


@dataclass(frozen=True)
class Method:
    """One correction method (see the module docstring).

    name: fit's, advise's and the page's name. column: the study's column suffix, or None. corrector: the
    class. fixed: constructor arguments that make this method of the class. settings: constructor arguments
    a user may set. evidence: "points" (fit(transformer, image_points, ground_points, camera_origin)) or
    "boxes" (fit(transformer, xyxy, ...): PedestrianCorrector.fit). description: one line. note: corrector ->
    the sentence fit prints after its summary.
    """

    name: str
    column: str | None
    corrector: type[Corrector]
    description: str
    fixed: dict = field(default_factory=dict)
    settings: tuple[str, ...] = ()
    evidence: str = "points"
    note: Callable[[Corrector], str] = lambda corrector: ""

    @property
    def json_method(self) -> str:
        """The "method" key of its correction files."""
        return self.corrector.method

    def make(self, **settings) -> Corrector:
        """An unfitted corrector with the given settings (None: the class's default); ValueError naming a setting
        this method does not take, or the constructor's complaint about a value."""
        unknown = sorted(set(settings) - set(self.settings))
        if unknown:
            raise ValueError(f"{', '.join(unknown)}: not a setting of {self.name} "
                             f"(its settings: {', '.join(self.settings) or 'none'})")
        return self.corrector(**self.fixed, **{k: v for k, v in settings.items() if v is not None})

    def describes(self, corrector: Corrector) -> bool:
        """True if ``corrector`` (fitted, loaded or not) is this method."""
        return type(corrector) is self.corrector and all(getattr(corrector, k) == v for k, v in self.fixed.items())


LEAST_CHANGE_PRIORS = ("click_sigma_px", "map_sigma_m", "point_sigma_m")
CATALOGUE = (  # the study's columns in its order, then the methods it does not run
    Method("regression", "regression", RegressionCorrector, "the paper's regression (Section 4.1): unsigned "
           "errors, a d^2 + b d clamped to a, b >= 0", {"signed": False, "intercept": False}, note=_regression_note),
    Method("regression-signed", "regression_signed", RegressionCorrector, "regression of the signed range error "
           "(also corrects overestimated range)", {"signed": True, "intercept": False}, note=_regression_note),
    Method("regression-intercept", "regression_intercept", RegressionCorrector, "signed regression with an "
           "intercept, a d^2 + b d + c", {"signed": True, "intercept": True}, note=_regression_note),
    Method("horizon", "horizon", HorizonCorrector, "fits the horizon shift of Section 3's error model",
           note=_horizon_note),
    Method("least-change", "least_change", LeastChangeCorrector, "the smallest move of the clicked image and map "
           "corners that explains the reference points", settings=LEAST_CHANGE_PRIORS, note=_least_change_note),
    Method("descent", "descent", DescentCorrector, "the paper's gradient descent on the image corners "
           "(Section 4.2)", settings=("seed",), note=_descent_note),
    Method("hybrid", "hybrid", HybridCorrector, "regression if its calibration improvement reaches the threshold, "
           "descent otherwise (Section 7)", settings=("threshold", "seed"), note=_hybrid_note),
    Method("pedestrians", None, PedestrianCorrector, "beyond the paper: the camera's tilt from people's boxes and "
           "their height distribution, with no reference point (docs/pedestrians.md)",
           settings=tuple(k for k in PEDESTRIAN_SETTINGS if k in PedestrianCorrector.param_names), evidence="boxes", note=_pedestrians_note),
)
METHODS: dict[str, Method] = {m.name: m for m in CATALOGUE}
DEFAULT_METHOD = "least-change"  # fit's, advise's and the page's default: near the best in every study setting
STUDY_COLUMNS = tuple(m.column for m in CATALOGUE if m.column is not None)  # the study's kernels.METHODS


def get_method(name: object, parameter: str = "method") -> Method:
    """The catalogue entry called ``name``; ValueError naming ``parameter`` otherwise."""
    if not isinstance(name, str) or name not in METHODS:
        raise ValueError(f"{parameter}: expected one of {', '.join(METHODS)}, got {name!r}")
    return METHODS[name]


def method_of(corrector: Corrector) -> Method:
    """The catalogue entry of a corrector (fitted, loaded or not); ValueError if it has none."""
    for method in CATALOGUE:
        if method.describes(corrector):
            return method
    raise ValueError(f"{corrector!r} is not a method of the catalogue")


def label(corrector: Corrector) -> str:
    """The method's name, with the hybrid's choice: ``"hybrid (descent)"``."""
    chosen = getattr(corrector, "chosen_", None)
    return method_of(corrector).name + (f" ({chosen})" if chosen else "")


def quality(corrector: Corrector) -> str:
    """The fitted corrector's calibration errors before and after, one phrase (metres, percent); for a method
    fitted from boxes, on its check points (or that it had none)."""
    check = " on the check points, which the fit did not use" if method_of(corrector).evidence == "boxes" else ""
    if math.isnan(corrector.error_before_):
        return "no check points (no calibration error measured)"
    return (f"mean calibration error {corrector.error_before_:.3f} m before, {corrector.error_after_:.3f} m after "
            f"(improvement {corrector.calibration_improvement_:.1f} %){check}")


def fit_note(corrector: Corrector) -> str:
    """The sentence fit prints after ``quality``: the method's own fitted numbers ("" if it has none)."""
    return method_of(corrector).note(corrector)

