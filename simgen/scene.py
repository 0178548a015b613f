"""A scene folder (``scene.toml`` + MJCF + ground texture) read and validated into one ``Scene``.

Everything a run needs is checked here, before any output exists: a bad field raises ``ConfigError``
whose one-line message names the field (``scene.toml: camera.tilt_deg: ...``).
"""
from __future__ import annotations

import dataclasses
import difflib
import hashlib
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from homocal.geometry import PinholeCamera, SiteMap
from homocal.names import check_name

GT_DT = 0.05  # ground-truth period, seconds (paper Section 5.1)
GT_RATE = 20  # 1 / GT_DT, samples per second, for exact integer time arithmetic
DETECTORS = ("segmentation", "rgb", "hog")
QUALITIES = ("draft", "default", "high")  # render presets (simgen.render.QUALITY)
MAX_SECONDS = 86400.0  # longest run (and preview time): a day; the agents' walks are planned for the whole run
MAX_FPS = 1000  # highest video frame rate
MAX_CAMERA_MOVES = 100  # [[camera.moves]] entries at most
MAX_SWAY_DEG = 45.0  # [camera.sway] amplitude_deg at most
HAND_PLACED_MAX_PX = 2.0  # a hand-placed vertex lies 1 to 2 px from the exact one (data_schema.md)
SHIPPED = Path(__file__).parent / "scenes"
"""The scenes that ship with simgen (package data; in a checkout a link to the top-level scenes/, their one source)."""


class ConfigError(ValueError):
    """A scene config or run option that cannot work; the message is one line naming the field."""


@dataclass(frozen=True)
class Route:
    """A walking route: polyline ``points`` (N, 2) world metres, lateral spread, direction, weight."""

    name: str
    points: np.ndarray
    width_m: float
    both_ways: bool
    weight: float
    wait_s: tuple[float, float] = (0.0, 0.0)  # a waiting walker's wait, uniform, seconds (agents.py)
    wait_share: float = 0.0  # fraction of walkers who wait


@dataclass(frozen=True)
class CameraMove:
    """A ``[[camera.moves]]`` entry: from ``at_s`` on, the camera's pose gains (tilt, roll, yaw) degrees, at once
    (``over_s`` 0) or linearly over ``over_s`` seconds."""

    at_s: float
    over_s: float = 0.0
    tilt_deg: float = 0.0
    roll_deg: float = 0.0
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class Sway:
    """``[camera.sway]``: the tilt swings by amplitude_deg sin(2 pi t / period_s), degrees."""

    amplitude_deg: float
    period_s: float


def camera_offsets(moves: tuple[CameraMove, ...], sway: Sway | None, t) -> np.ndarray:
    """The pose change (tilt, roll, yaw) in degrees, (N, 3), at times t (N,) seconds: the sum of the moves, each
    ramped (fraction clip((t - at_s) / over_s, 0, 1); a step (over_s 0) counts from t >= at_s on), plus the sway
    of the tilt. The one pose function of a moving camera (``Scene.camera_at``, the renders, gt.parquet,
    camera_pose.parquet, simgen.boxstream)."""
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    out = np.zeros((len(t), 3))
    for m in moves:
        if m.over_s > 0:
            share = np.clip((t - m.at_s) / m.over_s, 0.0, 1.0)
        else:
            share = (t >= m.at_s).astype(np.float64)
        out += share[:, None] * np.array([m.tilt_deg, m.roll_deg, m.yaw_deg])
    if sway is not None:
        out[:, 0] += sway.amplitude_deg * np.sin(2.0 * np.pi * t / sway.period_s)
    return out


def posed(camera: PinholeCamera, offsets) -> PinholeCamera:
    """``camera`` with the pose change (tilt, roll, yaw) degrees added to its own."""
    tilt, roll, yaw = (float(x) for x in offsets)
    return dataclasses.replace(camera, tilt_deg=camera.tilt_deg + tilt, roll_deg=camera.roll_deg + roll,
                               yaw_deg=camera.yaw_deg + yaw)


