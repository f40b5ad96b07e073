"""RAPID: the parse records of one module turned into the shared target model.

The grammar callbacks and the fast paths leave :mod:`.records` records in a
:class:`~.rapid_records.Sink`; :class:`Builder` reads each kind in turn (declarations,
calls, assignments) and finally accounts for every robtarget literal it did not take as a
target (:mod:`.accounting`).
"""

from __future__ import annotations

import bisect
import re

from ..grammar import PositionedBuilder
from ..literals import LiteralError, literal_error, read_elements
from ..targets import (CartesianTarget, MotionUse, NameReference, Routine, RuntimeTarget,
                       TargetCopy, TargetProblem, ToolData, WorkObject)
from .fast import value_ex
from .instructions import MOTIONS, RUNTIME_FUNCS, MotionSpec
from .records import CallRecord, Decl, Ex, Sink
from .values import READERS, Placement, read_robtarget, read_tooldata, read_wobjdata

TARGET_TYPES = ("robtarget", "jointtarget", "tooldata", "wobjdata")
UNKNOWN_INSTRUCTION = "unknown_instruction"
_NAMED_TARGETS = {"to": ("topoint", "tojointpos"), "circle": ("cirpoint",)}


class Builder(PositionedBuilder):
    """Turns the sink's records into model objects (one per parse)."""

    def __init__(self, text: str, file: str, sink: Sink):
        self.text, self.file, self.sink = text, file, sink
        self.index = sink.index
        self.targets: list = sink.targets   # the fast paths' (text order); appended to
        self.motions: list = sink.motions
        self.joints: list = []
        self.tools: list = []
        self.wobjs: list = []
        self.runtime: list = sink.runtime   # the fast paths'; appended to
        self.references: list = []
        self.problems: list[TargetProblem] = []
        self.copies: list[TargetCopy] = []
        self.record_values: list[tuple[int, int, str]] = []   # (start, end, what)
        routines = sorted(sink.routines, key=lambda r: r.start)
        self.routine_starts = [r.start for r in routines]
        self.routine_records = routines
        self.routine_names = {r.name.lower() for r in routines}
        self.routines = tuple(
            Routine(name=r.name, kind=r.kind, location=self.loc(r.name_pos),
                    span=(r.start, r.end), parameters=_param_names(r.parameters))
            for r in routines)
        self.fast_targets = len(sink.targets)
        self._names: tuple[set[str], set[str]] | None = None

    def routine_at(self, offset: int) -> str | None:
        k = bisect.bisect_right(self.routine_starts, offset) - 1
        if k >= 0 and offset < self.routine_records[k].end:
            return self.routine_records[k].name
        return None

    def error(self, exc: LiteralError, what: str):
        return literal_error(exc, what, self.text, self.file, self.index)

    # -- names
    def base_type(self, typ: str) -> str:
        """The built-in type behind an ALIAS (lower case)."""
        kind = typ.lower()
        for _ in range(8):
            t = self.sink.types.get(kind)
            if t is None or t.kind != "alias":
                break
            kind = t.base.lower()
        return kind

    @property
    def target_names(self) -> set[str]:
        """Lower-case names of the declared robtargets and jointtargets."""
        return self._name_sets()[0]

    @property
    def robtarget_names(self) -> set[str]:
        """Lower-case names of the declared robtargets."""
        return self._name_sets()[1]

    def _name_sets(self) -> tuple[set[str], set[str]]:
        if self._names is None:   # on first need: most big modules never ask
            robtargets = {t.name.lower() for t in self.targets[:self.fast_targets]
                          if t.name is not None}
            if self.sink.columns is not None:
                robtargets.update(n.lower() for n in self.sink.columns.targets.names)
            joints = set()
            for rec in self.sink.decls:
                kind = self.base_type(rec.type_name)
                if kind == "robtarget":
                    robtargets.add(rec.name.lower())
                elif kind == "jointtarget":
                    joints.add(rec.name.lower())
            self._names = (robtargets | joints, robtargets)
        return self._names

    def record_targets(self, kind: str, depth: int = 0) -> list[str]:
        """Fields of a user RECORD type that hold targets, tools or work objects."""
        t = self.sink.types.get(kind)
        if t is None or t.kind != "record" or depth > 8:
            return []
        out = []
        for ftype, fname in t.fields:
            base = self.base_type(ftype)
            if base in TARGET_TYPES:
                out.append(f"{fname} ({base})")
            out += [f"{fname}.{x}" for x in self.record_targets(base, depth + 1)]
        return out

    # -- declarations
    def declaration(self, rec: Decl) -> None:
        kind = self.base_type(rec.type_name)
        name_end = rec.name_pos + len(rec.name)
        if kind not in TARGET_TYPES:
            self._record_declaration(rec, kind, name_end)
            return
        routine = self.routine_at(rec.start) if self.routine_records else None
        init = rec.value
        if init is None or init.kind != "aggregate":
            self._valueless_declaration(rec, kind, routine, name_end)
            return
        reader = READERS[kind]
        keep = {"robtarget": self._keep_target, "jointtarget": self.joints.append,
                "tooldata": self.tools.append, "wobjdata": self.wobjs.append}[kind]
        text = self.text

        def leaf(pos, index):
            place = Placement(name=rec.name, source=self.src(pos if index else rec.name_pos),
                              storage=rec.storage, array_index=index, routine=routine,
                              type_span=rec.type_span)
            value = reader(text, pos, init.end, place)
            if type(value) is RuntimeTarget:
                self.runtime.append(value)
                return value.span[1]
            keep(value)
            return value.span[1]
        try:
            end = read_elements(text, init.start, rec.rank, leaf)
            if end != init.end:
                raise LiteralError("unexpected text after the value", end)
        except LiteralError as exc:
            raise self.error(exc, f"{rec.type_name} {rec.name}") from None

    def _keep_target(self, t: CartesianTarget) -> None:
        self.targets.append(t)

    def _record_declaration(self, rec: Decl, kind: str, name_end: int) -> None:
        """A declaration of another type: a user RECORD holding targets is listed."""
        inner = self.record_targets(kind) if self.sink.types else []
        if not inner:
            return
        what = f"record {rec.type_name} holds {', '.join(inner)}"
        self.runtime.append(RuntimeTarget(
            expression=self.text[rec.start:name_end], location=self.loc(rec.name_pos),
            reason=f"{what}: not read, not compensated", base_name=rec.name,
            routine=self.routine_at(rec.start), span=(rec.start, name_end)))
        if rec.value is not None:
            self.record_values.append((rec.value.start, rec.value.end,
                                       f"in the value of {rec.name} ({what})"))

    def _valueless_declaration(self, rec: Decl, kind: str, routine, name_end: int) -> None:
        init = rec.value
        what = ("declared without a value (set at run time or in another module)"
                if init is None else "initialized from an expression at run time")
        expr = self.text[rec.start:(init.end if init is not None else name_end)]
        loc = self.loc(rec.name_pos)
        if kind in ("robtarget", "jointtarget"):
            self.runtime.append(RuntimeTarget(expression=expr, location=loc, reason=what,
                                              base_name=rec.name, routine=routine,
                                              span=(rec.start, name_end)))
        elif kind == "tooldata":
            self.tools.append(ToolData(name=rec.name, location=loc, robhold=None,
                                       position=(), orientation=(), span=None,
                                       storage=rec.storage, routine=routine))
        else:
            self.wobjs.append(WorkObject(
                name=rec.name, location=loc, robhold=None, ufprog=None, ufmec=None,
                uframe_position=(), uframe_orientation=(), oframe_position=(),
                oframe_orientation=(), span=None, storage=rec.storage, routine=routine))

    # -- calls
    def ex(self, v) -> Ex:
        """An argument value as an Ex (fast-path values are bare (start, end) spans)."""
        return v if type(v) is Ex else value_ex(self.text, v[0], v[1])

    def call(self, rec: CallRecord) -> None:
        spec = MOTIONS.get(rec.name.lower())
        routine = self.routine_at(rec.start) if self.routine_records else None
        if spec is None:
            self._other_call(rec, routine)
            return
        by_name = {o.name.lower(): o for o in rec.opts} if rec.opts else {}
        positional = _with_named_targets(rec.positional, spec, by_name)
        tool, tool_inline = self._tool_argument(positional, spec, by_name, routine)
        wobj, wobj_inline = self._wobj_argument(by_name, routine)
        if spec.writes is not None and len(positional) > spec.writes:
            v = self.ex(positional[spec.writes])
            self.runtime.append(RuntimeTarget(
                expression=self.text[v.start:v.end], location=self.loc(v.start),
                reason=f"written by {rec.name} (search result) at run time",
                base_name=v.name if v.kind in ("name", "index") else None, routine=routine,
                span=(v.start, v.end)))
        for k, role in spec.targets:
            if k >= len(positional):
                continue
            v = self.ex(positional[k])
            use = dict(instruction=rec.name, source=self.src(v.start), role=role,
                       tool=tool, tool_inline=tool_inline, wobj=wobj, wobj_inline=wobj_inline,
                       joint=spec.joint, routine=routine,
                       instruction_span=(rec.start, rec.name_end),
                       statement_span=(rec.start, rec.end), target_span=(v.start, v.end))
            if v.kind == "name":
                use.update(target_name=v.name)
            elif v.kind == "index":
                use.update(target_name=v.name, target_index=self._index(v))
            elif v.kind == "aggregate":
                inline = self._inline(v, routine, spec)
                if inline is None:
                    continue
                use.update(inline=inline)
            else:
                runtime = self._runtime_arg(v, rec.name, routine)
                self.runtime.append(runtime)
                use.update(runtime=runtime)
            self.motions.append(MotionUse(**use))

    def _tool_argument(self, positional, spec: MotionSpec, by_name: dict, routine):
        """(tool name, inline ToolData) of a motion: ``Tool:=`` or its position."""
        o = by_name.get("tool")
        if o is not None:
            t_ex = o.value
        elif len(positional) > max(spec.tool, -spec.tool - 1):
            t_ex = positional[spec.tool]
        else:
            return None, None
        if t_ex is None:
            return None, None
        t_ex = self.ex(t_ex)
        if t_ex.kind == "aggregate":
            return None, self._inline_value(read_tooldata, t_ex, routine, "tooldata")
        return self._ref_text(t_ex), None

    def _wobj_argument(self, by_name: dict, routine):
        """(work-object name, inline WorkObject) of ``\\WObj``."""
        w = by_name.get("wobj")
        if w is None:
            return None, None
        if w.cond is not None:
            return w.cond, None
        if w.value is None:
            return None, None
        w_ex = self.ex(w.value)
        if w_ex.kind == "aggregate":
            return None, self._inline_value(read_wobjdata, w_ex, routine, "wobjdata")
        return self._ref_text(w_ex), None

    def _other_call(self, rec: CallRecord, routine) -> None:
        """A call that is no motion instruction known here: robtargets handed to an
        instruction that is neither known nor a routine of this module are reported
        'unknown_instruction'; names handed to a routine are references. ``RETURN v`` of a
        FUNC is no instruction: its value goes to the caller (a reference, no problem)."""
        known = (rec.name == "%" or rec.name.lower() in self.routine_names
                 or rec.name.upper() == "RETURN")
        context = "late-bound call" if rec.name == "%" else rec.name
        values = list(rec.positional) + [o.value for o in rec.opts if o.value is not None]
        for value in values:
            v = self.ex(value)
            if v.kind in ("name", "index"):
                self.references.append(NameReference(
                    name=v.name, index=self._index(v), location=self.loc(v.start),
                    context=context, routine=routine))
                if not known and self._robtarget_here(v.name.lower(), routine):
                    self._unknown_instruction(rec, self.text[v.start:v.end], v.start)
            elif v.kind == "aggregate" and not known and self._is_robtarget(v):
                self._unknown_instruction(rec, "<inline>", v.start)

    def _robtarget_here(self, low: str, routine) -> bool:
        """Whether the name ``low`` is a robtarget in ``routine``: declared a robtarget in
        the module and not shadowed there by a routine declaration of another type (a
        FUNC's ``VAR num result`` beside another routine's ``VAR robtarget result``)."""
        if low not in self.robtarget_names:
            return False
        if routine is None:
            return True
        span = next(((r.start, r.end) for r in self.routine_records if r.name == routine),
                    None)
        local = [d for d in self.sink.decls if d.name.lower() == low and span is not None
                 and span[0] <= d.start < span[1]]
        return not local or any(self.base_type(d.type_name) == "robtarget" for d in local)

    def _unknown_instruction(self, rec: CallRecord, shown: str, offset: int) -> None:
        self.problems.append(TargetProblem(
            target=shown, location=self.loc(offset), status=UNKNOWN_INSTRUCTION,
            reason=f"{rec.name} is no motion instruction this version knows, nor a routine "
                   f"of this module: its target is left as written"))

    def _is_robtarget(self, v: Ex) -> bool:
        place = Placement(name=None, source=("", 0, 0), storage="inline")
        try:
            value = read_robtarget(self.text, v.start, v.end, place)
        except LiteralError:
            return False
        return type(value) is CartesianTarget and value.span[1] == v.end

    def _inline(self, v: Ex, routine, spec: MotionSpec):
        """The inline target literal of a motion, kept; None when it holds names."""
        reader = READERS["jointtarget" if spec.joint else "robtarget"]
        value = self._inline_value(reader, v, routine,
                                   "jointtarget" if spec.joint else "robtarget")
        if type(value) is RuntimeTarget:
            self.runtime.append(value)
            return None
        (self.joints if spec.joint else self.targets).append(value)
        return value

    def _inline_value(self, reader, ex: Ex, routine, what):
        place = Placement(name=None, source=self.src(ex.start), storage="inline",
                          routine=routine)
        try:
            value = reader(self.text, ex.start, ex.end, place)
            if value.span is not None and value.span[1] != ex.end:
                raise LiteralError("unexpected text after the value", value.span[1])
        except LiteralError as exc:
            raise self.error(exc, f"inline {what}") from None
        return value

    def _runtime_arg(self, v: Ex, instruction: str, routine) -> RuntimeTarget:
        base = None
        if v.kind == "call":
            reason = RUNTIME_FUNCS.get(v.name.lower(), f"{v.name}() is evaluated at run time")
            first = v.args[0].value if v.args and v.args[0].value is not None else None
            first = self.ex(first) if first is not None else None
            if first is not None and first.kind in ("name", "index"):
                base = first.name
        elif v.kind == "star":
            reason = "'*' placeholder: the target is not written in the program"
        elif v.kind == "placeholder":
            reason = (f"editor placeholder {self.text[v.start:v.end]}: the target is not "
                      f"written in the program")
        elif v.kind == "complex":
            reason = "record field or expression evaluated at run time"
            base = v.name
        else:
            reason = "expression evaluated at run time"
        return RuntimeTarget(expression=self.text[v.start:v.end], location=self.loc(v.start),
                             reason=f"{reason} ({instruction})", base_name=base,
                             routine=routine, span=(v.start, v.end))

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
    def assign(self, lv: Ex, value: Ex) -> None:
        """``lv := value;``: a robtarget literal is a target where it stands, a plain copy
        is followed, anything else changes the target at run time."""
        if lv.name.lower() not in self.target_names:
            return
        start = lv.start
        routine = self.routine_at(start)
        index = self._index(lv) if lv.kind == "index" else None
        plain = lv.kind == "name" or (lv.kind == "index" and isinstance(index, tuple))
        robtarget = lv.name.lower() in self.robtarget_names
        if plain and robtarget and value.kind == "aggregate" and routine is not None:
            if self._assigned_literal(lv, index, value, routine):
                return
        if plain and value.kind in ("name", "index") and routine is not None:
            source_index = self._index(value) if value.kind == "index" else None
            if not isinstance(source_index, str):
                self.copies.append(TargetCopy(
                    name=lv.name, index=index, source_name=value.name,
                    source_index=source_index, routine=routine, offset=start,
                    location=self.loc(start)))
        reason = "field assigned at run time" if lv.kind == "complex" else "assigned at run time"
        self.runtime.append(RuntimeTarget(
            expression=self.text[start:value.end], location=self.loc(start), reason=reason,
            base_name=lv.name, routine=routine, span=(start, value.end)))

    def _assigned_literal(self, lv: Ex, index, value: Ex, routine: str) -> bool:
        """Keep the robtarget literal of ``lv := [...]`` as a target ('assigned');
        False when the literal holds names."""
        place = Placement(name=lv.name, source=self.src(value.start), storage="assigned",
                          array_index=index, routine=routine)
        try:
            target = read_robtarget(self.text, value.start, value.end, place)
            if target.span[1] != value.end:
                raise LiteralError("unexpected text after the value", target.span[1])
        except LiteralError as exc:
            raise self.error(exc, f"robtarget assigned to {lv.name}") from None
        if type(target) is RuntimeTarget:
            return False
        self.targets.append(target)
        return True


def _with_named_targets(positional: list, spec: MotionSpec, by_name: dict) -> list:
    """The positional values with the targets given by name (``ToPoint:=p10``,
    ``CirPoint:=``) put in their places."""
    out = None
    for k, role in spec.targets:
        for name in _NAMED_TARGETS[role]:
            o = by_name.get(name)
            if o is not None and o.value is not None:
                out = list(positional) if out is None else out
                out.insert(min(k, len(out)), o.value)
                break
    return positional if out is None else out


_WS_RE = re.compile(r"\s+")
_PARAM_NAME = re.compile(r"([A-Za-z_]\w*)\s*(?:\{[^{}]*\})?\s*(?=[,|)]|$)")


def _param_names(params: str) -> tuple[str, ...]:
    return tuple(m.group(1) for m in _PARAM_NAME.finditer(params.strip("()") + ")"))
