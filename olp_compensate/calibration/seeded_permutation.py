"""``numpy.random.default_rng(seed).permutation(n)`` without importing ``numpy.random``.

Importing ``numpy.random`` costs about 7 % of an ``olp-cal identify`` run on 100 poses,
for one permutation of the poses into cross-validation folds. This module computes the
same permutation, number for number, in plain Python integers: numpy's ``SeedSequence``
(the pool of four 32-bit words mixed from the seed, then eight state words), its PCG64
bit generator (128-bit LCG, XSL-RR output, two 32-bit halves per 64-bit draw), and the
Fisher-Yates shuffle of ``Generator.shuffle`` (a bounded draw by masking and rejection,
from the last element down). Written from the algorithms as numpy documents and
publishes them (numpy/random/bit_generator.pyx, _pcg64.pyx, src/pcg64, distributions.c);
``tests/test_seeded_permutation.py`` checks it against numpy itself. Above
``PYTHON_LIMIT`` elements the Python loop would cost more than the import, and numpy
does the work (the same numbers).
"""

from __future__ import annotations

import numpy as np

PYTHON_LIMIT = 4096
"""Longest permutation computed in Python; longer ones are numpy's own."""

_M32 = 0xFFFFFFFF
_M64 = 0xFFFFFFFFFFFFFFFF
_M128 = (1 << 128) - 1
_INIT_A, _MULT_A = 0x43B0D7E5, 0x931E8875  # SeedSequence's hash constants
_INIT_B, _MULT_B = 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R = 0xCA01F9DD, 0x4973F715
_PCG_MULT = (2549297995355413924 << 64) + 4865540595714422341  # PCG's 128-bit multiplier


def _seed_words(seed: int) -> list[int]:
    """The seed as numpy coerces it: 32-bit words, least significant first ([0] for 0)."""
    words = []
    while True:
        words.append(seed & _M32)
        seed >>= 32
        if not seed:
            return words


def _pool(seed: int, size: int = 4) -> list[int]:
    """SeedSequence(seed).pool: the entropy hashed into ``size`` 32-bit words, mixed."""
    const = _INIT_A

    def hashmix(value: int) -> int:
        nonlocal const
        value ^= const
        const = (const * _MULT_A) & _M32
        value = (value * const) & _M32
        return value ^ (value >> 16)

    def mix(x: int, y: int) -> int:
        result = (_MIX_L * x - _MIX_R * y) & _M32
        return result ^ (result >> 16)

    entropy = _seed_words(seed)
    pool = [hashmix(entropy[i] if i < len(entropy) else 0) for i in range(size)]
    for src in range(size):
        for dst in range(size):
            if src != dst:
                pool[dst] = mix(pool[dst], hashmix(pool[src]))
    for extra in entropy[size:]:
        for dst in range(size):
            pool[dst] = mix(pool[dst], hashmix(extra))
    return pool


def _state_words(pool: list[int], n_words: int) -> list[int]:
    """SeedSequence.generate_state(n_words // 2, uint64) as 64-bit integers."""
    const, words = _INIT_B, []
    for i in range(n_words):
        value = pool[i % len(pool)] ^ const
        const = (const * _MULT_B) & _M32
        value = (value * const) & _M32
        words.append(value ^ (value >> 16))
    return [words[i] | (words[i + 1] << 32) for i in range(0, n_words, 2)]


class _Pcg64:
    """numpy's PCG64 seeded from a SeedSequence, its 32-bit draws only."""

    def __init__(self, seed: int):
        s0, s1, i0, i1 = _state_words(_pool(seed), 8)
        self.inc = (((i0 << 64) | i1) << 1 | 1) & _M128
        self.state = (self.inc + ((s0 << 64) | s1)) & _M128
        self.state = (self.state * _PCG_MULT + self.inc) & _M128
        self.spare: int | None = None

    def next64(self) -> int:
        self.state = (self.state * _PCG_MULT + self.inc) & _M128
        state = self.state
        value, rot = ((state >> 64) ^ state) & _M64, state >> 122
        return ((value >> rot) | (value << (64 - rot))) & _M64

    def next32(self) -> int:
        if self.spare is not None:
            value, self.spare = self.spare, None
            return value
        value = self.next64()
        self.spare = value >> 32
        return value & _M32


def permutation(seed: int, n: int) -> np.ndarray:
    """``np.random.default_rng(seed).permutation(n)``: int64 (n,), the same numbers."""
    if n > PYTHON_LIMIT:
        return np.random.default_rng(seed).permutation(n)
    if seed < 0:
        raise ValueError("the seed must be non-negative")
    rng, order = _Pcg64(seed), list(range(n))
    for i in range(n - 1, 0, -1):
        mask = (1 << i.bit_length()) - 1  # smallest all-ones mask >= i (i < 2**32)
        j = rng.next32() & mask
        while j > i:
            j = rng.next32() & mask
        order[i], order[j] = order[j], order[i]
    return np.array(order, dtype=np.int64)
