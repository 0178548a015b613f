"""Print the lock file (constraints.txt): name==version of every installed distribution in the dependency closure
of homocal with the extras scripts/install.sh installs, sorted; homocal itself is left out (docs/maintaining.md).

    python3 scripts/lock.py > constraints.txt
"""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, distribution

from packaging.requirements import Requirement  # pip's and pytest's dependency
from packaging.utils import canonicalize_name

EXTRAS = ("dask", "hog", "supervision", "test")  # scripts/install.sh's


def wanted(requirement: Requirement, extras: tuple[str, ...]) -> bool:
    """Whether the requirement applies here with the given extras (its marker: Python, platform, extra)."""
    marker = requirement.marker
    return marker is None or any(marker.evaluate({"extra": e}) for e in extras or ("",))


def closure(root: str = "homocal") -> dict[str, str]:
    """{canonical name: installed version} of root's requirements (with EXTRAS for root), recursively."""
    found, todo = {}, [(root, EXTRAS)]
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


if __name__ == "__main__":
    print("# The versions the whole suite last passed with (docs/maintaining.md: the lock file).")
    print("# Written by: python3 scripts/lock.py > constraints.txt")
    for name, version in sorted(closure().items()):
        print(f"{name}=={version}")
