"""MP4 video in segments: one H.264 file per chunk, joined at the end without re-encoding.

Frames are converted to yuv420p by OpenCV (BT.601, video range, as ffmpeg assumes) and piped to
imageio's ffmpeg, which then only encodes. ``-fflags +bitexact`` and no metadata make the bytes
depend only on the frames, so a resumed run's video equals an uninterrupted run's.
"""
from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import cv2
import imageio_ffmpeg
import numpy as np

BITEXACT = ["-fflags", "+bitexact", "-map_metadata", "-1"]
ENCODE = ["-preset", "ultrafast", "-crf", "20", "-threads", "1", "-flags:v", "+bitexact", *BITEXACT]
"""x264 on one thread: its output depends on its thread count, which would otherwise follow the machine's cores."""


class SegmentWriter:
    """Write (H, W, 3) uint8 RGB frames to one MP4 file (H and W even); a context manager."""

    def __init__(self, path: Path, width: int, height: int, fps: int) -> None:
        self._gen = imageio_ffmpeg.write_frames(
            str(path), (width, height), pix_fmt_in="yuv420p", pix_fmt_out="yuv420p", fps=fps, codec="libx264",
            quality=None, macro_block_size=1, output_params=ENCODE, ffmpeg_log_level="error",
        )  # fmt: skip
        self._gen.send(None)

    def append(self, rgb: np.ndarray) -> None:
        self._gen.send(cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_I420).tobytes())

    def close(self) -> None:
        self._gen.close()

    def __enter__(self) -> "SegmentWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def concat(segments: list[Path], out: Path) -> None:
    """Join MP4 segments (same codec and size) into ``out`` by stream copy (the list of segments ffmpeg
    reads is a file in the system's temporary folder)."""
    with tempfile.NamedTemporaryFile("w", suffix=".txt", encoding="utf-8") as listing:
        listing.write("".join(f"file '{p.resolve()}'\n" for p in segments))
        listing.flush()
        done = subprocess.run(
            [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-f", "concat", "-safe", "0",
             "-i", listing.name, "-c", "copy", *BITEXACT, str(out)],
            capture_output=True, text=True,
        )  # fmt: skip
    if done.returncode:
        reason = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise OSError(f"{out}: ffmpeg could not join the video segments ({reason})")
