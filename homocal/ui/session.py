"""What ``homocal ui`` serves: the camera frame, the site map with its scale and origin, the camera's ground
point, the folder Save writes to, the people's boxes the pedestrian correction fits from (a file named at launch,
never one a request names) and, for a simgen dataset, its hand-placed trapezoid and calibration objects."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from homocal.boxes import PersonBoxes, read_boxes, read_detections_table
from homocal.correctors.catalogue import DEFAULT_METHOD, METHODS
from homocal.correctors.hybrid import DEFAULT_THRESHOLD
from homocal.correctors.pedestrians import SETTINGS as PEDESTRIAN_SETTINGS
from homocal.correctors.pedestrians import PedestrianCorrector
from homocal.dataset import load_dataset
from homocal.geometry.lens import undistort_input
from homocal.geometry import Lens, SiteMap
from homocal.lens.lines import DEFAULT_HFOV_DEG, DEFAULT_TERMS
from homocal.lens.lines import TERMS as LENS_TERMS
from homocal.boxes import file_fps

VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm")


@dataclass
class Session:
    """The page's fixed inputs. Images are PNG bytes; sizes in pixels; camera_origin (2,) metres."""

    frame_png: bytes
    frame_size: tuple[int, int]
    map_png: bytes
    map_size: tuple[int, int]
    site_map: SiteMap
    camera_origin: np.ndarray
    out_dir: Path
    title: str
    dataset: dict | None = None  # {"hand_placed": {"image", "map"}, "calibration": [[u, v, x, y], ...]}
    boxes: Path | None = None  # the boxes file of --boxes (or a dataset's detections.parquet), resolved
    detectors: tuple[str, ...] = ()  # the detectors of a detections.parquet boxes file (the page picks one)
    camera_height_m: float | None = None  # the page's default camera height (a dataset's mount height)
    fps: float | None = None  # frames per second of the boxes' video (--fps, else its folder's): the watch's time
    lens: Lens | None = None  # the camera's lens (--camera-json, a dataset's camera.json); None: a pinhole's pixels
    camera_file: Path | None = None  # the file the lens came from (Save's command names it)
    lens_fit: dict | None = None  # the lens fitted on the page (Fit lens, Calibrate): {"files": {path: a JSON object
    # or bytes}, "command": the homocal lens command that writes the same LENS_FILE (camera_file) from them}; Save
    # and Save lens write its files
    written: dict[Path, tuple] = field(default_factory=dict)  # the identity (api._identity) of each file this
    # server wrote: Save replaces those without asking while they are still what it wrote
    boxes_read: dict[str | None, PersonBoxes] = field(default_factory=dict, repr=False)  # person_boxes' reads

    def person_boxes(self, detector: str | None) -> PersonBoxes:
        """The boxes of ``boxes`` (of ``detector`` for a detections.parquet), read once per session (read_boxes:
        checked against the lens, in the frame's pixels, where a box is tested for the frame's border before the
        fit or the watch undistorts it): every fit and save of the page fits from them."""
        if detector not in self.boxes_read:
            self.boxes_read[detector] = read_boxes(self.boxes, detector, self.lens, undistort=False)
        return self.boxes_read[detector]

    def info(self) -> dict:
        """The JSON the page starts from."""
        return {
            "title": self.title,
            "frame": {"width": self.frame_size[0], "height": self.frame_size[1]},
            "map": {"width": self.map_size[0], "height": self.map_size[1],
                    "scale_px_per_m": self.site_map.scale_px_per_m, "origin_px": list(self.site_map.origin_px)},
            "camera_origin": self.camera_origin.tolist(),
            "out_dir": str(self.out_dir),
            "dataset": self.dataset,
            "methods": [name for name, m in METHODS.items() if self.boxes is not None or m.evidence == "points"],
            "box_methods": [name for name, m in METHODS.items() if m.evidence == "boxes"],  # fitted from boxes
            "settings": {name: list(m.settings) for name, m in METHODS.items()},  # the page's fields per method
            "boxes": None if self.boxes is None else {"file": str(self.boxes), "detectors": list(self.detectors),
                                                      "camera_height_m": self.camera_height_m, "fps": self.fps},
            "box_settings": box_settings(),
            "default_method": DEFAULT_METHOD,
            "threshold": DEFAULT_THRESHOLD,
            "lens_terms": list(LENS_TERMS), "lens_defaults": {"terms": DEFAULT_TERMS, "hfov_deg": DEFAULT_HFOV_DEG},
        }


def box_settings() -> list[dict]:
    """The page's fields of a fit from boxes, one per PedestrianCorrector setting (its declaration: name, the id of
    its field (the flag without dashes), bounds (None: a yes-or-no setting, a checkbox), choices (a yes, no or auto
    setting, a list; None otherwise), unit, help, and its default; None: what none means)."""
    defaults = PedestrianCorrector().get_params()
    return [{"name": name, "id": opt.flag.lstrip("-"), "low": getattr(opt.kind, "low", None),  # None: yes or no
             "high": getattr(opt.kind, "high", None), "unit": opt.unit,
             "choices": list(opt.kind.choices) if getattr(opt.kind, "auto", False) else None,
             "help": opt.help, "default": defaults.get(name), "none": opt.none}
            for name, opt in PEDESTRIAN_SETTINGS.items()]


