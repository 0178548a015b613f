#!/usr/bin/env bash
# Installs everything the project needs on a fresh Debian 12 machine (idempotent):
# the headless OpenGL libraries MuJoCo renders with (EGL and OSMesa, see data_schema.md),
# the headless browser the homocal ui test drives (chromium and its driver, tests/ui)
# and the Python package with its extras.
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
# opencv-contrib-python-headless (a superset, with the HOG people detector) replaces opencv-python-headless:
# both install the same cv2 package, so only one may be present
if python3 -m pip show -q opencv-python-headless >/dev/null 2>&1; then
  python3 -m pip uninstall -q -y opencv-python-headless
  # reinstalled: files the two shared went with the one removed
  python3 -m pip install -q --disable-pip-version-check --force-reinstall --no-deps "opencv-contrib-python-headless>=4.8"
fi
python3 -m pip install -q --disable-pip-version-check -e ".[dask,test]"
