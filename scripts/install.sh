#!/usr/bin/env bash
# Installs everything the project needs on a fresh Debian 12 machine (idempotent):
# the headless OpenGL libraries MuJoCo renders with (EGL and OSMesa, see data_schema.md),
# the headless browser the homocal ui test drives (chromium and its driver, tests/ui)
# and the Python package with all its extras (pyproject.toml's, as scripts/lock.py --extras lists them) at the versions
# the suite last passed with
# (constraints.txt, the lock: docs/maintaining.md).
set -euo pipefail
cd "$(dirname "$0")/.."
SYS_PKGS="libegl1 libgl1-mesa-dri libopengl0 libosmesa6 chromium chromium-driver"
missing=""
for p in $SYS_PKGS; do
  dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
done
if [ -n "$missing" ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing
fi
python3 -m pip install -q --disable-pip-version-check -c constraints.txt -e ".[$(python3 scripts/lock.py --extras)]"
# opencv-python-headless (a dependency) and opencv-contrib-python-headless (the hog extra, for simgen's hog detector and
# its tests) install the same cv2 folder, so cv2 is whichever of the two pip wrote last, and OpenCV 5's base build has
# no HOGDescriptor. Reinstalling contrib alone writes its files (a superset) over the shared ones: both stay
# installed as pip sees them (pip check is clean) and cv2 has HOG. Never uninstall either: that removes the shared files.
if ! python3 -c "import cv2; cv2.HOGDescriptor" >/dev/null 2>&1; then
  version="$(python3 -m pip show opencv-contrib-python-headless | sed -n 's/^Version: //p')"
  python3 -m pip install -q --disable-pip-version-check --force-reinstall --no-deps "opencv-contrib-python-headless==$version"
fi
