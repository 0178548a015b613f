"""Articulated pedestrians: body proportions, appearance and a walking gait whose feet do not slide.

A person is ``len(PARTS)`` capsules and spheres, each a segment ``(p0, p1)`` with a radius (a sphere
when p0 == p1), posed in the body frame: x forward (the heading), y left, z up, the origin on the
ground at the person's **foot point**: the ground projection of the pelvis, which is, at every
instant, also the midpoint of the two feet's ground points (sole centres).

The gait, for stride S (two steps) and phase phi = (s / S) mod 1 of the distance s walked
(``gait``): the left sole centre is on the ground at x_L = S (1/4 - phi) while phi < 1/2
(stance: the body advances by S phi, so the foot stays where it landed in the world), and at
x_L = S (phi - 3/4), lifted by ``LIFT * k * sin(2 pi (phi - 1/2))``, while phi >= 1/2 (swing, at
twice the walking speed); the right foot follows half a cycle later, x_R(phi) = x_L(phi + 1/2) =
-x_L(phi). So x_L + x_R = 0 and the feet are at y = +-hip_y: their midpoint is the foot point,
whatever the phase. ``pose`` takes x_L and the lifts, so that a walker can also stop (agents.py):
a closing half step brings the rear foot beside the front one, the person stands with its feet
together, and an opening half step starts the gait again, x_R = -x_L all the while. The arms swing
against the legs, in proportion to x_L. The legs reach their ankles by two-link inverse kinematics;
the pelvis sinks where the feet are far apart so that no leg is stretched beyond 98.5 % of its length.
Lengths are in units of k = height / 1.75 m; radii also scale with the body width factor.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# (name, colour key) of each geom, in model order; the head is a sphere, everything else a capsule
PARTS = (
    ("head", "skin"), ("torso", "shirt"), ("shoulders", "shirt"), ("pelvis", "trousers"),
    ("upper_arm_l", "shirt"), ("forearm_l", "sleeve"), ("upper_arm_r", "shirt"), ("forearm_r", "sleeve"),
    ("thigh_l", "trousers"), ("shin_l", "trousers"), ("thigh_r", "trousers"), ("shin_r", "trousers"),
    ("foot_l", "shoes"), ("foot_r", "shoes"),
)  # fmt: skip
FEET = (12, 13)  # indices of the feet in PARTS
SHIRTS = ((0.80, 0.15, 0.12), (0.12, 0.30, 0.75), (0.90, 0.75, 0.15), (0.20, 0.55, 0.25), (0.85, 0.85, 0.85),
          (0.15, 0.15, 0.18), (0.55, 0.20, 0.60), (0.95, 0.45, 0.10), (0.35, 0.65, 0.80), (0.60, 0.10, 0.25),
          (0.45, 0.40, 0.30), (0.95, 0.60, 0.70))
TROUSERS = ((0.10, 0.12, 0.25), (0.20, 0.20, 0.22), (0.35, 0.28, 0.20), (0.45, 0.45, 0.50), (0.25, 0.35, 0.55),
            (0.70, 0.65, 0.55))
SKINS = ((0.93, 0.78, 0.65), (0.78, 0.57, 0.42), (0.55, 0.38, 0.26), (0.36, 0.24, 0.17))
SHOES = ((0.08, 0.08, 0.08), (0.90, 0.90, 0.90), (0.40, 0.25, 0.15), (0.20, 0.25, 0.45))

HEIGHT_M = (1.50, 1.95)  # clipped normal, mean 1.71 m, sd 0.09 m
WIDTH = (0.85, 1.20)  # uniform body width factor
# body dimensions at k = 1 (height 1.75 m), metres
FOOT_R, FOOT_HALF, ANKLE_BACK, ANKLE_Z = 0.040, 0.085, 0.045, 0.075
SHIN, THIGH, HIP_Y = 0.42, 0.43, 0.085
REACH = 0.985  # the longest a leg gets, as a fraction of shin + thigh
LIFT = 0.07  # swing foot clearance
ARM_UP, ARM_LOW, SHOULDER_Y, SHOULDER_Z = 0.29, 0.27, 0.17, 0.52  # shoulder height above the hip
TORSO_Z, TORSO_R, HEAD_R = (0.07, 0.45), 0.14, 0.11
STRIDE = 0.75  # stride = STRIDE * height * sqrt(speed / 1.4 m/s)
STAND_HIP = ANKLE_Z + np.sqrt((REACH * (THIGH + SHIN)) ** 2 - ANKLE_BACK**2)  # hip height standing, feet together


@dataclass(frozen=True)
class Person:
    """One pedestrian's look: height (m), width factor, (len(PARTS), 4) rgba of its geoms."""

    height: float
    width: float
    rgba: np.ndarray


