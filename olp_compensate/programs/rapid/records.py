"""The records one RAPID parse collects (grammar callbacks and fast paths alike).

Offsets are character offsets into the decoded module text. The grammar's callbacks and the
fast paths (rapid_fast.py) append these records to the :class:`Sink` of the parse in
progress; the builder (rapid_build.py) turns them into the shared target model.
"""

from __future__ import annotations

from typing import NamedTuple

from ..grammar import LineIndex


class Decl(NamedTuple):
    """A data declaration ``[LOCAL|TASK] CONST|PERS|VAR type name[{dims}] [:= value];``.

    scope : 'LOCAL', 'TASK' or None; storage : upper case; type_name : as written.
    type_span : the type word; name_pos : where the name starts; rank : array dimensions
    (0 for a scalar); value : the initial value's Ex, or None; start : where it starts.
    """

    scope: str | None
    storage: str
    type_name: str
    type_span: tuple[int, int]
    name: str
    name_pos: int
    rank: int
    value: "Ex | None"
    start: int


class CallRecord(NamedTuple):
    """A procedure call (``%name%`` late-bound calls have the name '%').

    positional : the values in order, each an :class:`Ex` or a (start, end) span;
    opts : the optional arguments, :class:`Opt` (value an Ex, a span or None);
    name_end : where the name ends; end : where the last argument (or the name) ends.
    """

    name: str
    start: int
    name_end: int
    end: int
    positional: list
    opts: list


class Assignment(NamedTuple):
    """``target := value;`` (target: an Ex of kind name, index or complex)."""

    target: "Ex"
    value: "Ex"


class RoutineRecord(NamedTuple):
    """A PROC, FUNC or TRAP: its text from ``start`` to ``end``, parameters as written."""

    name: str
    kind: str
    start: int
    end: int
    parameters: str
    name_pos: int


class TypeDef(NamedTuple):
    """A user type: kind 'record' with ``fields`` ((type, name) pairs) or 'alias' of
    ``base``."""

    kind: str
    fields: tuple[tuple[str, str], ...] = ()
    base: str | None = None


class Ex:
    """An expression's span and what it is (kind: name, index, call, complex, aggregate,
    num, string, star, expr)."""

    __slots__ = ("start", "end", "kind", "name", "index", "args")

    def __init__(self, start, end, kind, name=None, index=None, args=None):
        self.start, self.end, self.kind = start, end, kind
        self.name, self.index, self.args = name, index, args


class Opt:
    """An optional argument ``\\name``, ``\\name:=value`` or ``\\name?param``."""

    __slots__ = ("name", "value", "cond", "start", "end")

    def __init__(self, name, value, cond, start, end):
        self.name, self.value, self.cond, self.start, self.end = name, value, cond, start, end


class Arg:
    """One comma-separated argument: a value (or None) and its optional arguments."""

    __slots__ = ("value", "opts")

    def __init__(self, value, opts):
        self.value, self.opts = value, opts


class Sink:
    """The records of one parse. The fast paths build module-level robtarget declarations
    and the plainest MoveL/MoveJ into model objects at once (``targets``, ``motions``), or
    (a column parse) into the tables of ``columns`` (columns.ModuleColumns);
    everything else is recorded for the builder."""

    __slots__ = ("text", "file", "index", "decls", "calls", "assigns", "routines", "modules",
                 "targets", "motions", "runtime", "depth", "routine", "pending", "reparse", "reparsing",
                 "types", "columns", "indexed_text", "displaced")

    def __init__(self, text: str, file: str, reparse, columns=None, displaced=None):
        self.text, self.file, self.reparse = text, file, reparse
        self.index = LineIndex(text)
        self.decls: list[Decl] = []
        self.calls: list[CallRecord] = []
        self.assigns: list[Assignment] = []
        self.routines: list[RoutineRecord] = []
        self.modules: list[str] = []
        self.targets: list = []
        self.motions: list = []
        self.runtime: list = []   # the fast paths' run-time targets (Offs() moves)
        self.types: dict[str, TypeDef] = {}  # ALIAS and RECORD: lower name -> TypeDef
        # set by lexer callbacks, in text order: routine nesting, name, names still to skip
        self.depth = 0
        self.routine: str | None = None
        self.pending = 0
        self.reparsing = False   # inside a call parsed again by the grammar
        self.columns = columns   # a column parse: the fast paths' tables, else None
        self.indexed_text = None   # the text with its line breaks listed, for reparses
        # a column parse may hold its plain Offs()/RelTool() motions as rows
        # (displaced.DisplacedMoves), else they are objects (``motions``, ``runtime``)
        self.displaced = displaced


_TOKEN_KIND = {"NUM": "num", "STRING": "string", "AGGREGATE": "aggregate", "STAR": "star",
               "PLACEHOLDER": "placeholder"}


def as_ex(x) -> Ex:
    if type(x) is Ex:
        return x
    return Ex(x.start_pos, x.end_pos, _TOKEN_KIND.get(x.type, "expr"))


def start_of(x) -> int:
    return x.start if type(x) is Ex else x.start_pos


def end_of(x) -> int:
    """End offset of an Ex, a lark Token or a (start, end) span."""
    t = type(x)
    return x.end if t is Ex else (x[1] if t is tuple else x.end_pos)



def call_record(name: str, start: int, name_end: int, args) -> CallRecord:
    """The :class:`CallRecord` of a call read by the grammar (``args``: :class:`Arg`)."""
    positional = [a.value for a in args if a.value is not None]
    opts = [o for a in args for o in a.opts]
    return call_record_of(name, start, name_end, positional, opts)


def call_record_of(name: str, start: int, name_end: int, positional, opts) -> CallRecord:
    end = max([name_end] + [end_of(v) for v in positional] + [o.end for o in opts])
    return CallRecord(name=name, start=start, name_end=name_end, end=end,
                      positional=positional, opts=opts)
