"""ABB RAPID: parse a module (.mod, .modx, .prg, .sys) into the shared target model.

Pipeline: ``grammars/rapid.lark`` (LALR, cached) with inline callbacks that append flat
records (declarations, calls, assignments, routines) to a per-parse sink, and token
callbacks that split the fast-path runs (rapid_fast.py); then this module reads the target
literals (literals.py) and builds a :class:`Program`.

RAPID conventions kept as written: positions in mm, quaternions ``[q1,q2,q3,q4]`` = w, x,
y, z (not necessarily normalized), confdata ``[cf1,cf4,cf6,cfx]``, external axes with 9E9
meaning "not used"; names are case-insensitive.
"""

from __future__ import annotations

import lark
from lark import Token
from lark.exceptions import UnexpectedInput
from lark.utils import TextSlice

from ..grammar import (LineIndex, NewlineIndexedText, check_text, convert_lark_error, current_sink,
                       error_at, newline_style, parser)
from ..targets import MotionUse, NameReference, Program, RuntimeTarget
from .accounting import unaccounted_literals
from .build import TARGET_TYPES, Builder
from .columns import ModuleColumns, MoveTable, TargetTable
from .fast import LEXER_CALLBACKS
from .records import (Arg, Assignment, Decl, Ex, Opt, RoutineRecord, Sink, TypeDef, as_ex,
                      call_record, end_of, start_of)

__all__ = ["parse_rapid", "parse_rapid_columns", "TARGET_TYPES"]


class _Dims:
    __slots__ = ("rank",)

    def __init__(self, rank):
        self.rank = rank


class Callbacks(lark.Transformer):
    """Inline LALR callbacks: expressions become :class:`Ex`; statements are appended to
    the sink of the parse in progress (``grammar.current_sink``)."""

    def __default__(self, data, children, meta):
        # inlined rules (``_name``) must stay trees for lark to splice them into the parent
        return lark.Tree(data, children) if data[0] == "_" else None

    # -- expressions
    def expr(self, c):
        return Ex(start_of(c[0]), end_of(c[-1]), "expr")

    def paren(self, c):
        return Ex(c[0].start_pos, c[-1].end_pos, "expr")

    def field(self, c):
        return ("field", c[0].end_pos, c[0].value)

    def index(self, c):
        return ("index", c[-1].end_pos, [as_ex(x) for x in c[:-1]])

    def fargs(self, c):
        return ("call", c[-1].end_pos, c[:-1])

    def ref(self, c):
        tok = c[0]
        if len(c) == 1:
            return Ex(tok.start_pos, tok.end_pos, "name", tok.value)
        end = c[-1][1]
        if len(c) == 2:
            kind = c[1][0]
            if kind == "index":
                return Ex(tok.start_pos, end, "index", tok.value, c[1][2])
            if kind == "call":
                return Ex(tok.start_pos, end, "call", tok.value, None, c[1][2])
        return Ex(tok.start_pos, end, "complex", tok.value)

    lvalue = ref

    def optarg(self, c):
        bs, name = c[0], c[1]
        if len(c) == 2:
            return Opt(name.value, None, None, bs.start_pos, name.end_pos)
        v = c[2]
        if type(v) is Token and v.type == "NAME":
            return Opt(name.value, None, v.value, bs.start_pos, v.end_pos)
        v = as_ex(v)
        return Opt(name.value, v, None, bs.start_pos, v.end)

    def namedarg(self, c):
        """A required argument given by name, ``Tool:=tool0`` (no backslash)."""
        tok, v = c[0], as_ex(c[1])
        return Opt(tok.value.split(":")[0].rstrip(), v, None, tok.start_pos, v.end)

    def arg(self, c):
        if type(c[0]) is Opt:
            return Arg(None, c)
        return Arg(as_ex(c[0]), c[1:])

    # -- statements
    def call(self, c):
        tok = c[0]
        current_sink.get().calls.append(call_record(tok.value, tok.start_pos, tok.end_pos,
                                                     c[1:]))

    def fast_calls(self, c):
        pass  # done by the FAST_CALLS lexer callback, in text order (see _on_fast_calls)

    def late_call(self, c):
        current_sink.get().calls.append(call_record("%", c[0].start_pos, c[2].end_pos,
                                                     c[3:]))

    def assign(self, c):
        current_sink.get().assigns.append(Assignment(target=c[0], value=as_ex(c[1])))

    # -- data
    def scope(self, c):
        return ("scope", c[0].value)

    def storage(self, c):
        return c[0]

    def dims(self, c):
        return _Dims(len(c))

    def declaration(self, c):
        i, scope = 0, None
        if type(c[0]) is tuple:
            scope, i = c[0][1], 1
        storage, typ, name = c[i], c[i + 1], c[i + 2]
        rank, init = 0, None
        for r in c[i + 3:]:
            if type(r) is _Dims:
                rank = r.rank
            else:
                init = as_ex(r)
        current_sink.get().decls.append(Decl(
            scope=scope, storage=storage.value.upper(), type_name=typ.value,
            type_span=(typ.start_pos, typ.end_pos), name=name.value, name_pos=name.start_pos,
            rank=rank, value=init, start=storage.start_pos))

    def fast_decls(self, c):
        pass  # done by the FAST_DECLS lexer callback, in text order (see _on_fast_decls)

    def record(self, c):
        names = [t for t in c if t.type == "NAME"]
        fields = [(names[k].value, names[k + 1].value) for k in range(1, len(names) - 1, 2)]
        current_sink.get().types[names[0].value.lower()] = TypeDef(kind="record",
                                                                   fields=tuple(fields))

    def alias(self, c):
        names = [t for t in c if t.type == "NAME"]
        current_sink.get().types[names[1].value.lower()] = TypeDef(kind="alias",
                                                                   base=names[0].value)

    # -- structure
    def _routine(self, kind, c, name_tok):
        params = c[3].value if kind == "FUNC" else (c[2].value if kind == "PROC" else "")
        current_sink.get().routines.append(RoutineRecord(
            name=name_tok.value, kind=kind, start=c[0].start_pos, end=c[-1].end_pos,
            parameters=params, name_pos=name_tok.start_pos))

    def proc(self, c):
        self._routine("PROC", c, c[1])

    def func(self, c):
        self._routine("FUNC", c, c[2])

    def trap(self, c):
        self._routine("TRAP", c, c[1])

    def module(self, c):
        current_sink.get().modules.append(c[1].value)


