"""VAL II / V+ (and Kawasaki AS) location files and programs into the shared target model.

Convention implemented (Adept, "V+ Language User's Guide" v17, Location Variables: the
orientation of a transformation is yaw, pitch, roll, "figured as ZYZ' Euler values"; and
"V+ Language Reference Guide", TRANS: ``TRANS(x, y, z, yaw, pitch, roll)``):

- a transformation is ``x y z`` in mm and ``yaw pitch roll`` in degrees with
  R = Rz(yaw) Ry(pitch) Rz(roll) (rotations about the moving axes), as
  :func:`olp_compensate.kinematics.conventions.matrix_from_euler_zyz`;
- a precision point ``#name`` holds joint values, degrees (mm for a prismatic joint);
- V+ names are case-insensitive and may contain ``.`` and ``_``; ``#name`` and ``name``
  are different variables.

What is read: ``.LOCATIONS`` (and Kawasaki ``.TRANS``/``.JOINTS``) lines
``name x y z yaw pitch roll`` and ``#name j1 ... jn``; ``SET``/``POINT name = TRANS(...)``
and ``#PPOINT(...)`` with literal numbers; MOVE, MOVES, MOVET, MOVEST, APPRO, APPROS (and
Kawasaki JMOVE, LMOVE, JAPPRO, LAPPRO, C1MOVE, C2MOVE) references; ``frame:name`` compound
transformations (the frame is recorded as the work object); ``TOOL name`` (the tool of the
following motions of the same program, in text order, until the next TOOL; TOOL NULL
resets it). Anything else (SHIFT, INVERSE, HERE, longer compounds) is recorded as a
run-time target. DEPART/DEPARTS take a distance, not a location: parsed, not recorded.
A transformation line must hold exactly 6 numbers (a 12-number matrix form is refused
with a ParseError). Other steps and data sections (.REALS, .STRINGS...) are opaque lines.
"""

from __future__ import annotations

import re

import lark
from lark.exceptions import UnexpectedInput

from .grammar import (PositionedBuilder, LineIndex, check_text, convert_lark_error, current_sink, error_at,
                      newline_style, no_gc, parser)
from .targets import (EULER_ZYZ_DEG, CartesianTarget, JointTarget, MotionUse, Program,
                      Routine, RuntimeTarget, SourceLocation, ToolData)

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_NUM_RE = re.compile(_NUM)
_LOC_LINE = re.compile(r"(#?[A-Za-z][A-Za-z0-9_.]*)(?:\[([^\]\r\n;]*)\])?")
_SEP = re.compile(r"(?:[ \t]*(?:;[^\r\n]*)?\r?\n)*[ \t]*")
# the common location line, read in one match: name[index] x y z yaw pitch roll ;comment
_TRANS_LINE = re.compile(
    r"([A-Za-z][A-Za-z0-9_.]*)(?:\[([^\]\r\n;]*)\])?"
    + "".join(r"[ \t]+(" + _NUM + ")" for _ in range(6))
    + r"[ \t]*(?:;[^\r\n]*)?(?=\r?\n|\Z)")
_FIRST_NAME = re.compile(r"(#?[A-Za-z][A-Za-z0-9_.]*)")
_LOC_NAME = re.compile(r"(#?[A-Za-z][A-Za-z0-9_.]*)(?:\[([^\]]*)\])?\Z")


class _Sink:
    __slots__ = ("steps", "loc_blocks", "programs")

    def __init__(self):
        self.steps, self.loc_blocks, self.programs = [], [], []


class Callbacks(lark.Transformer):
    """Inline callbacks appending records to the parse in progress (see rapid.py)."""

    def __default__(self, data, children, meta):
        return lark.Tree(data, children) if data[0] == "_" else None

    def loc_term(self, c):
        return (c[0], c[1] if len(c) > 1 else None)

    def loc_expr(self, c):
        return c

    def motion(self, c):
        current_sink.get().steps.append(("motion", c[0], c[1]))

    def set_stmt(self, c):
        current_sink.get().steps.append(("set", c[0], c[1], c[2]))

    def point_stmt(self, c):
        if len(c) == 3:
            current_sink.get().steps.append(("set", c[0], c[1], c[2]))

    def here_stmt(self, c):
        current_sink.get().steps.append(("here", c[0], c[1]))

    def tool_stmt(self, c):
        current_sink.get().steps.append(("tool", c[0], c[1] if len(c) > 1 else None))

    def program(self, c):
        head, end = c[0], c[-1]
        current_sink.get().programs.append((head, end))

    def locations(self, c):
        if len(c) == 3:
            current_sink.get().loc_blocks.append(c[1])


def _index(text: str | None):
    if text is None:
        return None
    parts = [p.strip() for p in text.split(",")]
    if all(p.isdigit() for p in parts):
        return tuple(int(p) for p in parts)
    return ",".join(parts)


