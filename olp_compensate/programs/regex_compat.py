"""Possessive quantifiers on groups, where this Python's ``re`` gets them right.

Python 3.11.2 (a fresh Debian's /usr/bin/python3; ``requires-python`` admits it) keeps the
partial match of a failed group under ``?+``, ``*+`` or ``++``: ``1(?:e\\d+)?+,`` matches
``1e,``, so a bare exponent (``[900,0,1e]``) was read as a number. Later 3.11 releases are
right. :func:`portable` keeps a pattern as written where :data:`GROUPS_OK` (probed once, not
a version list), else rewrites each such group as the atomic group of the greedy one,
``(?>(?:X)*)``: the same matches, right on 3.11.2, a fifth to a third slower to match.
"""

from __future__ import annotations

import re

__all__ = ["GROUPS_OK", "portable"]

GROUPS_OK = (re.fullmatch(r"1(?:e\d+)?+,", "1e,") is None
             and re.fullmatch(r"x(?:ab)*+,", "xa,") is None
             and re.fullmatch(r"x(?:ab)++,", "xaba,") is None)
"""Whether possessive quantifiers on groups never keep a failed group's partial match."""


def atomic(pattern: str) -> str:
    """``pattern`` with each group followed by ``?+``, ``*+`` or ``++`` rewritten as the
    atomic group of the greedy one (``(?:X)*+`` -> ``(?>(?:X)*)``); quantifiers on single
    characters and classes stay possessive (3.11.2 gets those right)."""
    while True:
        found = _group_possessive(pattern)
        if found is None:
            return pattern
        start, end = found
        pattern = (pattern[:start] + "(?>" + pattern[start:end + 2] + ")"
                   + pattern[end + 3:])


def _group_possessive(pattern: str) -> tuple[int, int] | None:
    """(start of the group, its ``)``) of the first group with a possessive quantifier."""
    opened: list[int] = []
    escaped = in_class = False
    for i, c in enumerate(pattern):
        if escaped:
            escaped = False
        elif c == "\\":
            escaped = True
        elif in_class:
            in_class = c != "]"
        elif c == "[":
            in_class = True
        elif c == "(":
            opened.append(i)
        elif c == ")":
            start = opened.pop()
            if pattern[i + 1:i + 3] in ("?+", "*+", "++"):
                return start, i
    return None


def portable(pattern: str) -> str:
    """``pattern`` as written where :data:`GROUPS_OK`, else :func:`atomic` of it."""
    return pattern if GROUPS_OK else atomic(pattern)
