"""The hybrid strategy of the paper's Discussion (Section 7): regression when it fits the calibration
points well, gradient descent otherwise."""
from __future__ import annotations

import numpy as np

from homocal.correctors.base import Corrector
from homocal.correctors.descent import DescentCorrector
from homocal.correctors.regression import RegressionCorrector
from homocal.geometry import ViewTransformer

DEFAULT_THRESHOLD = 75.0  # percent: the paper's (Section 7)


class HybridCorrector(Corrector):
    """Fit both methods; keep regression if its calibration improvement is >= threshold (percent), else descent.

    A NaN regression improvement (zero error before correction) fails the test, so descent is kept.

    Args:
        threshold: percent (DEFAULT_THRESHOLD, the paper's 75).
        signed: passed to RegressionCorrector.
        **descent_params: passed to DescentCorrector (delta_max, grid_offsets, initial_step, min_step,
            max_evals, seed).
    Attributes after fit: regression_, descent_ (the fitted correctors), chosen_ ("regression" or
    "descent"); calibration_improvement_, error_before_, error_after_ are the chosen one's.
    """

    method = "hybrid"
    param_names = ("threshold", "signed", *DescentCorrector.param_names)

    def __init__(self, threshold: float = DEFAULT_THRESHOLD, signed: bool = False, **descent_params) -> None:
        self.threshold = float(threshold)
        self.signed = RegressionCorrector(signed=signed).signed
        for name, value in DescentCorrector(**descent_params).get_params().items():
            setattr(self, name, value)

    def _fit(self, q: np.ndarray, p: np.ndarray, g: np.ndarray) -> None:
        calibration = (self.base_transformer_, q, g, self.camera_origin_)
        self.regression_ = RegressionCorrector(signed=self.signed).fit(*calibration)
        descent_params = {name: getattr(self, name) for name in DescentCorrector.param_names}
        self.descent_ = DescentCorrector(**descent_params).fit(*calibration)
        self.chosen_ = "regression" if self.regression_.calibration_improvement_ >= self.threshold else "descent"

    @property
    def chosen(self) -> Corrector:
        """The fitted corrector the threshold chose (regression_ or descent_)."""
        return self.regression_ if self.chosen_ == "regression" else self.descent_

    @property
    def mapping(self) -> ViewTransformer:
        """The chosen corrector's mapping."""
        return self.chosen.mapping

    def _transform(self, q: np.ndarray) -> np.ndarray:
        return self.chosen.transform_points(q)

    def _fitted_state(self) -> dict:
        return {"chosen": self.chosen_, "regression": self.regression_.to_dict(), "descent": self.descent_.to_dict()}

    def _set_fitted_state(self, state: dict) -> None:
        """Check what fit could have produced: both corrections valid, with the hybrid's params and trapezoid,
        and the choice the threshold makes."""
        self.regression_ = RegressionCorrector.from_dict(state["regression"], "field fitted.regression")
        self.descent_ = DescentCorrector.from_dict(state["descent"], "field fitted.descent")
        for name, sub in (("regression", self.regression_), ("descent", self.descent_)):
            if any(getattr(self, k) != v for k, v in sub.get_params().items() if k in self.param_names):
                raise ValueError(f"field fitted.{name}.params: {sub.get_params()} differ from the hybrid's params")
            if not (np.array_equal(sub.base_transformer_.source, self.base_transformer_.source)
                    and np.array_equal(sub.base_transformer_.target, self.base_transformer_.target)):
                raise ValueError(f"field fitted.{name}.transformer: not the hybrid's trapezoid")
        expected = "regression" if self.regression_.calibration_improvement_ >= self.threshold else "descent"
        if state["chosen"] != expected:
            improvement = self.regression_.calibration_improvement_
            raise ValueError(f"field fitted.chosen: {state['chosen']!r}, but the threshold {self.threshold:g} % and "
                             f"regression's improvement {improvement:.6g} % choose {expected!r}")
        self.chosen_ = expected
