"""Reading RAPID aggregates (``[[x,y,z],[q1,q2,q3,q4],...]``) with exact number spans.

A target literal reaches here as one token; a compiled regular expression for the common
shape (numbers only) reads all of its numbers in one call. Anything else (comments or
names inside, odd shapes) goes through a small generic reader, which also produces the
error messages. Arrays of any rank are split element by element.
"""

from __future__ import annotations

import operator
import re
from dataclasses import dataclass

from .grammar import LineIndex, error_at
from .regex_compat import portable
from .targets import Number

NUMBER_PATTERN = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
NUMBER_RE = re.compile(NUMBER_PATTERN)
NUMBER_GROUP = portable(r"([-+]?+(?:\d++(?:\.\d*+)?+|\.\d++)(?:[eE][-+]?+\d++)?+)")
"""NUMBER_PATTERN, possessive, as one capturing group (a number of a record literal);
atomic groups where ``re`` gets possessive groups wrong (:mod:`.regex_compat`)."""
_N = NUMBER_GROUP
_S = r"[ \t\r\n\f]*+"
_make_number = Number._make
_first = operator.itemgetter(0)


def _group(n: int) -> str:
    return r"\[" + _S + (_S + "," + _S).join([_N] * n) + _S + r"\]"


def _record(*counts: int) -> str:
    inner = (_S + "," + _S).join(_group(n) for n in counts)
    return r"\[" + _S + inner + _S + r"\]"


# robtarget [[x,y,z],[q1..q4],[cf1,cf4,cf6,cfx],[eax_a..eax_f]]; jointtarget [[6],[6]]
ROBTARGET_PATTERN = _record(3, 4, 4, 6)
ROBTARGET_RE = re.compile(ROBTARGET_PATTERN)
JOINTTARGET_RE = re.compile(_record(6, 6))
_MALFORMED = re.compile(r"[-+]?[\w.]+(?:[eE][-+]?[\w.]*)?")  # a number run, as shown in errors
_SKIP = re.compile(r"(?:[ \t\r\n\f]+|![^\r\n]*)*")
_TOKEN = re.compile(r"""
    (?P<ws>[ \t\r\n\f]+|![^\r\n]*)
  | (?P<open>\[) | (?P<close>\]) | (?P<comma>,)
  | (?P<num>""" + NUMBER_PATTERN + r""")
  | (?P<str>"(?:[^"\r\n]|"")*")
  | (?P<word>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<other>.)""", re.X | re.S)


@dataclass(frozen=True, slots=True)
class Atom:
    """A non-numeric item of an aggregate: a name (TRUE), a string, or an expression."""

    kind: str
    text: str
    start: int
    end: int


@dataclass(frozen=True, slots=True)
class Agg:
    """A bracketed aggregate: items are Number, Atom or Agg."""

    start: int
    end: int
    items: tuple


class LiteralError(Exception):
    """A malformed aggregate: message and offset; converted to ParseError by callers."""

    def __init__(self, message: str, offset: int):
        super().__init__(message)
        self.message = message
        self.offset = offset


def read_aggregate(text: str, start: int, end: int | None = None) -> Agg:
    """Generic reader: the aggregate starting at ``text[start] == '['``, not beyond ``end``."""
    stack: list[tuple[int, list]] = []
    item_tokens: list = []  # tokens of the current item (an expression when > 1)
    pos = start
    result = None

    def close_item(items: list, at: int, required: bool) -> None:
        if not item_tokens:
            if required:
                raise LiteralError("empty item in aggregate", at)
            return
        if len(item_tokens) == 1:
            items.append(item_tokens[0])
        else:
            a, b = _span(item_tokens[0]), _span(item_tokens[-1])
            items.append(Atom("expr", text[a[0]:b[1]], a[0], b[1]))
        item_tokens.clear()

    n = len(text) if end is None else end
    while pos < n:
        m = _TOKEN.match(text, pos, n)
        kind, pos0, pos = m.lastgroup, m.start(), m.end()
        if kind == "ws":
            continue
        if kind == "open":
            if stack and item_tokens:
                raise LiteralError("missing ',' before '['", pos0)
            stack.append((pos0, []))
        elif kind == "close":
            if not stack:
                raise LiteralError("unbalanced ']'", pos0)
            s, items = stack.pop()
            close_item(items, pos0, required=bool(items))
            agg = Agg(s, pos, tuple(items))
            if not stack:
                result = agg
                break
            item_tokens.append(agg)
        elif kind == "comma":
            if not stack:
                raise LiteralError("',' outside brackets", pos0)
            close_item(stack[-1][1], pos0, required=True)
        elif not stack:
            raise LiteralError("expected '['", pos0)
        elif kind == "num":
            if pos < n and (text[pos].isalnum() or text[pos] in "._"):
                bad = _MALFORMED.match(text, pos0, n).group()
                raise LiteralError(f"malformed number {bad!r}", pos0)
            item_tokens.append(_make_number((pos0, pos, m.group())))
        elif kind == "str":
            item_tokens.append(Atom("string", m.group(), pos0, pos))
        elif kind == "word":
            item_tokens.append(Atom("name", m.group(), pos0, pos))
        else:
            item_tokens.append(Atom("other", m.group(), pos0, pos))
    if result is None:
        raise LiteralError("unterminated '[' (missing ']')", stack[0][0] if stack else start)
    return result


