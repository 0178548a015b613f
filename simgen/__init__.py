"""simgen: MuJoCo synthetic traffic scenes and dataset generator.

Importing simgen changes nothing outside it: the OpenGL backend's default (``MUJOCO_GL=egl``) is set by
simgen.backend when it imports mujoco, the one module that does.
"""
from importlib.metadata import version

__version__ = version("homocal")  # simgen ships in the homocal distribution (pyproject.toml)
