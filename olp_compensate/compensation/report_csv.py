"""CSV lines of report rows (:class:`~.report.TargetReport` objects, or rows held as
:class:`~.report.RowColumns`), written as csv.writer writes them: numbers fixed-point
(mm 4 decimals, deg 5, joints 6), empty where not a finite number."""

from __future__ import annotations

import itertools
import math

import numpy as np

from ..programs.number_format import fixed_rows


class CsvRows:
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
        # a row of a target not compensated: no correction, its joints (or none)
        self.failed_line = "%s,%s,%d,%d,%s,%s,%s,,,,,,%s,%s,%s,%s\n"
        self.quoted = Quoted()

    def _who(self, c: RowColumns, rows: np.ndarray) -> tuple:
        """``rows`` as a list, and their target names (CSV fields), tools and work objects
        (quoted), one list each."""
        quoted = self.quoted.__getitem__
        r = rows.tolist()
        names = [c.names[i] for i in r]
        if any(ch in "".join(names) for ch in ',"\n\r'):
            names = list(map(csv_field, names))
        tools = [(quoted(t), quoted(w)) for t, w in c.pair_names]
        tool, wobj = zip(*[tools[p] for p in c.pair[rows].tolist()])
        return r, names, tool, wobj

    def column_fields(self, c: RowColumns, rows: np.ndarray) -> list:
        """The fields of :attr:`row_line` for the complete rows ``rows`` of ``c``, row
        after row in one flat list (each column converted in one pass, the numbers of a
        row's runs of floats written together: :func:`fixed_rows`)."""
        if not len(rows):
            return []
        quoted = self.quoted.__getitem__
        r, names, tool, wobj = self._who(c, rows)
        columns = [names, itertools.repeat(quoted(c.file)), c.line[rows].tolist(),
                   c.column[rows].tolist(), map(quoted, [c.status[i] for i in r]), tool, wobj,
                   fixed_rows(c.correction_mm[rows], 4),
                   fixed_rows(np.stack([c.correction_deg[rows], c.joint_change[rows]], 1), 5),
                   map(quoted, [c.config_before[i] for i in r]),
                   map(quoted, [c.config_after[i] for i in r]),
                   *[fixed_rows(c.joints[rows], 6)] * bool(self.n_joints),
                   map(quoted, [c.note[i] for i in r])]
        return list(itertools.chain.from_iterable(zip(*columns)))

    def failed_lines(self, c: RowColumns, rows: np.ndarray) -> list[str]:
        """The CSV lines (each ending in a line break) of the rows ``rows`` of ``c`` that
        are not compensated (no correction; joints where all are finite), as :meth:`line`
        writes them, each column converted in one pass."""
        if not len(rows):
            return []
        quoted = self.quoted.__getitem__
        r, names, tool, wobj = self._who(c, rows)
        q = c.joints[rows]
        found = np.isfinite(q).all(axis=1) if q.shape[1] else np.zeros(len(r), bool)
        joints = [self.empty_joints] * len(r)
        for k, text in zip(np.flatnonzero(found).tolist(), fixed_rows(q[found], 6)):
            joints[k] = text
        file = quoted(c.file)
        return [self.failed_line % fields for fields in zip(
            names, itertools.repeat(file), c.line[rows].tolist(), c.column[rows].tolist(),
            map(quoted, [c.status[i] for i in r]), tool, wobj,
            map(quoted, [c.config_before[i] for i in r]),
            map(quoted, [c.config_after[i] for i in r]), joints,
            map(quoted, [c.note[i] for i in r]))]

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
                csv_field(r.target), quoted[r.file], r.line, r.column, quoted[r.status],
                quoted[r.tool], quoted[r.wobj], *c, r.correction_deg, r.joint_change,
                quoted[r.config_before], quoted[r.config_after], *q, quoted[r.note])
        joint_text = ",".join(_num(v, 6) for v in q) if q else self.empty_joints
        return ",".join((
            csv_field(r.target), quoted[r.file], str(r.line), str(r.column),
            quoted[r.status], quoted[r.tool], quoted[r.wobj],
            *(_num(v, 4) for v in r.correction_mm), _num(r.correction_deg, 5),
            _num(r.joint_change, 5), quoted[r.config_before], quoted[r.config_after],
            joint_text, quoted[r.note]))


class Quoted(dict):
    """text -> its CSV field, computed once per distinct text."""

    def __missing__(self, text: str) -> str:
        value = self[text] = csv_field(text)
        return value


def csv_field(text: str) -> str:
    """One CSV field as csv.writer writes it (quoted only when it must be)."""
    if "," in text or '"' in text or "\n" in text or "\r" in text:
        return '"' + text.replace('"', '""') + '"'
    return text


def _num(value: float, decimals: int) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:.{decimals}f}"
