"""Grammar loading (package data), cached parser factories, and error conversion.

The grammars live in the repository folder ``grammars/``, installed as the package
``olp_compensate.grammars``. Lark's exceptions never leave this package: every parse error
becomes one :class:`~olp_compensate.errors.ParseError` with file, line, column and the
offending line with a caret under the spot.
"""

from __future__ import annotations

import bisect
import contextvars
import functools
import os
import re
import sys
from pathlib import Path

import lark
from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken

from ..data import data_folder
from ..errors import ParseError
from ..io.user_cache import cache_folder
from .targets import SourceLocation


def grammar_text(name: str) -> str:
    """The text of ``grammars/<name>`` (e.g. ``"rapid.lark"``): the package data
    ``olp_compensate.grammars`` (the source folder in an editable install)."""
    return (data_folder("grammars") / name).read_text("utf-8")


@functools.lru_cache(maxsize=None)
def parser(name: str, transformer_factory=None, start: tuple[str, ...] = ("start",)
           ) -> lark.Lark:
    """A cached LALR parser for ``grammars/<name>`` (one per process; lark's analysis of
    the grammar is kept on disk too, see :func:`cache_file`), with an inline transformer
    when given (``transformer_factory()`` is called once; its callbacks, and the token
    callbacks in its ``lexer_callbacks`` mapping, keep no per-parse state: they reach the
    parse in progress through :data:`current_sink`)."""
    transformer = transformer_factory() if transformer_factory is not None else None
    lexer_callbacks = getattr(transformer, "lexer_callbacks", None) or {}
    cache = cache_file(f"{Path(name).stem}-{'-'.join(start)}")
    return lark.Lark(grammar_text(name), parser="lalr", lexer="contextual",
                     transformer=transformer, maybe_placeholders=False,
                     propagate_positions=False, start=list(start),
                     lexer_callbacks=dict(lexer_callbacks), cache=cache or False)


def cache_file(key: str) -> str | None:
    """Where lark keeps a grammar's analysis between runs (it checks the grammar's hash on
    load, and builds the parser again when the file is stale, unreadable or unwritable):
    the user's cache folder (:mod:`olp_compensate.io.user_cache`); None when there is
    none."""
    folder = cache_folder()
    if folder is None:
        return None
    version = f"lark{lark.__version__}-py{sys.version_info[0]}.{sys.version_info[1]}"
    return os.path.join(folder, f"{key}-{version}.lark-cache")


# The records of the parse in progress; set by the dialect's parse function so that the
# cached parser's callbacks can append to them (thread- and reentrancy-safe).
current_sink: contextvars.ContextVar = contextvars.ContextVar("olp_program_sink")


class NewlineIndexedText(str):
    """A program text whose line breaks are listed once, so that ``count("\\n", start,
    end)`` and ``rindex("\\n", start, end)`` bisect instead of scanning: lark counts
    the lines before a :class:`~lark.utils.TextSlice` it is given from the start of the
    text, each time (a module of 3,400 calls parsed again took 8.6 s of counting for a
    1 MB text). Every answer is the one ``str`` gives."""

    def _newlines(self) -> list[int]:
        """Offsets of the line breaks, listed on first use (held by the instance)."""
        breaks = self.__dict__.get("breaks")
        if breaks is None:
            breaks = self.__dict__["breaks"] = [m.start() for m in re.finditer("\n", self)]
        return breaks

    def _bounds(self, start, end) -> tuple[int, int]:
        start, end, _ = slice(start, end).indices(len(self))
        return start, end

    def count(self, sub, start=None, end=None):
        if sub != "\n":
            return super().count(sub, start, end)
        start, end = self._bounds(start, end)
        if end <= start:
            return 0
        breaks = self._newlines()
        return bisect.bisect_left(breaks, end) - bisect.bisect_left(breaks, start)

    def rindex(self, sub, start=None, end=None):
        if sub != "\n":
            return super().rindex(sub, start, end)
        start, end = self._bounds(start, end)
        breaks = self._newlines()
        k = bisect.bisect_left(breaks, end) - 1
        if k < 0 or breaks[k] < start:
            raise ValueError("substring not found")
        return breaks[k]


