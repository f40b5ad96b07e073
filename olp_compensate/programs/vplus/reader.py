"""VAL II / V+ location files and programs, and Kawasaki AS dumps, into the shared target model.

Convention implemented (Adept, "V+ Language User's Guide" v17, Location Variables: the
orientation of a transformation is yaw, pitch, roll, "figured as ZYZ' Euler values"; and
"V+ Language Reference Guide", TRANS: ``TRANS(x, y, z, yaw, pitch, roll)``; Kawasaki AS
writes the same Z-Y-Z angles as O, A, T):

- a transformation is ``x y z`` in mm and ``yaw pitch roll`` (AS: ``o a t``) in degrees
  with R = Rz(yaw) Ry(pitch) Rz(roll) (rotations about the moving axes), as
  :func:`olp_compensate.kinematics.conventions.matrix_from_euler_zyz`;
- a precision point ``#name`` holds joint values, degrees (mm for a prismatic joint);
- names are case-insensitive and may contain ``.`` and ``_``; ``#name`` and ``name`` are
  different variables; in a program, ``.name`` is a local variable (Kawasaki AS).

What is read: ``.LOCATIONS`` lines ``name x y z yaw pitch roll`` (exactly 6 numbers; the
12-number matrix form is refused with a ParseError) and ``#name j1 ... jn``; Kawasaki
``.TRANS`` lines ``name x y z o a t [e1 ...]`` (the numbers after the sixth are external
axes, kept as written) and ``.JOINTS`` lines; ``SET``/``POINT name = TRANS(...)`` and
``#PPOINT(...)`` with literal numbers; MOVE, MOVES, MOVET, MOVEST, APPRO, APPROS (and
Kawasaki JMOVE, LMOVE, JAPPRO, LAPPRO, C1MOVE, C2MOVE) references; compound
transformations ``frame:name`` (AS ``frame+name``: the frame is recorded as the work
object); ``TOOL name`` and ``BASE name`` (the tool and the base frame of the following
motions of the same program, in text order, until the next TOOL / BASE; NULL resets);
Kawasaki block-teaching steps (``JOINT ... #[j1,...,jn]``: taught joints). Anything else
(SHIFT, INVERSE, HERE, ``p+TRANS(...)``, expressions) is recorded as a run-time target.
DEPART/DEPARTS take a distance, not a location: parsed, not recorded. Every other section
of a dump (``.REALS``, ``.AUXDATA``, ``.SYSDATA``, ``.INTER_PANEL_D``..., one-line
entries such as ``.NETCONF``, ``.*`` header lines) is one opaque token: its numbers are
not targets, and its bytes come back as read.
"""

from __future__ import annotations

import bisect
import re

import lark
from lark.exceptions import UnexpectedInput

from ..grammar import (PositionedBuilder, LineIndex, convert_lark_error, current_sink, error_at,
                       newline_style, parser)
from ..targets import (EULER_ZYZ_DEG, CartesianTarget, JointTarget, MotionUse, Program, Routine,
                       RuntimeTarget, SourceLocation, ToolData)
from ..text_checks import check_text
from .expressions import first_name, location_expression, skip_blanks, term_at, top_level_comma

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_NUM_RE = re.compile(_NUM)
_LOC_LINE = re.compile(r"(#?[A-Za-z][A-Za-z0-9_.]*)(?:\[([^\]\n;]*)\])?")
_SEP = re.compile(r"(?:[ \t\r]*(?:;[^\n]*)?\n)*[ \t]*")
# the common location line, read in one match: name[index] x y z yaw pitch roll ;comment
_TRANS_LINE = re.compile(
    r"([A-Za-z][A-Za-z0-9_.]*)(?:\[([^\]\n;]*)\])?"
    + "".join(r"[ \t]+(" + _NUM + ")" for _ in range(6))
    + r"[ \t\r]*(?:;[^\n]*)?(?=\n|\Z)")
_PROGRAM_HEAD = re.compile(r"\.PROGRAM\s+([A-Za-z][A-Za-z0-9_.]*)\s*(\(([^\n;]*)\))?", re.I)
_TAUGHT_JOINTS = re.compile(r"#\[([^\]\n;]*)\]")
_MODIFIER = re.compile(r"/[A-Za-z0-9]+[ \t]*")


class _Sink:
    __slots__ = ("steps", "loc_blocks", "programs")

    def __init__(self):
        self.steps, self.loc_blocks, self.programs = [], [], []


def _recorder(kind: str):
    """A callback recording (kind, keyword token, argument token or None)."""
    def record(self, c):
        current_sink.get().steps.append((kind, c[0], c[1] if len(c) > 1 else None))
    return record