def _use_key(u: MotionUse):
    return u.target_span or u.statement_span


def _span_key(r: RuntimeTarget):
    return r.span or (0, 0)


def _location_key(r: NameReference):
    return r.location.line, r.location.column


def _in_order(records: list, in_order: int, key) -> tuple:
    """``records`` sorted by ``key``, knowing the first ``in_order`` of them are."""
    return tuple(records) if len(records) == in_order else tuple(sorted(records, key=key))


def _reparse_call(text: str, file: str, start: int, end: int) -> None:
    """Parse ``text[start:end]`` as one call with the grammar (its records go to the sink of
    the parse in progress); raises ParseError.

    (It runs inside a lexer callback of the whole parse: lark's own error would be taken
    by that lexer for one of its own, and reported at the token after the run.)
    """
    sink = current_sink.get()
    sink.reparsing = True   # a run the lexer falls back to inside it is not parsed again
    try:
        if sink.indexed_text is None:
            sink.indexed_text = NewlineIndexedText(text)
        parser("rapid.lark", Callbacks, ("start", "call")).parse(
            TextSlice(sink.indexed_text, start, end), start="call")
    except UnexpectedInput as exc:
        raise convert_lark_error(exc, text, file) from None
    finally:
        sink.reparsing = False


def parse_rapid(text: str, file: str = "<string>") -> Program:
    """Parse RAPID module text (already decoded) into a :class:`Program`.

    Raises ParseError (file, line, column, caret context) on any malformed input.
    """
    return _parse(text, file, None)


def parse_rapid_columns(text: str, file: str = "<string>", displaced=None
                        ) -> tuple[Program, ModuleColumns]:
    """:func:`parse_rapid` keeping the module-level plain robtarget declarations and the
    plain MoveL/MoveJ in columns (:mod:`.columns`): ``(program, columns)``, where
    ``program`` holds everything else; ``with_objects(program, columns)`` is what
    :func:`parse_rapid` gives. ``displaced``: an empty :class:`~.displaced.DisplacedMoves`
    to receive the plain Offs()/RelTool() motions as rows (then missing from ``program``:
    the caller's to restore), else they are objects."""
    columns = ModuleColumns(TargetTable(), MoveTable())
    program = _parse(text, file, columns, displaced)
    columns.place(LineIndex(text).starts)
    return program, columns


def _parse(text: str, file: str, columns: ModuleColumns | None, displaced=None) -> Program:
    check_text(text, file)
    sink = Sink(text, file, lambda start, end: _reparse_call(text, file, start, end), columns,
                displaced)
    token = current_sink.set(sink)
    try:
        parser("rapid.lark", Callbacks, ("start", "call")).parse(text, start="start")
    except UnexpectedInput as exc:
        raise convert_lark_error(exc, text, file) from None
    finally:
        current_sink.reset(token)
    if not sink.modules:
        raise error_at("no MODULE found", text, file, 0)
    return _build(text, file, sink)


def _build(text: str, file: str, sink: Sink) -> Program:
    """The Program of a parse's records."""
    b = Builder(text, file, sink)
    fast_targets, fast_motions = len(sink.targets), len(sink.motions)
    for rec in sink.decls:
        b.declaration(rec)
    for rec in sink.calls:
        b.call(rec)
    for rec in sink.assigns:
        b.assign(rec.target, rec.value)
    problems = b.problems + unaccounted_literals(text, file, b)
    refs = ()
    if b.references:
        names = b.target_names
        refs = tuple(sorted((r for r in b.references if r.name.lower() in names),
                            key=_location_key))
    by_start = lambda t: t.span[0]  # noqa: E731
    return Program(
        file=file, text=text, encoding="latin-1", dialect="rapid",
        newline=newline_style(text),
        targets=_in_order(b.targets, fast_targets, by_start),
        joint_targets=tuple(sorted(b.joints, key=by_start)),
        tools=tuple(b.tools), wobjs=tuple(b.wobjs),
        motions=_in_order(b.motions, fast_motions, _use_key),
        runtime=tuple(sorted(b.runtime, key=_span_key)), references=refs,
        routines=b.routines, modules=tuple(sink.modules),
        problems=tuple(sorted(problems, key=_problem_key)), copies=tuple(b.copies))


def _problem_key(p):
    return p.location.line, p.location.column


Callbacks.lexer_callbacks = LEXER_CALLBACKS
