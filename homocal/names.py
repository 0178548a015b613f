"""The one rule for names that reach the file system (docs/maintaining.md principle 11).

Every name read from a file or a request (a scene, detector, sequence or study name) becomes part of a path only
after ``check_name``: letters, digits, ``.``, ``_`` and ``-``, at most ``MAX_NAME_LENGTH`` characters, not
starting with a dot (so never ``.``, ``..`` or a hidden file) and never a separator. homocal and simgen both use it.
"""
from __future__ import annotations

import re

MAX_NAME_LENGTH = 64
NAME_PATTERN = re.compile(rf"[A-Za-z0-9_-][A-Za-z0-9._-]{{0,{MAX_NAME_LENGTH - 1}}}")


def check_name(name: object, what: str = "name") -> str:
    """``name`` itself if it is a safe file-system name, else ValueError in one line naming ``what``.

    >>> check_name("scene1", "scene")
    'scene1'
    >>> check_name("../x", "scene")
    Traceback (most recent call last):
    ...
    ValueError: scene '../x': expected 1-64 letters, digits, '.', '_' or '-', not starting with '.'
    """
    if not (isinstance(name, str) and NAME_PATTERN.fullmatch(name)):
        shown = repr(name) if not isinstance(name, str) or len(name) <= 80 else repr(name[:77] + "...")
        raise ValueError(f"{what} {shown}: expected 1-{MAX_NAME_LENGTH} letters, digits, '.', '_' or '-', "
                         "not starting with '.'")
    return name
