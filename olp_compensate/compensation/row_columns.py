"""Report rows of solved targets held as columns (a big module compensated in columns):
:class:`RowColumns`, read by :class:`~.report.ReportRows`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .report import TargetReport

__all__ = ["RowColumns"]


@dataclass(frozen=True, eq=False)
class RowColumns:
    """Report rows of solved targets as columns (see :class:`TargetReport` for the meaning
    and units of each); ``pair`` indexes ``pair_names`` (tool, wobj). ``compensated``
    (n,) bool: False for a target not compensated (its status the failure's, no
    correction, its ``joints`` the closest found, a NaN row where none was)."""

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
    compensated: np.ndarray

    def __len__(self) -> int:
        return len(self.names)

    def row(self, i: int) -> TargetReport:
        """Row ``i`` as a :class:`TargetReport`."""
        tool, wobj = self.pair_names[int(self.pair[i])]
        if not self.compensated[i]:   # as object_model.rows.failure_row makes it
            q = self.joints[i]
            return TargetReport(
                target=self.names[i], file=self.file, line=int(self.line[i]),
                column=int(self.column[i]), status=self.status[i], tool=tool, wobj=wobj,
                config_before=self.config_before[i], config_after=self.config_after[i],
                joints=tuple(q.tolist()) if np.isfinite(q).all() else (),
                note=self.note[i])
        return TargetReport(
            target=self.names[i], file=self.file, line=int(self.line[i]),
            column=int(self.column[i]), status=self.status[i], tool=tool, wobj=wobj,
            correction_mm=tuple(self.correction_mm[i].tolist()),
            correction_deg=float(self.correction_deg[i]),
            joint_change=float(self.joint_change[i]), config_before=self.config_before[i],
            config_after=self.config_after[i], joints=tuple(self.joints[i].tolist()),
            note=self.note[i])

    def taken(self, rows: np.ndarray) -> RowColumns:
        """The rows ``rows`` (k,) int, in that order."""
        r = rows.tolist()
        return RowColumns(**{f.name: (
            getattr(self, f.name) if f.name in ("file", "pair_names") else
            [getattr(self, f.name)[i] for i in r] if isinstance(getattr(self, f.name), list)
            else getattr(self, f.name)[rows]) for f in dataclasses.fields(RowColumns)})

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
