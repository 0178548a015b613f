"""The study's inputs: its parameters (StudyParams) and one scene's calibration and test points (StudyScene)."""
from __future__ import annotations

import functools
from dataclasses import dataclass, fields

import numpy as np

from homocal.correctors.descent import DescentCorrector
from homocal.correctors.hybrid import DEFAULT_THRESHOLD
from homocal.correctors.least_change import LeastChangeCorrector
from homocal.dataset import CAMERA_POSE, EXACT, calibration_source, load_dataset
from homocal.geometry import SiteMap
from homocal.geometry.lens import undistort_input
from homocal.study.options import (DEFAULT_PRESET, Number, Parsed, Via, Words, declared_options, internal, option,
                                   preset_values)
from homocal.study.perturb import PERTURBATIONS, ShiftSpec, base_trapezoid, draw_base_error, draw_variant, perturbed_quads
from homocal.study.triples import distance_features, triples

METRICS = ("euclidean", "range")
LENS_MODES = ("ignore", "known")  # --lens: the datasets' lens distortion ignored (a pinhole's pixels) or removed
MAX_VARIANTS = 100_000  # 100x the paper's 1000 trapezoid variants per scene (one shard each)
MAX_N_TEST = 1_000_000  # test points per scene
MAX_MAP_SCALE = 1000.0  # px per metre: a 1 mm map pixel
MAX_IMAGE_WIDTH = 100_000.0  # px: 78x our datasets' 1280
MAX_DELTA_MAX = 100.0  # px: descent's largest move
MAX_SEED = 2**63 - 1  # a study's and advise's run seed


def descent_settings(delta_max: float) -> dict:
    """StudyParams.descent for a largest move delta_max (px): the phase-1 grid on TL and BR spans +/- delta_max / 2
    in 5 steps (the defaults: delta_max 8, grid -4..4 in 2 px steps); phase 2 as by default."""
    half = delta_max / 2
    return {**DESCENT_DEFAULTS, "delta_max": float(delta_max), "grid_offsets": (-half, -half / 2, 0.0, half / 2, half)}


DESCENT_DEFAULTS = {k: v for k, v in DescentCorrector().get_params().items() if k != "seed"}  # its seed is keyed per variant
DESCENT = Via(Number(0.0, MAX_DELTA_MAX, low_open=True), descent_settings, lambda d: d["delta_max"],
              lambda d: {**d, "grid_offsets": tuple(float(x) for x in d["grid_offsets"])},
              lambda d: {**d, "grid_offsets": list(d["grid_offsets"])})
SHIFT = Parsed(ShiftSpec, ShiftSpec.parse, "a number, normal:MU:SIGMA or uniform:A:B")


