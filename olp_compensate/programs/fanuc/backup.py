"""What a FANUC controller backup holds beyond its programs: the turn axes of the
configuration (``SYSMAST.VA``) and the position registers (``POSREG.VA``), read as ASCII
``.VA`` dumps (the layout of :mod:`.frames`: a variable starts at
``[section]$NAME  Storage: ...``, an array element at ``[g,n] =``).

- ``$SCR_GRP[g].$TURN_AXIS``: the three axes the turn numbers of a position's
  ``CONFIG : 'N U T, t1, t2, t3'`` belong to, "normally J4 J5 J6" (HandlingTool manual
  V9.40 sec. 11.21.2 in public notes). Read for group 1, as the .VA prints an array field::

       Field: $SCR_GRP[1].$TURN_AXIS  ARRAY[3] OF INTEGER
        [1] = 1
        [2] = 4
        [3] = 6

  (or on one line, ``... $TURN_AXIS ... = 1, 4, 6``), in ``SYSMAST.VA`` or (some backups)
  ``SYMOTN.VA``. Trailing axes 0 (no axis) are dropped; a 0 before an axis is refused.
- ``$POSREG[g,n]``: position register n of group g, Cartesian (``Group: 1  Config: N U T,
  0, 0, 0`` then ``X: .. Y: .. Z: ..`` mm and ``W: .. P: .. R: ..`` deg) or joint
  (``J1 = .. deg`` ...); ``Uninitialized`` or ``********`` values are registers the
  controller holds no value for; extended axes (``EXT1: ..``) are kept as written. Only
  group 1 is read. A register holds no UF/UT: a motion to it takes the frames in force.

Refused with a :class:`~olp_compensate.errors.ParseError` at line and column: a value that
is not a finite number, a turn axis outside 1..9, a file holding none of what is read.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from ...errors import ParseError
from ..pose_dialects import JOINTS, POSE, PoseTarget, line_column, line_starts_of
from ..targets import Number
from ..text_checks import check_text

_HEADER = re.compile(r"^[ \t]*(?:\[[^\]\r\n]*\])?(\$?[A-Za-z_][\w$]*)[ \t]+Storage[ \t]*:", re.M)
_TURN_FIELD = re.compile(r"^[ \t]*Field[ \t]*:[ \t]*\$SCR_GRP\[[ \t]*(\d+)[ \t]*\]\.\$TURN_AXIS"
                         r"\b([^\r\n]*)", re.M | re.I)
_ARRAY_ITEM = re.compile(r"[ \t]*\[[ \t]*(\d+)[ \t]*\][ \t]*=[ \t]*([^\r\n]*)")
_ELEMENT = re.compile(r"^[ \t]*\[[ \t]*(\d+)[ \t]*,[ \t]*(\d+)[ \t]*\][ \t]*=([^\r\n]*)", re.M)
_CARTESIAN = re.compile(r"(?<![\w$])([XYZWPR])[ \t]*:[ \t]*([^\s]*)")
_JOINT = re.compile(r"(?<![\w$])(J\d)[ \t]*=[ \t]*([^\s]*)")
_CONFIG = re.compile(r"\bConfig[ \t]*:[ \t]*([^\r\n]*?)[ \t]*(?:\r|\n|$)", re.I)
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
CONFIG_PARTS = re.compile(r"[ \t]*([NF])[ \t]*([UD])[ \t]*([TB])[ \t]*((?:,[ \t]*[-+]?\d+"
                          r"[ \t]*)*)$")
"""A six-axis arm's configuration: the letters N/F, U/D, T/B, then the turn numbers."""
SCARA_CONFIG = re.compile(r"[ \t]*(?:[NF][ \t]*)?[LR](?:[ \t]*[NFUDTB])*[ \t]*(?:,[ \t]*"
                          r"[-+]?\d+[ \t]*)*$")
