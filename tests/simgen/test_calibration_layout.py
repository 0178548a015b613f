"""Calibration objects on the centre line ("line", the default) or alternating off it ("zigzag")."""
from __future__ import annotations

import numpy as np
import pytest

from simgen.cli import main
from simgen.scene import load_scene

from scene_copies import copy_scene


def _with(folder, **keys):
    """Add ``key = value`` lines (TOML text values) to the [calibration] section."""
    toml = folder / "scene.toml"
    toml.write_text(toml.read_text().replace("[calibration]", "[calibration]\n" + "".join(f"{k} = {v}\n" for k, v in keys.items()), 1))


def test_line_is_the_default_and_zigzag_alternates(tmp_path):
    line = load_scene(copy_scene(tmp_path / "a"))
    d = np.linspace(5.0, 44.0, 40)
    np.testing.assert_array_equal(line.calibration_xy, np.column_stack([np.zeros(40), d]))
    explicit = copy_scene(tmp_path / "b")
    _with(explicit, layout='"line"')
    np.testing.assert_array_equal(load_scene(explicit).calibration_xy, line.calibration_xy)
    zig = copy_scene(tmp_path / "c")
    _with(zig, layout='"zigzag"', lateral_m="3.0")
    xy = load_scene(zig).calibration_xy
    np.testing.assert_array_equal(xy[:, 1], d)
    np.testing.assert_array_equal(xy[:, 0], np.tile([3.0, -3.0], 20))


@pytest.mark.generate
@pytest.mark.slow  # scene1 rendered at 1280x720
def test_zigzag_objects_are_rendered_where_they_stand(tmp_path):
    from simgen.static import calibration_table
    from simgen.stage import Stage

    folder = copy_scene(tmp_path, small=False)
    _with(folder, layout='"zigzag"', lateral_m="2.5")
    scene = load_scene(folder)
    with Stage(scene, seed=0, t_end=1.0) as stage:
        table = calibration_table(stage).to_pydict()
    x, y, dist = (np.array(table[k]) for k in ("x", "y", "distance_m"))
    np.testing.assert_array_equal(x, np.tile([2.5, -2.5], 20))
    np.testing.assert_allclose(dist, np.hypot(x, y))
    exact = scene.camera.project_ground(np.column_stack([x, y]))
    np.testing.assert_allclose(np.column_stack([table["u_exact"], table["v_exact"]]), exact)
    # off the centre line a standing person leans in the image, so the box's centre is not over the feet: check that
    # the feet's exact point is inside the box, on the object's side of the image, and at the box's bottom
    x1, x2, y2 = (np.array(table[k]) for k in ("x1", "x2", "y2"))
    assert np.all((x1 < exact[:, 0]) & (exact[:, 0] < x2)) and np.all(np.sign(x1 + x2 - 2 * 639.5) == np.sign(x))
    toes = scene.camera.project_ground(np.column_stack([x, y]) * (1 - 0.2 / dist)[:, None])  # 0.2 m nearer
    assert np.all(y2 >= exact[:, 1] - 1.0) and np.all(y2 <= toes[:, 1] + 1.0)


@pytest.mark.parametrize("keys, message", [
    ({"layout": '"spiral"'}, "calibration.layout"),
    ({"layout": '"zigzag"', "lateral_m": "-1.0"}, "calibration.layout"),
    ({"layout": '"line"', "lateral_m": "2.0"}, "calibration.layout"),
    ({"layout": '"zigzag"', "lateral_m": "40.0"}, "outside the view"),
])  # fmt: skip
def test_bad_layout_is_refused_with_one_line(tmp_path, capsys, keys, message):
    folder = copy_scene(tmp_path, small=False)
    _with(folder, **keys)
    out = tmp_path / "out"
    assert main(["generate", str(folder), "--out", str(out), "--seconds", "1", "--seed", "0", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("simgen: error: scene.toml: ") and message in err, err
    assert not out.exists()