class Callbacks(lark.Transformer):
    """Inline callbacks appending records to the parse in progress (see rapid.py)."""

    def __default__(self, data, children, meta):
        return lark.Tree(data, children) if data[0] == "_" else None

    motion = _recorder("motion")
    set_stmt = point_stmt = _recorder("set")
    here_stmt = _recorder("here")
    tool_stmt = _recorder("tool")
    base_stmt = _recorder("base")
    block_step = _recorder("block")

    def program(self, c):
        current_sink.get().programs.append((c[0], c[-1]))

    def locations(self, c):
        if len(c) == 3:
            current_sink.get().loc_blocks.append((c[0], c[1]))


def _index(text: str | None):
    """A literal index as a tuple of ints ((2,) for ``[2]``), else the index text."""
    if text is None:
        return None
    parts = [p.strip() for p in text.split(",")]
    if all(p.isdigit() for p in parts):
        return tuple(int(p) for p in parts)
    return ",".join(parts)


def _numbers_in(text: str, start: int, stop: int):
    """(texts, starts) of the comma-separated literal numbers in ``text[start:stop]``, or
    None when a part is not a number."""
    texts, starts = [], []
    off = start
    for part in text[start:stop].split(","):
        st = part.strip()
        if not _NUM_RE.fullmatch(st):
            return None
        texts.append(st)
        starts.append(off + len(part) - len(part.lstrip()))
        off += len(part) + 1
    return tuple(texts), tuple(starts)


