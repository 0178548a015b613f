"""Keyed random streams: every draw comes from a Generator seeded by (run seed, stable key)."""
from __future__ import annotations

import hashlib

import numpy as np


def keyed_generator(seed: int, *key: object) -> np.random.Generator:
    """A Generator that depends only on ``seed`` and the key's text (e.g. scene name, "slot", 3)."""
    digest = hashlib.sha256("/".join(map(str, key)).encode()).digest()
    words = np.frombuffer(digest, dtype="<u4").tolist()
    return np.random.default_rng(np.random.SeedSequence([int(seed), *words]))
