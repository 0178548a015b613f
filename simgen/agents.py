"""Pedestrian walks: seeded routes, speeds, waits and people, and where everyone is at time t.

The scene has ``agents.count`` slots (one articulated person each, humanoid.py). A slot hosts one
walk after another: a route drawn by weight, shifted sideways, maybe reversed, walked at constant
speed with at most one wait on the way (speed 0: at the route's first corner in the walking
direction, the kerb before a crossing in the shipped scenes, or at a random point of a straight
route), then a pause off the scene. Each walk is a new agent: ``agent_id = slot + count * j`` for
the slot's j-th walk, never reused. Slot k's walks come from ``keyed_rng(seed, scene, "slot", k)``
and each agent's look from ``keyed_rng(seed, scene, "person", agent_id)`` alone, so they do not
depend on the duration, on the other slots, or on where a run was resumed.
"""
from __future__ import annotations

import bisect
import dataclasses
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from simgen.humanoid import PARTS, Person, draw_person, pose, stride_length, to_world
from simgen.rng import keyed_rng
from simgen.scene import Scene

ARM_SWING = 0.35  # arm swing amplitude at 1.4 m/s, radians, proportional to speed (arms hang while waiting)


@dataclass(frozen=True)
class AgentState:
    """Active agents at one time, A of them, G = len(humanoid.PARTS) geoms each.

    Attributes:
        agent_id: (A,) int32; slot: (A,) int64 slot of each agent.
        xy: (A, 2) foot points, m; heading: (A,) rad; speed: (A,) m/s (0 while waiting).
        segments: (A, G, 2, 3) world segment ends of the geoms, m; radii: (A, G) m; rgba: (A, G, 4).
    """

    agent_id: np.ndarray
    slot: np.ndarray
    xy: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    segments: np.ndarray
    radii: np.ndarray
    rgba: np.ndarray


@dataclass(frozen=True)
class Walk:
    """One agent walking polyline ``points`` (N, 2) metres at ``speed`` m/s from ``t_start`` s,
    waiting ``wait`` s at arc length ``stop_at`` m on the way."""

    agent_id: int
    points: np.ndarray
    speed: float
    t_start: float
    person: Person
    stop_at: float = 0.0
    wait: float = 0.0

    @cached_property
    def cum(self) -> np.ndarray:
        """(N,) arc length at each vertex, metres."""
        return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(self.points, axis=0).T))])

    @property
    def t_end(self) -> float:
        return self.t_start + self.cum[-1] / self.speed + self.wait

    @cached_property
    def stride(self) -> float:
        return float(stride_length(self.person.height, self.speed))

    def walked(self, t: float) -> tuple[float, bool]:
        """(arc length walked at time t, clamped to the route, metres; whether the agent is waiting)."""
        s = max(t - self.t_start, 0.0) * self.speed
        waiting = self.stop_at <= s < self.stop_at + self.wait * self.speed
        s = self.stop_at if waiting else s if s < self.stop_at else s - self.wait * self.speed
        return min(s, self.cum[-1]), waiting

    def at(self, t: float) -> tuple[float, float, float]:
        """(x, y, heading) at time t (clamped to the route), metres and radians."""
        cum = self.cum
        s = self.walked(t)[0]
        i = min(int(np.searchsorted(cum, s, side="right")) - 1, len(cum) - 2)
        d = self.points[i + 1] - self.points[i]
        p = self.points[i] + d * ((s - cum[i]) / (cum[i + 1] - cum[i]))
        return float(p[0]), float(p[1]), float(np.arctan2(d[1], d[0]))


def _draw_walk(scene: Scene, seed: int, rng: np.random.Generator, agent_id: int, t_start: float) -> Walk:
    weights = np.array([r.weight for r in scene.routes])
    route = scene.routes[rng.choice(len(scene.routes), p=weights / weights.sum())]
    points = route.points + rng.uniform(-0.5, 0.5, size=2) * route.width_m
    if route.both_ways and rng.random() < 0.5:
        points = points[::-1]
    speed, waits, wait, where = float(rng.uniform(*scene.speed_mps)), rng.random() < route.wait_share, *rng.random(2)
    length = float(np.hypot(*np.diff(points, axis=0).T).sum())
    stop_at = float(np.hypot(*(points[1] - points[0]))) if len(points) > 2 else where * length
    lo, hi = route.wait_s
    person = draw_person(keyed_rng(seed, scene.name, "person", agent_id))
    return Walk(agent_id, points, speed, t_start, person, stop_at, lo + wait * (hi - lo) if waits else 0.0)


class Crowd:
    """All walks of a run up to ``t_to`` seconds, and the agents' state at any time before it."""

    def __init__(self, scene: Scene, seed: int, t_to: float) -> None:
        self.count = scene.agent_count
        self.slots: list[list[Walk]] = []
        for k in range(self.count):
            rng = keyed_rng(seed, scene.name, "slot", k)
            walk = _draw_walk(scene, seed, rng, k, 0.0)
            # the first walk is under way at t = 0: its start is spread over one walk's duration
            walk = dataclasses.replace(walk, t_start=-rng.uniform(0.0, walk.t_end))
            walks = [walk]
            while walks[-1].t_end < t_to:
                start = walks[-1].t_end + rng.uniform(*scene.gap_s)
                walks.append(_draw_walk(scene, seed, rng, k + self.count * len(walks), start))
            self.slots.append(walks)
        self._starts = [[w.t_start for w in walks] for walks in self.slots]

    def state(self, t: float) -> AgentState:
        """The active agents at time t, in slot order, posed (humanoid.pose; the gait phase is 0 where
        the walk stops, so a waiting agent stands on both feet, one ahead of the other, arms hanging)."""
        rows = []
        for k, walks in enumerate(self.slots):
            j = bisect.bisect_right(self._starts[k], t) - 1
            if j >= 0 and t < walks[j].t_end:
                w = walks[j]
                s, waiting = w.walked(t)
                rows.append((k, w, *w.at(t), 0.0 if waiting else w.speed, (s - w.stop_at) / w.stride))
        if not rows:
            empty = np.zeros((0, len(PARTS)))
            return AgentState(np.zeros(0, np.int32), np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                              np.zeros((0, len(PARTS), 2, 3)), empty, np.zeros((0, len(PARTS), 4)))
        slot, walks, *numbers = zip(*rows)
        x, y, heading, speed, phase = map(np.array, numbers)
        height, width = (np.array([getattr(w.person, a) for w in walks]) for a in ("height", "width"))
        segments, radii = pose(height, width, np.array([w.stride for w in walks]), phase, ARM_SWING * speed / 1.4)
        xy = np.column_stack([x, y])
        return AgentState(np.array([w.agent_id for w in walks], np.int32), np.array(slot, np.int64), xy, heading, speed,
                          to_world(segments, xy, heading), radii, np.stack([w.person.rgba for w in walks]))
