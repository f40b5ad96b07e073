"""Stäubli VAL3 data files (``.dtx``), read with every number's span; never re-serialised.

What is read (VAL3 data-file layouts as written by Stäubli Robotics Suite and by public
offline-programming post-processors, e.g. RoboDK's VAL3 posts; VAL3 types ``pointRx``,
``jointRx``, ``frame``, ``tool``, ``config``):

- *attributes of* ``<Value>`` (SRS 7 and later)::

      <Data name="pPick" access="public" xsi:type="array" type="pointRx" size="2">
        <Value key="0" x="412.5" y="-36.802" z="500" rx="135.407" ry="80.416" rz="46.453"
               shoulder="lefty" elbow="epositive" wrist="wpositive" fatherId="fPart[0]" />

  attributes left out hold their default (0 for numbers; the configuration then is free);
- *child elements* (older projects)::

      <point name="p1" ...><pFather alias="" name="world" fatherIndex="0" />
        <valuePoint index="0"><tpValue x=".." y=".." z=".." rx=".." ry=".." rz=".." />
          <cpValue shoulder="ssame" elbow="esame" wrist="wsame" /></valuePoint></point>

  and the same ``tpValue``/``cpValue``/``pFather`` elements inside ``<Data>``/``<Value>``;
- ``jointRx`` values (``j1``..``j6``, deg): joint targets, kept as written;
- ``frame`` values: the program's own frames (composed along their ``fatherId`` chain to
  ``world[0]``); ``tool`` values (composed to ``flange[0]``).

Units: mm and degrees; ``rx, ry, rz`` turn about x, then the new y, then the new z
(``Rx Ry Rz``, :func:`..kinematics.conventions.matrix_from_euler_xyz`). A point's frame is
its father: ``world[0]`` is the robot's world (base) frame; another frame is resolved when
the files define it, else the point is reported unresolved with the frame's name.

The motions (and so the tool each point is reached with) are in the ``.pgx`` programs,
which are not read: every ``pointRx`` value is compensated as if moved to, with the flange
(``flange[0]``) as tool, or with the file's tool when the files declare exactly one (a
calibrated tool of that name gives its real TCP); :attr:`PoseProgram.notes` says which.
"""

from __future__ import annotations

import re

import numpy as np

from ...errors import ParseError
from ...kinematics.conventions import euler_xyz_from_matrix, matrix_from_euler_xyz
from ..pose_dialects import (JOINTS, POSE, PoseMotion, PoseProgram, PoseTarget, line_column,
                             line_starts_of)
from ..targets import Number
from ..text_checks import check_text, check_xml

POSE_FIELDS = ("x", "y", "z", "rx", "ry", "rz")
JOINT_FIELDS = ("j1", "j2", "j3", "j4", "j5", "j6", "j7")
CONFIG_FIELDS = ("shoulder", "elbow", "wrist")
WORLD = "world[0]"
FLANGE = "flange[0]"

_OLD_TYPES = {"point": "pointRx", "joint": "jointRx", "frame": "frame", "tool": "tool"}
_CONTAINER = re.compile(r"<(Data|point|joint|frame|tool)\b([^>]*?)(/?)>")
_ENTRY = re.compile(r"<(Value|valuePoint|valueJoint|valueFrame|valueTool)\b([^>]*?)(/?)>")
_ATTR = re.compile(r"""([A-Za-z_][\w:.-]*)\s*=\s*"([^"]*)\"""")
_FATHER = re.compile(r"<\w*Father\b([^>]*?)/?>")
_TAG = re.compile(r"<(\w+)\b[^>]*>")
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?$")


def _attrs(text: str, lo: int, hi: int) -> dict[str, re.Match]:
    return {m.group(1): m for m in _ATTR.finditer(text, lo, hi)}


def _closing(text: str, tag: str, start: int, file: str, starts: list[int]) -> int:
    end = text.find(f"</{tag}>", start)
    if end < 0:
        line, column = line_column(text, start, starts)
        raise ParseError(f"<{tag}> is never closed", file, line, column)
    return end


def _mask_comments(text: str) -> str:
    """``text`` with XML comments blanked (offsets kept)."""
    return re.sub(r"<!--.*?-->", lambda m: " " * len(m.group()), text, flags=re.S)