class LineIndex:
    """Offsets to 1-based (line, column).

    An offset at or after the previous one (the parse callbacks ask in text order) is
    answered by counting the line breaks in between; an earlier one by counting from the
    start of the text while that has cost less than one pass over it (a big program asks
    for a few early offsets, its header declarations), then by bisection over the line
    starts, listed on first such need.

    Callers that walk a run of offsets in text order themselves (the fast paths) take the
    previous answer with :meth:`position` and hand their last one back with :meth:`moved`,
    so the index answers as if it had been asked each offset in turn.
    """

    __slots__ = ("text", "_starts", "_offset", "_line", "_line_start", "_budget")

    def __init__(self, text: str):
        self.text = text
        self._starts: list[int] | None = None
        self._offset, self._line, self._line_start = 0, 1, 0  # the previous answer
        self._budget = len(text)  # characters left to count from the start

    @property
    def starts(self) -> list[int]:
        """The offsets where lines start."""
        if self._starts is None:
            starts = [0]
            starts.extend(map(re.Match.end, re.finditer("\n", self.text)))
            self._starts = starts
        return self._starts

    def line_col(self, offset: int) -> tuple[int, int]:
        last = self._offset
        if offset < last:
            if self._starts is None and 0 <= offset <= self._budget:
                self._budget -= offset
                text = self.text
                return (text.count("\n", 0, offset) + 1,
                        offset - text.rfind("\n", 0, offset))
            starts = self.starts
            line = bisect.bisect_right(starts, offset)
            return line, offset - starts[line - 1] + 1
        text = self.text
        breaks = text.count("\n", last, offset)
        if breaks:
            self._line += breaks
            self._line_start = text.rfind("\n", last, offset) + 1
        self._offset = offset
        return self._line, offset - self._line_start + 1

    def position(self) -> tuple[int, int, int]:
        """The previous answer in text order: (offset, line, where that line starts)."""
        return self._offset, self._line, self._line_start

    def moved(self, offset: int, line: int, line_start: int) -> None:
        """Take (offset, line, line start) as the previous answer: a caller answered the
        offsets from :meth:`position` on, in text order, up to ``offset``."""
        self._offset, self._line, self._line_start = offset, line, line_start


class PositionedBuilder:
    """Base of the dialect builders: turns character offsets into source positions.
    Subclasses set ``self.file`` and ``self.index`` (a :class:`LineIndex`)."""

    file: str
    index: LineIndex

    def loc(self, offset: int) -> SourceLocation:
        """The source location of a character offset."""
        return SourceLocation(*self.src(offset))

    def src(self, offset: int) -> tuple[str, int, int]:
        """The ``source`` tuple (file, line, column) of targets and motion uses."""
        line, col = self.index.line_col(offset)
        return (self.file, line, col)


def caret_context(text: str, line: int, column: int) -> str:
    """The source line ``line`` (1-based) and a caret under ``column``."""
    lines = text.split("\n")  # as LineIndex and lark count lines: '\n' only
    src = lines[line - 1].rstrip("\r") if 0 < line <= len(lines) else ""
    pad = "".join("\t" if c == "\t" else " " for c in src[:max(column - 1, 0)])
    return f"{src}\n{pad}^"


def error_at(message: str, text: str, file: str, offset: int,
             index: LineIndex | None = None) -> ParseError:
    """A ParseError pointing at character ``offset`` of ``text``."""
    line, col = (index or LineIndex(text)).line_col(offset)
    return ParseError(message, file, line, col, caret_context(text, line, col))


