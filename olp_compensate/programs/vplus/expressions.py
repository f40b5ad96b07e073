"""Location expressions in V+ / Kawasaki AS program steps, read from the statement's text.

The grammar hands each motion, POINT/SET, HERE, TOOL and BASE statement its arguments as
one piece of text (so that any expression a controller accepts parses); this module finds
the location expression in it, as character offsets into the program text:

- a term is a name (``pick``, ``#home``, ``.p.rel`` (an AS local), ``a.pick``), an
  optional index ``[...]`` (``letter[.i,.j]``, ``#air.safe[.chuck.no]``), or a function
  call ``NAME(...)`` (``TRANS(0, 0, 50)``, ``SHIFT(pick BY 10, 0, 0)``);
- terms joined by ``:`` (V+) or ``+`` (Kawasaki AS) are a compound transformation;
- the expression ends at the first ``,`` outside brackets and quotes (``LAPPRO p, 50``);
- anything else (``-frame + p``, arithmetic) is kept as text: computed at run time.
"""

from __future__ import annotations

import re
from typing import NamedTuple

_NAME = re.compile(r"\.?#?\.?[A-Za-z_$][A-Za-z0-9_.$]*")
_SPACE = re.compile(r"[ \t\r\f]*")
_CLOSE = {"(": ")", "[": "]"}


class Term(NamedTuple):
    """One term of a location expression; offsets index the program text.

    name : as written (``pick``, ``#home``, ``TRANS``); name_start, name_end : its span.
    index : the text inside ``[...]`` after the name, else None.
    args : the text inside ``(...)`` of a function call, else None; args_start : the
        offset of its ``(`` (-1 without).
    end : the offset after the whole term (name, index, arguments).
    """

    name: str
    name_start: int
    name_end: int
    end: int
    index: str | None = None
    args: str | None = None
    args_start: int = -1


class LocationExpr(NamedTuple):
    """A location expression: ``terms`` joined by ``operators`` (':' or '+') when
    ``plain``; otherwise ``terms`` holds the terms read before the first part that is not
    a term. ``start``, ``end`` : its span in the program text (blanks trimmed)."""

    terms: tuple[Term, ...]
    operators: tuple[str, ...]
    start: int
    end: int
    plain: bool

    def text(self, program_text: str) -> str:
        return program_text[self.start:self.end]


def _balanced(text: str, pos: int, stop: int) -> int:
    """Offset after the bracket group opening at ``pos`` (``(`` or ``[``; nested groups
    and double-quoted strings inside), or -1 when it does not close before ``stop``."""
    want = [_CLOSE[text[pos]]]
    k = pos + 1
    while k < stop:
        c = text[k]
        if c == '"':
            q = text.find('"', k + 1, stop)
            if q < 0:
                return -1
            k = q
        elif c in _CLOSE:
            want.append(_CLOSE[c])
        elif c == want[-1]:
            want.pop()
            if not want:
                return k + 1
        elif c in ")]":
            return -1
        k += 1
    return -1


def top_level_comma(text: str, start: int, stop: int) -> int:
    """Offset of the first ',' in ``text[start:stop]`` outside brackets and quotes, or
    ``stop``."""
    k = start
    while k < stop:
        c = text[k]
        if c == ",":
            return k
        if c in _CLOSE:
            after = _balanced(text, k, stop)
            if after < 0:
                return stop
            k = after
            continue
        if c == '"':
            q = text.find('"', k + 1, stop)
            if q < 0:
                return stop
            k = q
        k += 1
    return stop


def skip_blanks(text: str, pos: int, stop: int) -> int:
    """The offset of the first character at or after ``pos`` that is not a blank."""
    return _SPACE.match(text, pos, stop).end()


def _rstrip(text: str, start: int, stop: int) -> int:
    while stop > start and text[stop - 1] in " \t\r\f":
        stop -= 1
    return stop


def term_at(text: str, pos: int, stop: int) -> Term | None:
    """The term starting at ``text[pos]`` (a name, its index, its arguments; not past
    ``stop``), or None."""
    m = _NAME.match(text, pos, stop)
    if m is None:
        return None
    end = m.end()
    index = None
    if end < stop and text[end] == "[":
        close = _balanced(text, end, stop)
        if close < 0:
            return None
        index, end = text[end + 1:close - 1], close
    k = _SPACE.match(text, end, stop).end()
    if index is None and k < stop and text[k] == "(":
        close = _balanced(text, k, stop)
        if close < 0:
            return None
        return Term(m.group(), m.start(), m.end(), close, None, text[k + 1:close - 1], k)
    return Term(m.group(), m.start(), m.end(), end, index)


def location_expression(text: str, start: int, stop: int) -> LocationExpr | None:
    """The location expression at the start of ``text[start:stop]`` (up to its first
    top-level comma), or None when that part is empty."""
    start = _SPACE.match(text, start, stop).end()
    end = _rstrip(text, start, top_level_comma(text, start, stop))
    if end <= start:
        return None
    terms: list[Term] = []
    operators: list[str] = []
    pos = start
    while True:
        term = term_at(text, pos, end)
        if term is None:
            return LocationExpr(tuple(terms), tuple(operators), start, end, False)
        terms.append(term)
        pos = _SPACE.match(text, term.end, end).end()
        if pos >= end:
            return LocationExpr(tuple(terms), tuple(operators), start, end, True)
        if text[pos] not in ":+":
            return LocationExpr(tuple(terms), tuple(operators), start, end, False)
        operators.append(text[pos])
        pos = _SPACE.match(text, pos + 1, end).end()


def first_name(text: str) -> str | None:
    """The first location name in an expression's text that is not a function call
    (``pick`` in ``SHIFT(pick BY 10, 0, 0)``), or None."""
    for m in _NAME.finditer(text):
        after = _SPACE.match(text, m.end()).end()
        if after < len(text) and text[after] == "(":
            continue
        if text[m.start() - 1:m.start()].isalnum():
            continue
        return m.group()
    return None
