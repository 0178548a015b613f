"""Articulated pedestrians: the gait (stance feet stay put, the feet's midpoint is the foot point), the
rendered feet against the ground truth at 10 m, variety, and waits at crossings."""
from __future__ import annotations

import numpy as np
import pytest

from simgen.agents import AgentState, Crowd
from simgen.humanoid import FEET, FOOT_R, HEIGHT_M, PARTS, WIDTH, draw_person, gait, pose, stride_length, to_world
from simgen.rng import keyed_generator
from simgen.scene import load_scene

from scene_copies import SCENES


def _walk(height: float, speed: float, times: np.ndarray, heading: float = 0.7):
    """World segments (T, G, 2, 3) of one person walking a straight line from the origin at ``speed``."""
    s = speed * times
    xy = np.column_stack([np.cos(heading) * s, np.sin(heading) * s])
    n = len(times)
    stride = stride_length(np.full(n, height), np.full(n, speed))
    segments, _ = pose(np.full(n, height), np.ones(n), stride, *gait(np.full(n, height), stride, s / stride), np.full(n, 0.3))
    return to_world(segments, xy, np.full(n, heading))


@pytest.mark.parametrize("height, speed", [(1.50, 0.9), (1.75, 1.4), (1.95, 1.8)])
def test_stance_foot_stays_where_it_landed(height, speed):
    """Every foot on the ground keeps its world position until it lifts: no sliding; it swings at twice the speed."""
    dt = 0.002
    times = np.arange(0.0, 3.0, dt)
    segments = _walk(height, speed, times)
    k = height / 1.75
    for f in FEET:
        centre = segments[:, f].mean(axis=1)  # (T, 3) sole centre
        down = np.isclose(centre[:, 2], FOOT_R * k)
        moved = np.linalg.norm(np.diff(centre[:, :2], axis=0), axis=1)
        stance = down[1:] & down[:-1]
        assert 0.4 < stance.mean() < 0.6
        assert np.all(moved[stance] < 1e-9)
        np.testing.assert_allclose(moved[~down[1:] & ~down[:-1]] / dt, 2 * speed, rtol=0.01)  # swing, linear


def test_feet_midpoint_is_the_foot_point_and_sizes_vary():
    rng = np.random.default_rng(1)
    n = 500
    height, width = rng.uniform(*HEIGHT_M, n), rng.uniform(*WIDTH, n)
    stride = rng.uniform(0.0, 1.7, n)
    segments, radii = pose(height, width, stride, *gait(height, stride, rng.random(n)), rng.uniform(0, 0.5, n))
    mid = segments[:, list(FEET)].mean(axis=(1, 2))
    np.testing.assert_allclose(mid[:, :2], 0.0, atol=1e-12)
    top = (segments[..., 2] + radii[..., None]).max(axis=(1, 2))
    bottom = (segments[..., 2] - radii[..., None]).min(axis=(1, 2))
    assert np.all(top <= height + 1e-9) and np.all(top > 0.9 * height)  # full height when standing tall
    np.testing.assert_allclose(bottom, 0.0, atol=1e-12)  # the lowest foot touches the ground
    standing, _ = pose(height, width, np.zeros(n), np.zeros(n), np.zeros((n, 2)), np.zeros(n))
    np.testing.assert_allclose((standing[..., 2] + radii[..., None]).max(axis=(1, 2)), height, atol=1e-9)
    thigh = np.linalg.norm(segments[:, 8, 1] - segments[:, 8, 0], axis=1)  # legs keep their length in every pose
    np.testing.assert_allclose(thigh, 0.43 * height / 1.75, rtol=1e-9)


def test_people_vary_within_their_ranges():
    people = [draw_person(keyed_generator(0, "s", "person", i)) for i in range(300)]
    height = np.array([p.height for p in people])
    assert HEIGHT_M[0] <= height.min() < 1.58 and 1.85 < height.max() <= HEIGHT_M[1]
    shirts = {tuple(p.rgba[1]) for p in people}
    assert len(shirts) >= 10 and all(p.rgba.shape == (len(PARTS), 4) for p in people)
    assert draw_person(keyed_generator(0, "s", "person", 3)).rgba.tolist() == people[3].rgba.tolist()  # seeded


@pytest.fixture(scope="module")
def stage():
    from simgen.stage import Stage

    with Stage(load_scene(SCENES / "scene1"), seed=0, t_end=1.0) as s:
        yield s


# foot point 10 m from the camera; both feet on the ground: double support (phase 0, 0.5) and standing (stride 0)
CASES = [(h, heading, stride, phase) for h in (1.5, 1.95) for heading in (0.0, 1.2, np.pi / 2, 3.0, -2.0)
         for stride, phase in ((1.2, 0.0), (1.2, 0.5), (0.0, 0.0))]