"""A SCARA's configuration (``'L, 0, 0, -1'``: arm left or right, then turn numbers)."""
_TURN = re.compile(r"[-+]?\d+")
POSE_FIELDS = ("X", "Y", "Z", "W", "P", "R")


@dataclass(frozen=True)
class TurnAxes:
    """The axes (1-based) the turn numbers of a CONFIG belong to, and where that was read."""

    axes: tuple[int, ...]
    source: str


@dataclass
class PositionRegisters:
    """The group 1 position registers of a ``POSREG.VA``.

    file, text : the file as given and its decoded text (the targets' spans are in it).
    registers : ``"PR[n]"`` -> the register's target (``source`` in this file).
    uninitialized : ``"PR[n]"`` -> (line, column) of a register without a value.
    """

    file: str
    text: str
    registers: dict[str, PoseTarget] = field(default_factory=dict)
    uninitialized: dict[str, tuple[int, int]] = field(default_factory=dict)


def config_numbers(text: str, file: str, starts: list[int], at: int, inner: str):
    """(letters and turns as Numbers, the configuration as one Number) of the configuration
    ``inner`` written at offset ``at``; None for a SCARA's configuration."""
    parts = CONFIG_PARTS.match(inner)
    if parts is None:
        if SCARA_CONFIG.match(inner):
            return None
        line, column = line_column(text, at, starts)
        raise ParseError(f"CONFIG '{inner}' is not 'N|F U|D T|B, turn, ...'", file, line,
                         column)
    letters = tuple(Number(at + parts.start(i), at + parts.end(i), parts.group(i))
                    for i in (1, 2, 3))
    t0 = at + parts.start(4)
    turns = tuple(Number(t0 + t.start(), t0 + t.end(), t.group())
                  for t in _TURN.finditer(parts.group(4)))
    return letters + turns, Number(at, at + len(inner), inner)


def _variables(text: str) -> dict[str, tuple[int, int]]:
    """Variable name (upper case) -> (start, end) of its dump."""
    found = list(_HEADER.finditer(text))
    return {m.group(1).upper(): (m.end(), nxt.start() if nxt else len(text))
            for m, nxt in zip(found, found[1:] + [None])}


def _line_column(text: str, offset: int) -> tuple[int, int]:
    """1-based (line, column) of ``offset`` without indexing the whole text (a SYMOTN.VA
    is over a megabyte and only a few places are asked)."""
    line_start = max(text.rfind("\n", 0, offset), text.rfind("\r", 0, offset)) + 1
    lines = text.count("\n", 0, offset)
    if lines == 0 and "\r" in text[:offset]:
        lines = text.count("\r", 0, offset)
    return lines + 1, offset - line_start + 1


def read_turn_axes(text: str, file: str = "SYSMAST.VA") -> TurnAxes | None:
    """Group 1's ``$TURN_AXIS`` of a ``.VA`` text, or None when the file has none."""
    check_text(text, file)
    for m in _TURN_FIELD.finditer(text):
        if int(m.group(1)) != 1:
            continue
        values: list[tuple[str, int]] = []
        inline = re.search(r"=[ \t]*(.*)$", m.group(2))
        if inline is not None and inline.group(1).strip():
            base = m.start(2) + inline.start(1)
            values = [(v.group(), base + v.start()) for v in re.finditer(r"[^,\s]+",
                                                                         inline.group(1))]
        else:
            lines = text[m.end():m.end() + 4096].splitlines(keepends=True)
            lo = m.end() + (len(lines[0]) if lines else 0)
            for line in lines[1:]:
                item = _ARRAY_ITEM.match(line.rstrip("\r\n"))
                if item is None:
                    break
                values.append((item.group(2).strip(), lo + item.start(2)))
                lo += len(line)
        return _turn_axes(text, file, m.start(), values)
    return None


