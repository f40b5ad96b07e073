"""Brackets in program text, as every language's reader needs them: where an opened
bracket closes (nesting counted) and the top-level arguments of a call."""

from __future__ import annotations

import re

_LINE_END = re.compile(r"[\r\n]")


def closing(text: str, start: int, hi: int | None = None, pair: str = "{}") -> int | None:
    """Offset just past the ``pair[1]`` closing the ``pair[0]`` at ``start`` (nesting
    counted), searched before ``hi`` (default: the end of ``text``); None when it is not
    closed there."""
    opening, closer = pair
    depth = 0
    for k in range(start, len(text) if hi is None else hi):
        c = text[k]
        if c == opening:
            depth += 1
        elif c == closer:
            depth -= 1
            if depth == 0:
                return k + 1
    return None


def line_end(text: str, start: int) -> int:
    """Offset of the first line break at or after ``start`` (the end of ``text`` if none)."""
    found = _LINE_END.search(text, start)
    return len(text) if found is None else found.start()


def strip_span(text: str, a: int, b: int, blanks: str | None = None) -> tuple[int, int]:
    """``(a, b)`` narrowed past the blanks at both ends (``blanks``: those characters;
    None: any white space)."""
    def blank(c: str) -> bool:
        return c.isspace() if blanks is None else c in blanks

    while a < b and blank(text[a]):
        a += 1
    while b > a and blank(text[b - 1]):
        b -= 1
    return a, b


def argument_spans(text: str, open_at: int, openers: str = "([", closers: str = ")]",
                   quote: str | None = None) -> tuple[list[tuple[int, int]], int]:
    """The top-level argument spans of the call whose ``(`` is at ``open_at`` (each as
    written, blanks included), and the offset just past its closing bracket (-1 when
    it is not closed: the spans are then those ended by a comma). Brackets inside
    ``quote``-delimited strings do not count."""
    depth, start, spans = 0, open_at + 1, []
    in_string = False
    for k in range(open_at, len(text)):
        c = text[k]
        if quote is not None and c == quote:
            in_string = not in_string
        if in_string:
            continue
        if c in openers:
            depth += 1
        elif c in closers:
            depth -= 1
            if depth == 0:
                spans.append((start, k))
                return spans, k + 1
        elif c == "," and depth == 1:
            spans.append((start, k))
            start = k + 1
    return spans, -1