@dataclass(frozen=True)
class StudyParams:
    """Everything that determines a study's numbers (written to study.json by to_dict). Each field is a study
    option (its declaration: flag, bounds, unit, help, presets; homocal.study.options) or internal; a bad value
    is a ValueError naming the field (options.OptionError)."""

    seed: int = option(0, flag="--seed", kind=Number(0, MAX_SEED, integer=True), sweep=True,
                       help="run seed (variants, base errors, descent orders, test subsample)")
    n_variants: int = option(1000, flag="--variants", kind=Number(0, MAX_VARIANTS, integer=True), metavar="N",
                             presets={"quick": "50", "paper": "1000", "table1-fit": "1000"},
                             help="perturbed trapezoid variants per scene (one shard each)")
    foot_source: str = option(EXACT, flag="--foot-source", kind=Words(),
                              help="exact (projected contact points) or a detector of the datasets: segmentation, rgb, "
                                   "hog (if generated with it) or an imported one; its test points are its matched "
                                   "detections, the calibration points are then the segmentation detector's")
    n_test: int = option(2000, flag="--n-test", kind=Number(1, MAX_N_TEST, integer=True), metavar="N",
                         presets={"quick": "2000", "paper": "2000", "table1-fit": "2000"},
                         help="test points per scene, a seeded subsample of those the dataset has (all of them if it "
                              "has fewer)")
    max_test_distance: float | None = option(50.0, flag="--max-test-distance", kind=Number(0.0, low_open=True),
                                             unit="m", none="all test points", sweep=True, metavar="M",
                                             help="test points at most M metres from the camera (50: the paper's "
                                                  "operating range, Fig. 2)")
    test_lateral_max: float | None = option(None, flag="--test-lateral-max", kind=Number(0.0, low_open=True),
                                            unit="m", none="all test points", sweep=True, metavar="M",
                                            help="test points at most M metres to the side of the calibration line "
                                                 "x = 0")
    horizon_shift: ShiftSpec | None = option(None, flag="--horizon-shift", kind=SHIFT, unit="px", sweep=True,
                                             none="the hand-placed trapezoid as it is", metavar="SPEC",
                                             presets={"paper": "none", "table1-fit": "16"},
                                             help="the clicked trapezoid's systematic error: the hand-placed trapezoid "
                                                  "moved as a tilt error moves it, so that its horizon lies SPEC px "
                                                  "above the true one (positive: the mapping underestimates range); "
                                                  "SPEC is a number or a per-variant distribution normal:MU:SIGMA or "
                                                  "uniform:A:B (kept parsed as a perturb.ShiftSpec)")
    click_noise: float = option(0.0, flag="--click-noise", kind=Number(0.0, 100.0), unit="px", sweep=True, metavar="PX",
                                help="per-variant Gaussian noise (standard deviation) on the 8 clicked image coordinates")
    metric: str = option("euclidean", flag="--metric", kind=Words(METRICS), sweep=True,
                         presets={"paper": "range", "table1-fit": "range"},
                         help="the calibration and path errors the improvements are computed from: euclidean (ground "
                              "error ||p - g||) or range (| ||g - o|| - ||p - o|| |); the correctors are unchanged")
    map_scale: float | None = option(None, flag="--map-scale", kind=Number(0.0, MAX_MAP_SCALE, low_open=True),
                                     unit="px/m", none="the dataset's own site map", sweep=True, omit_default=True,
                                     metavar="PX_PER_M", presets={"paper": "none", "table1-fit": "1.5"},
                                     help="scale of the site map the paper's 0-3 px map perturbations are clicked on "
                                          "(the paper never gives its map's; our scenes' maps are 10 px/m)")
    image_width: float | None = option(None, flag="--image-width", kind=Number(0.0, MAX_IMAGE_WIDTH, low_open=True),
                                       unit="px", none="the dataset's own image", sweep=True, omit_default=True,
                                       metavar="PX",
                                       help="width of the camera image (same field of view) the paper's 0-3 px image "
                                            "perturbations are clicked on (the paper never gives its camera's "
                                            "resolution; ours are 1280 px); --horizon-shift, --click-noise and "
                                            "descent's moves stay in the dataset's px")
    perturbation: str = option("coordinate", flag="--perturbation", kind=Words(PERTURBATIONS), sweep=True,
                               omit_default=True, presets={"paper": "coordinate", "table1-fit": "variant-positive"},
                               help="how the paper's 'perturbation of 0, 1, 2, or 3 pixels ... to a randomly selected "
                                    "subset of 2 to 16 coordinate values' is read (perturb.draw_variant): coordinate "
                                    "(each chosen coordinate its own 0-3 px and sign), variant (one 0-3 px per variant, "
                                    "each coordinate its own sign) or variant-positive (one 0-3 px per variant, added to "
                                    "every chosen coordinate)")
    lens: str = option("ignore", flag="--lens", kind=Words(LENS_MODES), sweep=True, omit_default=True,
                       help="the datasets' lens (camera.json's distortion): known undistorts every image point (the "
                            "calibration and test points, the hand-placed trapezoid) with it before the corrections; "
                            "ignore maps the camera's pixels as a pinhole's, as the paper's pipeline does on a real lens")
    threshold: float = internal(DEFAULT_THRESHOLD, why="the hybrid's switch, fixed by the paper (Section 5.4)")
    descent: dict = option(default_factory=lambda: dict(DESCENT_DEFAULTS), flag="--descent-delta-max", kind=DESCENT,
                           unit="px", sweep=True, metavar="PX", presets={"table1-fit": "18"},
                           help="descent's largest move of a trapezoid coordinate (the paper's delta_max, which it "
                                "does not give); the phase-1 grid spans +/- half of it in 5 steps, the other settings "
                                "are DescentCorrector's defaults")
    least_change: dict = internal(default_factory=lambda: LeastChangeCorrector().get_params(),
                                  why="least change's settings: its library defaults")

    def __post_init__(self) -> None:
        for name, opt in OPTIONS.items():
            object.__setattr__(self, name, opt.check(name, getattr(self, name)))

    def to_dict(self) -> dict:
        """Every field, JSON-ready (study.json; what --resume compares); the options declared omit_default are
        left out at their defaults, so studies written before they existed keep their study keys and resume."""
        d = {}
        for f in fields(self):
            value, opt = getattr(self, f.name), f.metadata.get("option")
            if opt is None:
                d[f.name] = dict(value) if isinstance(value, dict) else value
            elif not (opt.omit_default and value == f.default):
                d[f.name] = opt.to_json(value)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "StudyParams":
        """The inverse of to_dict (unknown keys are ignored: study.json holds more)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


OPTIONS = declared_options(StudyParams)  # {field name: its options.Option}, in field order


def option_text(name: str, value) -> str:
    """A StudyParams field's value as the study option that sets it: option_text("n_variants", 50) ->
    "--variants 50", ("map_scale", None) -> "--map-scale none", ("descent", {...}) -> "--descent-delta-max 14"."""
    return f"{OPTIONS[name].flag} {OPTIONS[name].to_text(value)}"


def changed_options(params: StudyParams, base: StudyParams, names: tuple[str, ...] = tuple(OPTIONS)) -> list[str]:
    """The study options among names (all by default; in declaration order; as option_text) whose values in
    params differ from base's as their flags give them."""
    return [option_text(n, getattr(params, n)) for n in OPTIONS
            if n in names and option_text(n, getattr(params, n)) != option_text(n, getattr(base, n))]


