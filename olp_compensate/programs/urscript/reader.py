"""Universal Robots URScript programs (``.script``), read with every number's span.

What is read (URScript manual, e-Series "Script Directory": ``movej(q, a, v, t, r)`` takes
joint positions or a pose, "q can also be specified as a pose, then inverse kinematics is
used"; ``movel``, ``movep``, ``movec(pose_via, pose_to, ...)``; poses ``p[x, y, z, rx, ry,
rz]`` in m with a rotation vector in rad; ``set_tcp(pose)``; ``get_inverse_kin(x, qnear)``:
"if qnear is defined, the solution closest to qnear is returned, otherwise the solution
closest to the current joint positions"; the Polyscope export pattern
``movej(get_inverse_kin(Waypoint_1_p, qnear=Waypoint_1_q), a=.., v=..)``):

- pose literals ``p[...]`` of six numbers, written in a motion or assigned once to a name
  (``global p1 = p[...]``, ``p1 = p[...]``): pose targets; joint lists ``[q1, .., q6]``
  (rad), written in ``movej`` or assigned: joint targets, kept as written;
- each motion's first argument (``movec``: the first two): a literal, a name, or
  ``get_inverse_kin(X, qnear=Q)``; anything computed (``pose_trans(...)``,
  ``get_actual_tcp_pose()``, a name assigned twice or from an expression): run time;
- the TCP in force (text order): ``set_tcp(p[...])`` or ``set_tcp(name)``; with one TCP
  literal in the script its key is ``tcp`` (the measured point's default name, so a
  calibration's ``tcp`` gives its real TCP), with several ``tcp@L<line>``; a named pose
  gives its name. Without ``set_tcp`` the flange.

There is no configuration in a target: the controller takes the inverse-kinematics solution
nearest the joints it starts from. Each pose target's ``config`` holds the joints that
decide its branch where the script writes them: the ``qnear`` list, or the joint target
moved to just before it (for the first motion: the first joint list of the script); where
the previous motion is a pose, its solved joints decide (the compensation follows program
order). Comments (``#``) and the insides of strings (``textmsg("movel(...)")``) are
skipped.
"""

from __future__ import annotations

import re

from ...errors import ParseError
from ..brackets import argument_spans, strip_span
from ..pose_dialects import (JOINTS, POSE, PoseMotion, PoseProgram, PoseTarget, blank_comments,
                             line_column, line_starts_of)
from ..targets import Number
from ..text_checks import check_text
from .literals import check_blocks, check_elements, other_literals, relative_waypoints

MOTIONS = ("movej", "movel", "movep", "movec")
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_NUMBER = re.compile(_NUM)
_POSE = re.compile(rf"p\[\s*{_NUM}(?:\s*,\s*{_NUM}){{5}}\s*\]\Z")
_JOINTS = re.compile(rf"\[\s*{_NUM}(?:\s*,\s*{_NUM}){{5}}\s*\]\Z")
_ASSIGN = re.compile(r"^[ \t]*(?:global[ \t]+|local[ \t]+)?([A-Za-z_]\w*)[ \t]*=(?!=)[ \t]*",
                     re.M)
_CALL = re.compile(r"\b(movej|movel|movep|movec|set_tcp)[ \t]*\(")
_IK = re.compile(r"get_inverse_kin[ \t]*\(")
_NAME = re.compile(r"[A-Za-z_]\w*\Z")


def strip_comments(text: str) -> str:
    """``text`` with ``#`` comments (outside strings) blanked, offsets kept."""
    return blank_comments(text, "#")


def blank_strings(text: str) -> str:
    """``text`` with the insides of ``"..."`` strings blanked (quotes and offsets kept), so
    a message such as ``textmsg("movel(p[0,0,0,0,0,0])")`` is not read as a motion."""
    return re.sub(r'"[^"\r\n]*"', lambda m: '"' + " " * (len(m.group()) - 2) + '"', text)


def _args(clean: str, open_at: int) -> tuple[list[tuple[int, int]], int]:
    """Top-level argument spans of the call whose ``(`` is at ``open_at``, blanks and empty
    arguments left out; and the offset just past its ``)`` (-1 when unclosed)."""
    spans, end = argument_spans(clean, open_at, "([{", ")]}", quote='"')
    if end < 0:
        return [], -1
    return [_strip(clean, a, b) for a, b in spans if clean[a:b].strip()], end


