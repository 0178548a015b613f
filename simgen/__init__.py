"""simgen: MuJoCo synthetic traffic scenes and dataset generator.

Importing simgen makes EGL the default OpenGL backend (``MUJOCO_GL=egl``) unless the environment
already chose one (``osmesa``, ``glfw``); it must happen before mujoco is imported.
"""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"