@dataclass(frozen=True)
class Ground:
    """The MJCF plane named ``ground``: extent (x0, x1, y0, y1) in world metres and its texture file."""

    extent: tuple[float, float, float, float]
    texture: Path


@dataclass(frozen=True)
class Scene:
    """A validated scene config; array fields are float64 unless noted."""

    name: str
    folder: Path
    model_path: Path
    camera: PinholeCamera
    seconds: float
    fps: int
    chunk_seconds: float
    detectors: tuple[str, ...]
    rgb_warmup_frames: int
    map_scale: float
    agent_count: int
    speed_mps: tuple[float, float]
    gap_s: tuple[float, float]
    routes: tuple[Route, ...]
    calibration_distances: np.ndarray  # (M,) metres
    calibration_xy: np.ndarray  # (M, 2) metres: (0, d) for layout "line", (+-lateral_m, d) alternating for "zigzag"
    trapezoid_ground: np.ndarray  # (4, 2) metres, TL TR BR BL
    hand_placed_image: np.ndarray  # (4, 2) int64 px
    hand_placed_map: np.ndarray  # (4, 2) int64 map px
    ground: Ground
    raw: dict = field(repr=False)
    quality: str = "default"  # render preset, one of QUALITIES
    moves: tuple[CameraMove, ...] = ()  # [[camera.moves]], by at_s
    sway: Sway | None = None  # [camera.sway]

    # ---- derived numbers ---------------------------------------------------------------
    @property
    def frames_total(self) -> int:
        return round(self.seconds * self.fps)

    @property
    def steps_total(self) -> int:
        return round(self.seconds * GT_RATE)

    @property
    def moving(self) -> bool:
        """Whether the camera moves (moves or a sway): only then is it posed per instant and camera_pose.parquet written."""
        return bool(self.moves) or self.sway is not None

    def camera_at(self, t: float) -> PinholeCamera:
        """The camera at time t seconds: ``camera`` (the ``[camera]`` pose, the same object for a static camera)
        with ``camera_offsets`` added."""
        return posed(self.camera, camera_offsets(self.moves, self.sway, t)[0]) if self.moving else self.camera

    @property
    def site_map(self) -> SiteMap:
        """The site map's scale and origin (homocal's SiteMap holds the convention): map pixel centres at
        integers, the ground plane's far-left corner (x0, y1) at the top-left pixel's outer corner (-0.5, -0.5)."""
        x0, _, _, y1 = self.ground.extent
        return SiteMap(self.map_scale, (-self.map_scale * x0 - 0.5, self.map_scale * y1 - 0.5))

    @property
    def trapezoid_exact_image(self) -> np.ndarray:
        """(4, 2) exact image vertices of ``trapezoid_ground``, px."""
        return self.camera.project_ground(self.trapezoid_ground)

    @property
    def trapezoid_exact_map(self) -> np.ndarray:
        """(4, 2) exact site-map vertices of ``trapezoid_ground``, map px."""
        return self.site_map.to_pixels(self.trapezoid_ground)

    def config_hash(self) -> str:
        """sha256 over the resolved config, the run options and the bytes of the scene's files."""
        h = hashlib.sha256()
        run = {"seconds": self.seconds, "fps": self.fps, "detectors": list(self.detectors), "quality": self.quality}
        h.update(json.dumps([self.raw, run], sort_keys=True).encode())
        for p in (self.model_path, self.ground.texture):
            h.update(p.read_bytes())
        return h.hexdigest()

    def with_run(self, seconds: float | None = None, fps: int | None = None, detectors=None, quality: str | None = None) -> "Scene":
        """The same scene with run options overridden (from the command line), re-validated."""
        s = dataclasses.replace(
            self,
            seconds=self.seconds if seconds is None else seconds,
            fps=self.fps if fps is None else fps,
            detectors=self.detectors if detectors is None else tuple(detectors),
            quality=self.quality if quality is None else quality,
        )
        _check_run(s, "--detectors" if detectors is not None else DETECTORS_KEY)
        return s


