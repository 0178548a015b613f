"""Print the lock file (constraints.txt): name==version of every installed distribution in the dependency closure
of homocal with all its extras (the ones scripts/install.sh installs), sorted; homocal itself is left out
(docs/maintaining.md). With --extras, print those extras instead, comma-separated (scripts/install.sh's list).

    python3 scripts/lock.py > constraints.txt
"""
from __future__ import annotations

import sys
import tomllib
from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path


def declared_extras() -> tuple[str, ...]:
    """The extras pyproject.toml declares ([project.optional-dependencies]), in its order: all are installed."""
    with open(Path(__file__).parent.parent / "pyproject.toml", "rb") as f:
        return tuple(tomllib.load(f)["project"]["optional-dependencies"])


def wanted(requirement, extras: tuple[str, ...]) -> bool:
    """Whether the requirement applies here with the given extras (its marker: Python, platform, extra)."""
    marker = requirement.marker
    return marker is None or any(marker.evaluate({"extra": e}) for e in extras or ("",))


def closure(root: str = "homocal") -> dict[str, str]:
    """{canonical name: installed version} of root's requirements (with all its extras), recursively."""
    from packaging.requirements import Requirement  # pip's and pytest's dependency (not needed for --extras,
    from packaging.utils import canonicalize_name  # which scripts/install.sh runs before installing anything)

    found, todo = {}, [(root, declared_extras())]
    while todo:
        name, extras = todo.pop()
        for text in distribution(name).requires or []:
            requirement = Requirement(text)
            key = canonicalize_name(requirement.name)
            if not wanted(requirement, extras) or key in found:
                continue
            try:
                found[key] = distribution(requirement.name).version
            except PackageNotFoundError:
                continue
            todo.append((requirement.name, tuple(requirement.extras)))
    found.pop(canonicalize_name(root), None)
    return found


if __name__ == "__main__" and sys.argv[1:] == ["--extras"]:
    print(",".join(declared_extras()))
elif __name__ == "__main__":
    print("# The versions the whole suite last passed with (docs/maintaining.md: the lock file).")
    print("# Written by: python3 scripts/lock.py > constraints.txt")
    for name, version in sorted(closure().items()):
        print(f"{name}=={version}")
