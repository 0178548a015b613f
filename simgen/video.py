"""MP4 video in segments: one H.264 file per chunk, joined at the end without re-encoding.

Frames are converted to yuv420p by OpenCV (BT.601, video range, as ffmpeg assumes) and piped to
ffmpeg (imageio-ffmpeg's binary), which then only encodes. ``-fflags +bitexact`` and no metadata make the bytes
depend only on the frames, so a resumed run's video equals an uninterrupted run's.
"""
from __future__ import annotations

import re
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
    """Write (H, W, 3) uint8 RGB frames to one MP4 file (H and W even); a context manager.

    ffmpeg encodes from a pipe; its messages go to a temporary file, never to the terminal, and a failure (a full
    disk while it writes the trailer, say) is one OSError naming its last message and no file (``write_atomic``
    adds the file's name).
    """

    def __init__(self, path: Path, width: int, height: int, fps: int) -> None:
        self._log = tempfile.TemporaryFile()
        self._ffmpeg = subprocess.Popen(
            [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-f", "rawvideo", "-vcodec", "rawvideo", "-s", f"{width}x{height}",
             "-pix_fmt", "yuv420p", "-r", str(fps), "-i", "-", "-an", "-vcodec", "libx264", "-pix_fmt", "yuv420p",
             "-v", "error", *ENCODE, str(path)],
            stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=self._log,
        )  # fmt: skip

    def append(self, rgb: np.ndarray) -> None:
        try:
            self._ffmpeg.stdin.write(cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_I420).tobytes())
        except BrokenPipeError:
            self._finish()  # ffmpeg has stopped: raises with its message

    def _finish(self) -> None:
        try:
            self._ffmpeg.stdin.close()
        except BrokenPipeError:
            pass  # ffmpeg has stopped: its exit status and message tell why
        code = self._ffmpeg.wait()
        self._log.seek(0)
        message = self._log.read().decode(errors="replace")
        self._log.close()
        if code:
            raise OSError(f"ffmpeg could not write the video ({last_message(message, code)})")

    def close(self) -> None:
        if not self._log.closed:
            self._finish()

    def __enter__(self) -> "SegmentWriter":
        return self

    def __exit__(self, *exc) -> None:
        if exc[0] is None:
            self.close()
        else:  # an error on our side: stop ffmpeg, the caller removes the file
            self._ffmpeg.kill()
            self._ffmpeg.wait()
            self._log.close()


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
        raise OSError(f"ffmpeg could not join the video segments ({last_message(done.stderr, done.returncode)})")


def last_message(stderr: str, code: int) -> str:
    """ffmpeg's last line without its ``[component @ address]`` prefix (or its exit status if it said nothing)."""
    lines = stderr.strip().splitlines()
    return re.sub(r"^\[[^]]*\]\s*", "", lines[-1]) if lines else f"exit status {code}"
