"""Regenerate the scenes' generated assets: ground textures and the hand-placed trapezoids.

    python scenes/make_scene_assets.py            # rewrite the shipped scenes' ground.png and trapezoid blocks
    python scenes/make_scene_assets.py DIR ...    # rewrite the trapezoid block of any scene folder (a copy you edited)

The ground texture is painted here from a list of rectangles in world metres (x right, y forward),
at RES px per metre, over the extent of the scene's ``ground`` plane. MuJoCo stretches it once over
the plane (``texrepeat="1 1" texuniform="false"``): image top = +y, image left = -x, like a site map.

The hand-placed trapezoids are a function of the scene: the exact vertices (the scene's own camera, with its
pose and lens, and ``trapezoid.ground_m``, image and site map) moved by 1 to 2 px in a random direction (keyed by SEED and
the folder's name) and rounded to integers, as a person clicks them. They are stored in ``scene.toml``
between the BEGIN/END markers, and ``load_scene`` refuses a block that no longer fits the camera
(edit the camera or the trapezoid, then rerun this on the folder). The shipped scenes' blocks are
this function's output; scene3 is scene1's street (its painting) seen by another camera.
"""
from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from homocal.files import write_text_atomic  # noqa: E402
from simgen.rng import keyed_generator  # noqa: E402
from simgen.scene import ConfigError, load_scene  # noqa: E402

RES = 20  # texture px per metre
SEED = 2024  # of the hand-placed trapezoids' click noise

ASPHALT, LINE, SIDEWALK, CURB, GRASS = (62, 62, 66), (232, 232, 228), (168, 165, 158), (128, 126, 122), (86, 118, 68)


def stripes(x0, x1, y0, y1, along: str, bar=0.5, gap=0.5):
    """Zebra bars inside the rectangle; bars elongated along ``along`` ("x" or "y")."""
    out, (a0, a1) = [], ((y0, y1) if along == "x" else (x0, x1))
    s = a0 + gap / 2
    while s + bar <= a1:
        out.append((x0, x1, s, s + bar) if along == "x" else (s, s + bar, y0, y1))
        s += bar + gap
    return [(r, LINE) for r in out]


def dashes(x, y0, y1, dash=3.0, period=9.0, w=0.12, skip=()):
    """A dashed line along y at x, leaving out the y-intervals in ``skip``."""
    out, y = [], y0
    while y < y1:
        if not any(a < y + dash and y < b for a, b in skip):
            out.append(((x - w / 2, x + w / 2, y, y + dash), LINE))
        y += period
    return out


def _gaps(spans, lo=-20.0, hi=140.0, margin=1.0):
    """The y-intervals of [lo, hi] outside the spans (each widened by margin): where lines are painted."""
    out, y = [], lo
    for a, b in sorted(spans):
        out.append((y, a - margin))
        y = b + margin
    return out + [(y, hi)]


def scene1():
    """Straight two-lane street, 7 m road, 4 m sidewalks, zebra crossings at y = 7..10 and 22..26 m."""
    zebras = [(7.0, 10.0), (22.0, 26.0)]
    r = [((-40, 40, -20, 140), GRASS), ((-3.5, 3.5, -20, 140), ASPHALT)]
    for s in (-1, 1):
        r += [((min(s * 3.5, s * 7.5), max(s * 3.5, s * 7.5), -20, 140), SIDEWALK)]
        r += [((min(s * 3.5, s * 3.7), max(s * 3.5, s * 3.7), -20, 140), CURB)]
        for ya, yb in _gaps(zebras):
            r += [((s * 3.25 - 0.075, s * 3.25 + 0.075, ya, yb), LINE)]
    r += dashes(0.0, -20, 140, skip=[(a - 1, b + 1) for a, b in zebras])
    for ya, yb in zebras:
        r += stripes(-3.2, 3.2, ya, yb, along="y")
    return r


