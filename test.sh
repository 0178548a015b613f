#!/usr/bin/env bash
# The README's test command: installs what is missing (with the lock, constraints.txt), runs the lint, then the
# whole suite headless (every marker: slow, browser and generate too).
set -euo pipefail
cd "$(dirname "$0")"
bash scripts/install.sh
export MUJOCO_GL="${MUJOCO_GL:-egl}"
python3 -m ruff check .
python3 -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder "$@"  # pytest-xdist: two processes, a test file in one, in collection order (tests/conftest.py) (docs/maintaining.md)
