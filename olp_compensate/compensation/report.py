"""The per-target report of a compensated program, and its CSV.

One :class:`TargetReport` row per target and tool/work-object pair (or per motion whose
target is computed at run time, or per target the parser could not read); the
:class:`CompensationReport` holds the rows in text order and writes them as CSV with the
unit of every number in its column name (mm, deg).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import operator
from dataclasses import dataclass

import numpy as np

from ..programs.targets import QUAT_WXYZ
from .pose import COMPENSATED

__all__ = ["TargetReport", "CompensationReport", "KEPT", "config_text", "config_texts"]

KEPT = ("joint_target",)
"""Statuses of targets that need no compensation (the program is still fully compensated)."""

NOT_MOVED = "not moved to in this file: tool and work object unknown, left as written"
LINE_COLUMN = operator.attrgetter("line", "column")
"""Sort key of report rows: text order."""


@dataclass(slots=True)   # not frozen: a frozen __init__ costs 2 us a row
class TargetReport:
    """One row of the report: one target with one tool/work-object pair (or one run-time
    motion). Lengths in mm, angles in degrees; NaN where not compensated.

    correction_mm : (dx, dy, dz) change of the written target, in its work object.
    joints : (n,) controller axes the real robot takes, deg (mm for prismatic axes).
    joint_change : largest |real - nominal| joint value for the original target, deg.
    """

    target: str
    file: str
    line: int
    column: int
    status: str
    tool: str = ""
    wobj: str = ""
    correction_mm: tuple[float, float, float] = (math.nan,) * 3
    correction_deg: float = math.nan
    joint_change: float = math.nan
    config_before: str = ""
    config_after: str = ""
    joints: tuple[float, ...] = ()
    note: str = ""

    @property
    def compensated(self) -> bool:
        return self.status in COMPENSATED

    @property
    def fine(self) -> bool:
        """Compensated, or needing no compensation."""
        return self.status in COMPENSATED or self.status in KEPT


@dataclass(frozen=True)
class CompensationReport:
    """Everything :func:`~olp_compensate.compensation.program.compensate_program` did: one
    row per target use, and warnings (one line each, file:line first)."""

    file: str
    rows: tuple[TargetReport, ...]
    warnings: tuple[str, ...] = ()
    n_joints: int = 6
    emit: str = "pose"
    edits: int = 0

    @property
    def all_compensated(self) -> bool:
        return all(r.fine for r in self.rows)

    @property
    def exit_code(self) -> int:
        """0 when every target was compensated (or needs no compensation), else 2."""
        return 0 if self.all_compensated else 2

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for r in self.rows:
            out[r.status] = out.get(r.status, 0) + 1
        return out

    def to_csv(self) -> str:
        """The report as CSV text (one row per target use; units in the column names)."""
        buf = io.StringIO()
        joint_columns = [f"q{k + 1}_deg" for k in range(self.n_joints)]
        csv.writer(buf, lineterminator="\n").writerow(
            ["target", "file", "line", "column", "status", "tool", "wobj", "dx_mm", "dy_mm",
             "dz_mm", "drot_deg", "dq_max_deg", "config_before", "config_after",
             *joint_columns, "note"])
        lines = [_CsvRows(self.n_joints).line(r) for r in self.rows]
        lines.append("")
        return buf.getvalue() + "\n".join(lines)


class _CsvRows:
    """CSV lines of report rows: one %-format per complete row (100k-target programs); a
    row with a missing number takes the per-field path. Repeated fields are quoted once."""

    def __init__(self, n_joints: int):
        self.n_joints = n_joints
        self.row_format = ",".join(["%s,%s,%d,%d,%s,%s,%s"] + ["%.4f"] * 3 + ["%.5f"] * 2
                                   + ["%s,%s"] + ["%.6f"] * n_joints + ["%s"])
        self.empty_joints = "," * (n_joints - 1)
        self.quoted = _Quoted()

    def line(self, r: TargetReport) -> str:
        quoted = self.quoted
        c, q = r.correction_mm, r.joints
        try:   # one sum: NaN or inf anywhere makes it non-finite
            whole = (len(c) == 3 and len(q) == self.n_joints and math.isfinite(
                c[0] + c[1] + c[2] + r.correction_deg + r.joint_change + sum(q)))
        except TypeError:   # a None
            whole = False
        if whole:
            return self.row_format % (
                _csv_field(r.target), quoted[r.file], r.line, r.column, quoted[r.status],
                quoted[r.tool], quoted[r.wobj], *c, r.correction_deg, r.joint_change,
                quoted[r.config_before], quoted[r.config_after], *q, quoted[r.note])
        joint_text = ",".join(_num(v, 6) for v in q) if q else self.empty_joints
        return ",".join((
            _csv_field(r.target), quoted[r.file], str(r.line), str(r.column),
            quoted[r.status], quoted[r.tool], quoted[r.wobj],
            *(_num(v, 4) for v in r.correction_mm), _num(r.correction_deg, 5),
            _num(r.joint_change, 5), quoted[r.config_before], quoted[r.config_after],
            joint_text, quoted[r.note]))


class _Quoted(dict):
    """text -> its CSV field, computed once per distinct text."""

    def __missing__(self, text: str) -> str:
        value = self[text] = _csv_field(text)
        return value


def _csv_field(text: str) -> str:
    """One CSV field as csv.writer writes it (quoted only when it must be)."""
    if "," in text or '"' in text or "\n" in text or "\r" in text:
        return '"' + text.replace('"', '""') + '"'
    return text


def _num(value: float, decimals: int) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:.{decimals}f}"


# ---- confdata as text ---------------------------------------------------------------

_CONFIG_TEXT: dict = {}


def config_text(values) -> str:
    """'[cf1,cf4,cf6,cfx]' of a confdata (memoized: programs repeat a few of them)."""
    key = tuple(values)
    text = _CONFIG_TEXT.get(key)
    if text is None:
        text = _CONFIG_TEXT[key] = "[" + ",".join(str(int(v)) for v in key) + "]" if key else ""
    return text


def config_texts(confdata: np.ndarray, has_conf: np.ndarray | None = None) -> list[str]:
    """'[cf1,cf4,cf6,cfx]' of each row of ``confdata`` (n, 4) int, '' where ``has_conf``
    is False. Programs repeat a few confdata: each distinct row is written once (rows
    found by one 64-bit key per row when every value fits in 16 bits)."""
    if not len(confdata):
        return []
    if np.abs(confdata).max() < 1 << 15:
        shifted = (confdata + (1 << 15)).astype(np.uint64)
        key = (shifted[:, 0] << 48) | (shifted[:, 1] << 32) | (shifted[:, 2] << 16) | shifted[:, 3]
        _, first, which = np.unique(key, return_index=True, return_inverse=True)
        texts = [config_text(tuple(c)) for c in confdata[first].tolist()]
        out = [texts[j] for j in which.reshape(-1).tolist()]
    else:
        out = [config_text(tuple(c)) for c in confdata.tolist()]
    if has_conf is not None and not has_conf.all():
        out = [t if h else "" for t, h in zip(out, has_conf.tolist())]
    return out


# ---- rows ---------------------------------------------------------------------------

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


def failure_row(row: TargetReport, failure, robot, vplus: bool) -> TargetReport:
    """``row`` of a target not compensated, with why (in words and numbers), the best
    joints found and their configuration."""
    if failure is None:
        return row
    note = failure.note if not row.note else f"{failure.note}; {row.note}"
    joints = ()
    if np.all(np.isfinite(failure.joints)):
        joints = tuple(robot.to_degrees_or_mm(failure.joints[None])[0].tolist())
    config = config_text(failure.config) if failure.config is not None and not vplus else ""
    return dataclasses.replace(row, note=note, joints=joints, config_after=config)


def solved_note(notes: tuple[str, ...], tool_note: str) -> str:
    """The report note of a solved entry: its resolution notes and the real-tool note."""
    if not notes:
        return tool_note
    kept = [x for x in notes if x != "unused"] + [tool_note]
    if "unused" in notes:
        kept.append("not moved to in this file: tool0/wobj0 assumed")
    return "; ".join(x for x in kept if x)