_MISSING = object()


def _get(d: dict, key: str, kind=float, default=_MISSING):
    """d["a.b.c"] converted by ``kind`` (``default`` if missing and given); ConfigError naming the key when
    missing or wrong (a float must be finite)."""
    cur = d
    for part in key.split("."):
        if not isinstance(cur, dict) or part not in cur:
            if default is not _MISSING:
                return default
            near = difflib.get_close_matches(part, list(dict.keys(cur)), n=1) if isinstance(cur, dict) else []
            raise ConfigError(f"scene.toml: {key}: missing" + (f" (is {near[0]} a typo of {part}?)" if near else ""))
        cur = cur[part]
    accepted = (int, float) if kind is float else kind
    if not isinstance(cur, accepted) or (isinstance(cur, bool) and kind is not bool):
        raise ConfigError(f"scene.toml: {key}: expected {kind.__name__}, got {cur!r}")
    if kind is float and not math.isfinite(cur):
        raise ConfigError(f"scene.toml: {key}: must be a finite number, got {cur}")
    return kind(cur)


class _ReadKeys(dict):
    """A TOML table that records the dotted paths of the keys looked up in it (``in``, ``[]``, ``get``)."""

    def __init__(self, table: dict, path: tuple, read: set) -> None:
        super().__init__({k: _track(v, (*path, k), read) for k, v in table.items()})
        self._path, self._read = path, read

    def __contains__(self, key) -> bool:
        self._read.add((*self._path, key))
        return super().__contains__(key)

    def __getitem__(self, key):
        self._read.add((*self._path, key))
        return super().__getitem__(key)

    def get(self, key, default=None):
        self._read.add((*self._path, key))
        return super().get(key, default)


def _track(value, path: tuple, read: set):
    if isinstance(value, dict):
        return _ReadKeys(value, path, read)
    if isinstance(value, list):
        return [_track(v, (*path, i), read) if isinstance(v, dict) else v for i, v in enumerate(value)]
    return value


