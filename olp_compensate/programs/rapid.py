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

import bisect
import re

import lark
from lark import Token
from lark.exceptions import UnexpectedInput
from lark.utils import TextSlice

from .grammar import (PositionedBuilder, check_text, convert_lark_error, current_sink,
                      error_at, newline_style, parser, young_gc_only)
from .literals import (JOINTTARGET_RE, ROBTARGET_RE, Agg, Atom, LiteralError, fast_groups,
                       literal_error, numbers_of, read_aggregate, read_elements, shape_of)
from .rapid_fast import (LEXER_CALLBACKS, MOTIONS, RUNTIME_FUNCS, Arg, Ex, Opt, Sink,
                         as_ex, call_record, end_of, start_of, value_ex)
from .targets import (QUAT_WXYZ, CartesianTarget, JointTarget, MotionUse, NameReference,
                      Number, Program, Routine, RuntimeTarget, SourceLocation, ToolData,
                      WorkObject)

TARGET_TYPES = ("robtarget", "jointtarget", "tooldata", "wobjdata")
_READERS = {"robtarget": "_robtarget", "jointtarget": "_jointtarget",
            "tooldata": "_tooldata", "wobjdata": "_wobjdata"}


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
        current_sink.get().assigns.append((c[0], as_ex(c[1])))

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
        current_sink.get().decls.append(
            (scope, storage.value.upper(), typ.value, (typ.start_pos, typ.end_pos),
             name.value, name.start_pos, rank, init, storage.start_pos))

    def fast_decls(self, c):
        pass  # done by the FAST_DECLS lexer callback, in text order (see _on_fast_decls)

    def record(self, c):
        names = [t for t in c if t.type == "NAME"]
        fields = [(names[k].value, names[k + 1].value) for k in range(1, len(names) - 1, 2)]
        current_sink.get().types[names[0].value.lower()] = ("record", fields)

    def alias(self, c):
        names = [t for t in c if t.type == "NAME"]
        current_sink.get().types[names[1].value.lower()] = ("alias", names[0].value)

    # -- structure
    def _routine(self, kind, c, name_tok):
        params = c[3].value if kind == "FUNC" else (c[2].value if kind == "PROC" else "")
        current_sink.get().routines.append(
            (name_tok.value, kind, c[0].start_pos, c[-1].end_pos, params, name_tok.start_pos))

    def proc(self, c):
        self._routine("PROC", c, c[1])

    def func(self, c):
        self._routine("FUNC", c, c[2])

    def trap(self, c):
        self._routine("TRAP", c, c[1])

    def module(self, c):
        current_sink.get().modules.append(c[1].value)


# ---- building the Program -------------------------------------------------------------