class _Builder(PositionedBuilder):
    def __init__(self, text: str, file: str):
        self.text, self.file = text, file
        self.index = LineIndex(text)
        self.targets: list = []
        self.joints: list = []
        self.runtime: list = []
        self.motions: list = []
        self.routines: list = []

    # -- location sections
    def loc_block(self, head, tok) -> None:
        """The lines of a .LOCATIONS (exactly 6 numbers a transformation), .TRANS (6, then
        external axes) or .JOINTS section."""
        kawasaki = head.value[1:].upper().startswith(("TRANS", "JOINTS"))
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
            name_span = (p0 + m.start(1), p0 + m.end(1))
            if name.startswith("#"):
                span = (starts[0], starts[-1] + len(texts[-1]))
                self.joints.append(JointTarget(name, self.src(p0 + pos), texts, starts,
                                               len(texts), span, "vplus", idx, None,
                                               name_span))
            else:
                if len(texts) != 6 and not (kawasaki and len(texts) > 6):
                    want = "at least 6 numbers (x y z o a t, then external axes)" \
                        if kawasaki else "6 numbers (x y z yaw pitch roll)"
                    raise error_at(f"transformation {name}: expected {want}, found "
                                   f"{len(texts)}", self.text, self.file, p0 + pos,
                                   self.index)
                # the robot's six numbers; external axes (AS) stay as written
                span = (starts[0], starts[5] + len(texts[5]))
                self.targets.append(CartesianTarget(
                    name, self.src(p0 + pos), texts, starts, EULER_ZYZ_DEG, span, "vplus",
                    idx, None, name_span))
            pos = _SEP.match(s, end_line).end()

    # -- program steps
    def _literal(self, term, name, name_span, storage, routine, where):
        """A CartesianTarget/JointTarget for TRANS(...)/#PPOINT(...) with literal numbers,
        else None."""
        kind = term.name.upper()
        if term.args is None or kind not in ("TRANS", "#PPOINT"):
            return None
        found = _numbers_in(self.text, term.args_start + 1, term.end - 1)
        if found is None:
            return None
        texts, starts = found
        span = (term.name_start, term.end)
        loc = self.src(where)
        if kind == "TRANS":
            if len(texts) != 6:
                return None
            return CartesianTarget(name, loc, texts, starts, EULER_ZYZ_DEG, span, storage,
                                   None, routine, name_span)
        return JointTarget(name, loc, texts, starts, len(texts), span, storage, None,
                           routine, name_span)

    def steps(self, steps, routine_at) -> None:
        """Record the statements in text order; TOOL and BASE hold until the next one of
        the same program."""
        tool_by_routine: dict = {}
        base_by_routine: dict = {}
        for kind, kw, arg in steps:
            routine = routine_at(kw.start_pos)
            if arg is None:
                if kind == "tool":
                    tool_by_routine[routine] = (None, None)
                elif kind == "base":
                    base_by_routine[routine] = None
                continue
            a0, a1 = arg.start_pos, arg.end_pos
            if self.text[a0] == "=":   # `tool = 3`: a variable named like the keyword
                continue
            if kind == "set":
                self._assignment(kw, a0, a1, routine)
            elif kind == "here":
                self._here(kw, a0, a1, routine)
            elif kind == "tool":
                tool_by_routine[routine] = self._tool(a0, a1, routine)
            elif kind == "base":
                base_by_routine[routine] = self._base(a0, a1)
            elif kind == "motion":
                self._motion(kw, a0, a1, tool_by_routine.get(routine, (None, None)),
                             base_by_routine.get(routine), routine)
            elif kind == "block":
                self._block_step(kw, a0, a1, routine)

    def _assignment(self, kw, a0, a1, routine) -> None:
        """``POINT lhs = expression`` / ``SET lhs = expression``."""
        text = self.text
        mod = _MODIFIER.match(text, a0, a1)
        lhs = term_at(text, mod.end() if mod else a0, a1)
        if lhs is None or lhs.args is not None:
            return
        eq = skip_blanks(text, lhs.end, a1)
        if eq >= a1 or text[eq] != "=":
            return   # `POINT name` (monitor command: teach the current position)
        rhs = location_expression(text, eq + 1, a1)
        if rhs is None:
            return
        target = None
        if mod is None and rhs.plain and len(rhs.terms) == 1:
            target = self._literal(rhs.terms[0], lhs.name, (lhs.name_start, lhs.end),
                                   "vplus", routine, lhs.name_start)
        if target is None:
            word = text[kw.start_pos:(mod.end() if mod else kw.end_pos)].strip().upper()
            self.runtime.append(RuntimeTarget(
                text[rhs.start:rhs.end], self.loc(lhs.name_start),
                f"{word} from an expression evaluated at run time", lhs.name, routine,
                (rhs.start, rhs.end)))
            return
        if lhs.index is not None:
            target = target._replace(array_index=_index(lhs.index))
        (self.joints if isinstance(target, JointTarget) else self.targets).append(target)

    def _here(self, kw, a0, a1, routine) -> None:
        mod = _MODIFIER.match(self.text, a0, a1)
        lhs = term_at(self.text, mod.end() if mod else a0, a1)
        if lhs is None:
            return
        self.runtime.append(RuntimeTarget(
            self.text[kw.start_pos:lhs.end], self.loc(lhs.name_start),
            "HERE records the current position at run time", lhs.name, routine,
            (kw.start_pos, lhs.end)))

    def _tool(self, a0, a1, routine):
        """(tool name, None), (None, inline ToolData), or (None, None) for NULL."""
        expr = location_expression(self.text, a0, a1)
        if expr is None:
            return (None, None)
        if expr.plain and len(expr.terms) == 1:
            term = expr.terms[0]
            if term.args is None:
                name = self.text[term.name_start:term.end]
                return (None, None) if name.upper() == "NULL" else (name, None)
            lit = self._literal(term, None, None, "inline", routine, term.name_start)
            if isinstance(lit, CartesianTarget):
                return (None, ToolData(None, lit.location, True, lit.position,
                                       lit.orientation, lit.span, "inline",
                                       orientation_kind=EULER_ZYZ_DEG, routine=routine))
        return (expr.text(self.text), None)

    def _base(self, a0, a1):
        """The frame name of ``BASE name`` (None for NULL); any other expression as its
        text (an unknown frame for the motions that follow)."""
        expr = location_expression(self.text, a0, a1)
        if expr is None:
            return None
        name = expr.text(self.text)
        return None if name.upper() == "NULL" else name

    def _motion(self, kw, a0, a1, tool, base, routine) -> None:
        expr = location_expression(self.text, a0, a1)
        if expr is None:
            return
        name = kw.value
        start, end = expr.start, expr.end
        loc = self.src(start)
        common = dict(tool=tool[0], tool_inline=tool[1], routine=routine,
                      instruction_span=(kw.start_pos, kw.end_pos),
                      statement_span=(kw.start_pos, end), target_span=(start, end))
        terms = expr.terms
        plain = [t for t in terms if t.args is None]
        if expr.plain and len(terms) == 1 and terms[0].args is None:
            t = terms[0]
            self.motions.append(MotionUse(
                name, loc, "to", t.name, _index(t.index), wobj=base,
                joint=t.name.lstrip(".").startswith("#"), **common))
            return
        if (expr.plain and len(terms) == 2 and len(plain) == 2 and base is None
                and not terms[1].name.lstrip(".").startswith("#")):
            frame = self.text[terms[0].name_start:terms[0].end]
            self.motions.append(MotionUse(
                name, loc, "to", terms[1].name, _index(terms[1].index), wobj=frame,
                **common))
            return
        if expr.plain and len(terms) == 1:
            lit = self._literal(terms[0], None, None, "inline", routine, start)
            if lit is not None:
                (self.joints if isinstance(lit, JointTarget) else self.targets).append(lit)
                self.motions.append(MotionUse(name, loc, "to", inline=lit, wobj=base,
                                              joint=isinstance(lit, JointTarget), **common))
                return
        if plain:
            base_name = plain[-1].name
        elif terms and terms[-1].args is not None:  # SHIFT(pick BY ...): first name inside
            base_name = first_name(terms[-1].args)
        else:
            base_name = first_name(expr.text(self.text))
        why = f"compound or computed location ({name})"
        if expr.plain and len(terms) == 2 and base is not None:
            why = f"compound location under BASE {base} ({name})"
        runtime = RuntimeTarget(self.text[start:end], SourceLocation(*loc), why, base_name,
                                routine, (start, end))
        self.runtime.append(runtime)
        # the BASE in force applies to the location the expression is built on too
        self.motions.append(MotionUse(name, loc, "to", runtime=runtime, wobj=base, **common))

    def _block_step(self, kw, a0, a1, routine) -> None:
        """A Kawasaki block-teaching step: its taught joints ``#[j1,...,jn]``."""
        m = _TAUGHT_JOINTS.search(self.text, a0, a1)
        if m is None:
            return
        loc = self.src(m.start())
        found = _numbers_in(self.text, m.start(1), m.end(1))
        common = dict(routine=routine, instruction_span=(kw.start_pos, kw.end_pos),
                      statement_span=(kw.start_pos, m.end()), target_span=m.span())
        if found is None:
            runtime = RuntimeTarget(m.group(), SourceLocation(*loc),
                                    f"taught joints that are not numbers ({kw.value})",
                                    None, routine, m.span())
            self.runtime.append(runtime)
            self.motions.append(MotionUse(kw.value, loc, "to", runtime=runtime, **common))
            return
        texts, starts = found
        taught = JointTarget(None, loc, texts, starts, len(texts),
                             (starts[0], starts[-1] + len(texts[-1])), "inline", None,
                             routine, None)
        self.joints.append(taught)
        self.motions.append(MotionUse(kw.value, loc, "to", inline=taught, joint=True,
                                      **common))


