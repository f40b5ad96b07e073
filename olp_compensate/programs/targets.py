"""The target model shared by every program dialect (ABB RAPID, V+).

Every number keeps its exact character span in the decoded program text, so an emitter can
replace it and leave every other byte alone. Units are the file's own: millimetres and
degrees; quaternions are w first (RAPID); V+ orientations are Z-Y-Z Euler angles
(yaw, pitch, roll) in degrees. Conversions to poses in metres are explicit helpers.

Speed shapes the records made once per number, target or motion (a 100,000-target program
makes millions): ``Number``, ``CartesianTarget``, ``JointTarget`` and ``MotionUse`` are
immutable ``NamedTuple``s (built 5 to 9 times faster than a frozen dataclass: 0.2 vs 1.7 us
for 16 fields); a target keeps its numbers as two plain tuples (texts, start offsets) and
its place as a plain (file, line, column) tuple ``source``, because the garbage collector
stops scanning plain tuples of plain values; ``position``, ``location``... build the
richer objects on access, and ``Number.value`` parses its text on access. Everything else
is a frozen, slotted dataclass.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..kinematics.conventions import (MM, matrix_from_euler_zyz, matrix_from_quat_wxyz,
                           pose_from_rotation_translation)

QUAT_WXYZ = "quat_wxyz"
EULER_ZYZ_DEG = "euler_zyz_deg"


class Number(NamedTuple):
    """One number as written: ``program.text[start:end] == text``; ``value`` is its float."""

    start: int
    end: int
    text: str

    @property
    def value(self) -> float:
        return float(self.text)


class Edit(NamedTuple):
    """Replace ``text[start:end]`` of the decoded program by ``replacement``."""

    start: int
    end: int
    replacement: str


class SourceLocation(NamedTuple):
    """Where something starts: file as given, 1-based line and column (characters)."""

    file: str
    line: int
    column: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.column}"


def values(numbers) -> np.ndarray:
    """The values of a sequence of :class:`Number` as a float array."""
    return np.array([n.value for n in numbers], dtype=float)


def _numbers(texts, starts, lo: int, hi: int) -> tuple[Number, ...]:
    return tuple(_make_number((s, s + len(t), t))
                 for s, t in zip(starts[lo:hi], texts[lo:hi]))


_make_number = Number._make

# how many numbers each part of a target has, by orientation kind
_LAYOUT = {QUAT_WXYZ: (0, 3, 7, 11, 17), EULER_ZYZ_DEG: (0, 3, 6, 6, 6)}


_CONFIG_VALUES: dict[tuple[str, ...], tuple[int, ...]] = {}


class CartesianTarget(NamedTuple):
    """A Cartesian target: a RAPID robtarget or a V+ transformation.

    The numbers are stored compactly (``texts`` as written and their ``starts`` offsets, in
    text order); the properties below give them as :class:`Number` tuples:

    position : x, y, z in mm, in the work-object (RAPID) or reference (V+) frame.
    orientation : q1..q4 = w, x, y, z (``quat_wxyz``; may be unnormalized or integer) or
        yaw, pitch, roll in degrees (``euler_zyz_deg``, R = Rz(yaw) Ry(pitch) Rz(roll)).
    config : RAPID cf1, cf4, cf6, cfx (quarter turns, cfx branch index); empty for V+.
    external : RAPID external axes eax_a..eax_f (mm or deg, 9E9 = not used); empty for V+.

    source : (file, line, column) where the target starts, as :attr:`location`.
    span : the literal's character span (the bracketed aggregate, the V+ number run, or
        the V+ ``TRANS(...)`` call).
    storage : 'CONST', 'PERS', 'VAR', 'inline' (literal inside an instruction),
        'assigned' (RAPID literal assigned in a routine, ``p := [...];``) or 'vplus'.
    array_index : 1-based index tuple for an element of an array declaration, else None.
    routine : routine holding a local declaration or the inline literal; None at module level.
    type_span : for rewriting with ``--emit joints``: the type word (``robtarget``) of its
        RAPID declaration, or the V+ name.
    """

    name: str | None
    source: tuple[str, int, int]
    texts: tuple[str, ...]
    starts: tuple[int, ...]
    orientation_kind: str
    span: tuple[int, int]
    storage: str
    array_index: tuple[int, ...] | None = None
    routine: str | None = None
    type_span: tuple[int, int] | None = None

    @property
    def location(self) -> SourceLocation:
        """Where it starts (``source`` as a SourceLocation)."""
        return SourceLocation(*self.source)

    @property
    def position(self) -> tuple[Number, ...]:
        return _numbers(self.texts, self.starts, 0, 3)

    @property
    def orientation(self) -> tuple[Number, ...]:
        k = _LAYOUT[self.orientation_kind]
        return _numbers(self.texts, self.starts, k[1], k[2])

    @property
    def config(self) -> tuple[Number, ...]:
        k = _LAYOUT[self.orientation_kind]
        return _numbers(self.texts, self.starts, k[2], k[3])

    @property
    def external(self) -> tuple[Number, ...]:
        k = _LAYOUT[self.orientation_kind]
        return _numbers(self.texts, self.starts, k[3], k[4])

    @property
    def numbers(self) -> tuple[Number, ...]:
        """All numbers of the target in text order."""
        return _numbers(self.texts, self.starts, 0, len(self.texts))

    @property
    def display_name(self) -> str:
        """``p10``, ``path{3}`` (RAPID), ``pick[3]`` (V+) or ``<inline>``."""
        return _display(self.name, self.array_index, self.storage)

    def position_mm(self) -> np.ndarray:
        """Position, shape (3,), mm."""
        return np.array([float(t) for t in self.texts[0:3]])

    def orientation_values(self) -> np.ndarray:
        """Quaternion (w, x, y, z) as written, or (yaw, pitch, roll) in degrees."""
        k = _LAYOUT[self.orientation_kind]
        return np.array([float(t) for t in self.texts[k[1]:k[2]]])

    def config_values(self) -> tuple[int, ...]:
        """RAPID confdata (cf1, cf4, cf6, cfx) as integers; () for V+."""
        k = _LAYOUT[self.orientation_kind]
        texts = self.texts[k[2]:k[3]]
        values = _CONFIG_VALUES.get(texts)
        if values is None:   # programs repeat a handful of confdata: parse each once
            if len(_CONFIG_VALUES) > 4096:
                _CONFIG_VALUES.clear()
            values = _CONFIG_VALUES[texts] = tuple(int(round(float(t))) for t in texts)
        return values

    def rotation(self) -> np.ndarray:
        """Rotation matrix (3, 3) of the orientation (quaternion normalized)."""
        o = self.orientation_values()
        if self.orientation_kind == QUAT_WXYZ:
            return matrix_from_quat_wxyz(o)
        return matrix_from_euler_zyz(*np.deg2rad(o))

    def pose(self) -> np.ndarray:
        """Target frame in its reference frame, (4, 4), translation in metres."""
        return pose_from_rotation_translation(self.rotation(), self.position_mm() * MM)


def _display(name, index, storage) -> str:
    if name is None:
        return "<inline>"
    if index is None:
        return name
    inner = ",".join(str(i) for i in index)
    return f"{name}[{inner}]" if storage == "vplus" else f"{name}{{{inner}}}"


class JointTarget(NamedTuple):
    """A joint target: a RAPID jointtarget or a V+ precision point.

    Numbers stored as for :class:`CartesianTarget`; the first ``n_joints`` are the robot
    axes (degrees; mm for a prismatic axis), the rest (RAPID) the external axes.
    """

    name: str | None
    source: tuple[str, int, int]
    texts: tuple[str, ...]
    starts: tuple[int, ...]
    n_joints: int
    span: tuple[int, int]
    storage: str
    array_index: tuple[int, ...] | None = None
    routine: str | None = None
    type_span: tuple[int, int] | None = None

    @property
    def location(self) -> SourceLocation:
        """Where it starts (``source`` as a SourceLocation)."""
        return SourceLocation(*self.source)

    @property
    def joints(self) -> tuple[Number, ...]:
        return _numbers(self.texts, self.starts, 0, self.n_joints)

    @property
    def external(self) -> tuple[Number, ...]:
        return _numbers(self.texts, self.starts, self.n_joints, len(self.texts))

    @property
    def numbers(self) -> tuple[Number, ...]:
        return _numbers(self.texts, self.starts, 0, len(self.texts))

    @property
    def display_name(self) -> str:
        return _display(self.name, self.array_index, self.storage)

    def joints_deg(self) -> np.ndarray:
        """Robot axes, shape (n,), degrees."""
        return np.array([float(t) for t in self.texts[:self.n_joints]])


@dataclass(frozen=True, slots=True)
class ToolData:
    """A RAPID tooldata (or a V+ tool transformation, orientation then in ZYZ degrees).

    robhold : True when the robot holds the tool; False for a stationary tool.
    position, orientation : tframe, the TCP in the flange frame (mm, quaternion w first).
    mass (kg), cog (mm), load_orientation (quaternion), inertia (kgm2): the load part.
    Fields are None/empty when the file declares the tool without a literal value.
    """

    name: str | None
    location: SourceLocation
    robhold: bool | None
    position: tuple[Number, ...]
    orientation: tuple[Number, ...]
    span: tuple[int, int] | None
    storage: str
    mass: Number | None = None
    cog: tuple[Number, ...] = ()
    load_orientation: tuple[Number, ...] = ()
    inertia: tuple[Number, ...] = ()
    orientation_kind: str = QUAT_WXYZ
    routine: str | None = None

    @property
    def defined(self) -> bool:
        """Whether the file gives the tool's value."""
        return bool(self.position)

    def pose(self) -> np.ndarray:
        """flange_T_tool (robot-held) or world_T_tool (stationary), (4, 4), metres."""
        o = values(self.orientation)
        rot = (matrix_from_quat_wxyz(o) if self.orientation_kind == QUAT_WXYZ
               else matrix_from_euler_zyz(*np.deg2rad(o)))
        return pose_from_rotation_translation(rot, values(self.position) * MM)