class _Builder(PositionedBuilder):
    """Turns the sink's records into model objects (one per parse)."""

    def __init__(self, text: str, file: str, sink: Sink):
        self.text, self.file, self.sink = text, file, sink
        self.index = sink.index
        self.targets: list = []
        self.joints: list = []
        self.tools: list = []
        self.wobjs: list = []
        self.runtime: list = []
        self.motions: list = []
        self.references: list = []
        routines = sorted(sink.routines, key=lambda r: r[2])
        self.routine_starts = [r[2] for r in routines]
        self.routine_records = routines
        self.routines = tuple(
            Routine(name, kind, self.loc(name_pos), (start, end), _param_names(params))
            for name, kind, start, end, params, name_pos in routines)
        self.target_names: set[str] = set()

    def routine_at(self, offset: int) -> str | None:
        k = bisect.bisect_right(self.routine_starts, offset) - 1
        if k >= 0 and offset < self.routine_records[k][3]:
            return self.routine_records[k][0]
        return None

    def error(self, exc: LiteralError, what: str):
        return literal_error(exc, what, self.text, self.file, self.index)

    # -- declarations
    def base_type(self, typ: str) -> str:
        """The built-in type behind an ALIAS (lower case)."""
        kind = typ.lower()
        for _ in range(8):
            t = self.sink.types.get(kind)
            if t is None or t[0] != "alias":
                break
            kind = t[1].lower()
        return kind

    def record_targets(self, kind: str, depth: int = 0) -> list[str]:
        """Fields of a user RECORD type that hold targets, tools or work objects."""
        t = self.sink.types.get(kind)
        if t is None or t[0] != "record" or depth > 8:
            return []
        out = []
        for ftype, fname in t[1]:
            base = self.base_type(ftype)
            if base in TARGET_TYPES:
                out.append(f"{fname} ({base})")
            out += [f"{fname}.{x}" for x in self.record_targets(base, depth + 1)]
        return out

    def declaration(self, rec) -> None:
        scope, storage, typ, type_span, name, name_pos, rank, init, start = rec
        kind = self.base_type(typ)
        if kind not in TARGET_TYPES:
            inner = self.record_targets(kind) if self.sink.types else []
            if inner:
                self.runtime.append(RuntimeTarget(
                    self.text[start:name_pos + len(name)], self.loc(name_pos),
                    f"record {typ} holds {', '.join(inner)}: not read, not compensated",
                    name, self.routine_at(start), (start, name_pos + len(name))))
            return
        routine = self.routine_at(start) if self.routine_records else None
        if kind in ("robtarget", "jointtarget"):
            self.target_names.add(name.lower())
        if init is None or init.kind != "aggregate":
            what = ("declared without a value (set at run time or in another module)"
                    if init is None else "initialized from an expression at run time")
            expr = self.text[start:(init.end if init is not None else name_pos + len(name))]
            if kind in ("robtarget", "jointtarget"):
                self.runtime.append(RuntimeTarget(expr, self.loc(name_pos), what, name,
                                                  routine, (start, name_pos + len(name))))
            elif kind == "tooldata":
                self.tools.append(ToolData(name, self.loc(name_pos), None, (), (), None,
                                           storage, routine=routine))
            else:
                self.wobjs.append(WorkObject(name, self.loc(name_pos), None, None, None, (),
                                             (), (), (), None, storage, routine))
            return
        reader = getattr(self, _READERS[kind])  # no bound methods stored: no cycle
        try:
            if rank == 0:
                end = reader(init.start, init.end, name, self.src(name_pos), storage, None,
                             routine, type_span)
            else:
                def leaf(pos, index):
                    return reader(pos, init.end, name, self.src(pos), storage, index,
                                  routine, type_span)
                end = read_elements(self.text, init.start, rank, leaf)
            if end != init.end:
                raise LiteralError("unexpected text after the value", end)
        except LiteralError as exc:
            raise self.error(exc, f"{typ} {name}") from None

    def _robtarget(self, pos, limit, name, loc, storage, index, routine, type_span,
                   inline=False):
        got = fast_groups(ROBTARGET_RE, self.text, pos)
        if got is not None:
            texts, starts, end = got
        else:
            agg = read_aggregate(self.text, pos, limit)
            end = agg.end
            groups = shape_of(agg, (3, 4, 4, 6), "robtarget [[x,y,z],[q1,q2,q3,q4],"
                                                  "[cf1,cf4,cf6,cfx],[eax_a..eax_f]]")
            if groups is None:
                self.runtime.append(RuntimeTarget(
                    self.text[pos:end], SourceLocation(*loc),
                    "robtarget literal holds non-numeric values",
                    name, routine, (pos, end)))
                return end
            texts, starts = _flat(groups)
        t = CartesianTarget(name, loc, texts, starts, QUAT_WXYZ, (pos, end), storage, index,
                            routine, type_span)
        self.targets.append(t)
        return t if inline else end

    def _jointtarget(self, pos, limit, name, loc, storage, index, routine, type_span,
                     inline=False):
        got = fast_groups(JOINTTARGET_RE, self.text, pos)
        if got is not None:
            texts, starts, end = got
        else:
            agg = read_aggregate(self.text, pos, limit)
            end = agg.end
            groups = shape_of(agg, (6, 6), "jointtarget [[rax_1..rax_6],[eax_a..eax_f]]")
            if groups is None:
                self.runtime.append(RuntimeTarget(
                    self.text[pos:end], SourceLocation(*loc),
                    "jointtarget literal holds non-numeric values",
                    name, routine, (pos, end)))
                return end
            texts, starts = _flat(groups)
        t = JointTarget(name, loc, texts, starts, 6, (pos, end), storage, index, routine,
                        type_span)
        self.joints.append(t)
        return t if inline else end

    def _tooldata(self, pos, limit, name, loc, storage, index, routine, type_span,
                  inline=False):
        agg = read_aggregate(self.text, pos, limit)
        what = "tooldata [robhold,[[x,y,z],[q1..q4]],[mass,[cx,cy,cz],[a1..a4],ix,iy,iz]]"
        if len(agg.items) != 3:
            raise LiteralError(f"expected 3 components in {what}, found {len(agg.items)}",
                               agg.start)
        robhold = _bool(agg.items[0], what)
        frame = shape_of(_agg(agg.items[1], what), (3, 4), what)
        load = _agg(agg.items[2], what)
        if len(load.items) != 6:
            raise LiteralError(f"expected 6 components in the load of {what}", load.start)
        mass = load.items[0] if type(load.items[0]) is Number else None
        cog = numbers_of(_agg(load.items[1], what), 3, "the centre of gravity") or ()
        aom = numbers_of(_agg(load.items[2], what), 4, "the load orientation") or ()
        inertia = tuple(i for i in load.items[3:] if type(i) is Number)
        if index is not None:
            name = f"{name}{{{','.join(map(str, index))}}}"
        tool = ToolData(name, SourceLocation(*loc), robhold, frame[0] if frame else (),
                        frame[1] if frame else (), (pos, agg.end), storage, mass, cog, aom,
                        inertia, QUAT_WXYZ, routine)
        if not inline:
            self.tools.append(tool)
        return tool if inline else agg.end

    def _wobjdata(self, pos, limit, name, loc, storage, index, routine, type_span,
                  inline=False):
        agg = read_aggregate(self.text, pos, limit)
        what = 'wobjdata [robhold,ufprog,"ufmec",[[x,y,z],[q1..q4]],[[x,y,z],[q1..q4]]]'
        if len(agg.items) != 5:
            raise LiteralError(f"expected 5 components in {what}, found {len(agg.items)}",
                               agg.start)
        robhold = _bool(agg.items[0], what)
        ufprog = _bool(agg.items[1], what)
        mec = agg.items[2]
        ufmec = mec.text[1:-1].replace('""', '"') if isinstance(mec, Atom) and \
            mec.kind == "string" else None
        uf = shape_of(_agg(agg.items[3], what), (3, 4), "the user frame of " + what)
        of = shape_of(_agg(agg.items[4], what), (3, 4), "the object frame of " + what)
        if index is not None:
            name = f"{name}{{{','.join(map(str, index))}}}"
        ok = uf is not None and of is not None
        wobj = WorkObject(name, SourceLocation(*loc), robhold, ufprog, ufmec, uf[0] if ok else (),
                          uf[1] if ok else (), of[0] if ok else (), of[1] if ok else (),
                          (pos, agg.end), storage, routine)
        if not inline:
            self.wobjs.append(wobj)
        return wobj if inline else agg.end

    # -- calls
    def ex(self, v) -> Ex:
        """An argument value as an Ex (fast-path values are bare (start, end) spans)."""
        return v if type(v) is Ex else value_ex(self.text, v[0], v[1])

    def call(self, rec) -> None:
        name, start, name_end, end, positional, opts = rec
        spec = MOTIONS.get(name.lower())
        routine = self.routine_at(start) if self.routine_records else None
        if spec is None:
            context = "late-bound call" if name == "%" else name
            for v in positional:
                v = self.ex(v)
                if v.kind in ("name", "index"):
                    self.references.append(NameReference(
                        v.name, self._index(v), self.loc(v.start), context, routine))
            return
        by_name = {o.name.lower(): o for o in opts} if opts else {}
        tool = tool_inline = None
        o = by_name.get("tool")
        t_ex = o.value if o is not None else (
            positional[spec.tool] if len(positional) > max(spec.tool, -spec.tool - 1)
            else None)
        if t_ex is not None:
            t_ex = self.ex(t_ex)
            if t_ex.kind == "aggregate":
                tool_inline = self._inline(self._tooldata, t_ex, None, routine, "tooldata")
            else:
                tool = self._ref_text(t_ex)
        wobj = wobj_inline = None
        w = by_name.get("wobj")
        if w is not None:
            if w.cond is not None:
                wobj = w.cond
            elif w.value is not None:
                w_ex = self.ex(w.value)
                if w_ex.kind == "aggregate":
                    wobj_inline = self._inline(self._wobjdata, w_ex, None, routine,
                                               "wobjdata")
                else:
                    wobj = self._ref_text(w_ex)
        if spec.writes is not None and len(positional) > spec.writes:
            v = self.ex(positional[spec.writes])
            self.runtime.append(RuntimeTarget(
                self.text[v.start:v.end], self.loc(v.start),
                f"written by {name} (search result) at run time",
                v.name if v.kind in ("name", "index") else None, routine, (v.start, v.end)))
        for k, role in spec.targets:
            if k >= len(positional):
                continue
            v = self.ex(positional[k])
            kind = v.kind
            target_name = target_index = inline = runtime = None
            if kind == "name":
                target_name = v.name
            elif kind == "index":
                target_name, target_index = v.name, self._index(v)
            elif kind == "aggregate":
                reader = self._jointtarget if spec.joint else self._robtarget
                inline = self._inline(reader, v, None, routine,
                                      "jointtarget" if spec.joint else "robtarget")
                if inline is None:
                    continue
            else:
                runtime = self._runtime_arg(v, name, routine)
                self.runtime.append(runtime)
            self.motions.append(MotionUse(
                name, self.src(v.start), role, target_name, target_index, inline, runtime,
                tool, tool_inline, wobj, wobj_inline, spec.joint, routine, (start, name_end),
                (start, end), (v.start, v.end)))

    def _inline(self, reader, ex: Ex, name, routine, what):
        try:
            obj = reader(ex.start, ex.end, name, self.src(ex.start), "inline", None, routine,
                         None, inline=True)
        except LiteralError as exc:
            raise self.error(exc, f"inline {what}") from None
        if isinstance(obj, int):  # non-numeric literal: recorded as runtime
            return None
        if obj.span[1] != ex.end:
            raise self.error(LiteralError("unexpected text after the value", obj.span[1]),
                             f"inline {what}")
        return obj

    def _runtime_arg(self, v: Ex, instruction: str, routine) -> RuntimeTarget:
        base = None
        if v.kind == "call":
            reason = RUNTIME_FUNCS.get(v.name.lower(),
                                        f"{v.name}() is evaluated at run time")
            first = v.args[0].value if v.args and v.args[0].value is not None else None
            first = self.ex(first) if first is not None else None
            if first is not None and first.kind in ("name", "index"):
                base = first.name
        elif v.kind == "star":
            reason = "'*' placeholder: the target is not written in the program"
        elif v.kind == "complex":
            reason = "record field or expression evaluated at run time"
            base = v.name
        else:
            reason = "expression evaluated at run time"
        return RuntimeTarget(self.text[v.start:v.end], self.loc(v.start),
                             f"{reason} ({instruction})", base, routine, (v.start, v.end))

    def _index(self, v: Ex):
        if v.kind != "index":
            return None
        if all(e.kind == "num" and self.text[e.start:e.end].isdigit() for e in v.index):
            return tuple(int(self.text[e.start:e.end]) for e in v.index)
        return ",".join(self.text[e.start:e.end].strip() for e in v.index)

    def _ref_text(self, v: Ex) -> str:
        if v.kind == "name":
            return v.name
        return _WS_RE.sub("", self.text[v.start:v.end])

    # -- assignments
    def assign(self, rec) -> None:
        lv, value = rec
        if lv.name.lower() not in self.target_names:
            return
        start = lv.start
        reason = ("field assigned at run time" if lv.kind == "complex"
                  else "assigned at run time")
        self.runtime.append(RuntimeTarget(
            self.text[start:value.end], self.loc(start), reason, lv.name,
            self.routine_at(start), (start, value.end)))