def _insertion_point(text: str, tag_start: int) -> int:
    """Where an attribute is inserted in the tag opening at ``tag_start``: before its
    ``/>`` or ``>``, after the last attribute."""
    end = text.find(">", tag_start)
    j = end - 1 if text[end - 1] == "/" else end
    while text[j - 1] in " \t\r\n":
        j -= 1
    return j


class _Entry:
    """One value of a data container: its span and what it holds."""

    def __init__(self, name: str, typ: str, key: str, lo: int, hi: int, tag_start: int,
                 father: str | None):
        self.name, self.typ, self.key = name, typ, key
        self.lo, self.hi, self.tag_start, self.father = lo, hi, tag_start, father

    @property
    def ref(self) -> str:
        return f"{self.name}[{self.key}]"


def _father(text: str, lo: int, hi: int) -> str | None:
    attrs = _attrs(text, lo, hi)
    if "fatherId" in attrs:
        return attrs["fatherId"].group(2)
    m = _FATHER.search(text, lo, hi)
    if m is not None:
        fa = {a.group(1): a.group(2) for a in _ATTR.finditer(m.group(1))}
        if fa.get("name"):
            return f"{fa['name']}[{fa.get('fatherIndex', '0') or '0'}]"
    return None


def _entries(text: str, clean: str, file: str, starts: list[int]) -> list[_Entry]:
    out = []
    for c in _CONTAINER.finditer(clean):
        kind = c.group(1)
        attrs = {a.group(1): a.group(2) for a in _ATTR.finditer(c.group(2))}
        typ = attrs.get("type", "") if kind == "Data" else _OLD_TYPES[kind]
        name = attrs.get("name")
        if typ not in ("pointRx", "jointRx", "frame", "tool") or not name or c.group(3):
            continue
        end = _closing(clean, kind, c.end(), file, starts)
        found = []
        for e in _ENTRY.finditer(clean, c.end(), end):
            ea = {a.group(1): a.group(2) for a in _ATTR.finditer(e.group(2))}
            key = ea.get("key", ea.get("index", "0"))
            e_end = e.end() if e.group(3) else _closing(clean, e.group(1), e.end(), file, starts)
            found.append((key, e.start(), e_end))
        if not found:                      # values written straight in the container
            found.append(("0", c.end(), end))
        for key, lo, hi in found:
            father = _father(clean, lo, hi)
            if father is None:             # pFather beside the values (older layout)
                father = _father(clean, c.end(), found[0][1]) if found[0][1] > c.end() else None
            out.append(_Entry(name, typ, key, lo, hi, lo, father))
    return out


def _numbers(text: str, clean: str, entry: _Entry, fields, file: str,
             starts: list[int]) -> tuple[tuple[Number, ...], list[str]]:
    """The entry's numbers in ``fields`` order; absent ones as empty spans where they would
    be inserted (text '0', their default). Returns (numbers, absent field names)."""
    attrs = _attrs(clean, entry.lo, entry.hi)
    present = [attrs[f] for f in fields if f in attrs]
    holder = entry.tag_start
    if present:
        holder = clean.rfind("<", 0, present[0].start())
    else:
        tp = re.compile(r"<tpValue\b").search(clean, entry.lo, entry.hi)
        if tp is not None:
            holder = tp.start()
    insert_at = _insertion_point(clean, holder)
    numbers, absent = [], []
    for f in fields:
        m = attrs.get(f)
        if m is None:
            numbers.append(Number(insert_at, insert_at, "0"))
            absent.append(f)
            continue
        value = m.group(2).strip()
        if not _NUMBER.match(value) or not np.isfinite(float(value)):
            line, column = line_column(text, m.start(2), starts)
            raise ParseError(f'{f}="{m.group(2)}" is not a finite number', file, line, column)
        numbers.append(Number(m.start(2), m.end(2), m.group(2)))
    return tuple(numbers), absent


def _pose(values) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = matrix_from_euler_xyz(*np.radians(values[3:6]))
    T[:3, 3] = values[:3]
    return T


def _six(T: np.ndarray) -> tuple[float, ...]:
    return tuple(T[:3, 3].tolist()) + tuple(np.degrees(euler_xyz_from_matrix(T[:3, :3])).tolist())


