"""Report rows of the object model's targets (RAPID, V+/AS): a target as written, a joint
target, a motion whose target is known only at run time, a target not compensated (why,
its best joints and configuration), and the note of one that was."""

from __future__ import annotations

import dataclasses

import numpy as np

from ...compensation.report import TargetReport, config_text
from ..targets import QUAT_WXYZ


def row_name(t) -> str:
    """The report name of a target: its name, or ``<inline>``, ``p{3}``, ``pick[3]``."""
    name = t.name
    if name is None or t.array_index is not None:
        name = t.display_name
    return name


def written_row(t, pair, status: str, note: str) -> TargetReport:
    """A row for a Cartesian target left as written (``pair``: its FramePair)."""
    try:
        config = config_text(t.config_values()) if t.orientation_kind == QUAT_WXYZ else ""
    except (OverflowError, ValueError):   # inf, nan: shown as written
        config = "[" + ",".join(t.texts[7:11]) + "]"
    file, line, column = t.source
    return TargetReport(target=row_name(t), file=file, line=line, column=column,
                        status=status, tool=pair.tool_name, wobj=pair.wobj_name,
                        config_before=config, note=note)


def joint_target_row(t, pair) -> TargetReport:
    """A row for a joint target: joints already, kept as written."""
    file, line, column = t.source
    return TargetReport(target=row_name(t), file=file, line=line, column=column,
                        status="joint_target", tool=pair.tool_name, wobj=pair.wobj_name,
                        joints=tuple(t.joints_deg()), note="joints kept as written")


def motion_row(use, status: str, why: str) -> TargetReport:
    """A row for a motion whose target is not a literal of the file (run time, unknown)."""
    where = use.location
    name = (use.runtime.expression if use.runtime is not None
            else use.target_name or "<target>")
    return TargetReport(target=name, file=where.file, line=where.line, column=where.column,
                        status=status, tool=use.tool or "", wobj=use.wobj or "", note=why)


def failure_row(row: TargetReport, failure, robot, configless: bool) -> TargetReport:
    """``row`` of a target not compensated, with why (in words and numbers), the best
    joints found and their configuration."""
    if failure is None:
        return row
    note = failure.note if not row.note else f"{failure.note}; {row.note}"
    joints = ()
    if np.all(np.isfinite(failure.joints)):
        joints = tuple(robot.to_degrees_or_mm(failure.joints[None])[0].tolist())
    config = config_text(failure.config) if failure.config is not None and not configless else ""
    return dataclasses.replace(row, status=failure.status or row.status, note=note,
                               joints=joints, config_after=config)


def solved_note(notes: tuple[str, ...], tool_note: str) -> str:
    """The report note of a solved entry: its resolution notes and the real-tool note."""
    if not notes:
        return tool_note
    kept = [x for x in notes if x != "unused"] + [tool_note]
    if "unused" in notes:
        kept.append("not moved to in this file: tool0/wobj0 assumed")
    return "; ".join(x for x in kept if x)