def _flat(groups) -> tuple[tuple[str, ...], tuple[int, ...]]:
    nums = [n for g in groups for n in g]
    return tuple(n.text for n in nums), tuple(n.start for n in nums)


def _agg(item, what) -> Agg:
    if not isinstance(item, Agg):
        raise LiteralError(f"expected [...] in {what}", item.start)
    return item


def _bool(item, what) -> bool | None:
    if isinstance(item, Atom) and item.kind == "name" and item.text.upper() in ("TRUE",
                                                                                "FALSE"):
        return item.text.upper() == "TRUE"
    if isinstance(item, Agg):
        raise LiteralError(f"expected TRUE or FALSE in {what}", item.start)
    return None


_WS_RE = re.compile(r"\s+")
_PARAM_NAME = re.compile(r"([A-Za-z_]\w*)\s*(?:\{[^{}]*\})?\s*(?=[,|)]|$)")


def _param_names(params: str) -> tuple[str, ...]:
    return tuple(m.group(1) for m in _PARAM_NAME.finditer(params.strip("()") + ")"))


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
    try:
        parser("rapid.lark", Callbacks, ("start", "call")).parse(TextSlice(text, start, end),
                                                                 start="call")
    except UnexpectedInput as exc:
        raise convert_lark_error(exc, text, file) from None