def _compose(local: dict[str, tuple[np.ndarray, str | None]], root: str) -> dict:
    """Frames composed along their father chains to ``root``: ref -> six numbers."""
    out = {}

    def resolve(ref, seen):
        if ref == root:
            return np.eye(4)
        if ref not in local or ref in seen:
            return None
        T, father = local[ref]
        parent = resolve(father or root, seen | {ref})
        return None if parent is None else parent @ T

    for ref in local:
        T = resolve(ref, frozenset())
        if T is not None:
            out[ref] = _six(T)
    return out


def parse_val3(texts: dict[str, str] | str, file: str = "<dtx>",
               programs: dict[str, str] | None = None) -> PoseProgram:
    """Read VAL3 data files: ``texts`` file name -> decoded text (or one text and its
    ``file`` name); ``programs``: the project's ``.pgx`` texts (file -> text), whose motions
    say which point is reached with which tool (:mod:`.programs`)."""
    if isinstance(texts, str):
        texts = {file: texts}
    program = PoseProgram(dialect="val3", texts=dict(texts), targets=[], motions=[])
    frames: dict[str, tuple[np.ndarray, str | None]] = {}
    tools: dict[str, tuple[np.ndarray, str | None]] = {}
    points: list[tuple[PoseTarget, str | None]] = []
    for name, text in texts.items():
        check_text(text, name)
        check_xml(text, name, "VAL3 data (.dtx)")
        starts = line_starts_of(text)
        clean = _mask_comments(text)
        for entry in _entries(text, clean, name, starts):
            if entry.typ in ("frame", "tool"):
                numbers, _ = _numbers(text, clean, entry, POSE_FIELDS, name, starts)
                T = _pose(np.array([n.value for n in numbers]))
                (frames if entry.typ == "frame" else tools)[entry.ref] = (T, entry.father)
                continue
            if entry.typ == "jointRx":
                attrs = _attrs(clean, entry.lo, entry.hi)
                numbers = tuple(Number(attrs[f].start(2), attrs[f].end(2), attrs[f].group(2))
                                for f in JOINT_FIELDS if f in attrs)
                where = (name, *line_column(text, entry.lo, starts))
                program.targets.append(PoseTarget(name=entry.ref, source=where, kind=JOINTS,
                                                  numbers=numbers))
                continue
            numbers, absent = _numbers(text, clean, entry, POSE_FIELDS, name, starts)
            attrs = _attrs(clean, entry.lo, entry.hi)
            config = tuple(Number(attrs[f].start(2), attrs[f].end(2), attrs[f].group(2))
                           for f in CONFIG_FIELDS if f in attrs)
            first = next((n for n in numbers if n.end > n.start), None)
            where = (name, *line_column(text, first.start if first else entry.lo, starts))
            target = PoseTarget(name=entry.ref, source=where, kind=POSE, numbers=numbers,
                                config=config, frame=(entry.father, None))
            program.targets.append(target)
            points.append((target, entry.father))
            if absent:
                program.notes.append(f"{entry.ref}: {', '.join(absent)} left out of the file "
                                     f"(0); written as attributes where they change")
    program.frames.update(_compose(frames, WORLD))
    program.frames.update(_compose(tools, FLANGE))
    if programs:
        from .programs import read_programs

        read_programs(programs, program, {t.name: father for t, father in points})
        return program
    tool_key = None
    if len(tools) == 1:
        tool_key = next(iter(tools))
        program.notes.append(
            f"the tool of each motion is set in the .pgx programs, not read here: the points "
            f"are compensated with {tool_key}, the only tool of the data files (a calibrated "
            f"tool of that name gives its real TCP)")
    elif points:
        several = f" ({', '.join(sorted(tools))})" if tools else ""
        program.notes.append(
            f"the tool of each motion is set in the .pgx programs, not read here: the points "
            f"are compensated with the flange (flange[0]), the data files declaring "
            f"{'several tools' + several if tools else 'no tool'}")
    for target, father in points:
        program.motions.append(PoseMotion(instruction="pointRx", target=target.name,
                                          source=target.source, tool=tool_key,
                                          base=father or WORLD))
    return program
