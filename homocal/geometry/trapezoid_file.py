"""The trapezoid file ``homocal fit``, ``homocal advise`` and the page read (TRAP.json)::

    {"image": [[u, v], x4], "map": [[x, y], x4]}            image pixels; map in metres
    {"image": ..., "map": [[px, py], x4], "site_map": {"scale_px_per_m": s, "origin_px": [ox, oy]}}

or a simgen dataset's trapezoids.json (its "hand_placed" trapezoid, with the site_map.json beside it).
Vertices in the order TL, TR, BR, BL as seen in the image; the map goes round the same way. An optional
"image_size": [W, H] names the frame the image vertices were clicked on (a dataset's: its camera.json's), checked
against the lens's.

The image vertices are the camera's pixels; with a lens they are undistorted (``undistort_input``) before the
homography, which maps the undistorted image.
"""
from __future__ import annotations

from pathlib import Path

from homocal.files import read_json
from homocal.geometry.camera_file import read_camera
from homocal.geometry.homography import ViewTransformer, check_orientation, validate_quad
from homocal.geometry.lens import Lens, check_image_size, first_outside_frame, undistort_input
from homocal.geometry.sitemap import SiteMap


def read_trapezoid_file(path: str | Path, lens: Lens | None = None) -> tuple[ViewTransformer, SiteMap | None]:
    """The image-to-ground (metres) ViewTransformer of a trapezoid file and its site map (None for a map in
    metres); ValueError naming the file for bad content (a missing key, a degenerate or mirrored quad, an
    image_size other than the lens's, a vertex beyond the lens's fold). With a lens the ViewTransformer maps the
    undistorted image (its source is the undistorted vertices)."""
    path = Path(path)
    data = read_json(path)
    try:
        if lens is not None:
            _check_size(path, data, lens)
        if "hand_placed" in data:  # a simgen dataset's trapezoids.json: map in site-map pixels
            entry, site_map_path = data["hand_placed"], path.parent / "site_map.json"
            if not site_map_path.is_file():
                raise ValueError(f"a dataset's trapezoids.json needs the site_map.json beside it ({site_map_path})")
            site_map = SiteMap.from_json(site_map_path)
        else:
            entry = data
            sm = data.get("site_map")
            site_map = None if sm is None else SiteMap.from_dict(sm, f"{path} site_map")
        image, ground = validate_quad(entry["image"], "image"), validate_quad(entry["map"], "map")
        if lens is not None and (i := first_outside_frame(image, lens.image_size)) is not None:
            raise ValueError(f"image: vertex {i} = {image[i].tolist()} lies outside the lens's "
                             f"{lens.image_size[0]}x{lens.image_size[1]} frame (--camera-json): the trapezoid was "
                             "clicked on another camera's frame")
        image = validate_quad(undistort_input(image, lens, "image"), "image (undistorted)")
        if site_map is not None:
            ground = site_map.to_metres(ground)
        check_orientation(image, ground, target_y_up=True)  # metres now (site-map pixels converted)
        return ViewTransformer(image, ground), site_map
    except KeyError as e:
        raise ValueError(f"{path}: missing key {e} (expected \"image\" and \"map\", see homocal fit --help)") from None
    except (TypeError, ValueError) as e:
        raise ValueError(f"{path}: {e}") from None


def _check_size(path: Path, data: dict, lens: Lens) -> None:
    """ValueError if the trapezoid's frame (its "image_size", or the camera.json beside a dataset's trapezoids.json)
    is not the lens's."""
    if "image_size" in data:
        size = check_image_size(tuple(data["image_size"]) if isinstance(data["image_size"], list) else data["image_size"])
    elif "hand_placed" in data and (path.parent / "camera.json").is_file():
        size = read_camera(path.parent / "camera.json").image_size
    else:
        return
    if size != lens.image_size:
        raise ValueError(f"image_size {list(size)} differs from the lens's {list(lens.image_size)} (--camera-json): "
                         "the trapezoid was clicked on another camera's frame")
