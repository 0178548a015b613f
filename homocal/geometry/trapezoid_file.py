"""The trapezoid file ``homocal fit``, ``homocal advise`` and the page read (TRAP.json)::

    {"image": [[u, v], x4], "map": [[x, y], x4]}            image pixels; map in metres
    {"image": ..., "map": [[px, py], x4], "site_map": {"scale_px_per_m": s, "origin_px": [ox, oy]}}

or a simgen dataset's trapezoids.json (its "hand_placed" trapezoid, with the site_map.json beside it).
Vertices in the order TL, TR, BR, BL as seen in the image; the map goes round the same way.
"""
from __future__ import annotations

from pathlib import Path

from homocal.files import read_json
from homocal.geometry.homography import ViewTransformer, check_orientation, validate_quad
from homocal.geometry.sitemap import SiteMap


def read_trapezoid_file(path: str | Path) -> tuple[ViewTransformer, SiteMap | None]:
    """The image-to-ground (metres) ViewTransformer of a trapezoid file and its site map (None for a map in
    metres); ValueError naming the file for bad content (a missing key, a degenerate or mirrored quad)."""
    path = Path(path)
    data = read_json(path)
    try:
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
        if site_map is not None:
            ground = site_map.to_metres(ground)
        check_orientation(image, ground, target_y_up=True)  # metres now (site-map pixels converted)
        return ViewTransformer(image, ground), site_map
    except KeyError as e:
        raise ValueError(f"{path}: missing key {e} (expected \"image\" and \"map\", see homocal fit --help)") from None
    except (TypeError, ValueError) as e:
        raise ValueError(f"{path}: {e}") from None