def _strip(text: str, a: int, b: int) -> tuple[int, int]:
    return strip_span(text, a, b, " \t\r\n")


def _numbers(text: str, a: int, b: int) -> tuple[Number, ...]:
    return tuple(Number(m.start(), m.end(), m.group()) for m in _NUMBER.finditer(text, a, b))


class _Reader:
    def __init__(self, text: str, file: str, program: PoseProgram):
        self.text, self.file, self.program = text, file, program
        self.clean = blank_strings(strip_comments(text))
        self.starts = line_starts_of(text)
        self.assigned: dict[str, list[tuple[int, int]]] = {}
        self.named: dict[str, int] = {}           # name -> index in program.targets
        self.runtime_names: dict[str, str] = {}
        self.tcp_names: set[str] = set()
        self.kinds: list[tuple[str, int | None, tuple | None]] = []   # per motion

    def where(self, offset: int) -> tuple[str, int, int]:
        return (self.file, *line_column(self.text, offset, self.starts))

    def _value_span(self, start: int) -> tuple[int, int]:
        """The expression assigned from ``start`` to the end of its line (brackets may
        continue it on the next lines)."""
        depth, k = 0, start
        while k < len(self.clean):
            c = self.clean[k]
            if c in "([{":
                depth += 1
            elif c in ")]}":
                depth -= 1
            elif c in "\r\n" and depth <= 0:
                break
            k += 1
        return _strip(self.clean, start, k)

    def assignments(self) -> None:
        for m in _ASSIGN.finditer(self.clean):
            self.assigned.setdefault(m.group(1), []).append(self._value_span(m.end()))
        for m in _CALL.finditer(self.clean):
            if m.group(1) == "set_tcp":
                args, _ = _args(self.clean, m.end() - 1)
                if args and _NAME.match(self.clean[args[0][0]:args[0][1]]):
                    self.tcp_names.add(self.clean[args[0][0]:args[0][1]])
        for name, spans in self.assigned.items():
            a, b = spans[0]
            value = self.clean[a:b]
            literal = _POSE.match(value) or _JOINTS.match(value)
            if len(spans) > 1:
                self.runtime_names[name] = f"{name} is assigned {len(spans)} times, its value " \
                                           f"is known only at run time"
                continue
            if not literal:
                self.runtime_names[name] = f"{name} = {value.split(chr(10))[0][:40]} is " \
                                           f"computed at run time"
                continue
            if name in self.tcp_names:
                self.program.frames[name] = tuple(n.value for n in _numbers(self.text, a, b))
                continue
            kind = POSE if value.startswith("p") else JOINTS
            numbers = _numbers(self.text, a + (1 if kind == POSE else 0), b)
            self.named[name] = len(self.program.targets)
            self.program.targets.append(PoseTarget(name=name, source=self.where(numbers[0].start),
                                                   kind=kind, numbers=numbers))

    def literal(self, a: int, b: int) -> int | None:
        """Index of a new inline target for the literal ``clean[a:b]``, or None."""
        value = self.clean[a:b]
        if _POSE.match(value):
            numbers, kind = _numbers(self.text, a + 1, b), POSE
        elif _JOINTS.match(value):
            numbers, kind = _numbers(self.text, a, b), JOINTS
        else:
            return None
        self.program.targets.append(PoseTarget(name=None, source=self.where(numbers[0].start),
                                               kind=kind, numbers=numbers))
        return len(self.program.targets) - 1

    def motions(self) -> None:
        tcp_literals = {}
        for m in _CALL.finditer(self.clean):
            if m.group(1) == "set_tcp":
                args, _ = _args(self.clean, m.end() - 1)
                if args and _POSE.match(self.clean[args[0][0]:args[0][1]]):
                    tcp_literals.setdefault(self.clean[args[0][0]:args[0][1]].replace(" ", ""),
                                            []).append(args[0])
        tool = None
        for m in _CALL.finditer(self.clean):
            call = m.group(1)
            args, _ = _args(self.clean, m.end() - 1)
            where = self.where(m.start())
            if call == "set_tcp":
                if not args:
                    continue
                a, b = args[0]
                value = self.clean[a:b]
                if _POSE.match(value):
                    line = where[1]
                    tool = "tcp" if len(tcp_literals) == 1 else f"tcp@L{line}"
                    self.program.frames[tool] = tuple(n.value
                                                      for n in _numbers(self.text, a + 1, b))
                elif _NAME.match(value) and value in self.program.frames:
                    tool = value
                else:
                    tool = f"set_tcp({value[:30]})"
                    self.program.notes.append(f"{self.file}:{where[1]}: set_tcp({value}) is "
                                              f"computed at run time; the motions after it "
                                              f"are reported unresolved")
                continue
            if not args:
                self.program.unknown.append((where, call))
                continue
            for a, b in args[:2 if call == "movec" else 1]:
                self.motion(call, where, a, b, tool)

    def motion(self, call, where, a, b, tool) -> None:
        value = self.clean[a:b]
        near = None
        ik = _IK.match(value)
        if ik is not None:
            inner, _ = _args(self.clean, a + ik.end() - 1)
            if not inner:
                self._runtime(call, where, tool, f"{value[:40]} cannot be read")
                return
            for qa, qb in inner[1:]:
                q_text = self.clean[qa:qb]
                q_text = q_text.split("=", 1)[1].strip() if q_text.startswith("qnear") else q_text
                if q_text == self.clean[qa:qb] and "=" in q_text:
                    continue                      # another keyword argument
                near = self._near(q_text, qb)
                break
            a, b = inner[0]
            value = self.clean[a:b]
        inline = self.literal(a, b)
        if inline is not None:
            self._add(call, None, where, tool, inline=inline, near=near)
        elif _NAME.match(value):
            if value in self.runtime_names:
                self._runtime(call, where, tool, self.runtime_names[value], name=value)
            else:
                self._add(call, value, where, tool, near=near)
        else:
            self._runtime(call, where, tool, f"{value[:40]} is computed at run time")

    def _near(self, q_text: str, end: int):
        if _NAME.match(q_text) and q_text in self.named:
            target = self.program.targets[self.named[q_text]]
            return target.numbers if target.kind == JOINTS else None
        if _JOINTS.match(q_text):
            a = end - len(q_text)
            return _numbers(self.text, a, end)
        return None

    def _runtime(self, call, where, tool, reason, name=None) -> None:
        self.program.motions.append(PoseMotion(instruction=call, target=name, source=where,
                                               tool=tool, runtime=reason))
        self.kinds.append(("runtime", None, None))

    def _add(self, call, name, where, tool, inline=None, near=None) -> None:
        self.program.motions.append(PoseMotion(instruction=call, target=name, source=where,
                                               tool=tool, inline=inline))
        index = inline if inline is not None else self.named.get(name)
        kind = None if index is None else self.program.targets[index].kind
        self.kinds.append((kind, index, near))

    def hints(self) -> None:
        """Each pose target's deciding joints (``config``) at its first use."""
        targets = self.program.targets
        first_joints = next((t.numbers for t in targets if t.kind == JOINTS), None)
        done = set()
        previous: tuple | None = None
        started = False
        for kind, index, near in self.kinds:
            if kind == POSE and index not in done:
                done.add(index)
                hint = near if near is not None else previous if started else first_joints
                if hint is not None:
                    targets[index] = targets[index]._replace(config=tuple(hint))
            started = True
            if kind == JOINTS:
                previous = targets[index].numbers
            elif kind == POSE:
                previous = None                 # the previous pose's solved joints decide
            else:
                previous = None


def parse_urscript(text: str, file: str = "<script>") -> PoseProgram:
    """Read a URScript program (decoded text)."""
    check_text(text, file)
    program = PoseProgram(dialect="urscript", texts={file: text}, targets=[], motions=[])
    reader = _Reader(text, file, program)
    check_elements(text, reader.clean, file, reader.starts)
    check_blocks(text, reader.clean, file, reader.starts)
    reader.assignments()
    reader.motions()
    reader.hints()
    other_literals(text, reader.clean, file, reader.starts, program, reader.tcp_names,
                   reader.runtime_names)
    relative_waypoints(reader.clean, text, reader.starts, program)
    if not any(m.tool for m in program.motions) and program.motions:
        program.notes.append("no set_tcp in the script: the targets are taken as flange poses "
                             "(the TCP set in the installation is not read)")
    for target in program.targets:
        if target.kind == POSE and len(target.numbers) != 6:
            raise ParseError("a pose needs six numbers", *target.source)
    return program
