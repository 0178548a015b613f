"""The study's inputs: its parameters (StudyParams) and one scene's calibration and test points (StudyScene)."""
from __future__ import annotations

import functools
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from homocal.correctors.descent import DescentCorrector
from homocal.correctors.hybrid import DEFAULT_THRESHOLD
from homocal.correctors.least_change import LeastChangeCorrector
from homocal.dataset import EXACT, calibration_source, load_dataset
from homocal.geometry import SiteMap, ViewTransformer
from homocal.study.perturb import ShiftSpec, base_quad, check_reading, draw_base_error, draw_variant, perturbed_quads
from homocal.study.triples import distance_features, triples

METRICS = ("euclidean", "range")
MAX_MAP_SCALE = 1000.0  # px per metre: a 1 mm map pixel
MAX_IMAGE_WIDTH = 100_000.0  # px: 78x our datasets' 1280


@dataclass(frozen=True)
class StudyParams:
    """Everything that determines a study's numbers (written to study.json by to_dict).

    horizon_shift: None (the hand-placed trapezoid as it is) or the clicked trapezoid's systematic error, a
    ShiftSpec string: its horizon is put that many px above the true one (positive: the mapping
    underestimates range). click_noise: standard deviation (px) of Gaussian noise on its 8 image coordinates.
    metric: "euclidean" (ground error ||p - g||) or "range" (| ||g - o|| - ||p - o|| |) for the calibration
    and path errors the improvements are computed from (the correctors themselves are unchanged).
    test_lateral_max: test points at most this many metres to the side of the calibration line x = o_x.
    map_scale: the scale (px per metre) of the site map the paper's 0-3 px map perturbations are clicked on
    (the paper never gives its map's scale); None: the dataset's own site map (10 px/m in our scenes).
    image_width: the width (px) of the camera image, of the same field of view, the paper's 0-3 px image
    perturbations are clicked on (the paper never gives its camera's resolution); None: the dataset's own image
    (1280 px in our scenes). Only those perturbations scale: horizon_shift, click_noise and descent's moves
    stay in px of the dataset's image.
    perturbation: how the paper's 0-3 px perturbation of 2-16 coordinates is read (perturb.draw_variant):
    "coordinate" (each its own size and sign), "variant" (one size per variant, each its own sign) or
    "variant-positive" (one size per variant, all +).
    """

    seed: int = 0
    n_variants: int = 1000
    foot_source: str = EXACT  # "exact", "segmentation" or another detector's name
    n_test: int = 2000
    max_test_distance: float | None = 50.0  # metres from the camera; the paper's operating range (Fig. 2); None: all
    test_lateral_max: float | None = None
    horizon_shift: str | None = None
    click_noise: float = 0.0
    metric: str = "euclidean"
    map_scale: float | None = None
    image_width: float | None = None
    perturbation: str = "coordinate"
    threshold: float = DEFAULT_THRESHOLD
    descent: dict = field(default_factory=lambda: {  # DescentCorrector's defaults (its seed is keyed per variant)
        k: v for k, v in DescentCorrector().get_params().items() if k != "seed"})
    least_change: dict = field(default_factory=lambda: LeastChangeCorrector().get_params())  # its defaults

    def __post_init__(self) -> None:
        if self.horizon_shift is not None:
            object.__setattr__(self, "horizon_shift", str(ShiftSpec.parse(self.horizon_shift)))  # one spelling
        grid = tuple(float(x) for x in self.descent["grid_offsets"])
        object.__setattr__(self, "descent", {**self.descent, "grid_offsets": grid})
        check_reading(self.perturbation)
        if self.metric not in METRICS:
            raise ValueError(f"--metric {self.metric!r}: expected one of {', '.join(METRICS)}")
        if not (isinstance(self.click_noise, (int, float)) and 0 <= self.click_noise <= 100):
            raise ValueError(f"--click-noise {self.click_noise!r}: expected a number of pixels in [0, 100]")
        if not isinstance(self.seed, int) or not 0 <= self.seed < 2**63:
            raise ValueError(f"--seed {self.seed!r}: expected an integer in [0, 2**63)")
        for name in ("max_test_distance", "test_lateral_max"):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, (int, float)) and 0 < value < float("inf")):
                raise ValueError(f"--{name.replace('_', '-')} {value!r}: expected a positive number of metres or none")
        scale = self.map_scale
        if scale is not None and not (isinstance(scale, (int, float)) and 0 < scale <= MAX_MAP_SCALE):
            raise ValueError(f"--map-scale {self.map_scale!r}: expected px per metre in (0, {MAX_MAP_SCALE:g}] or none")
        width = self.image_width
        if width is not None and not (isinstance(width, (int, float)) and 0 < width <= MAX_IMAGE_WIDTH):
            raise ValueError(f"--image-width {width!r}: expected px in (0, {MAX_IMAGE_WIDTH:g}] or none")

    def to_dict(self) -> dict:
        """Every field, JSON-ready (study.json; what --resume compares). map_scale, image_width and perturbation
        are left out at their defaults, so studies written before they existed keep their study keys and resume."""
        d = asdict(self)
        defaults = {f.name: f.default for f in fields(self)}
        for name in ("map_scale", "image_width", "perturbation"):
            if d[name] == defaults[name]:
                del d[name]
        d["descent"]["grid_offsets"] = list(d["descent"]["grid_offsets"])
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "StudyParams":
        """The inverse of to_dict (unknown keys are ignored: study.json holds more)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


OPTIONS = ("n_variants", "foot_source", "n_test", "max_test_distance", "test_lateral_max", "horizon_shift",
           "click_noise", "metric", "map_scale", "image_width", "perturbation", "seed", "descent")  # the StudyParams fields a study option sets


def option_text(name: str, value) -> str:
    """A StudyParams field's value as the study option that sets it: option_text("n_variants", 50) ->
    "--variants 50", ("map_scale", None) -> "--map-scale none", ("descent", {...}) -> "--descent-delta-max 14"."""
    if name == "descent":
        name, value = "descent_delta_max", value["delta_max"]
    flag = "--variants" if name == "n_variants" else "--" + name.replace("_", "-")
    return f"{flag} {'none' if value is None else f'{value:g}' if isinstance(value, (int, float)) else value}"


def changed_options(params: StudyParams, base: StudyParams, names: tuple[str, ...] = OPTIONS) -> list[str]:
    """The study options among names (OPTIONS by default, in its order; as option_text) whose values in params
    differ from base's."""
    return [option_text(n, getattr(params, n)) for n in OPTIONS
            if n in names and (getattr(params, n)["delta_max"] != getattr(base, n)["delta_max"] if n == "descent"
                               else getattr(params, n) != getattr(base, n))]


