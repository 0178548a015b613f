"""The one import of mujoco in simgen, guarded: the OpenGL backend, and one line naming what to install.

MuJoCo picks its offscreen backend from ``MUJOCO_GL`` when it is imported: importing this module sets
simgen's default, egl, unless the environment already chose one (osmesa is supported), then imports
mujoco. Importing mujoco with osmesa but without libosmesa6 fails inside ctypes, and making a renderer
fails without EGL's libraries; both become ``BackendError`` with a one-line message that names the
Debian packages to install. Every simgen module takes mujoco from here (``from simgen.backend import
mujoco``), so the friendly error does not depend on which module is imported first.
"""
from __future__ import annotations

import os

DEFAULT = "egl"
PACKAGES = {"egl": "libegl1 libgl1-mesa-dri libopengl0", "osmesa": "libosmesa6"}


class BackendError(RuntimeError):
    """No usable OpenGL backend; the message is one line."""


def backend() -> str:
    """The OpenGL backend mujoco renders with (``MUJOCO_GL``; simgen's default egl)."""
    return os.environ.get("MUJOCO_GL", DEFAULT)


def backend_message(err: BaseException) -> str:
    """One line: which backend failed, why (first line of the error), what to install."""
    b = backend()
    reason = (str(err).strip().splitlines() or [type(err).__name__])[0][:160]
    if b in PACKAGES:
        fix = f"apt-get install {PACKAGES[b]}"
    else:
        fix = f"set MUJOCO_GL=egl (apt-get install {PACKAGES['egl']}) or MUJOCO_GL=osmesa (apt-get install {PACKAGES['osmesa']})"
    return f"cannot render offscreen with MUJOCO_GL={b} ({type(err).__name__}: {reason}); fix: {fix}"


os.environ.setdefault("MUJOCO_GL", DEFAULT)  # what mujoco reads when imported, just below
try:
    import mujoco
except Exception as e:  # osmesa without libosmesa6 fails here with an AttributeError from ctypes
    raise BackendError(backend_message(e)) from e

__all__ = ["PACKAGES", "BackendError", "backend", "backend_message", "mujoco"]