def _leaves(value, path: tuple = ()):
    """Dotted paths (tuples) of the values of a TOML document, tables of arrays entered."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(value, list) and any(isinstance(v, dict) for v in value):
        for i, v in enumerate(value):
            yield from _leaves(v, (*path, i))
    else:
        yield path


def _dotted(path: tuple) -> str:
    return "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".")


def _check_unknown_keys(raw: dict, read: set) -> None:
    """Refuse the first key of ``raw`` the loader never looked up, naming the nearest known key (difflib)."""
    for leaf in _leaves(raw):
        if leaf in read or any(leaf[:n] in read and not any(r[:n] == leaf[:n] and len(r) > n for r in read)
                               for n in range(1, len(leaf))):
            continue  # looked up, or inside a value read whole
        n = next(n for n in range(1, len(leaf) + 1) if not any(r[:n] == leaf[:n] for r in read))
        siblings = sorted({r[n - 1] for r in read if len(r) >= n and r[: n - 1] == leaf[: n - 1] and isinstance(r[n - 1], str)})
        near = difflib.get_close_matches(str(leaf[n - 1]), siblings, n=1)
        hint = f" (did you mean {_dotted((*leaf[: n - 1], near[0]))}?)" if near else f" (known here: {', '.join(siblings)})"
        raise ConfigError(f"scene.toml: {_dotted(leaf[:n])}: unknown key{hint}")


def _points(d: dict, key: str, n: int | None = None, integer: bool = False) -> np.ndarray:
    """d[key] as an (N, 2) array (N == n if given)."""
    try:
        a = np.array(_get(d, key, list), dtype=np.float64)
    except ValueError:
        raise ConfigError(f"scene.toml: {key}: expected a list of [x, y] pairs") from None
    if a.ndim != 2 or a.shape[1] != 2 or (n is not None and len(a) != n) or len(a) < 2:
        raise ConfigError(f"scene.toml: {key}: expected {n or 'at least 2'} [x, y] pairs, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ConfigError(f"scene.toml: {key}: coordinates must be finite numbers")
    if integer:
        if not np.all(a == np.round(a)):
            raise ConfigError(f"scene.toml: {key}: vertices must be integer pixels")
        return a.astype(np.int64)
    return a


def _range(d: dict, key: str, low: float = 0.0) -> tuple[float, float]:
    """d[key] as a (min, max) pair with low <= min <= max."""
    v = _get(d, key, list)
    if len(v) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v) or not low <= v[0] <= v[1] < math.inf:
        raise ConfigError(f"scene.toml: {key}: expected [min, max] with {low} <= min <= max, got {v!r}")
    return float(v[0]), float(v[1])


def _read_ground(model_path: Path) -> Ground:
    """Find the plane named ``ground`` and its texture in the MJCF (compiling it on the way)."""
    from simgen.backend import mujoco  # noqa: PLC0415  (only here: reading a config needs no GL otherwise)

    try:
        spec = mujoco.MjSpec.from_file(str(model_path))
        spec.compile()
    except Exception as e:  # noqa: BLE001  (mujoco raises ValueError or its own errors)
        raise ConfigError(f"scene.toml: model: {model_path.name} does not compile: {str(e).splitlines()[0]}") from None
    g = spec.geom("ground")
    if g is None or g.type != mujoco.mjtGeom.mjGEOM_PLANE or g.size[0] <= 0 or g.size[1] <= 0:
        raise ConfigError(f"scene.toml: model: {model_path.name} needs a finite plane geom named 'ground'")
    mat = spec.material(g.material) if g.material else None
    tex_names = [t for t in (mat.textures if mat else []) if t]
    tex = spec.texture(tex_names[0]) if tex_names else None
    if tex is None or not tex.file:
        raise ConfigError(f"scene.toml: model: the 'ground' plane in {model_path.name} needs a material with a 2d texture file")
    (hx, hy), (cx, cy) = g.size[:2], g.pos[:2]
    return Ground((cx - hx, cx + hx, cy - hy, cy + hy), model_path.parent / spec.texturedir / tex.file)


DETECTORS_KEY = "scene.toml: detection.detectors"


def _check_run(s: Scene, detectors_from: str = DETECTORS_KEY) -> None:
    """Run options: durations on the 50 ms grid, integer frame counts, known detectors (a refusal of the detectors
    names where they came from: ``detectors_from``, the scene.toml key or the flag)."""
    for key, v in (("run.seconds", s.seconds), ("run.chunk_seconds", s.chunk_seconds)):
        if not (0 < v <= MAX_SECONDS and abs(v * GT_RATE - round(v * GT_RATE)) < 1e-9):
            raise ConfigError(f"scene.toml: {key}: must be a positive multiple of {GT_DT} s, at most {MAX_SECONDS:g}, got {v}")
    if not (isinstance(s.fps, int) and 0 < s.fps <= MAX_FPS):
        raise ConfigError(f"scene.toml: run.fps: must be an integer in [1, {MAX_FPS}], got {s.fps!r}")
    for key, v in (("run.seconds", s.seconds), ("run.chunk_seconds", s.chunk_seconds)):
        if abs(v * s.fps - round(v * s.fps)) > 1e-9:
            raise ConfigError(f"scene.toml: {key}: {v} s is not a whole number of frames at {s.fps} fps")
    if s.quality not in QUALITIES:
        raise ConfigError(f"scene.toml: render.quality: expected one of {', '.join(QUALITIES)}, got {s.quality!r}")
    if problem := detectors_problem(s.detectors):
        raise ConfigError(f"{detectors_from}: {problem}")
    if "hog" in s.detectors:
        from simgen.detection.hog import hog_missing  # noqa: PLC0415  (cv2 only when hog is asked for)

        if hog_missing():
            raise ConfigError(f"{detectors_from}: hog: {hog_missing()}")


def detectors_problem(names: list[str] | tuple[str, ...]) -> str | None:
    """What is wrong with a list of detector names (None if they are one or more distinct names of DETECTORS)."""
    if not names or any(name not in DETECTORS for name in names) or len(set(names)) != len(names):
        return f"expected distinct names from {', '.join(DETECTORS)}, got {list(names)}"
    return None


def in_frame(camera: PinholeCamera, uv: np.ndarray) -> np.ndarray:
    """(N, 2) the camera's pixels -> (N,) bool: inside the image (pixel centres at integers) and below the horizon
    (a line of the undistorted image: tested on the undistorted pixels)."""
    a, b, c = camera.horizon
    u, v = uv[:, 0], uv[:, 1]
    hu, hv = (camera.lens.undistort_points(uv).T if any(camera.distortion) else (u, v))
    with np.errstate(invalid="ignore"):  # NaN (not in front of the camera) -> False
        inside = (u >= -0.5) & (u < camera.width - 0.5) & (v >= -0.5) & (v < camera.height - 0.5)
        return inside & (a * hu + b * hv + c > 0)


def _visible(camera: PinholeCamera, xy: np.ndarray) -> np.ndarray:
    """(N, 2) ground points, metres -> (N,) bool: their pixels are ``in_frame``."""
    return in_frame(camera, camera.project_ground(xy))


def shipped_scenes() -> list[str]:
    """The names of the shipped scenes (folders of SHIPPED with a scene.toml), sorted."""
    return sorted(p.name for p in SHIPPED.iterdir() if (p / "scene.toml").is_file())


def scene_folder(scene: str) -> Path:
    """A scene as the command line gives it: a folder (kept as it is), else the name of a shipped scene.

    ConfigError (one line listing the shipped scenes) when ``scene`` is neither.
    """
    if scene and _is_dir(scene):  # not "": Path("") is the current folder
        return Path(scene)
    shipped = shipped_scenes()
    if scene in shipped:  # a listed folder name: no path reaches outside SHIPPED
        return SHIPPED / scene
    raise ConfigError(f"scene {scene!r}: no such folder and no shipped scene of that name (shipped: {', '.join(shipped)})")


def _is_dir(path: str) -> bool:
    try:
        return Path(path).is_dir()
    except OSError:  # a name too long for the file system, say
        return False


def describe(scene: Scene) -> str:
    """One line: the title in the first line of the scene's scene.toml (``# Scene 1: TITLE (...``) and its run."""
    first = (scene.folder / "scene.toml").read_text(encoding="utf-8").splitlines()[0]
    title = first.lstrip("# ").split(": ", 1)[-1].split(" (")[0].rstrip(",.")
    return (f"{title}; {scene.camera.width}x{scene.camera.height}, {scene.seconds:g} s at {scene.fps} fps, "
            f"{scene.agent_count} people, detectors {','.join(scene.detectors)}")