def preset_params(preset: str, **values) -> StudyParams:
    """StudyParams of the preset (options.PRESETS), with values on top."""
    return StudyParams(**{**preset_values(StudyParams, preset), **values})


def options_label(params: StudyParams) -> str:
    """The study options of params that differ from homocal study's defaults (its quick preset), as a command
    line gives them; "(defaults)" if none."""
    return " ".join(changed_options(params, preset_params(DEFAULT_PRESET))) or "(defaults)"


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
        """The variant's clicked base image trapezoid (4, 2) px (perturb.base_trapezoid): the hand-placed one, its
        horizon put the variant's horizon shift above the true one if params has a horizon shift, plus the
        variant's click noise; the hand-placed one itself by default."""
        eps, noise = draw_base_error(params.seed, self.name, variant, params.horizon_shift, params.click_noise)
        return base_trapezoid(self.image_quad, self.site_map.to_metres(self.map_quad), self.K, self.true_horizon_row, eps, noise)

    @functools.cached_property
    def distance_features(self) -> tuple[np.ndarray, np.ndarray]:
        """(d_sum, d_spread) (S,) float32 of every triple (triples.distance_features)."""
        return distance_features(self.distance, self.triples)

    @classmethod
    def from_dataset(cls, path, params: StudyParams) -> "StudyScene":
        """Load a dataset folder; calibration points from the exact or segmentation foot points (a detector's
        test points use segmentation calibration points, the only detector calibration objects carry)."""
        ds = load_dataset(path)
        if ds.moving:
            raise ValueError(f"{path}: its camera moves ({CAMERA_POSE}): the study's trapezoid and test points need a "
                             "camera that stays still")
        cal_image, cal_ground, distance = ds.calibration_points(calibration_source(params.foot_source))
        if len(cal_image) < 3:
            raise ValueError(f"{path}: need at least 3 calibration points, got {len(cal_image)}")
        test_image, test_ground = ds.test_points(params.foot_source, n=params.n_test, seed=params.seed,
                                                  max_distance=params.max_test_distance,
                                                  max_lateral=params.test_lateral_max)
        lens = ds.camera.lens if params.lens == "known" else None  # ignore: the camera's pixels as a pinhole's
        cal_image, test_image, image_quad = (undistort_input(q, lens, f"{path}: {what}") for q, what in (
            (cal_image, "calibration points"), (test_image, "test points"), (ds.trapezoid_image, "hand-placed trapezoid")))
        return cls(ds.name, ds.site_map, image_quad, ds.trapezoid_map, np.asarray(ds.camera_origin, float),
                   cal_image, cal_ground, distance, test_image, test_ground, triples(len(cal_image)),
                   ds.camera.K, ds.camera.horizon_row,
                   float(ds.camera.image_size[0]), str(ds.manifest.get("config_hash", "")))

