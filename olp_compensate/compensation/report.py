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

from ..programs.number_format import fixed_rows
from .pose import COMPENSATED

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
        writer = _CsvRows(self.n_joints)
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


class _CsvRows:
    """CSV lines of report rows: one %-format per complete row (100k-target programs); a
    row with a missing number takes the per-field path. Repeated fields are quoted once."""

    def __init__(self, n_joints: int):
        self.n_joints = n_joints
        self.row_format = ",".join(["%s,%s,%d,%d,%s,%s,%s"] + ["%.4f"] * 3 + ["%.5f"] * 2
                                   + ["%s,%s"] + ["%.6f"] * n_joints + ["%s"])
        # of column rows: each run of numbers written beforehand (fixed_rows), one field
        self.row_line = ",".join(["%s,%s,%d,%d,%s,%s,%s,%s,%s,%s,%s"] + ["%s"] * bool(
            n_joints) + ["%s"]) + "\n"
        self.width = 12 + bool(n_joints)    # fields of a column row
        self.empty_joints = "," * (n_joints - 1)
        self.quoted = _Quoted()

    def column_fields(self, c: RowColumns, rows: np.ndarray) -> list:
        """The fields of :attr:`row_line` for the complete rows ``rows`` of ``c``, row
        after row in one flat list (each column converted in one pass, the numbers of a
        row's runs of floats written together: :func:`fixed_rows`)."""
        if not len(rows):
            return []
        quoted = self.quoted.__getitem__
        r = rows.tolist()
        names = [c.names[i] for i in r]
        if any(ch in "".join(names) for ch in ',"\n\r'):
            names = list(map(_csv_field, names))
        tools = [(quoted(t), quoted(w)) for t, w in c.pair_names]
        tool, wobj = zip(*[tools[p] for p in c.pair[rows].tolist()])
        columns = [names, itertools.repeat(quoted(c.file)), c.line[rows].tolist(),
                   c.column[rows].tolist(), map(quoted, [c.status[i] for i in r]), tool, wobj,
                   fixed_rows(c.correction_mm[rows], 4),
                   fixed_rows(np.stack([c.correction_deg[rows], c.joint_change[rows]], 1), 5),
                   map(quoted, [c.config_before[i] for i in r]),
                   map(quoted, [c.config_after[i] for i in r]),
                   *[fixed_rows(c.joints[rows], 6)] * bool(self.n_joints),
                   map(quoted, [c.note[i] for i in r])]
        return list(itertools.chain.from_iterable(zip(*columns)))

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


# ---- rows held as columns (a big module compensated in columns) ---------------------

@dataclass(frozen=True, eq=False)
class RowColumns:
    """Report rows of compensated targets as columns (see :class:`TargetReport` for the
    meaning and units of each); ``pair`` indexes ``pair_names`` (tool, wobj)."""

    names: list
    file: str
    line: np.ndarray
    column: np.ndarray
    status: list
    pair: np.ndarray
    pair_names: list
    correction_mm: np.ndarray
    correction_deg: np.ndarray
    joint_change: np.ndarray
    config_before: list
    config_after: list
    joints: np.ndarray
    note: list

    def __len__(self) -> int:
        return len(self.names)

    def row(self, i: int) -> TargetReport:
        """Row ``i`` as a :class:`TargetReport`."""
        tool, wobj = self.pair_names[int(self.pair[i])]
        return TargetReport(
            target=self.names[i], file=self.file, line=int(self.line[i]),
            column=int(self.column[i]), status=self.status[i], tool=tool, wobj=wobj,
            correction_mm=tuple(self.correction_mm[i].tolist()),
            correction_deg=float(self.correction_deg[i]),
            joint_change=float(self.joint_change[i]), config_before=self.config_before[i],
            config_after=self.config_after[i], joints=tuple(self.joints[i].tolist()),
            note=self.note[i])

    @staticmethod
    def concatenate(parts: list[RowColumns]) -> RowColumns:
        """One RowColumns of ``parts`` (of one file and the same pairs), in order."""
        def joined(name):
            values = [getattr(p, name) for p in parts]
            if isinstance(values[0], list):
                return [v for vs in values for v in vs]
            return np.concatenate(values)
        first = parts[0]
        return RowColumns(**{f.name: (getattr(first, f.name) if f.name in ("file", "pair_names")
                                      else joined(f.name))
                             for f in dataclasses.fields(RowColumns)})