@dataclass(frozen=True, slots=True)
class WorkObject:
    """A RAPID wobjdata.

    robhold : True when the robot holds the work object (stationary tool).
    ufprog : False when the user frame moves with a mechanical unit (``ufmec``).
    uframe_*, oframe_* : user and object frames (mm, quaternion w first); the work object
        pose is uframe * oframe, in world (robhold False) or flange (robhold True).
    """

    name: str | None
    location: SourceLocation
    robhold: bool | None
    ufprog: bool | None
    ufmec: str | None
    uframe_position: tuple[Number, ...]
    uframe_orientation: tuple[Number, ...]
    oframe_position: tuple[Number, ...]
    oframe_orientation: tuple[Number, ...]
    span: tuple[int, int] | None
    storage: str
    routine: str | None = None

    @property
    def defined(self) -> bool:
        return bool(self.uframe_position)

    def pose(self) -> np.ndarray:
        """uframe * oframe, (4, 4), metres."""
        uf = pose_from_rotation_translation(matrix_from_quat_wxyz(values(self.uframe_orientation)),
                                            values(self.uframe_position) * MM)
        of = pose_from_rotation_translation(matrix_from_quat_wxyz(values(self.oframe_orientation)),
                                            values(self.oframe_position) * MM)
        return uf @ of