def _read_camera(raw: dict) -> PinholeCamera:
    """``[camera]``: the PinholeCamera it describes (each key is a PinholeCamera field). Raises ConfigError."""
    try:
        camera = PinholeCamera(
            width=_get(raw, "camera.width", int),
            height=_get(raw, "camera.height", int),
            hfov_deg=_get(raw, "camera.hfov_deg"),
            mount_height_m=_get(raw, "camera.mount_height_m"),
            tilt_deg=_get(raw, "camera.tilt_deg"),
            roll_deg=_get(raw, "camera.roll_deg", default=0.0),
            yaw_deg=_get(raw, "camera.yaw_deg", default=0.0),
            distortion=tuple(_get(raw, "camera.distortion", list, default=[0.0] * 5)),
        )
        camera.lens.check_folds()
    except ConfigError:
        raise
    except ValueError as e:
        message = str(e)  # PinholeCamera's start with "camera:", the Lens's with the field ("distortion: ...")
        raise ConfigError(f"scene.toml: {message if message.startswith('camera') else 'camera.' + message}") from None
    if camera.width % 2 or camera.height % 2:
        raise ConfigError(f"scene.toml: camera.width, camera.height: must be even (yuv420p video), got {camera.width}x{camera.height}")
    return camera


def _read_motion(raw: dict, camera: PinholeCamera) -> tuple[tuple[CameraMove, ...], Sway | None]:
    """``[[camera.moves]]`` and ``[camera.sway]``; every pose they reach must be a valid camera. Raises ConfigError."""
    entries = _get(raw, "camera.moves", list, default=[])
    if len(entries) > MAX_CAMERA_MOVES:
        raise ConfigError(f"scene.toml: camera.moves: at most {MAX_CAMERA_MOVES} moves, got {len(entries)}")
    moves = []
    for i, entry in enumerate(entries):
        key, rd = f"camera.moves[{i}]", {"camera": {f"moves[{i}]": entry}}
        if not isinstance(entry, dict):
            raise ConfigError(f"scene.toml: {key}: expected a table ([[camera.moves]]), got {entry!r:.40}")
        move = CameraMove(_get(rd, f"{key}.at_s"),
                          *(_get(rd, f"{key}.{name}", default=0.0) for name in ("over_s", "tilt_deg", "roll_deg", "yaw_deg")))
        for name in ("at_s", "over_s"):
            if not 0.0 <= getattr(move, name) <= MAX_SECONDS:
                raise ConfigError(f"scene.toml: {key}.{name}: must be in [0, {MAX_SECONDS:g}] s, got {getattr(move, name)}")
        if moves and move.at_s < moves[-1].at_s:
            raise ConfigError(f"scene.toml: {key}.at_s: moves must come in time order ({move.at_s:g} s after {moves[-1].at_s:g} s)")
        moves.append(move)
    sway = None
    if "sway" in raw["camera"]:
        sway = Sway(_get(raw, "camera.sway.amplitude_deg"), _get(raw, "camera.sway.period_s"))
        if not 0.0 <= sway.amplitude_deg <= MAX_SWAY_DEG:
            raise ConfigError(f"scene.toml: camera.sway.amplitude_deg: must be in [0, {MAX_SWAY_DEG:g}], got {sway.amplitude_deg}")
        if not 0.0 < sway.period_s <= MAX_SECONDS:
            raise ConfigError(f"scene.toml: camera.sway.period_s: must be in (0, {MAX_SECONDS:g}] s, got {sway.period_s}")
    # the offsets are linear between the moves' ends, so the poses' extremes are at them or just before a step
    # (the sway at its extremes)
    knots = np.array([0.0, *(m.at_s for m in moves), *(m.at_s + m.over_s for m in moves)])
    knots = np.concatenate([knots, np.nextafter(knots[1:], -np.inf)])
    swing = 0.0 if sway is None else sway.amplitude_deg
    for offsets in camera_offsets(tuple(moves), None, knots):
        for extra in {-swing, swing}:
            try:
                posed(camera, offsets + [extra, 0.0, 0.0])
            except ValueError as e:
                raise ConfigError(f"scene.toml: camera.moves, camera.sway: a pose they reach is no camera: {e}") from None
    return tuple(moves), sway


