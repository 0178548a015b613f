"""simgen: MuJoCo synthetic traffic scenes and dataset generator.

Importing simgen makes EGL the default OpenGL backend (``MUJOCO_GL=egl``) unless the environment
already chose one (``osmesa``, ``glfw``); it must happen before mujoco is imported (simgen.backend
imports it).
"""
import os
from importlib.metadata import version

os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = version("homocal")  # simgen ships in the homocal distribution (pyproject.toml)