def options_label(params: StudyParams) -> str:
    """The study options of params that differ from homocal study's defaults (its quick preset, 50 variants), as a
    command line gives them; "(defaults)" if none."""
    return " ".join(changed_options(params, StudyParams(n_variants=50))) or "(defaults)"


def descent_settings(delta_max: float) -> dict:
    """StudyParams.descent for a largest move delta_max (px): the phase-1 grid on TL and BR spans +/- delta_max / 2
    in 5 steps (the defaults: delta_max 8, grid -4..4 in 2 px steps); phase 2 as by default."""
    if not 0 < delta_max <= 100:
        raise ValueError(f"--descent-delta-max must be in (0, 100] px, got {delta_max}")
    half = delta_max / 2
    return {**StudyParams().descent, "delta_max": float(delta_max), "grid_offsets": (-half, -half / 2, 0.0, half / 2, half)}


@dataclass
class StudyScene:
    """A scene's study inputs: hand-placed quads (4, 2), calibration q (M, 2) px, g (M, 2) m, distance (M,) m,
    test points (N, 2) px and (N, 2) m, camera origin (2,) m, the triples (S, 3), the intrinsics K (3, 3), the
    true horizon row (px) and the image width (px; NaN where there is no camera image, as in advise)."""

    name: str
    site_map: SiteMap
    image_quad: np.ndarray
    map_quad: np.ndarray
    origin: np.ndarray
    cal_image: np.ndarray
    cal_ground: np.ndarray
    distance: np.ndarray
    test_image: np.ndarray
    test_ground: np.ndarray
    triples: np.ndarray
    K: np.ndarray
    true_horizon_row: float
    image_width: float = float("nan")
    config_hash: str = ""

    @functools.cached_property
    def horizon_row(self) -> float:
        """Horizon row (px) of the hand-placed trapezoid's mapping at the principal column."""
        return float(ViewTransformer(self.image_quad, self.site_map.to_metres(self.map_quad)).horizon_row(self.K[0, 2]))

    def variant_offsets(self, params: StudyParams, variant: int) -> tuple[np.ndarray, int]:
        """(offsets (16,), n_perturbed) of the variant (perturb.draw_variant, as params.perturbation reads it) in px
        of this scene's image and site map: its 8 image offsets drawn in px of an image params.image_width px wide
        (this one's by default), its 8 map offsets in px of a site map of params.map_scale px/m (this one's by
        default)."""
        offsets, n = draw_variant(params.seed, self.name, variant, params.perturbation)
        if params.image_width is not None:
            offsets[:8] *= self.image_width / params.image_width
        if params.map_scale is not None:
            offsets[8:] *= self.site_map.scale_px_per_m / params.map_scale
        return offsets, n

    def variant_quads(self, params: StudyParams, variant: int) -> tuple[np.ndarray, np.ndarray]:
        """The variant's (image (4, 2) px, map (4, 2) map px) quads: its base image quad and the hand-placed map
        quad, moved by its offsets (variant_offsets)."""
        offsets, _ = self.variant_offsets(params, variant)
        return perturbed_quads(self.base_image_quad(params, variant), self.map_quad, offsets)

    def base_image_quad(self, params: StudyParams, variant: int) -> np.ndarray:
        """The variant's clicked base image trapezoid (4, 2) px (perturb.base_quad): the hand-placed one, its
        horizon put the variant's horizon shift above the true one if params has a horizon shift, plus the
        variant's click noise; the hand-placed one itself by default."""
        eps, noise = draw_base_error(params.seed, self.name, variant, shift_spec(params), params.click_noise)
        return base_quad(self.image_quad, self.K, self.horizon_row, self.true_horizon_row, eps, noise)

    @functools.cached_property
    def distance_features(self) -> tuple[np.ndarray, np.ndarray]:
        """(d_sum, d_spread) (S,) float32 of every triple (triples.distance_features)."""
        return distance_features(self.distance, self.triples)

    @classmethod
    def from_dataset(cls, path, params: StudyParams) -> "StudyScene":
        """Load a dataset folder; calibration points from the exact or segmentation foot points (a detector's
        test points use segmentation calibration points, the only detector calibration objects carry)."""
        ds = load_dataset(path)
        cal_image, cal_ground, distance = ds.calibration_points(calibration_source(params.foot_source))
        if len(cal_image) < 3:
            raise ValueError(f"{path}: need at least 3 calibration points, got {len(cal_image)}")
        test_image, test_ground = ds.test_points(params.foot_source, n=params.n_test, seed=params.seed,
                                                  max_distance=params.max_test_distance,
                                                  max_lateral=params.test_lateral_max)
        return cls(ds.name, ds.site_map, ds.trapezoid_image, ds.trapezoid_map, np.asarray(ds.camera_origin, float),
                   cal_image, cal_ground, distance, test_image, test_ground, triples(len(cal_image)),
                   np.asarray(ds.camera["K"], dtype=np.float64), float(ds.camera["horizon_row"]),
                   float(ds.camera["width"]), str(ds.manifest.get("config_hash", "")))


def shift_spec(params: StudyParams) -> ShiftSpec | None:
    """The study's horizon-shift spec, None if it has none."""
    return None if params.horizon_shift is None else ShiftSpec.parse(params.horizon_shift)
