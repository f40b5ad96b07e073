"""The per-target report of a compensated program, and its CSV.

One :class:`TargetReport` row per target and tool/work-object pair (or per motion whose
target is computed at run time, or per target the parser could not read); the
:class:`CompensationReport` holds the rows in text order and writes them as CSV with the
unit of every number in its column name (mm, deg).
"""

from __future__ import annotations

import bisect
import csv
import dataclasses
import io
import itertools
import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .pose import COMPENSATED
from .report_csv import CsvRows

__all__ = ["TargetReport", "CompensationReport", "KEPT", "config_text", "config_texts"]

KEPT = ("joint_target", "frame")
"""Statuses of targets that need no compensation (the program is still fully compensated):
joints already; ``frame``, a pose literal that is a tool or frame, not a target (URScript
``set_tcp(p[...])``, ``force_mode`` task frames)."""

CSV_CHUNK = 4096
"""Report rows written per piece of :meth:`CompensationReport.csv_chunks`."""
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

    def __reduce__(self):
        # the fields in order: pickled and unpickled (results of -j N workers) about twice
        # as fast, and 40 % smaller, than the slots' default state
        return TargetReport, _FIELDS_OF(self)

    @property
    def compensated(self) -> bool:
        return self.status in COMPENSATED

    @property
    def fine(self) -> bool:
        """Compensated, or needing no compensation."""
        return self.status in COMPENSATED or self.status in KEPT


_FIELDS_OF = operator.attrgetter(*(f.name for f in dataclasses.fields(TargetReport)))


@dataclass(frozen=True)
class CompensationReport:
    """Everything :func:`~olp_compensate.programs.object_model.program.compensate_program` did: one
    row per target use, and warnings (one line each, file:line first).

    rows : a tuple of :class:`TargetReport`, or (a big module compensated in columns) a
        :class:`ReportRows` sequence that makes each row on access.
    """

    file: str
    rows: tuple[TargetReport, ...]
    warnings: tuple[str, ...] = ()
    n_joints: int = 6
    emit: str = "pose"
    edits: int = 0

    @property
    def all_compensated(self) -> bool:
        if isinstance(self.rows, RowSequence):
            return not self.rows.problem_rows()
        return all(r.fine for r in self.rows)

    @property
    def exit_code(self) -> int:
        """0 when every target was compensated (or needs no compensation), else 2."""
        return 0 if self.all_compensated else 2

    def counts(self) -> dict[str, int]:
        """How many rows have each status."""
        if isinstance(self.rows, RowSequence):
            return self.rows.counts()
        out: dict[str, int] = {}
        for r in self.rows:
            out[r.status] = out.get(r.status, 0) + 1
        return out

    def to_csv(self) -> str:
        """The report as CSV text (one row per target use; units in the column names)."""
        return "".join(self.csv_chunks())

    def csv_chunks(self):
        """:meth:`to_csv` in pieces (a header, then :data:`CSV_CHUNK` rows each), written
        one after the other without holding the whole text."""
        buf = io.StringIO()
        joint_columns = [f"q{k + 1}_deg" for k in range(self.n_joints)]
        csv.writer(buf, lineterminator="\n").writerow(
            ["target", "file", "line", "column", "status", "tool", "wobj", "dx_mm", "dy_mm",
             "dz_mm", "drot_deg", "dq_max_deg", "config_before", "config_after",
             *joint_columns, "note"])
        yield buf.getvalue()
        writer = CsvRows(self.n_joints)
        if isinstance(self.rows, RowSequence):
            yield from self.rows.csv_chunks(writer)
            return
        rows = self.rows
        for k in range(0, len(rows), CSV_CHUNK):
            yield "".join([writer.line(r) + "\n" for r in rows[k:k + CSV_CHUNK]])

    def largest_correction(self) -> tuple[float, float, float] | None:
        """(mm, deg, joint deg): the largest correction, turn and joint change among the
        compensated rows (each the largest of its own), or None when none is."""
        rows = self.rows
        if isinstance(rows, RowSequence):
            return rows.largest_correction()
        return _largest(r for r in rows if r.status in COMPENSATED)

    def problem_rows(self) -> list[TargetReport]:
        """The rows neither compensated nor needing no compensation, in order."""
        if isinstance(self.rows, RowSequence):
            return self.rows.problem_rows()
        return [r for r in self.rows if not r.fine]


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

def _largest(rows) -> tuple[float, float, float] | None:
    """(mm, deg, joint deg) largest correction, turn and joint change of ``rows``."""
    shift = turn = dq = -1.0
    for r in rows:
        dx, dy, dz = r.correction_mm
        shift = max(shift, math.sqrt(dx * dx + dy * dy + dz * dz))
        turn = max(turn, r.correction_deg)
        if r.joint_change > dq:   # False for NaN
            dq = r.joint_change
    return None if shift < 0 else (shift, turn, max(dq, 0.0))


