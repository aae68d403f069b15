"""Seeded random streams. There is no global RNG anywhere in the package.

Every random choice draws from a ``numpy.random.Generator`` derived from the run's master
seed and a fixed key (a component name and, for stages, the step and stage index), so that
any component can be re-run alone and draw the same numbers.
"""

from __future__ import annotations

import zlib

import numpy as np


def _key_words(key: tuple[int | str, ...]) -> list[int]:
    words: list[int] = []
    for k in key:
        if isinstance(k, str):
            words.append(zlib.crc32(k.encode("utf-8")))
        else:
            assert k >= 0, "rng keys are non-negative"
            words.extend([k & 0xFFFFFFFF, (k >> 32) & 0xFFFFFFFF])
    return words


def derive_rng(seed: int, *key: int | str) -> np.random.Generator:
    """A generator that depends only on ``seed`` and ``key`` (e.g. ``derive_rng(7, "crowd")``)."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed & 0xFFFFFFFF, seed >> 32, *_key_words(key)])))


def derive_seed(seed: int, *key: int | str) -> int:
    """A 63-bit integer seed derived like :func:`derive_rng` (for torch generators)."""
    return int(derive_rng(seed, *key).integers(0, 2**63 - 1))