def _span(item) -> tuple[int, int]:
    return (item.start, item.end)


def numbers_of(agg: Agg, count: int, what: str) -> tuple[Number, ...] | None:
    """The ``count`` numbers of a flat aggregate; None when an item is not a number.

    Raises LiteralError when the item count is wrong.
    """
    if not isinstance(agg, Agg):
        raise LiteralError(f"expected {what} as [{count} numbers]", agg.start)
    if len(agg.items) != count:
        raise LiteralError(f"expected {count} values in {what}, found {len(agg.items)}",
                           agg.start)
    if all(type(i) is Number for i in agg.items):
        return agg.items
    for i in agg.items:
        if isinstance(i, Agg):
            raise LiteralError(f"expected a number in {what}, found '['", i.start)
    return None


def shape_of(agg: Agg, counts: tuple, what: str) -> tuple | None:
    """Check ``agg`` is ``[[n1 numbers],[n2 numbers],...]``; its number groups or None."""
    if len(agg.items) != len(counts):
        raise LiteralError(f"expected {len(counts)} components in {what}, found "
                           f"{len(agg.items)}", agg.start)
    out = []
    for k, (item, n) in enumerate(zip(agg.items, counts)):
        if not isinstance(item, Agg):
            raise LiteralError(f"expected component {k + 1} of {what} to be [...]",
                               item.start)
        nums = numbers_of(item, n, f"component {k + 1} of {what}")
        if nums is None:
            return None
        out.append(nums)
    return tuple(out)


def fast_groups(pattern: re.Pattern, text: str, pos: int):
    """The numbers of a literal of the common shape at ``pos``, by one regex match.

    Returns (texts, starts, end) or None when the literal is not of that simple shape.
    """
    m = pattern.match(text, pos)
    if m is None:
        return None
    return m.groups(), tuple(map(_first, m.regs[1:])), m.end()


def read_elements(text: str, start: int, rank: int, read_leaf):
    """Read an aggregate of rank ``rank`` (0 = a single value) starting at ``start``.

    ``read_leaf(pos, index)`` reads one element at ``pos`` and returns its end offset.
    Returns the end offset of the whole aggregate. Raises LiteralError.
    """
    if rank == 0:
        return read_leaf(start, None)
    return _read_level(text, start, rank, (), read_leaf)


def _read_level(text, pos, rank, prefix, read_leaf):
    if not text.startswith("[", pos):
        raise LiteralError("expected '[' (array value)", pos)
    pos = _SKIP.match(text, pos + 1).end()
    k = 0
    while True:
        k += 1
        index = prefix + (k,)
        if len(index) == rank:
            pos = read_leaf(pos, index)
        else:
            pos = _read_level(text, pos, rank, index, read_leaf)
        pos = _SKIP.match(text, pos).end()
        c = text[pos:pos + 1]
        if c == ",":
            pos = _SKIP.match(text, pos + 1).end()
        elif c == "]":
            return pos + 1
        else:
            raise LiteralError("expected ',' or ']' in array value", pos)


def literal_error(exc: LiteralError, context: str, text: str, file: str,
                  index: LineIndex | None = None):
    """The ParseError for a LiteralError, prefixed with what was being read."""
    return error_at(f"{context}: {exc.message}", text, file, exc.offset, index)