def _read_routes(raw: dict) -> tuple[Route, ...]:
    """``[[agents.routes]]``. Raises ConfigError."""
    routes = []
    for i, r in enumerate(_get(raw, "agents.routes", list)):
        key = f"agents.routes[{i}]"
        rd = {"agents": {f"routes[{i}]": r}}
        route = Route(
            name=str(r.get("name", f"route {i}")) if isinstance(r, dict) else "",
            points=_points(rd, f"{key}.points"),
            width_m=_get(rd, f"{key}.width_m"),
            both_ways=_get(rd, f"{key}.both_ways", bool),
            weight=_get(rd, f"{key}.weight"),
            wait_s=_range(rd, f"{key}.wait_s") if "wait_s" in r else (0.0, 0.0),
            wait_share=_get(rd, f"{key}.wait_share") if "wait_share" in r else 0.0,
        )
        if not 0 <= route.wait_share <= 1:
            raise ConfigError(f"scene.toml: {key}.wait_share: must be in [0, 1], got {route.wait_share}")
        if route.weight <= 0 or route.width_m < 0 or np.any(np.hypot(*np.diff(route.points, axis=0).T) == 0):
            raise ConfigError(f"scene.toml: {key}: needs weight > 0, width_m >= 0 and no repeated points")
        routes.append(route)
    return tuple(routes)