def draw_person(rng: np.random.Generator) -> Person:
    """Height (clipped normal), width factor and clothing colours from the palettes."""
    height = float(np.clip(rng.normal(1.71, 0.09), *HEIGHT_M))
    width = float(rng.uniform(*WIDTH))
    colours = {key: np.array(pal[rng.integers(len(pal))]) for key, pal in
               (("shirt", SHIRTS), ("trousers", TROUSERS), ("skin", SKINS), ("shoes", SHOES))}
    colours["sleeve"] = colours["skin"] if rng.random() < 0.4 else colours["shirt"]  # short sleeves
    return Person(height, width, np.array([[*colours[key], 1.0] for _, key in PARTS]))


def stride_length(height: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Stride (two steps), metres, of people ``height`` m walking at ``speed`` m/s > 0; arrays broadcast."""
    return STRIDE * np.asarray(height) * np.sqrt(np.asarray(speed) / 1.4)


def _leg(hip: np.ndarray, ankle: np.ndarray, thigh: np.ndarray, shin: np.ndarray) -> np.ndarray:
    """Knee (A, 3) of legs from hip to ankle (A, 3), knees bending forward (+x), by the law of cosines."""
    d_vec = ankle - hip
    d = np.linalg.norm(d_vec, axis=1)
    u = d_vec / d[:, None]
    n = np.column_stack([-u[:, 2], np.zeros(len(u)), u[:, 0]])  # u turned 90 deg towards +x in the x-z plane
    cos_a = np.clip((thigh**2 + d**2 - shin**2) / (2 * thigh * d), -1.0, 1.0)
    return hip + thigh[:, None] * (cos_a[:, None] * u + np.sqrt(1 - cos_a**2)[:, None] * n)


def gait(height: np.ndarray, stride: np.ndarray, phase: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Walking: the left sole's offset x_L (A,) m ahead of the foot point and the lifts (A, 2) m of the
    left and right soles, for people ``height`` (A,) m with ``stride`` (A,) m at gait ``phase`` (A,) (module docstring)."""
    stride, phase = np.asarray(stride, float), np.asarray(phase, float) % 1.0
    swing = phase >= 0.5  # the left foot's swing; the right one swings while phase < 1/2
    x_left = np.where(swing, stride * (phase - 0.75), stride * (0.25 - phase))
    up = LIFT * np.asarray(height, float) / 1.75 * np.abs(np.sin(2 * np.pi * phase))  # the swinging foot's lift
    return x_left, np.column_stack([np.where(swing, up, 0.0), np.where(swing, 0.0, up)])


def pose(height: np.ndarray, width: np.ndarray, stride: np.ndarray, x_left: np.ndarray, lift: np.ndarray,
         arm_swing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame segments of A people (module docstring).

    Args:
        height: (A,) m; width: (A,) factor; stride: (A,) m (stride_length; 0: standing, arms still);
        x_left: (A,) m the left sole's offset ahead of the foot point (the right one's is -x_left);
        lift: (A, 2) m of the left and right soles above the ground; arm_swing: (A,) arm amplitude, radians.
    Returns:
        segments (A, G, 2, 3) metres and radii (A, G) metres, G = len(PARTS).
    """
    k, kw = np.asarray(height, float) / 1.75, np.asarray(height, float) / 1.75 * np.asarray(width, float)
    stride, x_left, lift, n = np.asarray(stride, float), np.asarray(x_left, float), np.asarray(lift, float), len(k)
    feet = [np.column_stack([side * x_left, side * HIP_Y * kw, FOOT_R * k + lift[:, j]]) for j, side in enumerate((1.0, -1.0))]
    ankles = [f + np.column_stack([-ANKLE_BACK * k, np.zeros(n), (ANKLE_Z - FOOT_R) * k]) for f in feet]
    thigh, shin = THIGH * k, SHIN * k
    reach = REACH * (thigh + shin)
    hip_z = STAND_HIP * k  # never above standing height
    for a in ankles:
        hip_z = np.minimum(hip_z, a[:, 2] + np.sqrt(reach**2 - a[:, 0] ** 2))
    segs, radii = np.zeros((n, len(PARTS), 2, 3)), np.zeros((n, len(PARTS)))

    def put(i, p0, p1, r):
        segs[:, i, 0], segs[:, i, 1], radii[:, i] = p0, p1, r

    def at(x, y, z):
        return np.column_stack(np.broadcast_arrays(x, y, z))

    top = hip_z + SHOULDER_Z * k
    head = at(0, 0, top + (1.75 - HEAD_R - STAND_HIP - SHOULDER_Z) * k)  # the top at the person's height when standing
    put(0, head, head, HEAD_R * k)
    put(1, at(0, 0, hip_z + TORSO_Z[0] * k), at(0, 0, hip_z + TORSO_Z[1] * k), TORSO_R * kw)
    put(2, at(0, (SHOULDER_Y - 0.02) * kw, top), at(0, -(SHOULDER_Y - 0.02) * kw, top), 0.07 * kw)
    put(3, at(0, HIP_Y * kw, hip_z + 0.02 * k), at(0, -HIP_Y * kw, hip_z + 0.02 * k), 0.095 * kw)
    ahead = np.divide(4 * x_left, stride, out=np.zeros(n), where=stride > 0)  # +-1 at the longest step
    for j, side in enumerate((1.0, -1.0)):  # arms swing against the legs: the left arm is back when the left foot is ahead
        theta = -side * arm_swing * np.clip(ahead, -1.0, 1.0)
        bend = 0.25 + 0.3 * np.clip(theta, 0.0, None)
        shoulder = at(0, side * (SHOULDER_Y + 0.02) * kw, top)
        elbow = shoulder + ARM_UP * k[:, None] * at(np.sin(theta), 0.02 * side, -np.cos(theta))
        hand = elbow + ARM_LOW * k[:, None] * at(np.sin(theta + bend), 0.04 * side, -np.cos(theta + bend))
        put(4 + 2 * j, shoulder, elbow, 0.048 * kw)
        put(5 + 2 * j, elbow, hand, 0.040 * kw)
        hip = at(0, side * HIP_Y * kw, hip_z)
        knee = _leg(hip, ankles[j], thigh, shin)
        put(8 + 2 * j, hip, knee, 0.068 * kw)
        put(9 + 2 * j, knee, ankles[j], 0.050 * kw)
        put(FEET[j], feet[j] - at(FOOT_HALF * k, 0, 0), feet[j] + at(FOOT_HALF * k, 0, 0), FOOT_R * k)
    return segs, radii


def to_world(segments: np.ndarray, xy: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Body-frame segments (A, G, 2, 3) of people at foot points xy (A, 2) m, heading (A,) rad -> world (A, G, 2, 3)."""
    c, s = np.cos(heading)[:, None, None], np.sin(heading)[:, None, None]
    x, y, z = segments[..., 0], segments[..., 1], segments[..., 2]
    return np.stack([xy[:, 0, None, None] + c * x - s * y, xy[:, 1, None, None] + s * x + c * y, z], axis=-1)