def _parameters(text: str | None) -> tuple[str, ...]:
    """The parameter names of a program header, without AS's by-reference ``&`` and
    array brackets: ``.&p.rel[,]`` -> ``.p.rel``."""
    if not text:
        return ()
    out, pos = [], 0
    while pos <= len(text):
        comma = top_level_comma(text, pos, len(text))
        part = text[pos:comma].strip().replace("&", "")
        part = part.split("[", 1)[0].strip()
        if part:
            out.append(part)
        pos = comma + 1
    return tuple(out)


def parse_vplus(text: str, file: str = "<string>") -> Program:
    """Parse a V+ / VAL II file or a Kawasaki AS dump (already decoded) into a
    :class:`Program`.

    Raises ParseError (file, line, column, caret context) on malformed input.
    """
    check_text(text, file)
    sink = _Sink()
    token = current_sink.set(sink)
    try:
        parser("vplus.lark", Callbacks).parse(text)
    except UnexpectedInput as exc:
        raise convert_lark_error(exc, text, file) from None
    finally:
        current_sink.reset(token)
    b = _Builder(text, file)
    for head, tok in sink.loc_blocks:
        b.loc_block(head, tok)
    starts, spans = [], []
    for head, end in sink.programs:
        m = _PROGRAM_HEAD.match(head.value)
        name = m.group(1) if m else "?"
        spans.append((head.start_pos, end.end_pos, name))
        starts.append(head.start_pos)
        b.routines.append(Routine(name, "PROGRAM", b.loc(head.start_pos),
                                  (head.start_pos, end.end_pos),
                                  _parameters(m.group(3) if m else None)))

    def routine_at(offset):
        k = bisect.bisect_right(starts, offset) - 1
        if k >= 0 and offset < spans[k][1]:
            return spans[k][2]
        return None

    b.steps(sink.steps, routine_at)
    by_start = lambda t: t.span[0]  # noqa: E731
    return Program(
        file=file, text=text, encoding="latin-1", dialect="vplus",
        newline=newline_style(text),
        targets=tuple(sorted(b.targets, key=by_start)),
        joint_targets=tuple(sorted(b.joints, key=by_start)),
        tools=(), motions=tuple(b.motions),
        runtime=tuple(sorted(b.runtime, key=lambda r: r.span or (0, 0))),
        routines=tuple(b.routines))
