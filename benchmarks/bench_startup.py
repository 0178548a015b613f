"""Start-up cost: CPU seconds (user + sys) of ``import homocal`` and of ``homocal --version`` (homocal.launch, the
console script's entry point), each the median of --runs fresh interpreters, beside an interpreter that imports
numpy alone (the floor: homocal needs numpy). Target: both under 0.35 s (printed, never asserted).

    python benchmarks/bench_startup.py [--runs 7]
"""
from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys

TARGET_S = 0.35
CASES = {
    "python -c 'import numpy' (floor)": "import numpy",
    "python -c 'import homocal'": "import homocal",
    "homocal --version": "import sys; sys.argv = ['homocal', '--version']; import homocal.launch as l; l.homocal()",
}


def cpu_seconds(code: str) -> float:
    """user + sys CPU seconds of one fresh interpreter running code."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-c", code], check=True, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    runs = parser.parse_args().runs
    for name, code in CASES.items():
        times = [cpu_seconds(code) for _ in range(runs)]
        print(f"{name}: median {statistics.median(times):.3f} s CPU over {runs} runs "
              f"(min {min(times):.3f}, max {max(times):.3f}; target for homocal {TARGET_S} s)")


if __name__ == "__main__":
    main()
