"""The shared base of the correctors: calibration input checks, errors before/after, JSON save/load.

Every corrector is fitted from calibration pairs (paper Section 4: three reference measurements, or more)::

    corrector.fit(transformer, image_points, ground_points, camera_origin)
    corrector.transform_points(image_points)   # corrected ground positions (N, 2)
    corrector.calibration_improvement_         # percent, 100 (E_before - E_after) / E_before

and saved to / loaded from a JSON file (format in ``homocal.correctors.serialization``).
"""
from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from homocal.correctors.serialization import (
    FORMAT,
    FORMAT_VERSION,
    float_or_none,
    number,
)
from homocal.files import read_json, write_text_atomic
from homocal.geometry import CameraModel, Lens, ViewTransformer, as_points, check_magnitude
from homocal.uncertainty import ground_uncertainty

MAX_REFERENCE_POINTS = 100_000  # calibration pairs a fit takes (fit, advise and the page refuse more)

def mean_error(points: np.ndarray, ground_points: np.ndarray) -> float:
    """Mean Euclidean distance between (N, 2) points and their (N, 2) ground truth (mean of eq. (18))."""
    return float(np.mean(np.linalg.norm(points - ground_points, axis=1)))


def improvement_percent(error_before: float, error_after: float) -> float:
    """Calibration improvement 100 (E_before - E_after) / E_before, percent; NaN if E_before == 0."""
    return math.nan if error_before == 0 else 100.0 * (error_before - error_after) / error_before


def check_camera_origin(camera_origin) -> np.ndarray:
    """The ground point under the camera as (2,) float64; ValueError for another shape or a non-finite value."""
    o = np.asarray(camera_origin, dtype=np.float64)
    if o.shape != (2,) or not np.isfinite(o).all():
        raise ValueError(f"camera_origin: expected 2 finite numbers, got {np.asarray(camera_origin).tolist()}")
    return o