class _Builder(PositionedBuilder):
    def __init__(self, text: str, file: str):
        self.text, self.file = text, file
        self.index = LineIndex(text)
        self.targets: list = []
        self.joints: list = []
        self.tools: list = []
        self.runtime: list = []
        self.motions: list = []
        self.routines: list = []

    # -- .LOCATIONS lines
    def loc_block(self, tok) -> None:
        s, p0, n = tok.value, tok.start_pos, len(tok.value)
        pos = 0
        six, skip = _TRANS_LINE.match, _SEP.match
        while pos < n:
            m = six(s, pos)
            if m is not None:  # the common line: name x y z yaw pitch roll, one match
                starts = tuple([p0 + r[0] for r in m.regs[3:]])
                texts = m.groups()[2:]
                self.targets.append(CartesianTarget(
                    m.group(1), self.src(p0 + pos), texts, starts, EULER_ZYZ_DEG,
                    (starts[0], p0 + m.end(8)), "vplus", _index(m.group(2)), None,
                    (p0 + m.start(1), p0 + m.end(1))))
                pos = skip(s, m.end()).end()
                continue
            m = _LOC_LINE.match(s, pos)
            name, idx = m.group(1), _index(m.group(2))
            end_line = s.find("\n", pos)
            end_line = n if end_line < 0 else end_line
            semi = s.find(";", m.end(), end_line)
            stop = end_line if semi < 0 else semi
            nums = [(p0 + k.start(), k.group()) for k in _NUM_RE.finditer(s, m.end(), stop)]
            texts = tuple(t for _, t in nums)
            starts = tuple(a for a, _ in nums)
            span = (starts[0], starts[-1] + len(texts[-1]))
            name_span = (p0 + m.start(1), p0 + m.end(1))
            if name.startswith("#"):
                self.joints.append(JointTarget(name, self.src(p0 + pos), texts, starts,
                                               len(texts), span, "vplus", idx, None,
                                               name_span))
            else:
                if len(texts) != 6:
                    raise error_at(f"transformation {name}: expected 6 numbers (x y z yaw "
                                   f"pitch roll), found {len(texts)}", self.text, self.file,
                                   p0 + pos, self.index)
                self.targets.append(CartesianTarget(
                    name, self.src(p0 + pos), texts, starts, EULER_ZYZ_DEG, span, "vplus",
                    idx, None, name_span))
            pos = _SEP.match(s, end_line).end()

    # -- literals in program steps
    def _literal(self, term, name, name_span, storage, routine, where):
        """A CartesianTarget/JointTarget for TRANS(...)/#PPOINT(...) with literal numbers,
        else None."""
        func, args = term
        kind = func.value.upper()
        if args is None or kind not in ("TRANS", "#PPOINT"):
            return None
        inner_start = args.start_pos + 1
        parts = args.value[1:-1].split(",")
        texts, starts = [], []
        off = inner_start
        for part in parts:
            st = part.strip()
            if not _NUM_RE.fullmatch(st):
                return None
            texts.append(st)
            starts.append(off + len(part) - len(part.lstrip()))
            off += len(part) + 1
        span = (func.start_pos, args.end_pos)
        loc = self.src(where)
        if kind == "TRANS":
            if len(texts) != 6:
                return None
            return CartesianTarget(name, loc, tuple(texts), tuple(starts), EULER_ZYZ_DEG,
                                   span, storage, None, routine, name_span)
        return JointTarget(name, loc, tuple(texts), tuple(starts), len(texts), span,
                           storage, None, routine, name_span)

    def steps(self, steps, routine_at) -> None:
        tool_by_routine: dict = {}
        for step in steps:
            kind, kw = step[0], step[1]
            routine = routine_at(kw.start_pos)
            if kind == "set":
                lhs, expr = step[2], step[3]
                m = _LOC_NAME.match(lhs.value)
                name, idx = m.group(1), _index(m.group(2))
                target = (self._literal(expr[0], name, (lhs.start_pos, lhs.end_pos), "vplus",
                                        routine, lhs.start_pos) if len(expr) == 1 else None)
                if target is None:
                    a, b = expr[0][0].start_pos, _term_end(expr[-1])
                    self.runtime.append(RuntimeTarget(
                        self.text[a:b], self.loc(lhs.start_pos),
                        f"{kw.value.upper()} from an expression evaluated at run time",
                        name, routine, (a, b)))
                    continue
                if idx is not None:
                    target = _with_index(target, idx)
                (self.joints if isinstance(target, JointTarget) else self.targets).append(
                    target)
            elif kind == "here":
                lhs = step[2]
                self.runtime.append(RuntimeTarget(
                    self.text[kw.start_pos:lhs.end_pos], self.loc(lhs.start_pos),
                    "HERE records the current position at run time",
                    _LOC_NAME.match(lhs.value).group(1), routine, (kw.start_pos, lhs.end_pos)))
            elif kind == "tool":
                expr = step[2]
                tool_by_routine[routine] = self._tool(expr, routine)
            elif kind == "motion":
                self._motion(kw, step[2], tool_by_routine.get(routine, (None, None)), routine)

    def _tool(self, expr, routine):
        if not expr:
            return (None, None)
        if len(expr) == 1 and expr[0][1] is None:
            name = expr[0][0].value
            return (None, None) if name.upper() == "NULL" else (name, None)
        lit = self._literal(expr[0], None, None, "inline", routine, expr[0][0].start_pos) \
            if len(expr) == 1 else None
        if isinstance(lit, CartesianTarget):
            tool = ToolData(None, lit.location, True, lit.position, lit.orientation, lit.span,
                            "inline", orientation_kind=EULER_ZYZ_DEG, routine=routine)
            return (None, tool)
        a, b = expr[0][0].start_pos, _term_end(expr[-1])
        return (self.text[a:b], None)

    def _motion(self, kw, expr, tool, routine) -> None:
        name = kw.value
        start, end = expr[0][0].start_pos, _term_end(expr[-1])
        loc = self.src(start)
        common = dict(tool=tool[0], tool_inline=tool[1], routine=routine,
                      instruction_span=(kw.start_pos, kw.end_pos),
                      statement_span=(kw.start_pos, end), target_span=(start, end))
        plain = [t for t in expr if t[1] is None]
        if len(expr) == 1 and expr[0][1] is None:
            m = _LOC_NAME.match(expr[0][0].value)
            tname = m.group(1)
            self.motions.append(MotionUse(
                name, loc, "to", tname, _index(m.group(2)), joint=tname.startswith("#"),
                **common))
            return
        if len(expr) == 2 and len(plain) == 2 and not expr[1][0].value.startswith("#"):
            frame = expr[0][0].value
            m = _LOC_NAME.match(expr[1][0].value)
            self.motions.append(MotionUse(
                name, loc, "to", m.group(1), _index(m.group(2)), wobj=frame, **common))
            return
        if len(expr) == 1:
            lit = self._literal(expr[0], None, None, "inline", routine, start)
            if lit is not None:
                (self.joints if isinstance(lit, JointTarget) else self.targets).append(lit)
                self.motions.append(MotionUse(name, loc, "to", inline=lit,
                                              joint=isinstance(lit, JointTarget), **common))
                return
        base = None
        if plain:
            m = _LOC_NAME.match(plain[-1][0].value)
            base = m.group(1) if m else None
        elif expr[-1][1] is not None:  # SHIFT(pick BY ...), INVERSE(pick): first name inside
            m = _FIRST_NAME.search(expr[-1][1].value)
            base = m.group(1) if m else None
        runtime = RuntimeTarget(self.text[start:end], SourceLocation(*loc),
                                f"compound or computed location ({name})", base, routine,
                                (start, end))
        self.runtime.append(runtime)
        self.motions.append(MotionUse(name, loc, "to", runtime=runtime, **common))