def from_files(frame: Path, site_map_image: Path, site_map: SiteMap, camera_origin, out_dir: Path,
               frame_index: int = 0, boxes: Path | None = None, fps: float | None = None) -> Session:
    """A session from a frame (an image, or a video's frame ``frame_index``) and a site-map image, with the
    boxes file ``boxes`` (homocal.read_boxes's three kinds) when given, at ``fps`` frames per second (None: the
    rate its folder says, homocal.boxes.file_fps, if any)."""
    frame_png, frame_size = read_frame(frame, frame_index)
    map_png, map_size = _png(cv2.imread(str(site_map_image), cv2.IMREAD_COLOR), site_map_image)
    session = Session(frame_png, frame_size, map_png, map_size, site_map, np.asarray(camera_origin, float),
                      _folder(out_dir), f"{frame.name} on {site_map_image.name}")
    if boxes is not None:
        session.boxes, session.detectors = _boxes_file(boxes)
        session.fps = fps if fps is not None else _folder_fps(session.boxes)
    return session


def _folder_fps(boxes: Path) -> float | None:
    """The frame rate the boxes file's folder says (file_fps), None if it says none or one out of (0, MAX_FPS]."""
    try:
        return file_fps(boxes)
    except ValueError:
        return None


def _boxes_file(path: Path) -> tuple[Path, tuple[str, ...]]:
    """The resolved boxes file and its detectors (a detections.parquet's, sorted; () otherwise); ValueError for a
    missing file or a Parquet file without a detector column."""
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    if path.suffix.lower() != ".parquet":
        return path.resolve(), ()
    names = read_detections_table(path, ["detector"]).column("detector").unique().to_pylist()
    return path.resolve(), tuple(sorted(names))


def from_dataset(path: Path, out_dir: Path, frame_index: int = 0, boxes: Path | None = None,
                 fps: float | None = None) -> Session:
    """A session from a simgen dataset folder (data_schema.md): video.mp4, site_map.png / .json,
    trapezoids.json (hand_placed), calibration.parquet (the detected foot points of the calibration objects),
    the boxes of detections.parquet (or of ``boxes``) and the camera's mount height."""
    ds = load_dataset(path)
    session = from_files(path / "video.mp4", path / "site_map.png", ds.site_map, ds.camera_origin, out_dir,
                         frame_index, path / "detections.parquet" if boxes is None else boxes, fps)
    session.camera_height_m = ds.camera.mount_height_m
    use_lens(session, ds.camera.lens, path / "camera.json")
    image, ground, _ = ds.calibration_points(source="segmentation")
    session.title = f"{ds.name} ({path})"
    session.dataset = {
        "hand_placed": {"image": ds.trapezoid_image.tolist(), "map": ds.trapezoid_map.tolist()},
        "calibration": np.column_stack([image, ground]).tolist(),
    }
    return session


def use_lens(session: Session, lens: Lens | None, camera_file: Path) -> None:
    """Give the session the camera's lens (an identity lens: none, the pixels are a pinhole's); ValueError if its
    image size is not the frame's. The boxes are read again through it."""
    if lens is not None and lens.image_size != session.frame_size:
        raise ValueError(f"{camera_file}: the lens's image size {list(lens.image_size)} differs from the frame's "
                         f"{list(session.frame_size)}")
    identity = lens is None or lens.is_identity
    session.lens, session.camera_file = (None, None) if identity else (lens, camera_file)
    session.boxes_read.clear()


def undistorted(session: Session, points: np.ndarray, name: str) -> np.ndarray:
    """Image points (N, 2) the page sends, in the frame's pixels -> the undistorted pixels every homography of
    the session maps (geometry.lens.undistort_input; as they are without a lens)."""
    return undistort_input(points, session.lens, name)


def to_frame(session: Session, points: np.ndarray) -> np.ndarray:
    """Undistorted pixels (N, 2) -> the frame's (the lens's distort_points; as they are without a lens): what the
    page draws."""
    return points if session.lens is None else session.lens.distort_points(points)


def read_frame(path: Path, index: int) -> tuple[bytes, tuple[int, int]]:
    """PNG bytes and (width, height) of an image file, or of frame ``index`` (0-based) of a video."""
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        return _png(cv2.imread(str(path), cv2.IMREAD_COLOR), path)
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise ValueError(f"{path}: cannot open the video")
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        if not 0 <= index < max(count, 1):
            raise ValueError(f"{path}: no frame {index} (the video has {count} frames, counted from 0)")
        capture.set(cv2.CAP_PROP_POS_FRAMES, index)
        ok, image = capture.read()
    finally:
        capture.release()
    return _png(image if ok else None, path)


def _png(image: np.ndarray | None, path: Path) -> tuple[bytes, tuple[int, int]]:
    if image is None:
        raise ValueError(f"{path}: not a readable image" if path.is_file() else f"{path}: no such file")
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"{path}: could not encode it as PNG")
    return data.tobytes(), (image.shape[1], image.shape[0])


def _folder(path: Path) -> Path:
    """The folder Save writes to, resolved: an existing folder, or a new one inside an existing folder (``homocal
    ui`` makes it when it starts: one new folder, never a chain of missing parents, so a typo in a parent's name
    is refused rather than built)."""
    if path.exists() and not path.is_dir():
        raise ValueError(f"{path}: exists and is not a folder")
    if not path.exists() and not path.resolve().parent.is_dir():
        raise ValueError(f"{path}: its parent folder {path.resolve().parent} does not exist (homocal ui makes one "
                         "new folder, not its parents)")
    return path.resolve()