# ---- rows held as columns (a big module compensated in columns: .row_columns) -------

class RowSequence(Sequence):
    """Report rows that are not a tuple: made on access, with the summaries the report
    asks of them computed without making every row."""

    def counts(self) -> dict[str, int]:
        raise NotImplementedError

    def problem_rows(self) -> list[TargetReport]:
        raise NotImplementedError

    def largest_correction(self) -> tuple[float, float, float] | None:
        raise NotImplementedError

    def csv_chunks(self, writer: CsvRows):
        raise NotImplementedError


class MergedRows(Sequence):
    """Rows of two sources merged in the order ``order`` (n,) int: ``order[k] >= 0`` is
    the first source's row ``order[k]``, ``-1 - j`` the second's row ``j``; each made on
    access by :meth:`first_row` and :meth:`second_row`."""

    order: np.ndarray

    def first_row(self, j: int) -> TargetReport:
        raise NotImplementedError

    def second_row(self, j: int) -> TargetReport:
        raise NotImplementedError

    def __len__(self) -> int:
        return len(self.order)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        j = int(self.order[k])
        return self.first_row(j) if j >= 0 else self.second_row(-1 - j)

    def __iter__(self):
        first, second = self.first_row, self.second_row
        for j in self.order.tolist():
            yield first(j) if j >= 0 else second(-1 - j)


class RowSource(Sequence):
    """Report rows held beside a report's columns (the ``others`` of
    :class:`ReportRows`), in text order, with the summaries the report asks of them."""

    def keys(self) -> np.ndarray:
        """(n,) int64: ``line << 32 | column`` of each row, in order."""
        return np.fromiter(((r.line << 32) | r.column for r in self), np.int64, len(self))

    def statuses(self):
        """The status of each row, in order."""
        return (r.status for r in self)

    def compensated_rows(self):
        """The compensated rows, any order."""
        return (r for r in self if r.status in COMPENSATED)

    def problem_rows(self) -> Sequence:
        """The rows neither compensated nor needing none, in order."""
        return [r for r in self if not r.fine]

    def fine_mask(self) -> np.ndarray:
        """(n,) bool: which rows are compensated or need no compensation, in order."""
        return np.fromiter((r.fine for r in self), bool, len(self))

    def csv_lines(self, rows: list[int], writer: CsvRows) -> list[str]:
        """The CSV lines (each ending in a line break) of rows ``rows``, in that order."""
        return [writer.line(self[j]) + "\n" for j in rows]

    def renoted(self, change) -> RowSource:
        """These rows with each compensated row replaced by ``change(row)`` (the same row,
        its note changed), in order."""
        return ListedRows([change(r) if r.status in COMPENSATED else r for r in self])


class ListedRows(RowSource):
    """A list of :class:`TargetReport` (in text order) as a :class:`RowSource`."""

    def __init__(self, rows: list):
        self.rows = rows

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, k):
        return self.rows[k]

    def __iter__(self):
        return iter(self.rows)


def row_source(rows) -> RowSource:
    """``rows`` as a :class:`RowSource`: itself if one, else a list of rows in text order."""
    return rows if isinstance(rows, RowSource) else ListedRows(list(rows))