def _read_calibration(raw: dict) -> np.ndarray:
    """``[calibration]``: (M, 2) ground points (x, d), metres, of the calibration objects. Raises ConfigError."""
    key = "calibration.distances_m"
    calib = np.linspace(_get(raw, key + ".start"), _get(raw, key + ".stop"), _get(raw, key + ".count", int))
    if len(calib) < 3:
        raise ConfigError(f"scene.toml: {key}.count: must be >= 3")
    layout = _get(raw, "calibration.layout", str) if "layout" in raw["calibration"] else "line"
    lateral = _get(raw, "calibration.lateral_m") if "lateral_m" in raw["calibration"] else 0.0
    if layout not in ("line", "zigzag") or lateral < 0 or (layout == "line" and lateral):
        raise ConfigError(f"scene.toml: calibration.layout, lateral_m: expected \"line\" (lateral_m 0) or \"zigzag\" "
                          f"with lateral_m >= 0, got {layout!r}, {lateral}")
    sign = np.where(np.arange(len(calib)) % 2 == 0, 1.0, -1.0) if layout == "zigzag" else np.zeros(len(calib))
    return np.column_stack([sign * lateral, calib])


def load_scene(folder: str | Path, check_trapezoid: bool = True) -> Scene:
    """Read and validate ``folder/scene.toml`` and the MJCF it names. Raises ConfigError.

    The scene's name is the folder's name (it keys the random draws and names the scene in the dataset's
    manifest.json): it must pass ``homocal.names.check_name``.
    """
    folder = Path(folder)
    path = folder / "scene.toml"
    if not path.is_file():
        raise ConfigError(f"{path}: no such scene config")
    try:
        plain = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"scene.toml: not valid TOML: {e}") from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    read: set[tuple] = set()
    raw = _ReadKeys(plain, (), read)  # records every key looked up, for _check_unknown_keys

    model_path = folder / _get(raw, "model", str)
    if not model_path.is_file():
        raise ConfigError(f"scene.toml: model: {model_path} does not exist")
    camera = _read_camera(raw)
    moves, sway = _read_motion(raw, camera)
    routes = _read_routes(raw)
    calib_xy = _read_calibration(raw)

    scene = Scene(
        name=_scene_name(folder),
        folder=folder,
        model_path=model_path,
        camera=camera,
        seconds=_get(raw, "run.seconds"),
        fps=_get(raw, "run.fps", int),
        chunk_seconds=_get(raw, "run.chunk_seconds"),
        detectors=tuple(_get(raw, "detection.detectors", list)),
        rgb_warmup_frames=_get(raw, "detection.rgb_warmup_frames", int),
        map_scale=_get(raw, "site_map.scale_px_per_m"),
        agent_count=_get(raw, "agents.count", int),
        speed_mps=_range(raw, "agents.speed_mps", low=1e-3),
        gap_s=_range(raw, "agents.gap_s"),
        routes=routes,
        calibration_distances=calib_xy[:, 1],
        calibration_xy=calib_xy,
        trapezoid_ground=_points(raw, "trapezoid.ground_m", 4),
        hand_placed_image=_points(raw, "trapezoid.hand_placed_image", 4, integer=True),
        hand_placed_map=_points(raw, "trapezoid.hand_placed_map", 4, integer=True),
        ground=_read_ground(model_path),
        raw=plain,
        quality=_get(raw, "render.quality", str, default="default"),
        moves=moves,
        sway=sway,
    )
    _check_unknown_keys(plain, read)
    _check_run(scene)
    if scene.agent_count < 0 or scene.rgb_warmup_frames < 0:
        raise ConfigError("scene.toml: agents.count and detection.rgb_warmup_frames must be >= 0")
    if not scene.routes and scene.agent_count:
        raise ConfigError("scene.toml: agents.routes: at least one route is needed when agents.count > 0")
    if not scene.map_scale > 0:
        raise ConfigError(f"scene.toml: site_map.scale_px_per_m: must be > 0, got {scene.map_scale}")
    _check_placement(scene, check_trapezoid)
    return scene