def parse_rapid(text: str, file: str = "<string>") -> Program:
    """Parse RAPID module text (already decoded) into a :class:`Program`.

    Raises ParseError (file, line, column, caret context) on any malformed input.
    """
    check_text(text, file)
    with young_gc_only():
        return _parse(text, file)


def _parse(text: str, file: str) -> Program:
    sink = Sink(text, file, lambda start, end: _reparse_call(text, file, start, end))
    token = current_sink.set(sink)
    try:
        parser("rapid.lark", Callbacks, ("start", "call")).parse(text, start="start")
    except UnexpectedInput as exc:
        raise convert_lark_error(exc, text, file) from None
    finally:
        current_sink.reset(token)
    if not sink.modules:
        raise error_at("no MODULE found", text, file, 0)
    b = _Builder(text, file, sink)
    b.targets = sink.targets  # the fast paths' (in text order); the builder appends
    b.motions = sink.motions
    fast_targets, fast_motions = len(sink.targets), len(sink.motions)
    # robtarget/jointtarget names first, so assignments can be recognized
    for rec in sink.decls:
        if b.base_type(rec[2]) in ("robtarget", "jointtarget"):
            b.target_names.add(rec[4].lower())
    for rec in sink.decls:
        b.declaration(rec)
    for rec in sink.calls:
        b.call(rec)
    if sink.assigns or b.references:  # then the names of the fast paths' targets are needed
        b.target_names.update(t.name.lower() for t in sink.targets[:fast_targets]
                              if t.name is not None)
    for rec in sink.assigns:
        b.assign(rec)
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
        routines=b.routines, modules=tuple(sink.modules))


Callbacks.lexer_callbacks = LEXER_CALLBACKS
