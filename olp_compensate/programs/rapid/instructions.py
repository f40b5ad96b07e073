"""What the RAPID parser knows of instructions: where motion instructions keep their
targets and tool, and which functions compute a target at run time."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class MotionSpec:
    """Where a motion instruction keeps its targets and its tool.

    targets : (positional index, role) pairs; tool : positional index (-1 = last);
    joint : the target is a jointtarget; writes : positional index of a robtarget the
    instruction writes (SearchL's search point), or None.
    """

    targets: tuple[tuple[int, str], ...]
    tool: int = -1
    joint: bool = False
    writes: int | None = None


_TO = ((0, "to"),)
_CIRC = ((0, "circle"), (1, "to"))
MOTIONS: dict[str, MotionSpec] = {}
for _n in ("MoveL", "MoveJ", "TriggL", "TriggJ", "TriggLIOs", "TriggJIOs", "ArcL",
           "ArcLStart", "ArcLEnd", "ArcL1", "ArcL2", "ArcRepL", "SpotL", "SpotJ", "SpotML",
           "SpotMJ", "CapL", "PaintL", "DispL", "MoveLFF", "MoveLStart", "MoveLEnd"):
    MOTIONS[_n.lower()] = MotionSpec(_TO)
for _n in ("MoveC", "TriggC", "ArcC", "ArcCStart", "ArcCEnd", "ArcC1", "ArcC2", "CapC",
           "PaintC", "DispC"):
    MOTIONS[_n.lower()] = MotionSpec(_CIRC)
for _n in ("MoveLDO", "MoveJDO", "MoveLAO", "MoveJAO", "MoveLGO", "MoveJGO", "MoveLSync",
           "MoveJSync"):
    MOTIONS[_n.lower()] = MotionSpec(_TO, tool=3)
for _n in ("MoveCDO", "MoveCAO", "MoveCGO", "MoveCSync"):
    MOTIONS[_n.lower()] = MotionSpec(_CIRC, tool=4)
MOTIONS["searchl"] = MotionSpec(((2, "to"),), writes=1)
MOTIONS["searchc"] = MotionSpec(((2, "circle"), (3, "to")), writes=1)
MOTIONS["moveabsj"] = MotionSpec(_TO, joint=True)

RUNTIME_FUNCS = {
    "offs": "Offs() displaces the target at run time",
    "reltool": "RelTool() displaces the target in the tool frame at run time",
    "crobt": "CRobT() reads the current position at run time",
    "cjointt": "CJointT() reads the current joints at run time",
    "calcrobt": "CalcRobT() computes the target from joints at run time",
    "calcjointt": "CalcJointT() computes joints at run time",
    "mirpos": "MirPos() mirrors the target at run time",
    "poseinv": "pose arithmetic at run time",
    "posemult": "pose arithmetic at run time",
}
