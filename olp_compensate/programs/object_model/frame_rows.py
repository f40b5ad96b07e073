"""Rows for the V+/AS transformations a program uses only as a TOOL or BASE operand: a
frame, not a target, kept as written (every literal of a program has its report row)."""

from __future__ import annotations

from ...compensation.report import TargetReport
from ..targets import CartesianTarget, Program


def frame_rows(program: Program, res) -> list[TargetReport]:
    """A ``frame`` row for each V+/AS transformation used only as a TOOL or BASE operand
    (a frame, not a target: kept as written, and every literal still has its row)."""
    if not getattr(res, "frames", ()):
        return []
    names = {n.upper() for n in res.frames}
    moved = {id(t) for t in res.entry_targets}
    out = []
    for t in program.targets:
        if isinstance(t, CartesianTarget) and t.name.upper() in names and id(t) not in moved:
            file, line, column = t.source
            out.append(TargetReport(target=t.name, file=file, line=line, column=column,
                                    status="frame", note="a transformation used as a TOOL or "
                                    "BASE frame, not a target; kept as written"))
    return out
