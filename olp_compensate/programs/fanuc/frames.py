"""FANUC user frames and tool frames from a controller backup: ``SYSFRAME.VA`` (some
backups: ``SYSTEM.VA``), the ASCII dump of the system variables ``$MNUFRAME`` and
``$MNUTOOL``.

What is read (the layout of real V9.x backups' ``sysframe.va`` files on GitHub; the
HandlingTool operator's manual for the meaning: user frames UF 1..n and tool frames UT 1..n
of each motion group, frame 0 the world / the faceplate, never stored)::

    [*SYSTEM*]$MNUFRAME  Storage: SHADOW  Access: RW  : ARRAY[2,32] OF POSITION
        [1,1] =
      Group: 1   Config: N U T, 0, 0, 0
      X:  3495.600   Y:  5813.000   Z: -1166.400
      W:      .140   P:      .080   R:   -90.040

- a variable starts at a line ``[section]$NAME  Storage: ...`` (the ``[section]`` may be
  missing); only ``$MNUFRAME`` and ``$MNUTOOL`` are read, every other variable (``$CELL_GRP``,
  ``$MNUFRAMENUM``...) is skipped unread;
- an element ``[g,n] =`` is group g's frame n; only group 1 is read (other groups' elements
  are skipped unread). Its head may carry a comment (``[1,3] = 'Gripper'``), the group
  (``[1,3] = '' Group: 1``) or ``Uninitialized``; its body an optional ``Group: g  Config:
  ...`` line (the configuration is ignored) and the six values ``X: .. Y: .. Z: ..`` (mm)
  ``W: .. P: .. R: ..`` (deg; W, P, R about the fixed x, y, z axes, ``Rz(R) Ry(P) Rx(W)``,
  as the positions of a ``.ls`` program), in any line layout;
- an element ``Uninitialized``, or whose values are ``********``, is a frame the controller
  does not know: it is listed apart (:attr:`SystemFrames.uninitialized`), never read as the
  identity. A frame of all zeros is a frame the controller holds (it is its world or its
  faceplate) and is read as such.

Refused with a :class:`~olp_compensate.errors.ParseError` at the offending line and column:
a group 1 element with a value that is not a number, a value missing or given twice, a line
that is none of the above (joint values ``J1 = ..`` included), an index that is not
``[group, frame]`` or a frame 0; a variable given twice; a file holding neither variable.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from ...errors import ParseError
from ..pose_dialects import is_finite_number, line_starts_of

VARIABLES = {"$MNUFRAME": "UF", "$MNUTOOL": "UT"}
"""The system variables read, and the prefix of their frames' names in a ``.ls`` program."""
FIELDS = ("X", "Y", "Z", "W", "P", "R")

_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_HEADER = re.compile(r"(?:\[[^\]\r\n]*\])?(\$?[A-Za-z_][\w$]*)[ \t]+Storage[ \t]*:")
_ELEMENT = re.compile(r"[ \t]*\[([^\]\r\n]*)\][ \t]*=")
_HEAD_REST = re.compile(r"[ \t]*(?:'[^'\r\n]*'[ \t]*)?(?:(Uninitialized)|Group[ \t]*:[ \t]*\d+"
                        r"(?:[ \t]+Config[ \t]*:.*)?)?[ \t]*$", re.I)
_GROUP_LINE = re.compile(r"[ \t]*Group[ \t]*:[ \t]*\d+(?:[ \t]+Config[ \t]*:.*)?[ \t]*$", re.I)
_UNINITIALIZED = re.compile(r"[ \t]*Uninitialized[ \t]*$", re.I)
_VALUE = re.compile(r"[ \t]*([A-Za-z]\w*)[ \t]*:[ \t]*(\S*)")
_BLANK = re.compile(r"[ \t]*$")


@dataclass(frozen=True)
class SystemFrames:
    """The group 1 frames of a ``SYSFRAME.VA`` file.

    file : the file's name as the user gave it.
    frames : ``"UF<n>"`` / ``"UT<n>"`` -> (x, y, z mm, w, p, r deg).
    uninitialized : ``"UF<n>"`` / ``"UT<n>"`` -> (line, column, ``"$MNUFRAME[1,n]"``) of the
        elements the controller holds no value for.
    counts : ``"UF"`` / ``"UT"`` -> how many group 1 elements the file has (absent: the
        variable is not in the file).
    """

    file: str
    frames: dict[str, tuple[float, ...]] = field(default_factory=dict)
    uninitialized: dict[str, tuple[int, int, str]] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)

    def why_unknown(self, key: str) -> str | None:
        """Why frame ``key`` (``"UF3"``) has no value in this file, or None where it has one
        (or is not a numbered frame: ``"UF0"``, ``"UFRAME_NUM=R[1]"``...)."""
        m = re.fullmatch(r"(UF|UT)(\d+)", key or "")
        if m is None or int(m.group(2)) == 0 or key in self.frames:
            return None
        variable = next(v for v, p in VARIABLES.items() if p == m.group(1))
        if key in self.uninitialized:
            line, column, element = self.uninitialized[key]
            return f"{self.file}:{line}:{column}: {key} ({element}) is uninitialized"
        if m.group(1) not in self.counts:
            return f"{self.file}: {key}: the file has no {variable}"
        return f"{self.file}: {key} is not in the file ({variable} has no element [1,{m.group(2)}])"


