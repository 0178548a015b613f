"""Pedestrian walks: seeded routes, speeds, waits and people, and where everyone is at time t.

The scene has ``agents.count`` slots (one articulated person each, humanoid.py). A slot hosts one
walk after another: a route drawn by weight, shifted sideways, maybe reversed, walked at constant
speed with at most one wait on the way (speed 0: at the route's first corner in the walking
direction, the kerb before a crossing in the shipped scenes, or at a random point of a straight
route), then a pause off the scene. Each walk is a new agent: ``agent_id = slot + count * j`` for
the slot's j-th walk, never reused. Slot k's walks come from ``keyed_generator(seed, scene, "slot", k)``
and each agent's look from ``keyed_generator(seed, scene, "person", agent_id)`` alone, so they do not
depend on the duration, on the other slots, or on where a run was resumed.
"""
from __future__ import annotations

import bisect
import dataclasses
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from simgen.humanoid import LIFT, PARTS, Person, draw_person, gait, pose, stride_length, to_world
from simgen.rng import keyed_generator
from simgen.scene import Scene

ARM_SWING = 0.35  # arm swing amplitude at 1.4 m/s, radians, proportional to the walking speed


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

    @cached_property
    def stride(self) -> float:
        return float(stride_length(self.person.height, self.speed))

    @property
    def t_end(self) -> float:
        stop = self.wait + self.stride / (2 * self.speed) if self.wait > 0 else 0.0  # the wait and its two half steps
        return self.t_start + self.cum[-1] / self.speed + stop

    def gait(self, t: float) -> tuple[float, float, float, np.ndarray]:
        """At time t: arc length walked (m, clamped to the route), speed (m/s), the left sole's offset ahead of
        the foot point (m) and the soles' lifts (2,) m (humanoid.pose).

        A stop at arc length ``stop_at`` (gait phase 0 there: the left foot ahead, the right one behind, both
        down) is a closing half step (the right foot swings beside the left one while the body moves S/4 at
        half speed), ``wait`` seconds standing with the feet together (speed 0), and an opening half step
        (the left foot swings S/2 ahead while the body moves S/4), after which the gait goes on at phase 0.
        """
        v, S, s0 = self.speed, self.stride, self.stop_at
        h = np.array([self.person.height])
        tau, half = max(t - self.t_start, 0.0), S / (2 * v)  # a half step lasts half a cycle
        u = tau - s0 / v  # time since the stop began
        if self.wait == 0 or u < 0 or u >= 2 * half + self.wait:
            after = self.wait > 0 and u >= 0  # the gait resumes at phase 0 at s0 + S/2
            s = s0 + S / 2 + (u - 2 * half - self.wait) * v if after else tau * v
            x_left, lift = gait(h, np.array([S]), np.array([(s - s0 - (S / 2 if after else 0.0)) / S]))
            return min(s, self.cum[-1]), v, float(x_left[0]), lift[0]
        up = LIFT * h[0] / 1.75
        if u < half:  # closing: the left foot stays, the right one joins it
            f = u / half
            return min(s0 + S / 4 * f, self.cum[-1]), v / 2, S / 4 * (1 - f), np.array([0.0, up * np.sin(np.pi * f)])
        if u < half + self.wait:
            return min(s0 + S / 4, self.cum[-1]), 0.0, 0.0, np.zeros(2)
        f = (u - half - self.wait) / half  # opening: the right foot stays, the left one steps out
        return min(s0 + S / 4 * (1 + f), self.cum[-1]), v / 2, S / 4 * f, np.array([up * np.sin(np.pi * f), 0.0])

    def at(self, t: float) -> tuple[float, float, float]:
        """(x, y, heading) at time t (clamped to the route), metres and radians."""
        cum = self.cum
        s = self.gait(t)[0]
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
    person = draw_person(keyed_generator(seed, scene.name, "person", agent_id))
    return Walk(agent_id, points, speed, t_start, person, stop_at, lo + wait * (hi - lo) if waits else 0.0)


class Crowd:
    """All walks of a run up to ``t_to`` seconds, and the agents' state at any time before it."""

    def __init__(self, scene: Scene, seed: int, t_to: float) -> None:
        self.count = scene.agent_count
        self.slots: list[list[Walk]] = []
        for k in range(self.count):
            rng = keyed_generator(seed, scene.name, "slot", k)
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
        """The active agents at time t, in slot order, posed (humanoid.pose, Walk.gait)."""
        rows = []
        for k, walks in enumerate(self.slots):
            j = bisect.bisect_right(self._starts[k], t) - 1
            if j >= 0 and t < walks[j].t_end:
                w = walks[j]
                _, speed, x_left, lift = w.gait(t)
                rows.append((k, w, *w.at(t), speed, x_left, lift))
        if not rows:
            empty = np.zeros((0, len(PARTS)))
            return AgentState(np.zeros(0, np.int32), np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                              np.zeros((0, len(PARTS), 2, 3)), empty, np.zeros((0, len(PARTS), 4)))
        slot, walks, *numbers = zip(*rows)
        x, y, heading, speed, x_left, lift = map(np.array, numbers)
        height, width = (np.array([getattr(w.person, a) for w in walks]) for a in ("height", "width"))
        cruise = np.array([w.speed for w in walks])
        segments, radii = pose(height, width, np.array([w.stride for w in walks]), x_left, lift, ARM_SWING * cruise / 1.4)
        xy = np.column_stack([x, y])
        return AgentState(np.array([w.agent_id for w in walks], np.int32), np.array(slot, np.int64), xy, heading, speed,
                          to_world(segments, xy, heading), radii, np.stack([w.person.rgba for w in walks]))
