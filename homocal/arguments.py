"""Command-line numbers checked where they are parsed (shared by the homocal and simgen commands): a bad value
is refused by argparse as one line naming the flag ("argument --seed: must be an integer >= 0, got -1")."""
from __future__ import annotations

import argparse
import math
import numbers
from pathlib import Path

from homocal.geometry import CameraModel, read_camera


def number(kind: type, low: float, high: float = math.inf, low_open: bool = False):
    """argparse type: a finite ``kind`` (int or float) in [low, high] (``(low, high]`` if low_open)."""
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None
        if not within(value, low, high, low_open):
            what = "an integer" if kind is int else "a finite number"
            raise argparse.ArgumentTypeError(f"must be {what} {range_text(low, high, low_open)}, got {text}")
        return value
    return parse


def within(value: float, low: float, high: float = math.inf, low_open: bool = False) -> bool:
    """Whether value is finite and in [low, high] ((low, high] if low_open); an integer of any size (math.isfinite
    would overflow on one beyond a float's range)."""
    return (isinstance(value, numbers.Integral) or math.isfinite(value)) and (value > low if low_open else value >= low) and value <= high


def range_text(low: float, high: float = math.inf, low_open: bool = False) -> str:
    """[low, high] as an error message says it: "in [0, 100]", "in (0, 1000]", ">= 1", "> 0"."""
    if math.isfinite(high):
        return f"in {'(' if low_open else '['}{bound_text(low)}, {bound_text(high)}]"
    return f"{'>' if low_open else '>='} {bound_text(low)}"


def bound_text(bound: float) -> str:
    """A bound as an error message shows it: 2**64 - 1, 1000, 0.5."""
    if isinstance(bound, int) and bound > 2**32 and (bound + 1).bit_count() == 1:
        return f"2**{bound.bit_length()} - 1"
    return str(bound) if isinstance(bound, int) else f"{bound:g}"


SEED = number(int, 0, 2**64 - 1)  # a run seed: numpy's SeedSequence and the keyed generators take 64 bits


def xy_pair(text: str) -> tuple[float, float]:
    """argparse type: two finite numbers ``X,Y`` (a point: metres or pixels, as the flag says)."""
    try:
        x, y = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected two numbers X,Y, got {text!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise argparse.ArgumentTypeError(f"expected two finite numbers X,Y, got {text!r}")
    return x, y


CAMERA_JSON_HELP = ("the camera: a dataset's camera.json or a lens.json (K, distortion, image_size); the image points "
                    "given are undistorted with its lens before any homography (docs/real-camera.md)")


def camera_json(path: Path | None) -> CameraModel | None:
    """--camera-json's camera (homocal.geometry.read_camera), None without the flag; ValueError "--camera-json
    FILE: key: problem" for a bad file."""
    if path is None:
        return None
    try:
        return read_camera(path)
    except ValueError as e:
        raise ValueError(f"--camera-json {e}") from None
