"""simgen: MuJoCo synthetic traffic scenes and dataset generator.

Importing simgen changes nothing outside it: the OpenGL backend's default (``MUJOCO_GL=egl``) is set by
simgen.backend when it imports mujoco, the one module that does.
"""
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("homocal")  # simgen ships in the homocal distribution: pyproject.toml's version, as homocal's
except PackageNotFoundError:  # a checkout on sys.path that pip never installed
    __version__ = "0+unknown"