def scene2():
    """Four-lane avenue (14 m) with a side street (y = 40..52 m) crossing it; zebras on every arm and one near
    the camera (y = 9..13 m)."""
    side = (40.0, 52.0)
    cross = [(9.0, 13.0), (side[0] - 7, side[0] - 3), (side[1] + 3, side[1] + 7)]  # zebras across the avenue
    r = [((-50, 50, -20, 140), GRASS), ((-11, 11, -20, 140), SIDEWALK)]
    r += [((-50, 50, side[0] - 4, side[0]), SIDEWALK), ((-50, 50, side[1], side[1] + 4), SIDEWALK)]
    r += [((-7.2, 7.2, -20, 140), CURB), ((-50, 50, side[0] - 0.2, side[1] + 0.2), CURB)]
    r += [((-7, 7, -20, 140), ASPHALT), ((-50, 50, *side), ASPHALT)]
    junction = [(cross[0][0], cross[0][1]), (cross[1][0], cross[2][1])]
    for s in (-1, 1):
        for ya, yb in _gaps(junction):
            r += [((s * 6.75 - 0.075, s * 6.75 + 0.075, ya, yb), LINE)]
            r += [((s * 0.15 - 0.06, s * 0.15 + 0.06, ya, yb), LINE)]  # double centre line
        r += dashes(s * 3.5, -20, 140, skip=[(a - 1, b + 1) for a, b in junction])
        r += stripes(min(s * 7, s * 11), max(s * 7, s * 11), side[0] + 0.5, side[1] - 0.5, along="x")
    for ya, yb in cross:
        r += stripes(-6.7, 6.7, ya, yb, along="y")
    return r


def paint(rects, extent) -> np.ndarray:
    """Paint rectangles (x0, x1, y0, y1) over the plane extent (x0, x1, y0, y1) -> (H, W, 3) uint8 RGB."""
    ex0, ex1, ey0, ey1 = extent
    img = np.zeros((round((ey1 - ey0) * RES), round((ex1 - ex0) * RES), 3), np.uint8)
    for (x0, x1, y0, y1), colour in rects:
        c0, c1 = round((x0 - ex0) * RES), round((x1 - ex0) * RES)
        r0, r1 = round((ey1 - y1) * RES), round((ey1 - y0) * RES)
        img[max(r0, 0) : max(r1, 0), max(c0, 0) : max(c1, 0)] = colour
    return img


def hand_placed(exact: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(4, 2) float -> (4, 2) int: each vertex rounded after a 1-2 px offset, kept only if still 1-2 px off."""
    out = []
    for p in exact:
        while True:
            a, d = rng.uniform(0, 2 * np.pi), rng.uniform(1.0, 2.0)
            q = np.round(p + d * np.array([np.cos(a), np.sin(a)]))
            if 1.0 <= np.hypot(*(q - p)) <= 2.0:
                out.append(q.astype(int))
                break
    return np.array(out)


def write_trapezoid_block(scene_dir: Path, seed: int = SEED) -> None:
    """Replace the BEGIN/END block of scene.toml with seeded hand-placed trapezoid vertices."""
    toml_path = scene_dir / "scene.toml"
    if not re.search(r"# BEGIN hand-placed.*?# END hand-placed", toml_path.read_text(encoding="utf-8"), flags=re.S):
        sys.exit(f"make_scene_assets: error: {toml_path}: no '# BEGIN hand-placed' ... '# END hand-placed' block "
                 "in [trapezoid] to rewrite (copy it from scenes/scene1/scene.toml)")
    scene = load_scene(scene_dir, check_trapezoid=False)
    rng = keyed_generator(seed, scene.name, "hand-placed trapezoid")
    img, mp = hand_placed(scene.trapezoid_exact_image, rng), hand_placed(scene.trapezoid_exact_map, rng)
    fmt = lambda q: "[" + ", ".join(f"[{a}, {b}]" for a, b in q) + "]"  # noqa: E731
    block = (
        "# BEGIN hand-placed (scenes/make_scene_assets.py, seed %d)\n" % seed
        + f"hand_placed_image = {fmt(img)}\nhand_placed_map = {fmt(mp)}\n"
        + "# END hand-placed"
    )
    text = re.sub(r"# BEGIN hand-placed.*?# END hand-placed", block, toml_path.read_text(encoding="utf-8"), flags=re.S)
    tomllib.loads(text)
    write_text_atomic(toml_path, text)


def main() -> None:
    if sys.argv[1:]:
        for folder in map(Path, sys.argv[1:]):
            try:
                write_trapezoid_block(folder)
            except ConfigError as e:
                sys.exit(f"make_scene_assets: error: {folder}: {e}")
            print(f"{folder}: trapezoid block written")
        return
    for name, rects in (("scene1", scene1()), ("scene2", scene2()), ("scene3", scene1())):
        d = HERE / name
        xml = (d / "scene.xml").read_text()
        m = re.search(r'name="ground"[^>]*size="([\d.]+) ([\d.]+)[^"]*"[^>]*pos="([-\d.]+) ([-\d.]+)', xml)
        hx, hy, cx, cy = map(float, m.groups())
        img = paint(rects, (cx - hx, cx + hx, cy - hy, cy + hy))
        cv2.imwrite(str(d / "ground.png"), img[:, :, ::-1])
        write_trapezoid_block(d)
        print(f"{name}: ground.png {img.shape[1]}x{img.shape[0]}, trapezoid block written")


if __name__ == "__main__":
    main()