@dataclass(frozen=True, slots=True)
class RuntimeTarget:
    """A target computed or changed when the program runs, so not compensated here.

    expression : the source text (``Offs(p10,0,0,50)``, ``p10.trans.x := 5``, ``CRobT()``).
    reason : why it is not compensated, in words.
    base_name : the declared target it derives from (``p10`` in ``Offs(p10,...)``), if any.
    """

    expression: str
    location: SourceLocation
    reason: str
    base_name: str | None = None
    routine: str | None = None
    span: tuple[int, int] | None = None


class MotionUse(NamedTuple):
    """One target argument of one motion instruction.

    instruction : as written (``MoveL``, ``MOVES``).
    source : (file, line, column) of the target argument, as :attr:`location`.
    role : 'to' (the destination) or 'circle' (MoveC's circle point).
    target_name, target_index : the declared target referred to; index is a 1-based tuple
        when literal, the index text when computed at run time (``i``), else None.
    inline : the target literal written inside the instruction, if so.
    runtime : set when the argument is an expression (Offs(), RelTool(), CRobT()...).
    tool, wobj : names (RAPID ``tool1``, ``\\WObj:=wobj1``; V+ TOOL name, compound frame)
        or None (tool0 / wobj0 / V+ NULL tool and base frame); ``*_inline`` when given
        by a literal.
    joint : True when the instruction moves to a joint target (MoveAbsJ, V+ ``#name``).
    instruction_span, statement_span, target_span : the instruction word, the statement
        (without ';') and the target argument, for rewriting (``--emit joints``).
    """

    instruction: str
    source: tuple[str, int, int]
    role: str = "to"
    target_name: str | None = None
    target_index: tuple[int, ...] | str | None = None
    inline: CartesianTarget | JointTarget | None = None
    runtime: RuntimeTarget | None = None
    tool: str | None = None
    tool_inline: ToolData | None = None
    wobj: str | None = None
    wobj_inline: WorkObject | None = None
    joint: bool = False
    routine: str | None = None
    instruction_span: tuple[int, int] | None = None
    statement_span: tuple[int, int] | None = None
    target_span: tuple[int, int] | None = None

    @property
    def location(self) -> SourceLocation:
        """Where it starts (``source`` as a SourceLocation)."""
        return SourceLocation(*self.source)