class RowSequence(Sequence):
    """Report rows that are not a tuple: made on access, with the summaries the report
    asks of them computed without making every row."""

    def counts(self) -> dict[str, int]:
        raise NotImplementedError

    def problem_rows(self) -> list[TargetReport]:
        raise NotImplementedError

    def largest_correction(self) -> tuple[float, float, float] | None:
        raise NotImplementedError

    def csv_chunks(self, writer: _CsvRows):
        raise NotImplementedError


class ReportRows(RowSequence):
    """The rows of a report as a sequence of :class:`TargetReport`, made on access from
    ``columns`` (compensated targets) and ``others`` (rows held as objects), in the
    ``order`` given: ``order[k] >= 0`` is column row ``order[k]``, ``-1 - j`` is
    ``others[j]``."""

    def __init__(self, columns: RowColumns, others: list, order: np.ndarray):
        self.columns, self.others, self.order = columns, others, order

    def __len__(self) -> int:
        return len(self.order)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        j = int(self.order[k])
        return self.columns.row(j) if j >= 0 else self.others[-1 - j]

    def __iter__(self):
        row, others = self.columns.row, self.others
        for j in self.order.tolist():
            yield row(j) if j >= 0 else others[-1 - j]

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for status in self.columns.status:
            out[status] = out.get(status, 0) + 1
        others = self.others
        statuses = others.statuses() if hasattr(others, "statuses") else \
            (r.status for r in others)   # others made on access give their statuses
        for status in statuses:
            out[status] = out.get(status, 0) + 1
        return out

    def problem_rows(self) -> list[TargetReport]:
        if hasattr(self.others, "problem_rows"):   # others made on access: a sequence
            return self.others.problem_rows()
        return [r for r in self.others if not r.fine]   # others keep their text order

    def largest_correction(self) -> tuple[float, float, float] | None:
        c, others = self.columns, self.others
        found = _largest(others.compensated_rows() if hasattr(others, "compensated_rows")
                         else (r for r in others if r.status in COMPENSATED))
        if not len(c):
            return found
        change = c.joint_change[~np.isnan(c.joint_change)]
        ours = (float(np.sqrt((c.correction_mm ** 2).sum(axis=1)).max()),
                float(c.correction_deg.max()), float(change.max()) if len(change) else 0.0)
        if found is None:
            return ours
        return tuple(max(a, b) for a, b in zip(ours, found))

    def csv_chunks(self, writer: _CsvRows):
        """The CSV lines of the rows, in pieces of :data:`CSV_CHUNK` rows: each run of
        complete column rows in one ``%`` format (:meth:`_CsvRows.column_fields`), the
        others row by row."""
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
            done = 0    # fast rows written
            for a, b in zip(bounds, bounds[1:]):
                if fast[a]:
                    pieces.append((writer.row_line * (b - a)) % tuple(
                        fields[done * width:(done + b - a) * width]))
                    done += b - a
                    continue
                for j in order[a:b].tolist():
                    pieces.append(writer.line(others[-1 - j] if j < 0 else c.row(j)) + "\n")
            yield "".join(pieces)


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

    def csv_chunks(self, writer: _CsvRows):
        for part in self.parts:
            if isinstance(part, RowSequence):
                yield from part.csv_chunks(writer)
            else:
                for k in range(0, len(part), CSV_CHUNK):
                    yield "".join([writer.line(r) + "\n" for r in part[k:k + CSV_CHUNK]])