class ReportRows(RowSequence, MergedRows):
    """The rows of a report as a sequence of :class:`TargetReport`, made on access from
    ``columns`` (compensated targets) and ``others`` (a :class:`RowSource`, or a list of
    rows in text order), in the ``order`` given: ``order[k] >= 0`` is column row
    ``order[k]``, ``-1 - j`` is ``others[j]``."""

    def __init__(self, columns: RowColumns, others, order: np.ndarray):
        self.columns, self.order = columns, order
        self.others = row_source(others)

    def first_row(self, j: int) -> TargetReport:
        return self.columns.row(j)

    def second_row(self, j: int) -> TargetReport:
        return self.others[j]

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for status in itertools.chain(self.columns.status, self.others.statuses()):
            out[status] = out.get(status, 0) + 1
        return out

    def problem_rows(self) -> Sequence:
        """The rows neither compensated nor needing none, in order (made on access where
        columns hold some)."""
        failed = ~self.columns.compensated
        if not failed.any():
            return self.others.problem_rows()
        order = self.order
        mine = order >= 0
        problem = np.empty(len(order), bool)
        problem[mine] = failed[order[mine]]
        problem[~mine] = ~self.others.fine_mask()[-1 - order[~mine]]
        return PickedRows(self, np.flatnonzero(problem))

    def largest_correction(self) -> tuple[float, float, float] | None:
        c = self.columns
        found = _largest(self.others.compensated_rows())
        if not c.compensated.all():
            c = c.taken(np.flatnonzero(c.compensated))
        if not len(c):
            return found
        change = c.joint_change[~np.isnan(c.joint_change)]
        ours = (float(np.sqrt((c.correction_mm ** 2).sum(axis=1)).max()),
                float(c.correction_deg.max()), float(change.max()) if len(change) else 0.0)
        if found is None:
            return ours
        return tuple(max(a, b) for a, b in zip(ours, found))

    def csv_chunks(self, writer: CsvRows):
        """The CSV lines of the rows, in pieces of :data:`CSV_CHUNK` rows: each run of
        complete column rows in one ``%`` format (:meth:`CsvRows.column_fields`), the
        others' lines from :meth:`RowSource.csv_lines`."""
        c, others = self.columns, self.others
        whole = np.isfinite(c.correction_mm.sum(axis=1) + c.correction_deg + c.joint_change
                            + c.joints.sum(axis=1)) if len(c) else np.zeros(0, bool)
        for k in range(0, len(self.order), CSV_CHUNK):
            order = self.order[k:k + CSV_CHUNK]
            fast = order >= 0
            fast[fast] = whole[order[fast]]
            fields = writer.column_fields(c, order[fast])
            width = writer.width
            pieces = []
            bounds = [0, *(np.flatnonzero(fast[1:] != fast[:-1]) + 1).tolist(), len(order)]
            slow = order[~fast]
            theirs = slow < 0
            lines = merged(theirs, others.csv_lines((-1 - slow[theirs]).tolist(), writer),
                           _column_lines(c, slow[~theirs], writer))
            done = 0    # fast rows written
            for a, b in zip(bounds, bounds[1:]):
                if fast[a]:
                    pieces.append((writer.row_line * (b - a)) % tuple(
                        fields[done * width:(done + b - a) * width]))
                    done += b - a
                else:
                    pieces.append("".join(lines[a - done:b - done]))
            yield "".join(pieces)


class PickedRows(Sequence):
    """Rows ``positions`` (k,) int of a sequence of rows, made on access; equal to any
    sequence of the same rows."""

    def __init__(self, rows: Sequence, positions: np.ndarray):
        self.rows, self.positions = rows, positions

    def __len__(self) -> int:
        return len(self.positions)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        return self.rows[int(self.positions[k])]

    def __eq__(self, other) -> bool:
        return isinstance(other, Sequence) and list(self) == list(other)


def _column_lines(c: RowColumns, rows: np.ndarray, writer: CsvRows) -> list[str]:
    """The CSV lines of column rows ``rows`` that are not complete: those of targets not
    compensated written together (:meth:`CsvRows.failed_lines`), the others row by row."""
    failed = ~c.compensated[rows]
    if not failed.any():
        return [writer.line(c.row(j)) + "\n" for j in rows.tolist()]
    return merged(failed, writer.failed_lines(c, rows[failed]),
                  [writer.line(c.row(j)) + "\n" for j in rows[~failed].tolist()])


def merged(mask: np.ndarray, yes: list, no: list) -> list:
    """One list of ``yes`` (at the places ``mask`` (n,) bool is true, in order) and
    ``no`` (at the others)."""
    take_yes, take_no = iter(yes).__next__, iter(no).__next__
    return [take_yes() if m else take_no() for m in mask.tolist()]


class ChainedRows(RowSequence):
    """The rows of several modules one after the other; each part a :class:`RowSequence`
    or a tuple of :class:`TargetReport`."""

    def __init__(self, parts: list):
        self.parts = list(parts)
        self.ends = list(itertools.accumulate(len(p) for p in self.parts))

    def __len__(self) -> int:
        return self.ends[-1] if self.ends else 0

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        if k < 0:
            k += len(self)
        if not 0 <= k < len(self):
            raise IndexError(k)
        p = bisect.bisect_right(self.ends, k)
        return self.parts[p][k - (self.ends[p - 1] if p else 0)]

    def __iter__(self):
        return itertools.chain.from_iterable(self.parts)

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for part in self.parts:
            if isinstance(part, RowSequence):
                for status, n in part.counts().items():
                    out[status] = out.get(status, 0) + n
            else:
                for r in part:
                    out[r.status] = out.get(r.status, 0) + 1
        return out

    def problem_rows(self) -> list[TargetReport]:
        return [r for part in self.parts for r in (
            part.problem_rows() if isinstance(part, RowSequence) else
            [r for r in part if not r.fine])]

    def largest_correction(self) -> tuple[float, float, float] | None:
        found = [part.largest_correction() if isinstance(part, RowSequence) else
                 _largest(r for r in part if r.status in COMPENSATED) for part in self.parts]
        found = [f for f in found if f is not None]
        return tuple(max(values) for values in zip(*found)) if found else None

    def csv_chunks(self, writer: CsvRows):
        for part in self.parts:
            if isinstance(part, RowSequence):
                yield from part.csv_chunks(writer)
            else:
                for k in range(0, len(part), CSV_CHUNK):
                    yield "".join([writer.line(r) + "\n" for r in part[k:k + CSV_CHUNK]])