@dataclass(frozen=True, slots=True)
class NameReference:
    """A declared target's name handed to something that is not a motion instruction
    (``MyPick p10;``): the tool and work object it will be used with are unknown."""

    name: str
    index: tuple[int, ...] | str | None
    location: SourceLocation
    context: str
    routine: str | None = None


class TargetCopy(NamedTuple):
    """A plain copy between target variables, ``name := source;`` inside a routine (RAPID):
    a motion to ``name`` after it moves to what ``source`` held.

    index, source_index : 1-based index tuples of array elements, else None.
    offset : where the assignment starts in the text (copies apply to later motions).
    """

    name: str
    index: tuple[int, ...] | None
    source_name: str
    source_index: tuple[int, ...] | None
    routine: str | None
    offset: int
    location: SourceLocation


class TargetProblem(NamedTuple):
    """A target the parser found but that cannot be compensated, so that every target is
    accounted for in the report.

    target : its name as shown (``pWeld{3}``, ``<inline>``, the instruction's text).
    status : 'bad_target' (a value no controller accepts, e.g. a zero quaternion) or
        'unknown_instruction' (a motion instruction this parser does not know).
    reason : why, in words.
    """

    target: str
    location: SourceLocation
    status: str
    reason: str


@dataclass(frozen=True, slots=True)
class Routine:
    """A RAPID PROC/FUNC/TRAP or a V+ .PROGRAM; span covers its whole text."""

    name: str
    kind: str
    location: SourceLocation
    span: tuple[int, int]
    parameters: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Program:
    """A parsed program: the decoded text and everything found in it.

    text : the file decoded as latin-1 (one character per byte, so every byte survives).
    newline : '\\r\\n', '\\n', 'mixed' or '' (no line break), as found.
    """

    file: str
    text: str
    encoding: str
    dialect: str
    newline: str
    targets: tuple[CartesianTarget, ...] = ()
    joint_targets: tuple[JointTarget, ...] = ()
    tools: tuple[ToolData, ...] = ()
    wobjs: tuple[WorkObject, ...] = ()
    motions: tuple[MotionUse, ...] = ()
    runtime: tuple[RuntimeTarget, ...] = ()
    references: tuple[NameReference, ...] = ()
    routines: tuple[Routine, ...] = ()
    modules: tuple[str, ...] = field(default=())
    problems: tuple[TargetProblem, ...] = ()
    copies: tuple[TargetCopy, ...] = ()

    def target(self, name: str, index: tuple[int, ...] | None = None,
               routine: str | None = None) -> CartesianTarget | JointTarget:
        """The declared target ``name`` (case-insensitive, RAPID rules), element ``index``.

        Raises KeyError when absent.
        """
        key = name.lower()
        for t in self.targets + self.joint_targets:
            if (t.name is not None and t.name.lower() == key and t.array_index == index
                    and (routine is None or t.routine == routine)):
                return t
        raise KeyError(f"no target {name!r}{'' if index is None else index} in {self.file}")