def _turn_axes(text: str, file: str, at: int, values) -> TurnAxes:
    """The axes of ``values`` ((text, offset) of each element), checked."""
    axes = []
    none_at = None
    for value, offset in values:
        if not re.fullmatch(r"\d", value):
            raise ParseError(f"$SCR_GRP[1].$TURN_AXIS: {value!r} is not an axis number "
                             f"(1..9, 0 for none)", file, *_line_column(text, offset))
        if value == "0":
            none_at = none_at if none_at is not None else offset
            continue
        if none_at is not None:
            raise ParseError("$SCR_GRP[1].$TURN_AXIS: a turn number without an axis (0) "
                             "before one with an axis is not read", file,
                             *_line_column(text, none_at))
        axes.append(int(value))
    if not axes:
        raise ParseError("$SCR_GRP[1].$TURN_AXIS names no axis", file, *_line_column(text, at))
    return TurnAxes(tuple(axes), f"{file}:{_line_column(text, at)[0]}")


def read_position_registers(text: str, file: str = "POSREG.VA") -> PositionRegisters | None:
    """Group 1's ``$POSREG`` of a ``.VA`` text, or None when the file has none."""
    check_text(text, file)
    if "$POSREG" not in text.upper():
        return None
    span = _variables(text).get("$POSREG")
    if span is None:
        return None
    out = PositionRegisters(file, text)
    starts = line_starts_of(text)
    heads = list(_ELEMENT.finditer(text, *span))
    for head, nxt in zip(heads, heads[1:] + [None]):
        group, number = int(head.group(1)), int(head.group(2))
        if group != 1:
            continue
        name = f"PR[{number}]"
        lo, hi = head.end(), nxt.start() if nxt else span[1]
        where = line_column(text, head.start(1) - 1, starts)
        if re.search(r"\bUninitialized\b", head.group(3), re.I):
            out.uninitialized[name] = where
            continue
        target = _register(text, file, starts, name, where, head.start(3), lo, hi)
        if target is None:
            out.uninitialized[name] = where
        else:
            out.registers[name] = target
    return out


def _values(pattern: re.Pattern, text: str, file: str, starts, lo: int, hi: int):
    """label -> Number of ``pattern``'s matches in ``text[lo:hi]``; None when a value is
    ``********`` (not set)."""
    found: dict[str, Number] = {}
    for m in pattern.finditer(text, lo, hi):
        value = m.group(2)
        if value and set(value) == {"*"}:
            return None
        if _NUMBER.fullmatch(value) is None or abs(float(value)) == float("inf"):
            raise ParseError(f"{m.group(1)}: {value or '(nothing)'!r} is not a finite number",
                             file, *line_column(text, m.start(2), starts))
        found[m.group(1).upper()] = Number(m.start(2), m.end(2), value)
    return found


def _register(text, file, starts, name, where, head_at, lo, hi) -> PoseTarget | None:
    """The target of one register element (``None``: no value)."""
    cartesian = _values(_CARTESIAN, text, file, starts, head_at, hi)
    joints = _values(_JOINT, text, file, starts, head_at, hi)
    if cartesian is None or joints is None:
        return None
    source = (file, *where)
    if cartesian:
        missing = [f for f in POSE_FIELDS if f not in cartesian]
        if missing:
            raise ParseError(f"{name} has no {', '.join(missing)}", file, *where)
        config, config_text = (), None
        m = _CONFIG.search(text, head_at, hi)
        if m is not None and m.group(1).strip():
            spans = config_numbers(text, file, starts, m.start(1), m.group(1))
            if spans is None:
                raise ParseError(f"{name}: a SCARA configuration '{m.group(1)}' is not read",
                                 file, *line_column(text, m.start(1), starts))
            config, config_text = spans
        first = cartesian["X"]
        return PoseTarget(name=name, source=(file, *line_column(text, first.start, starts)),
                          kind=POSE, numbers=tuple(cartesian[f] for f in POSE_FIELDS),
                          config=config, config_text=config_text)
    if joints:
        return PoseTarget(name=name, source=source, kind=JOINTS,
                          numbers=tuple(joints[k] for k in sorted(joints)))
    return None
