"""The tool and work object of target uses as poses (metres): a (tool, work object) pair of
RAPID ``tooldata``/``wobjdata`` or V+ frames, with its notes and the problems that make the
flange pose unknowable (undefined, a moved user frame, a stationary tool without a
robot-held work object)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .targets import CartesianTarget, ToolData, WorkObject

IDENTITY = np.eye(4)
IDENTITY.flags.writeable = False


@dataclass(frozen=True, eq=False, slots=True)
class FramePair:
    """The tool and work object of some target uses, as poses (metres).

    flange_T_tool, base_T_wobj : see :class:`ResolvedTarget`; None when unknown.
    stationary_tool : the tool is fixed and the robot holds the work object.
    notes : remarks and problems of the pair; problem : the flange pose cannot be known.
    """

    tool_name: str
    wobj_name: str
    flange_T_tool: np.ndarray | None
    base_T_wobj: np.ndarray | None
    stationary_tool: bool
    notes: tuple[str, ...]
    problem: bool


def _frame_pose(item) -> tuple[np.ndarray | None, str | None, bool | None]:
    """(pose, problem, robhold) of a tool/wobj/V+ frame found by lookup."""
    if item is None:
        return IDENTITY, None, None
    if isinstance(item, str):
        return None, "unknown", None
    if isinstance(item, CartesianTarget):  # V+ transformation used as tool or frame
        return item.pose(), None, None
    if isinstance(item, ToolData):
        if not item.defined:
            return None, "has no value in this file", item.robhold
        return item.pose(), None, item.robhold
    if isinstance(item, WorkObject):
        if not item.defined:
            return None, "has no value in this file", item.robhold
        if item.ufprog is False:
            mec = f" by {item.ufmec}" if item.ufmec else ""
            return None, f"has a user frame moved{mec} (ufprog FALSE)", item.robhold
        return item.pose(), None, item.robhold
    return None, "is not a frame", None


def frame_pair(info) -> FramePair:
    """The poses of a (tool, work object) pair, with its notes and problems."""
    (tool_name, tool), (wobj_name, wobj) = info
    notes = []
    tool_pose, tproblem, tool_robhold = _frame_pose(tool)
    wobj_pose, wproblem, wobj_robhold = _frame_pose(wobj)
    if tproblem:
        notes.append(f"tool {tool_name} {tproblem}")
    if wproblem:
        notes.append(f"work object {wobj_name} {wproblem}")
    stationary = tool_robhold is False
    problem = bool(tproblem or wproblem)
    if stationary:
        notes.append("stationary tool (robhold FALSE)")
        if wobj_robhold is not True:
            notes.append(f"stationary tool {tool_name} needs a robot-held work object")
            problem = True
    elif wobj_robhold is True:
        notes.append(f"work object {wobj_name} is robot-held but tool {tool_name} is not "
                     f"stationary")
        problem = True
    return FramePair(tool_name, wobj_name, tool_pose, wobj_pose, stationary,
                     tuple(notes), problem)
