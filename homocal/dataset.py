"""Reading a simgen dataset folder through data_schema.md only (homocal never imports simgen or mujoco)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from homocal.files import read_json
from homocal.geometry import CameraModel, SiteMap, read_camera, validate_quad
from homocal.geometry.camera_file import UNIT_LINE_TOL
from homocal.names import check_name

EXACT = "exact"
SEGMENTATION = "segmentation"
CALIBRATION_SOURCES = (EXACT, SEGMENTATION)  # calibration objects are detected by the segmentation detector only
REQUIRED_COLUMNS = {
    "gt.parquet": ["t", "agent_id", "x", "y", "u", "v", "in_frame"],
    "detections.parquet": ["detector", "frame", "agent_id", "u", "v", "gt_x", "gt_y"],
    "calibration.parquet": ["index", "distance_m", "x", "y", "u", "v", "u_exact", "v_exact"],
}

CAMERA_POSE = "camera_pose.parquet"  # the camera's pose per ground-truth step, in a dataset whose camera moves
POSE_COLUMNS = ("t", "step", "tilt_deg", "roll_deg", "yaw_deg", "horizon_a", "horizon_b", "horizon_c")  # CAMERA_POSE's
POSE_TIME_TOL_S = 1e-6  # camera_pose.parquet's t is step * gt_dt within this (s): far below a 50 ms step


@dataclass(frozen=True)
class PoseTrack:
    """camera_pose.parquet (data_schema.md): a moving camera's pose at each ground-truth step, read-only arrays.

    Attributes:
        t: (N,) s, step * gt_dt. step: (N,) int64, 0 .. N - 1, N the manifest's steps_total.
        tilt_deg, roll_deg, yaw_deg: (N,) degrees, camera.json's angles plus the moves' changes.
        horizon: (N, 3) lines (a, b, c) of the undistorted image, a u + b v + c = 0, hypot(a, b) = 1, positive on
            the ground side (as camera.json's horizon).
    """

    t: np.ndarray
    step: np.ndarray
    tilt_deg: np.ndarray
    roll_deg: np.ndarray
    yaw_deg: np.ndarray
    horizon: np.ndarray

    def __post_init__(self) -> None:
        for key in ("t", "step", "tilt_deg", "roll_deg", "yaw_deg", "horizon"):
            getattr(self, key).flags.writeable = False

    def horizon_rows(self, u: float) -> np.ndarray:
        """The horizon's row (N,) px at column u of the undistorted image: -(a u + c) / b."""
        a, b, c = self.horizon.T
        return -(a * u + c) / b


@dataclass(frozen=True)
class Dataset:
    """One simgen dataset: the scene's calibration set, its trapezoids and its test trajectories.

    Attributes:
        path: the dataset folder. name: the scene name (manifest.json's "scene", else the folder's name;
            names.check_name: it becomes part of paths).
        camera: camera.json (read_camera; it has K and camera_origin). camera_origin: (2,) world metres.
        site_map: scale and origin of the site map.
        trapezoid_image: (4, 2) hand-placed image trapezoid, px (TL, TR, BR, BL).
        trapezoid_map: (4, 2) hand-placed site-map trapezoid, map px.
        trapezoids: trapezoids.json as a dict (hand-placed and exact).
        pose: camera_pose.parquet's pose track (read_pose_track), None for a static camera (no such file).
    """

    path: Path
    name: str
    manifest: dict
    camera: CameraModel
    camera_origin: np.ndarray
    site_map: SiteMap
    trapezoid_image: np.ndarray
    trapezoid_map: np.ndarray
    trapezoids: dict
    pose: PoseTrack | None = None

    @property
    def moving(self) -> bool:
        """Whether the camera moves during the recording (simgen writes CAMERA_POSE only then, data_schema.md)."""
        return self.pose is not None

    def calibration_points(self, source: str = EXACT) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Calibration objects in index order: image (M, 2) px, ground (M, 2) m, distance (M,) m.

        source "exact" takes the exact projection of each contact point, "segmentation" the foot point the
        segmentation detector found (the only detector calibration objects carry); anything else is a
        ValueError (``calibration_source`` gives the source that goes with a study's foot source).
        """
        if source not in CALIBRATION_SOURCES:
            raise ValueError(f"{self.path}: calibration points come from {' or '.join(map(repr, CALIBRATION_SOURCES))}, "
                             f"not {source!r} (calibration objects are detected by the segmentation detector only)")
        table = self.table("calibration.parquet")
        cols = ("u_exact", "v_exact") if source == EXACT else ("u", "v")
        image = _columns(table, cols)
        ground = _columns(table, ("x", "y"))
        distance = table.column("distance_m").to_numpy().astype(np.float64)
        bad = ~np.isfinite(np.column_stack([image, ground, distance])).all(axis=1)
        if bad.any():
            raise ValueError(f"{self.path}: calibration objects {np.flatnonzero(bad).tolist()} have no {source} foot point "
                             "or no finite ground position and distance")
        return image, ground, distance

    def test_points(
        self, source: str = EXACT, n: int | None = None, seed: int = 0, max_distance: float | None = None,
        max_lateral: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Test trajectory points: image (N, 2) px and true ground (N, 2) m, optionally only those whose true
        distance from the camera origin is at most max_distance (m) and whose lateral distance |x - o_x| from
        the line straight ahead of the camera (where the calibration objects stand) is at most max_lateral
        (m), then a seeded subsample of n.

        source "exact": the exact projections (u, v) of in-frame agents' contact points (gt.parquet);
        a detector name: that detector's detections matched to an agent (detections.parquet, with the
        temporally nearest ground truth gt_x, gt_y).
        """
        if source == EXACT:
            table = self.table("gt.parquet")
            table = table.filter(table.column("in_frame"))
            image, ground = _columns(table, ("u", "v")), _columns(table, ("x", "y"))
        else:
            table = self.table("detections.parquet")
            detectors = set(table.column("detector").unique().to_pylist())
            if source not in detectors:
                raise ValueError(f"{self.path}: no detections from detector {source!r} (have {sorted(detectors)})")
            import pyarrow.compute as pc  # pyarrow loads where a Parquet file is read (a cheap ``import homocal``)

            table = table.filter(pc.and_(pc.equal(table.column("detector"), source), pc.greater_equal(table.column("agent_id"), 0)))
            image, ground = _columns(table, ("u", "v")), _columns(table, ("gt_x", "gt_y"))
        keep = np.isfinite(image).all(axis=1) & np.isfinite(ground).all(axis=1)
        if max_distance is not None:
            keep &= np.hypot(*(ground - self.camera_origin).T) <= max_distance
        if max_lateral is not None:
            keep &= np.abs(ground[:, 0] - self.camera_origin[0]) <= max_lateral
        image, ground = image[keep], ground[keep]
        if len(image) == 0:
            limits = [f"within {max_distance} m" if max_distance else "", f"within {max_lateral} m of x = 0" if max_lateral else ""]
            raise ValueError(f"{self.path}: no {source} test points {' and '.join(x for x in limits if x)}".rstrip())
        if n is not None and n < len(image):
            pick = np.sort(np.random.default_rng(seed).choice(len(image), size=n, replace=False))
            image, ground = image[pick], ground[pick]
        return image, ground

    def table(self, filename: str):
        """A Parquet table of the dataset (its columns were checked by load_dataset)."""
        import pyarrow.parquet as pq

        return _parquet(pq.read_table, self.path / filename)


def calibration_source(foot_source: str) -> str:
    """The calibration foot points that go with test points of ``foot_source``: exact with "exact", the
    segmentation detector's with any detector's (calibration objects carry no other detector's)."""
    return EXACT if foot_source == EXACT else SEGMENTATION


def load_dataset(path: str | Path) -> Dataset:
    """Open a dataset folder; ValueError naming the missing file, key or column, or an incomplete run."""
    path = Path(path)
    if not path.is_dir():
        raise ValueError(f"{path}: not a dataset folder")
    manifest = read_json(path / "manifest.json")
    if not manifest.get("complete", False):
        raise ValueError(f"{path}: the run is not complete (manifest.json complete = false); finish it with simgen generate --resume")
    camera = read_camera(path / "camera.json")
    missing = [key for key in ("K", "camera_origin") if getattr(camera, key) is None]
    if missing:
        raise ValueError(f"{path / 'camera.json'}: missing key {missing[0]} (a dataset's camera.json has K and camera_origin)")
    trapezoids = read_json(path / "trapezoids.json")
    try:
        hand = trapezoids["hand_placed"]
        image = validate_quad(np.asarray(hand["image"], dtype=np.float64), f"{path}/trapezoids.json hand_placed.image")
        site_map_quad = validate_quad(np.asarray(hand["map"], dtype=np.float64), f"{path}/trapezoids.json hand_placed.map")
    except KeyError as e:
        raise ValueError(f"{path}: missing key {e} in trapezoids.json") from None
    if not (path / "site_map.json").is_file():
        raise ValueError(f"{path}: missing site_map.json")
    dataset = Dataset(
        path=path,
        name=check_name(manifest.get("scene", path.name), f"{path / 'manifest.json'}: scene"),
        manifest=manifest,
        camera=camera,
        camera_origin=camera.camera_origin,
        site_map=SiteMap.from_json(path / "site_map.json"),
        trapezoid_image=image,
        trapezoid_map=site_map_quad,
        trapezoids=trapezoids,
        pose=read_pose_track(path / CAMERA_POSE, manifest) if (path / CAMERA_POSE).is_file() else None,
    )
    import pyarrow.parquet as pq

    for filename, columns in REQUIRED_COLUMNS.items():
        if not (path / filename).is_file():
            raise ValueError(f"{path}: missing {filename}")
        missing = [c for c in columns if c not in _parquet(pq.read_schema, path / filename).names]
        if missing:
            raise ValueError(f"{path / filename}: missing column(s) {', '.join(missing)}")
    return dataset


def read_pose_track(file: Path, manifest: dict) -> PoseTrack:
    """camera_pose.parquet as a PoseTrack; ValueError naming the file and the problem: a missing column, not one row
    per step of the run (manifest.json's steps_total), t not step * gt_dt, an angle or line that is not finite, a
    line whose (a, b) is not a unit vector."""
    import pyarrow.parquet as pq

    meta = _parquet(pq.read_metadata, file)  # the row count before reading: the table is no longer than the run
    missing = [c for c in POSE_COLUMNS if c not in meta.schema.names]
    if missing:
        raise ValueError(f"{file}: missing column(s) {', '.join(missing)}")
    n = manifest.get("steps_total")
    table = _parquet(pq.read_table, file) if isinstance(n, int) and meta.num_rows == n else None
    step = None if table is None else table.column("step").to_numpy(zero_copy_only=False)
    if step is None or not np.array_equal(step, np.arange(n)):
        raise ValueError(f"{file}: needs one row per ground-truth step 0 .. steps_total - 1 in order "
                         f"(manifest.json steps_total {n!r}), got {meta.num_rows} rows")
    columns = {c: table.column(c).to_numpy(zero_copy_only=False).astype(np.float64)
               for c in POSE_COLUMNS if c != "step"}
    bad = [c for c, x in columns.items() if not np.isfinite(x).all()]
    if bad:
        raise ValueError(f"{file}: column {bad[0]} has a value that is not a finite number (or a null)")
    dt = manifest.get("gt_dt")
    if not isinstance(dt, (int, float)) or np.abs(columns["t"] - step * dt).max() > POSE_TIME_TOL_S:
        raise ValueError(f"{file}: t must be step * gt_dt (manifest.json gt_dt {dt!r}) within {POSE_TIME_TOL_S:g} s")
    horizon = np.column_stack([columns["horizon_a"], columns["horizon_b"], columns["horizon_c"]])
    if np.abs(np.hypot(horizon[:, 0], horizon[:, 1]) - 1.0).max() > UNIT_LINE_TOL:
        raise ValueError(f"{file}: each horizon line needs hypot(horizon_a, horizon_b) = 1")
    return PoseTrack(columns["t"], step.astype(np.int64), columns["tilt_deg"], columns["roll_deg"], columns["yaw_deg"], horizon)


def _parquet(read, file: Path):
    """read(file) (pq.read_table, pq.read_schema); ValueError naming the file if it is not a Parquet file."""
    import pyarrow as pa

    try:
        return read(file)
    except (pa.ArrowException, OSError) as e:
        raise ValueError(f"{file}: not a readable Parquet file ({(str(e).splitlines() or [type(e).__name__])[0]})") from None


def _columns(table, names: tuple[str, str]) -> np.ndarray:
    return np.column_stack([table.column(n).to_numpy().astype(np.float64) for n in names])
