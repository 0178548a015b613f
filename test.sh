#!/usr/bin/env bash
# The README's test command: installs what is missing, then runs the whole suite headless.
set -euo pipefail
cd "$(dirname "$0")"
bash scripts/install.sh
export MUJOCO_GL="${MUJOCO_GL:-egl}"
python3 -m pytest -q "$@"