_FRIENDLY = {
    "SEMICOLON": "';'", "COMMA": "','", "COLON": "':'", "DOT": "'.'", "EQUAL": "'='",
    "LPAR": "'('", "RPAR": "')'", "LBRACE": "'{'", "RBRACE": "'}'", "MINUS": "'-'",
    "PLUS": "'+'", "STAR": "'*'", "SLASH": "'/'", "BACKSLASH": "'\\'", "PERCENT": "'%'",
    "QMARK": "'?'", "LESSTHAN": "'<'", "MORETHAN": "'>'", "NAME": "a name",
    "NUM": "a number", "STRING": "a string", "AGGREGATE": "a bracketed value [...]",
    "PARAMS": "a parameter list (...)", "MODATTRS": "module attributes (...)",
    "$END": "end of file", "_NL": "end of line", "LOC": "a location name",
    "ARGS": "an argument list (...)", "LOC_LINES": "a location line",
    "MOTION_KW": "a motion instruction", "END_DOT": ".END", "OTHER": "a program step",
}
_HIDDEN = {"FAST_CALLS", "FAST_DECLS", "WS", "COMMENT", "HEADER"}


def _describe(names) -> str:
    names = sorted({n for n in names if n not in _HIDDEN and not n.startswith("__ANON")},
                   key=lambda n: (n not in ("SEMICOLON", "COMMA", "RPAR", "_NL"), n))
    shown = [_FRIENDLY.get(n, n) for n in names]
    if not shown:
        return "something else"
    if len(shown) > 10:
        shown = shown[:10] + ["..."]
    return ", ".join(shown)


def convert_lark_error(exc: UnexpectedInput, text: str, file: str) -> ParseError:
    """Turn lark's UnexpectedInput into a ParseError with a caret under the spot."""
    if isinstance(exc, UnexpectedEOF) or (
            isinstance(exc, UnexpectedToken) and exc.token.type == "$END"):
        index = LineIndex(text)
        end = len(text.rstrip())
        expected = getattr(exc, "expected", None) or getattr(exc, "accepts", None) or ()
        err = error_at(f"unexpected end of file (truncated?); expected {_describe(expected)}",
                       text, file, max(end - 1, 0), index)
        return err
    if isinstance(exc, UnexpectedCharacters):
        ch = text[exc.pos_in_stream] if exc.pos_in_stream < len(text) else ""
        if ch == "[":
            msg = "unterminated or too deeply nested bracket '['"
        elif ch == '"':
            msg = "unterminated string"
        else:
            msg = f"unexpected character {ch!r}; expected {_describe(exc.allowed or ())}"
        return error_at(msg, text, file, exc.pos_in_stream)
    if isinstance(exc, UnexpectedToken):
        tok = exc.token
        shown = str(tok).splitlines()[0] if str(tok) else tok.type
        if tok.type in _HIDDEN or len(shown) > 40:  # a whole-run token: show its first word
            shown = re.match(r"[^\s,;(\[]*", shown).group() or shown[:1]
        msg = f"unexpected {shown!r}; expected {_describe(exc.expected or ())}"
        offset = tok.start_pos if tok.start_pos is not None else 0
        return error_at(msg, text, file, offset)
    line, col = getattr(exc, "line", None), getattr(exc, "column", None)
    return ParseError(str(exc).splitlines()[0], file, line, col)


def check_text(text: str, file: str) -> None:
    """Reject binary or UTF-16 input before the parser sees it, in one line that does not
    echo its bytes (:func:`.text_checks.check_text`, shared by every dialect)."""
    from .text_checks import check_text as check

    check(text, file, "an encrypted RAPID module cannot be read; compensate its plain "
                      "source")


def newline_style(text: str) -> str:
    """'\\r\\n', '\\n', 'mixed' or '' for a text without line breaks."""
    lf = text.count("\n")
    if lf == 0:
        return ""
    crlf = text.count("\r\n")
    return "\r\n" if crlf == lf else ("\n" if crlf == 0 else "mixed")
