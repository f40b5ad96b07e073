"""The target model of the dialects whose targets are six numbers (position and three
angles, or a rotation vector): KUKA KRL, FANUC TP, Staubli VAL3, URScript.

Like the RAPID/V+ model (:mod:`.targets`), every number keeps its exact character span in
its file's decoded text, so compensation replaces those numbers and leaves every other byte
alone. A program may span several files (KRL: ``.src`` and ``.dat``): each target and each
motion names its file.

Units are the file's own (mm or m, degrees or radians): a :class:`PoseConvention` says how
its six numbers make a pose, and back.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import numpy as np

from .targets import Number

POSE = "pose"
JOINTS = "joints"


class PoseTarget(NamedTuple):
    """One target as written.

    name : its declared name (``XP1``, ``P[3]``), or None for a literal inside a motion.
    source : (file, line, column) of the target's first number (or of its name), 1-based.
    kind : 'pose' (six pose numbers) or 'joints' (axis values, kept as written).
    numbers : the pose numbers in the file's order and units (x, y, z, then the three
        orientation numbers), or the axis values for 'joints'.
    config : the configuration numbers as written (KRL S and T; FANUC turn numbers...),
        dialect-specific, possibly empty.
    config_text : configuration words as written (FANUC ``'N U T, 0, 0, 0'``), or None.
    frame : the dialect's frame reference of the target itself (FANUC ``UF``/``UT``
        numbers), or None when the motion decides.
    """

    name: str | None
    source: tuple[str, int, int]
    kind: str
    numbers: tuple[Number, ...]
    config: tuple[Number, ...] = ()
    config_text: Number | None = None
    frame: tuple[str | None, str | None] | None = None


class PoseMotion(NamedTuple):
    """A motion instruction and the target it moves to.

    instruction : as written (``PTP``, ``LIN``, ``movel``...).
    target : the target's name, or ``None`` with ``inline`` the index of a literal target.
    tool, base : the dialect's references of the tool and base (work object) frames in force
        (``"TOOL_DATA[1]"``, ``"BASE_DATA[0]"``), None where the program does not say.
    source : (file, line, column) of the instruction.
    runtime : why the motion's target is only known at run time (``PTP_REL``, a system
        variable, a computed expression), or None.
    candidates : names of the targets a run-time motion may move to (every element of an
        array indexed by a variable): each is compensated with this motion's tool and base.
    left : the left operand of a KRL geometric operator ``left : {inline}``: the motion
        moves to ``left`` composed with the inline target (its name, or None).
    """

    instruction: str
    target: str | None
    source: tuple[str, int, int]
    tool: str | None = None
    base: str | None = None
    inline: int | None = None
    runtime: str | None = None
    candidates: tuple[str, ...] = ()
    left: str | None = None


@dataclass
class PoseProgram:
    """A parsed program of a pose dialect: its files' texts and what they hold.

    texts : file name -> decoded text (latin-1, one character per byte).
    targets : every target literal found, in file and text order.
    motions : every motion instruction, in program order.
    unknown : (source, instruction) of instructions that take a target but are not
        understood (reported, never silently dropped).
    frames : named frame data the program itself defines (KRL ``$config.dat`` tool and base
        data, FANUC user frames...), name -> six numbers in the file's units.
    kept : targets read but kept as written, each reported with its reason: (source, name,
        status, note) (a FANUC SCARA configuration, a KRL point moved to through ``:``).
    runtime_uses : target name -> why a use of it is known only at run time (a URScript
        relative waypoint moved by through ``pose_sub``): such a target that no motion moves
        to directly is reported ``runtime`` with that reason, not ``unused``.
    external : files of ``texts`` that are not program files written back (a FANUC
        ``POSREG.VA``, a KRL ``$config.dat``): file -> (status, what its targets are).
        Their targets are solved and reported with that status (``register``,
        ``config_point``) and the values to set; their text is never written.
    """

    dialect: str
    texts: dict[str, str]
    targets: list[PoseTarget]
    motions: list[PoseMotion]
    unknown: list[tuple[tuple[str, int, int], str]] = field(default_factory=list)
    frames: dict[str, tuple[float, ...]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    kept: list[tuple[tuple[str, int, int], str, str, str]] = field(default_factory=list)
    external: dict[str, tuple[str, str]] = field(default_factory=dict)
    runtime_uses: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class PoseConvention:
    """How a dialect's six numbers make a pose (and back).

    position_scale : metres per file unit (1e-3 for mm).
    rotation : ``(3,) file-unit angles -> (3, 3)`` rotation matrix.
    angles : ``((3, 3) rotation, (3,) reference angles) -> (3,)`` the angles nearest the
        reference (for a representation with two solutions or a gimbal lock).
    position_decimals, angle_decimals : the resolution written (at least), in file units.
    """

    position_scale: float
    rotation: Callable[[np.ndarray], np.ndarray]
    angles: Callable[[np.ndarray, np.ndarray], np.ndarray]
    position_decimals: int
    angle_decimals: int

    def pose(self, numbers: np.ndarray) -> np.ndarray:
        """(4, 4) pose, m, from six numbers in file units."""
        T = np.eye(4)
        T[:3, :3] = self.rotation(np.asarray(numbers[3:6], dtype=float))
        T[:3, 3] = np.asarray(numbers[:3], dtype=float) * self.position_scale
        return T

    def numbers(self, pose: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """Six numbers in file units for ``pose`` (4, 4) m, angles nearest ``reference``."""
        out = np.empty(6)
        out[:3] = pose[:3, 3] / self.position_scale
        out[3:] = self.angles(pose[:3, :3], np.asarray(reference[3:6], dtype=float))
        return out


def line_column(text: str, offset: int, line_starts: list[int]) -> tuple[int, int]:
    """1-based (line, column) of ``offset`` in ``text`` given the offsets where lines start."""
    import bisect

    k = bisect.bisect_right(line_starts, offset) - 1
    return k + 1, offset - line_starts[k] + 1


def line_starts_of(text: str) -> list[int]:
    """Offsets where each line of ``text`` starts (any of LF, CR LF, CR ends a line)."""
    starts = [0]
    k, n = 0, len(text)
    while k < n:
        c = text[k]
        if c == "\n":
            starts.append(k + 1)
        elif c == "\r":
            if k + 1 < n and text[k + 1] == "\n":
                k += 1
            starts.append(k + 1)
        k += 1
    return starts


def blank_comments(text: str, marker: str) -> str:
    """``text`` with every comment (``marker`` to the end of the line, outside ``"``
    strings) replaced by spaces, so offsets stay those of the original."""
    out = list(text)
    in_string = False
    k, n = 0, len(text)
    while k < n:
        c = text[k]
        if c == '"':
            in_string = not in_string
        elif c in "\r\n":
            in_string = False
        elif c == marker and not in_string:
            while k < n and text[k] not in "\r\n":
                out[k] = " "
                k += 1
            continue
        k += 1
    return "".join(out)


def is_finite_number(text: str) -> bool:
    """Whether ``text`` reads as a finite float."""
    try:
        value = float(text)
    except ValueError:
        return False
    return value == value and abs(value) != float("inf")
