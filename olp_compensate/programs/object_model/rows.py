"""Report rows of the object model's targets (RAPID, V+/AS): a target as written, a joint
target, a motion whose target is known only at run time, a target not compensated (why,
its best joints and configuration), and the note of one that was."""

from __future__ import annotations

import math

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
    joints = robot.to_degrees_or_mm(failure.joints).tolist()
    config = config_text(failure.config) if failure.config is not None and not configless else ""
    return TargetReport(
        target=row.target, file=row.file, line=row.line, column=row.column,
        status=failure.status or row.status, tool=row.tool, wobj=row.wobj,
        correction_mm=row.correction_mm, correction_deg=row.correction_deg,
        joint_change=row.joint_change, config_before=row.config_before,
        config_after=config, joints=tuple(joints) if math.isfinite(sum(joints)) else (),
        note=failure_note(failure.note, row.note))


def failure_note(why: str, row_note: str) -> str:
    """The note of a row not compensated: ``why`` (the failure's note), then the row's own."""
    return f"{why}; {row_note}" if row_note else why


def solved_note(notes: tuple[str, ...], tool_note: str) -> str:
    """The report note of a solved entry: its resolution notes and the real-tool note."""
    if not notes:
        return tool_note
    kept = [x for x in notes if x != "unused"] + [tool_note]
    if "unused" in notes:
        kept.append("not moved to in this file: tool0/wobj0 assumed")
    return "; ".join(x for x in kept if x)