def _check_placement(scene: Scene, check_trapezoid: bool) -> None:
    """The calibration objects and the trapezoid in the camera's view; the hand-placed vertices (if
    ``check_trapezoid``) inside their images and near the exact ones. Raises ConfigError."""
    camera = scene.camera
    x0, x1, y0, y1 = scene.ground.extent
    calib = scene.calibration_distances
    bad = ~_visible(camera, scene.calibration_xy) | (calib <= 0) | (calib > y1)
    if bad.any():
        near = camera.mount_height_m / math.tan(math.radians(camera.tilt_deg + camera.vfov_deg / 2))
        raise ConfigError(
            f"scene.toml: calibration.distances_m: {calib[bad][0]:g} m is outside the view of the camera "
            f"(visible ground straight ahead: {near:.2f} m to the end of the ground plane at {y1:g} m)"
        )
    if not _visible(camera, scene.trapezoid_ground).all():
        raise ConfigError("scene.toml: trapezoid.ground_m: a vertex is outside the view of the camera")
    if check_trapezoid:
        for key, q, (w, h) in (
            ("trapezoid.hand_placed_image", scene.hand_placed_image, (camera.width, camera.height)),
            ("trapezoid.hand_placed_map", scene.hand_placed_map, (round((x1 - x0) * scene.map_scale), round((y1 - y0) * scene.map_scale))),
        ):
            if np.any(q < 0) or np.any(q[:, 0] > w - 1) or np.any(q[:, 1] > h - 1):
                raise ConfigError(f"scene.toml: {key}: a vertex lies outside the {w}x{h} image")
        _check_hand_placed(scene)


def _scene_name(folder: Path) -> str:
    try:
        return check_name(folder.resolve().name, "scene (the scene folder's name)")
    except ValueError as e:
        raise ConfigError(str(e)) from None


def _check_hand_placed(scene: Scene) -> None:
    """Each hand-placed vertex within HAND_PLACED_MAX_PX of the exact one (the camera and trapezoid.ground_m)."""
    for key, hand, exact in (("trapezoid.hand_placed_image", scene.hand_placed_image, scene.trapezoid_exact_image),
                             ("trapezoid.hand_placed_map", scene.hand_placed_map, scene.trapezoid_exact_map)):
        off = np.hypot(*(hand - exact).T)
        if np.any(off > HAND_PLACED_MAX_PX + 1e-9):
            i = int(np.argmax(off))
            raise ConfigError(
                f"scene.toml: {key}: vertex {i + 1} is {off[i]:.1f} px from the exact one (at most {HAND_PLACED_MAX_PX:g} "
                f"px; the camera or trapezoid.ground_m changed?): rewrite it with python scenes/make_scene_assets.py {scene.folder}"
            )
