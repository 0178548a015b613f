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
python3 -m pip install -q --disable-pip-version-check -e ".[dask,test]"
