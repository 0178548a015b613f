"""homocal: homography ground-plane mapping, its error model and corrections (Szulc & Iwanowski).

The flat public API (supervision's style): geometry, the Section 3 error model, the Section 4
correctors (and the pedestrian correction with its box reader) and the dataset loader. The study lives in homocal.study.
Importing it loads nothing heavy: each public name (and each subpackage) is imported when first used (PEP 562's
module ``__getattr__``), numpy with the first of them; numba, pyarrow and OpenCV load where compiled code runs, a
Parquet file is read or an image is warped (benchmarks/bench_startup.py measures it).
"""
from importlib import import_module
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("homocal")  # pyproject.toml's version, the one source of both tools' --version
except PackageNotFoundError:  # a checkout on sys.path that pip never installed
    __version__ = "0+unknown"

_PUBLIC = {  # name -> the module it lives in: the flat public API, loaded on first use
    "Corrector": "homocal.correctors",
    "DescentCorrector": "homocal.correctors",
    "HorizonCorrector": "homocal.correctors",
    "HybridCorrector": "homocal.correctors",
    "LeastChangeCorrector": "homocal.correctors",
    "PedestrianCorrector": "homocal.correctors",
    "RegressionCorrector": "homocal.correctors",
    "load_corrector": "homocal.correctors",
    "PersonBoxes": "homocal.boxes",
    "read_boxes": "homocal.boxes",
    "Dataset": "homocal.dataset",
    "load_dataset": "homocal.dataset",
    "ColumnModel": "homocal.error_model",
    "column_model": "homocal.error_model",
    "first_order_error": "homocal.error_model",
    "horizon_shift": "homocal.error_model",
    "quadratic_error": "homocal.error_model",
    "Lens": "homocal.geometry",
    "PinholeCamera": "homocal.geometry",
    "SiteMap": "homocal.geometry",
    "ViewTransformer": "homocal.geometry",
    "box_bottom_points": "homocal.geometry",
    "homography_from_quads": "homocal.geometry",
    "validate_quad": "homocal.geometry",
    "ground_uncertainty": "homocal.uncertainty",
    "max_trustworthy_range": "homocal.uncertainty",
    "sigma_radius": "homocal.uncertainty",
    "OnlineCalibrator": "homocal.watch",
}

__all__ = ["__version__", *sorted(_PUBLIC)]


def __getattr__(name: str):
    """A public name from its module (_PUBLIC), or a subpackage such as ``homocal.study``, imported on first use."""
    if name in _PUBLIC:
        value = getattr(import_module(_PUBLIC[name]), name)
    elif not name.startswith("__"):
        try:
            value = import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as e:
            if e.name != f"{__name__}.{name}":
                raise
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
