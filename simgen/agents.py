"""Pedestrian walks: seeded routes and speeds, and where everyone is at time t.

The scene has ``agents.count`` slots (one mocap body each). A slot hosts one walk after another:
a route drawn by weight, shifted sideways, maybe reversed, walked at constant speed, then a pause.
Each walk is a new agent: ``agent_id = slot + count * j`` for the slot's j-th walk, never reused.
Slot k's walks come from ``keyed_rng(seed, scene, "slot", k)`` alone, so they do not depend on the
duration, on the other slots, or on where a run was resumed.
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from simgen.rng import keyed_rng
from simgen.scene import Scene


@dataclass(frozen=True)
class Walk:
    """One agent walking polyline ``points`` (N, 2) metres at ``speed`` m/s from ``t_start`` s."""

    agent_id: int
    points: np.ndarray
    speed: float
    t_start: float

    @cached_property
    def cum(self) -> np.ndarray:
        """(N,) arc length at each vertex, metres."""
        return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(self.points, axis=0).T))])

    @property
    def t_end(self) -> float:
        return self.t_start + self.cum[-1] / self.speed

    def at(self, t: float) -> tuple[float, float, float]:
        """(x, y, heading) at time t (clamped to the route), metres and radians."""
        cum = self.cum
        s = min(max(t - self.t_start, 0.0) * self.speed, cum[-1])
        i = min(int(np.searchsorted(cum, s, side="right")) - 1, len(cum) - 2)
        d = self.points[i + 1] - self.points[i]
        p = self.points[i] + d * ((s - cum[i]) / (cum[i + 1] - cum[i]))
        return float(p[0]), float(p[1]), float(np.arctan2(d[1], d[0]))


def _draw_walk(scene: Scene, rng: np.random.Generator, agent_id: int, t_start: float) -> Walk:
    weights = np.array([r.weight for r in scene.routes])
    route = scene.routes[rng.choice(len(scene.routes), p=weights / weights.sum())]
    points = route.points + rng.uniform(-0.5, 0.5, size=2) * route.width_m
    if route.both_ways and rng.random() < 0.5:
        points = points[::-1]
    return Walk(agent_id, points, float(rng.uniform(*scene.speed_mps)), t_start)


class Crowd:
    """All walks of a run up to ``t_to`` seconds, and the agents' state at any time before it."""

    def __init__(self, scene: Scene, seed: int, t_to: float) -> None:
        self.count = scene.agent_count
        self.slots: list[list[Walk]] = []
        for k in range(self.count):
            rng = keyed_rng(seed, scene.name, "slot", k)
            walk = _draw_walk(scene, rng, k, 0.0)
            # the first walk is under way at t = 0: its start is spread over one walk's duration
            walk = Walk(walk.agent_id, walk.points, walk.speed, -rng.uniform(0.0, walk.t_end))
            walks = [walk]
            while walks[-1].t_end < t_to:
                start = walks[-1].t_end + rng.uniform(*scene.gap_s)
                walks.append(_draw_walk(scene, rng, k + self.count * len(walks), start))
            self.slots.append(walks)
        self._starts = [[w.t_start for w in walks] for walks in self.slots]

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per slot at time t: agent_id (S,) int32 (-1 if idle), xy (S, 2) m, heading (S,) rad, speed (S,) m/s."""
        ids = np.full(self.count, -1, np.int32)
        xy = np.full((self.count, 2), np.nan)
        heading = np.full(self.count, np.nan)
        speed = np.full(self.count, np.nan)
        for k, walks in enumerate(self.slots):
            j = bisect.bisect_right(self._starts[k], t) - 1
            if j >= 0 and t < walks[j].t_end:
                w = walks[j]
                ids[k], speed[k] = w.agent_id, w.speed
                xy[k, 0], xy[k, 1], heading[k] = w.at(t)
        return ids, xy, heading, speed