@pytest.mark.generate
@pytest.mark.slow  # 30 segmentation renders of scene1 at 1280x720
def test_rendered_feet_agree_with_the_foot_point_at_10_m(stage):
    """Each foot found in a feet-only segmentation render (MuJoCo offscreen), its pixels back-projected to the
    plane of the foot's axis (z = foot radius); the midpoint of the two feet, projected, lies within 2 px of the
    ground truth's (u, v)."""
    camera, model = stage.scene.camera, stage.model
    slot, errors = 0, []
    geoms = stage.run_model.slot_geom[slot]
    groups = model.geom_group.copy()
    model.geom_group[np.setdiff1d(geoms, geoms[list(FEET)])] = 3  # group 3 is hidden by default
    try:
        for height, heading, stride, phase in CASES:
            xy = np.array([[2.0, np.sqrt(100.0 - 4.0)]])  # 10 m from the camera's ground point
            h, st = np.array([height]), np.array([stride])
            segments, radii = pose(h, np.ones(1), st, *gait(h, st, np.array([phase])), np.array([0.3]))
            person = draw_person(keyed_generator(0, "feet", height))
            state = AgentState(np.array([5], np.int32), np.array([slot]), xy, np.array([heading]), np.ones(1),
                               to_world(segments, xy, np.array([heading])), radii, person.rgba[None])
            stage.place(state)
            seen = stage.renderer.segmentation()
            feet = []
            for g in geoms[list(FEET)]:
                rows, cols = np.nonzero(seen == g)
                assert len(rows) > 15, (height, heading, stride, phase)
                ground = camera.ray_to_ground(np.column_stack([cols, rows]).astype(float))
                feet.append((ground * (1 - FOOT_R * height / 1.75 / camera.mount_height_m)).mean(axis=0))
            rendered = camera.project_ground(np.mean(feet, axis=0))[0]
            errors.append(np.hypot(*(rendered - camera.project_ground(xy)[0])))
    finally:
        model.geom_group[:] = groups
    assert max(errors) < 2.0, errors


def test_walkers_stop_at_the_kerb_without_sliding():
    """A waiting walker closes its feet, stands (speed 0) and steps out again: every foot on the ground stays
    put, the feet's midpoint stays the foot point, and the route position never jumps."""
    scene = load_scene(SCENES / "scene1")
    crowd = Crowd(scene, seed=3, t_to=120.0)
    walks = [w for slot in crowd.slots for w in slot]
    waiting = [w for w in walks if w.wait > 0]
    assert 0.1 < len(waiting) / len(walks) < 0.5
    crossing = [w for w in waiting if len(w.points) > 2]
    assert crossing and all(np.isclose(w.stop_at, np.hypot(*(w.points[1] - w.points[0]))) for w in crossing)
    w = crossing[0]
    t_stop, dt = w.t_start + w.stop_at / w.speed, 0.02
    times = np.arange(t_stop - 1.0, t_stop + w.wait + w.stride / w.speed + 1.0, dt)
    xy, feet, speed, heading = [], [], [], []
    for t in times:
        state = crowd.state(t)
        k = list(state.agent_id).index(w.agent_id)
        xy.append(state.xy[k])
        feet.append(state.segments[k, list(FEET)].mean(axis=1))  # (2, 3) sole centres
        speed.append(state.speed[k])
        heading.append(state.heading[k])
    xy, feet, speed, heading = map(np.array, (xy, feet, speed, heading))
    np.testing.assert_allclose(feet[:, :, :2].mean(axis=1), xy, atol=1e-9)  # the midpoint is the foot point
    step = np.hypot(*np.diff(xy, axis=0).T)
    assert np.all(step <= w.speed * dt * (1 + 1e-6))  # no jump
    standing = speed == 0.0
    assert standing.sum() * dt == pytest.approx(w.wait, abs=2 * dt)
    assert np.all(step[standing[1:] & standing[:-1]] == 0.0)
    across = np.diff(w.points[1:3], axis=0)[0] / np.hypot(*np.diff(w.points[1:3], axis=0)[0])
    np.testing.assert_allclose((feet[standing, 0, :2] - feet[standing, 1, :2]) @ across, 0.0, atol=1e-9)  # side by side
    down = np.isclose(feet[:, :, 2], FOOT_R * w.person.height / 1.75)
    straight = np.diff(heading) == 0.0  # turning the corner swings the feet round the body
    for f in range(2):  # a foot on the ground at two samples in a row has not moved
        moved = np.hypot(*np.diff(feet[:, f, :2], axis=0).T)
        assert np.all(moved[down[1:, f] & down[:-1, f] & straight] < 1e-9)
    assert (down[1:, 0] & down[:-1, 0] & straight).sum() * dt > w.wait  # (the check saw the standing and the steps)
