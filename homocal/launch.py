"""The console scripts ``homocal`` and ``simgen`` (pyproject.toml's entry points).

``homocal --version`` answers from the package metadata before the subcommands load (a cheap start-up:
benchmarks/bench_startup.py). ``simgen`` first checks that no other distribution installs a top-level
``simgen`` (PyPI's unrelated one does): both write the same folder, and the commands would run a mix of them.
"""
from __future__ import annotations

import sys
from importlib.metadata import packages_distributions

DISTRIBUTION = "homocal"  # the distribution that ships both homocal and simgen (pyproject.toml)


def homocal() -> int:
    if sys.argv[1:] == ["--version"]:
        from homocal import __version__

        print(f"homocal {__version__}")
        return 0
    from homocal.cli import main

    return main()


def simgen_shadows() -> list[str]:
    """The distributions other than ours that install a top-level ``simgen`` package."""
    return sorted(set(packages_distributions().get("simgen", [])) - {DISTRIBUTION})


def simgen() -> int:
    others = simgen_shadows()
    if others:
        print(f"simgen: error: the distribution {', '.join(others)} also installs a top-level simgen package (PyPI's "
              f"unrelated simgen), so simgen runs a mix of both: pip uninstall {' '.join(others)}, then "
              f"reinstall {DISTRIBUTION} (pip install --force-reinstall --no-deps . in its checkout)", file=sys.stderr)
        return 2
    from simgen.cli import main

    return main()