def check_calibration(
    transformer: ViewTransformer, image_points: np.ndarray, ground_points: np.ndarray, camera_origin: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validate calibration input; return q (N, 2) px, p = transformer(q) (N, 2), g (N, 2), o (2,), float64.

    Raises ValueError naming the problem: fewer than 3 or more than MAX_REFERENCE_POINTS pairs, mismatched shapes, a NaN/inf or a coordinate
    beyond +/-1e9 (with the point's index), two pairs with the same image point or the same ground point (they
    would count twice), or an image point on or above the horizon of the transformer (it maps to NaN).
    Warns (UserWarning) for a ground point behind the camera (y < camera_origin y: homocal's y axis points
    forward), which is usually a sign error.
    """
    if not isinstance(transformer, ViewTransformer):
        raise TypeError(f"transformer: expected a homocal.ViewTransformer, got {type(transformer).__name__}")
    q = as_points(image_points, "image_points")
    g = as_points(ground_points, "ground_points")
    o = check_camera_origin(camera_origin)
    if len(q) != len(g):
        raise ValueError(f"image_points has {len(q)} points but ground_points has {len(g)}")
    if len(q) < 3:
        raise ValueError(f"need at least 3 reference points, got {len(q)}")
    if len(q) > MAX_REFERENCE_POINTS:
        raise ValueError(f"image_points: at most {MAX_REFERENCE_POINTS:,} reference points, got {len(q):,}")
    for name, arr in (("image_points", q), ("ground_points", g)):
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
        if bad.size:
            raise ValueError(f"{name}[{bad[0]}] is not finite: {arr[bad[0]].tolist()}")
        check_magnitude(arr, name)
        _, first, inverse, counts = np.unique(arr, axis=0, return_index=True, return_inverse=True, return_counts=True)
        repeated = np.flatnonzero(counts > 1)
        if repeated.size:  # the first point measured twice, and its first repeat
            i, j = np.flatnonzero(inverse.ravel() == repeated[np.argmin(first[repeated])])[:2]
            raise ValueError(f"{name}[{i}] and {name}[{j}] are the same point {arr[i].tolist()}: "
                             "each reference point must be measured once")
    for i in np.flatnonzero(g[:, 1] < o[1]):
        warnings.warn(f"ground_points[{i}] = {g[i].tolist()} is behind the camera (y < {o[1]:g}, the camera "
                      "origin's y; y points forward): a sign error?", UserWarning, stacklevel=3)
    p = transformer.transform_points(q)
    bad = np.flatnonzero(np.isnan(p).any(axis=1))
    if bad.size:
        raise ValueError(
            f"image_points[{bad[0]}] = {q[bad[0]].tolist()} is on or above the horizon of the trapezoid mapping "
            "(it maps to no ground point)"
        )
    return q, p, g, o


class Corrector:
    """Base of the correctors. Subclasses set ``method`` (the JSON "method" key) and ``param_names`` (their
    constructor arguments) and implement ``_fit``, ``_transform``, ``_fitted_state`` and ``_set_fitted_state``.

    Image points are pixels of the undistorted image (a pinhole's). ``lens_``, the camera's Lens when the caller
    set it (homocal fit: --camera-json's), travels with the saved correction so that homocal apply undistorts
    the feet it is given (``Lens.undistort_points``) before ``transform_points``; None: a pinhole's pixels.

    Attributes after fit (or load):
        base_transformer_: the ViewTransformer being corrected.
        camera_origin_: (2,) camera ground point, target units.
        error_before_, error_after_: mean Euclidean calibration error of the mapped / corrected points.
        calibration_improvement_: 100 (error_before_ - error_after_) / error_before_, percent (NaN if 0 before).
    """

    method: ClassVar[str]
    param_names: ClassVar[tuple[str, ...]]
    _registry: ClassVar[dict[str, type[Corrector]]] = {}
    lens_: Lens | None = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        Corrector._registry[cls.method] = cls

    # ---- fitting and applying ---------------------------------------------------------------
    def fit(
        self, transformer: ViewTransformer, image_points: np.ndarray, ground_points: np.ndarray, camera_origin
    ) -> Corrector:
        """Fit from N >= 3 calibration pairs.

        Args:
            transformer: the image-to-ground ViewTransformer to correct.
            image_points: (N, 2) image foot points of the calibration objects, pixels.
            ground_points: (N, 2) their true ground positions, the transformer's target units (metres).
            camera_origin: (2,) ground point under the camera, same units.
        Returns self.
        """
        q, p, g, o = check_calibration(transformer, image_points, ground_points, camera_origin)
        self.base_transformer_ = transformer
        self.camera_origin_ = o
        self.error_before_ = mean_error(p, g)
        self._fit(q, p, g)
        self.error_after_ = mean_error(self._transform(q), g)
        self.calibration_improvement_ = improvement_percent(self.error_before_, self.error_after_)
        return self

    def transform_points(self, image_points: np.ndarray) -> np.ndarray:
        """Corrected ground positions (N, 2) float64 of image points (N, 2) or (N, 1, 2), pixels.

        Points on or above the horizon give NaN.
        """
        if not hasattr(self, "calibration_improvement_"):
            raise RuntimeError(f"{type(self).__name__} is not fitted: call fit() or load() first")
        return self._transform(as_points(image_points, "image_points"))

    @property
    def mapping(self) -> ViewTransformer:
        """The trapezoid mapping the fitted correction maps with: its own ``transformer_`` (descent, horizon,
        least change, pedestrians), the clicked one otherwise (the regressions, whose radial correction is
        applied after it)."""
        return getattr(self, "transformer_", self.base_transformer_)

    def ground_uncertainty(self, image_points: np.ndarray, click_sigma_px: float = 1.5, point_sigma_px: float = 1.0,
                           map_sigma_px: float = 0.0) -> np.ndarray:
        """First-order covariance (N, 2, 2), target units squared (metres^2), of the corrected ground positions of
        image points (N, 2) px: the correction's own error model. Here ``homocal.ground_uncertainty`` of
        ``mapping`` (the paper's eq. (1): click_sigma_px on each of its image corner coordinates, map_sigma_px on
        each map corner coordinate in target units, point_sigma_px on the point); a method that knows more of
        its own error (PedestrianCorrector: its fitted horizon's) adds it. With ``lens_`` the image sigmas are on the
        camera's distorted frame, propagated through the lens (ground_uncertainty's lens). NaN on or above the
        horizon."""
        return ground_uncertainty(self.mapping, image_points, click_sigma_px, point_sigma_px, map_sigma_px, self.lens_)

    def _fit(self, q: np.ndarray, p: np.ndarray, g: np.ndarray) -> None:
        """Fit from validated image points q, their mapping p and ground truth g, all (N, 2)."""
        raise NotImplementedError

    def _transform(self, q: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _fitted_state(self) -> dict:
        raise NotImplementedError

    def _set_fitted_state(self, state: dict) -> None:
        raise NotImplementedError

    def get_params(self) -> dict:
        """The constructor arguments."""
        return {name: getattr(self, name) for name in self.param_names}

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    # ---- JSON -----------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Everything needed to apply the correction later, as a JSON-ready dict (see serialization.py)."""
        if not hasattr(self, "calibration_improvement_"):
            raise RuntimeError(f"{type(self).__name__} is not fitted: nothing to save")
        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "method": self.method,
            "params": self.get_params(),
            "transformer": {
                "source": self.base_transformer_.source.tolist(),
                "target": self.base_transformer_.target.tolist(),
            },
            "camera_origin": self.camera_origin_.tolist(),
            "error_before": self.error_before_,
            "error_after": self.error_after_,
            "calibration_improvement": float_or_none(self.calibration_improvement_),
            "fitted": self._fitted_state(),
            **({} if self.lens_ is None else {"lens": self.lens_.to_dict()}),
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n"

    def save(self, path: str | Path) -> None:
        """Write the JSON to path (through a temporary file and a rename)."""
        write_text_atomic(path, self.to_json())

    @classmethod
    def from_dict(cls, data: dict, where: str = "correction") -> Corrector:
        """Rebuild a fitted corrector from ``to_dict`` output. On ``Corrector`` it dispatches on "method";
        on a subclass, a file of another method is a ValueError. Bad content: ValueError naming ``where``."""
        if data.get("format") != FORMAT:
            raise ValueError(f"{where}: not a homocal correction (format is {data.get('format')!r}, not {FORMAT!r})")
        if data.get("format_version") != FORMAT_VERSION:
            raise ValueError(f"{where}: unsupported format_version {data.get('format_version')!r} (expected 1)")
        method = data.get("method")
        if not isinstance(method, str) or method not in Corrector._registry:
            raise ValueError(f"{where}: unknown method {method!r} (known: {', '.join(Corrector._registry)})")
        target_cls = Corrector._registry[method]
        if cls is not Corrector and target_cls is not cls:
            raise ValueError(f"{where}: holds a {method!r} correction, not {cls.method!r}")
        try:
            obj = target_cls._from_fields(data)
        except (KeyError, TypeError, ValueError) as e:
            detail = f"missing key {e}" if isinstance(e, KeyError) else str(e)
            raise ValueError(f"{where}: bad {method} correction ({detail})") from None
        return obj

    @classmethod
    def _from_fields(cls, data: dict) -> Corrector:
        """The corrector of a file's fields, each checked against what fit could have produced (ValueError
        "field NAME: ..." otherwise): the constructor's checks of params, valid quads, finite numbers, errors
        >= 0, the improvement that follows from them, and the method's own fitted state (_set_fitted_state)."""
        if not isinstance(data["params"], dict):
            raise ValueError(f"field params: expected an object, got {data['params']!r}")
        try:
            obj = cls(**data["params"])
        except (TypeError, ValueError) as e:
            raise ValueError(f"field params: {e}") from None
        try:
            obj.base_transformer_ = ViewTransformer(data["transformer"]["source"], data["transformer"]["target"])
        except (TypeError, ValueError) as e:
            raise ValueError(f"field transformer: {e}") from None
        try:
            obj.camera_origin_ = np.array(data["camera_origin"], dtype=np.float64)
        except (TypeError, ValueError):
            obj.camera_origin_ = np.full(1, np.nan)
        if obj.camera_origin_.shape != (2,) or not np.isfinite(obj.camera_origin_).all():
            raise ValueError(f"field camera_origin: must be 2 finite numbers, got {data['camera_origin']!r}")
        obj.error_before_ = number(data["error_before"], "error_before", minimum=0)
        obj.error_after_ = number(data["error_after"], "error_after", minimum=0)
        expected = improvement_percent(obj.error_before_, obj.error_after_)
        stored = data["calibration_improvement"]
        if math.isnan(expected):
            consistent = stored is None
        else:
            consistent = stored is not None and abs(number(stored, "calibration_improvement") - expected) <= 1e-6
        if not consistent:
            raise ValueError(f"field calibration_improvement: {stored!r} does not follow from error_before and "
                             f"error_after ({float_or_none(expected)!r})")
        obj.calibration_improvement_ = expected
        if not isinstance(data["fitted"], dict):
            raise ValueError(f"field fitted: expected an object, got {data['fitted']!r}")
        obj._set_fitted_state(data["fitted"])
        if data.get("lens") is not None:  # files before the lens have none: a pinhole's pixels
            try:
                obj.lens_ = CameraModel.from_dict(data["lens"]).lens.check_folds()
            except (AttributeError, TypeError, ValueError) as e:
                raise ValueError(f"field lens: {e if isinstance(e, ValueError) else 'expected K, distortion, image_size'}") from None
        return obj

    @classmethod
    def from_json(cls, text: str, where: str = "correction") -> Corrector:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as e:
            raise ValueError(f"{where}: not JSON ({e})") from None
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a JSON object")
        return cls.from_dict(data, where)

    @classmethod
    def load(cls, path: str | Path) -> Corrector:
        """Read a correction JSON file (see ``from_dict``)."""
        return cls.from_dict(read_json(path), str(path))


def load_corrector(path: str | Path) -> Corrector:
    """Load a correction JSON file of any method (dispatches on its "method" key)."""
    return Corrector.load(path)