def _lines(text: str) -> list[str]:
    """Each line of ``text`` without its line end (LF, CR LF or CR)."""
    starts = line_starts_of(text)
    ends = starts[1:] + [len(text)]
    return [text[s:e].rstrip("\r\n") for s, e in zip(starts, ends)]


class _Element:
    """One group 1 element being read."""

    def __init__(self, key: str, name: str, line: int, column: int):
        self.key, self.name, self.line, self.column = key, name, line, column
        self.values: dict[str, float | None] = {}     # None: ********
        self.uninitialized = False


def read_system_frames(text: str, file: str = "SYSFRAME.VA") -> SystemFrames:
    """The group 1 user frames and tool frames of a ``.VA`` text (see the module notes)."""
    out = SystemFrames(file)
    seen: dict[str, int] = {}
    prefix: str | None = None            # "UF"/"UT" inside a frames variable, else None
    variable = ""
    element: _Element | None = None
    skipping = False                     # inside an element of another group

    def finish() -> None:
        nonlocal element
        if element is None:
            return
        e, element = element, None
        if e.uninitialized or any(v is None for v in e.values.values()):
            out.uninitialized[e.key] = (e.line, e.column, e.name)
            return
        missing = [f for f in FIELDS if f not in e.values]
        if missing:
            raise ParseError(f"{e.name} has no {', '.join(missing)} (expected X, Y, Z mm and "
                             f"W, P, R deg)", file, e.line, e.column)
        out.frames[e.key] = tuple(float(e.values[f]) for f in FIELDS)

    for number, line in enumerate(_lines(text), 1):
        header = _HEADER.match(line)
        if header:
            finish()
            skipping = False
            name = header.group(1).upper()
            prefix = VARIABLES.get(name)
            variable = name
            if prefix is not None:
                if name in seen:
                    raise ParseError(f"{name} is given twice (first at line {seen[name]})",
                                     file, number, header.start(1) + 1)
                seen[name] = number
                out.counts[prefix] = 0
            continue
        if prefix is None:
            continue
        head = _ELEMENT.match(line)
        if head:
            finish()
            index = [p.strip() for p in head.group(1).split(",")]
            if len(index) != 2 or not all(p.isdigit() for p in index):
                raise ParseError(f"{variable}[{head.group(1)}]: expected an element "
                                 f"[group,frame]", file, number, head.start(1) + 1)
            group, frame = int(index[0]), int(index[1])
            skipping = group != 1
            if skipping:
                continue
            if frame == 0:
                raise ParseError(f"{variable}[1,0]: frame 0 (the world, the faceplate) is "
                                 f"never stored; frames are numbered from 1", file, number,
                                 head.start(1) + 1)
            element = _Element(f"{prefix}{frame}", f"{variable}[1,{frame}]", number,
                               len(line) - len(line.lstrip(" \t")) + 1)
            out.counts[prefix] += 1
            rest = _HEAD_REST.match(line, head.end())
            if rest is None:
                tail = line[head.end():]
                column = head.end() + len(tail) - len(tail.lstrip(" \t")) + 1
                raise ParseError(f"{element.name}: cannot read '{line[head.end():].strip()}' "
                                 f"(expected a comment, Group: n or Uninitialized)", file,
                                 number, column)
            element.uninitialized = rest.group(1) is not None
            continue
        if skipping or _BLANK.match(line):
            continue
        if element is None:
            raise ParseError(f"{variable}: expected an element '[group,frame] =', got "
                             f"'{line.strip()}'", file, number,
                             len(line) - len(line.lstrip(" \t")) + 1)
        _body_line(line, number, element, file)
    finish()
    if not seen:
        raise ParseError("neither $MNUFRAME nor $MNUTOOL in the file: not a FANUC "
                         "SYSFRAME.VA (or SYSTEM.VA) with the user and tool frames", file, 1, 1)
    return out


def _body_line(line: str, number: int, element: _Element, file: str) -> None:
    """Read one line of a group 1 element's body into ``element``."""
    if _GROUP_LINE.match(line):
        return
    if _UNINITIALIZED.match(line):
        element.uninitialized = True
        return
    k = 0
    while k < len(line):
        if _BLANK.match(line, k):
            break
        m = _VALUE.match(line, k)
        at = k + len(line[k:]) - len(line[k:].lstrip(" \t")) + 1
        if m is None or m.group(1).upper() not in FIELDS:
            what = line[k:].strip()
            what = what if len(what) <= 24 else what[:21] + "..."
            hint = (" (joint values: a frame is X, Y, Z, W, P, R)"
                    if re.match(r"J\d", what, re.I) else "")
            raise ParseError(f"{element.name}: cannot read '{what}'{hint}; expected "
                             f"X: .. Y: .. Z: .. W: .. P: .. R: ..", file, number, at)
        label, value = m.group(1).upper(), m.group(2)
        if label in element.values:
            raise ParseError(f"{element.name}: {label} given twice", file, number, at)
        value_at = m.start(2) + 1
        if value and set(value) == {"*"}:
            element.values[label] = None
        elif _NUMBER.fullmatch(value) and is_finite_number(value):
            element.values[label] = float(value)
        else:
            raise ParseError(f"{element.name}: {label} = {value or '(nothing)'!r} is not a "
                             f"number", file, number, value_at)
        k = m.end()