def _term_end(term) -> int:
    return term[1].end_pos if term[1] is not None else term[0].end_pos


def _with_index(t, idx):
    return t._replace(array_index=idx)


def parse_vplus(text: str, file: str = "<string>") -> Program:
    """Parse a V+ / VAL II / Kawasaki AS file (already decoded) into a :class:`Program`.

    Raises ParseError (file, line, column, caret context) on malformed input.
    """
    check_text(text, file)
    with no_gc():
        return _parse(text, file)


def _parse(text: str, file: str) -> Program:
    sink = _Sink()
    token = current_sink.set(sink)
    try:
        parser("vplus.lark", Callbacks).parse(text)
    except UnexpectedInput as exc:
        raise convert_lark_error(exc, text, file) from None
    finally:
        current_sink.reset(token)
    b = _Builder(text, file)
    for tok in sink.loc_blocks:
        b.loc_block(tok)
    spans = []
    for head, end in sink.programs:
        m = re.match(r"\.PROGRAM\s+([A-Za-z][A-Za-z0-9_.]*)\s*(\(([^)]*)\))?", head.value,
                     re.I)
        name = m.group(1) if m else "?"
        params = tuple(p.strip() for p in (m.group(3) or "").split(",") if p.strip()) \
            if m else ()
        spans.append((head.start_pos, end.end_pos, name))
        b.routines.append(Routine(name, "PROGRAM", b.loc(head.start_pos),
                                  (head.start_pos, end.end_pos), params))

    def routine_at(offset):
        for a, z, name in spans:
            if a <= offset < z:
                return name
        return None

    b.steps(sink.steps, routine_at)
    by_start = lambda t: t.span[0]  # noqa: E731
    return Program(
        file=file, text=text, encoding="latin-1", dialect="vplus",
        newline=newline_style(text),
        targets=tuple(sorted(b.targets, key=by_start)),
        joint_targets=tuple(sorted(b.joints, key=by_start)),
        tools=tuple(b.tools), motions=tuple(b.motions),
        runtime=tuple(sorted(b.runtime, key=lambda r: r.span or (0, 0))),
        routines=tuple(b.routines))
