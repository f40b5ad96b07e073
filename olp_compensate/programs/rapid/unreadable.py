"""A RAPID task compensated module by module as far as it can be.

A controller's task folder often holds modules that cannot be read as RAPID text: encrypted
libraries, licence modules, templates and fragments. One of them must not cost the whole
task: :func:`compensate_readable` compensates the readable modules together (they still
resolve each other's tools, work objects and targets), copies each unreadable module
unchanged (its bytes are written where its output goes: nothing of the task is lost or left
out), reports it on a row of status ``unreadable`` with the position and reason of the
parse error, and names it in the note of every ``unresolved`` row (a name declared only in
that module cannot be found in the others).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Sequence

from ...compensation.report import ChainedRows, CompensationReport, TargetReport
from ...errors import ParseError

__all__ = ["UNREADABLE", "compensate_readable"]

UNREADABLE = "unreadable"
"""Status of the report row of a module that could not be read."""
COPIED = "copied unchanged, none of its targets compensated"


@dataclasses.dataclass(frozen=True)
class _Skipped:
    """A module left out of the compensation: its index, name, text and parse error."""

    index: int
    name: str
    text: str
    error: ParseError


def compensate_readable(texts: Sequence[str], names: Sequence[str],
                        run: Callable[[list[int]], object]):
    """``run(keep)`` (a :class:`~.files.FilesResult` of the modules ``keep``, indices into
    ``texts``), retried without each module whose :class:`ParseError` names it, until the
    rest compensates; the result then holds every module (the unreadable ones as read, as
    text: encoded when written) and their report rows. Raises the error when no module is left to read, or
    when it names no module of the task."""
    skipped: list[_Skipped] = []
    while True:
        keep = [k for k in range(len(texts)) if all(s.index != k for s in skipped)]
        try:
            result = run(keep)
            break
        except ParseError as exc:
            k = next((k for k in keep if names[k] == exc.file), None)
            if k is None or len(keep) == 1:
                raise
            skipped.append(_Skipped(k, names[k], texts[k], exc))
    if not skipped:
        return result
    new = list(result.new)
    for s in sorted(skipped, key=lambda s: s.index):
        new.insert(s.index, s.text)
    return dataclasses.replace(result, new=tuple(new),
                               report=_with_unreadable(result.report, skipped))


def _with_unreadable(report: CompensationReport, skipped: list[_Skipped]
                     ) -> CompensationReport:
    """``report`` with a first row per unreadable module and the unresolved rows' notes
    naming the unreadable modules."""
    rows = [TargetReport(target=f"(module {s.name})", file=s.name, line=s.error.line or 1,
                         column=s.error.column or 1, status=UNREADABLE,
                         note=f"{s.error.message}; {COPIED}")
            for s in sorted(skipped, key=lambda s: s.index)]
    for row in report.problem_rows():
        if row.status == "unresolved":
            row.note += _unresolved_note(row, skipped)
    joined = (tuple(rows) + report.rows if isinstance(report.rows, tuple)
              else ChainedRows([tuple(rows), report.rows]))
    return dataclasses.replace(report, rows=joined)


def _unresolved_note(row: TargetReport, skipped: list[_Skipped]) -> str:
    """What an unresolved row's note adds: the unreadable module that names one of the
    row's names (target, tool, work object) in its text, else every unreadable module."""
    for name in (row.tool, row.wobj, row.target.split("{")[0]):
        if not name or not re.fullmatch(r"\w+", name):
            continue
        word = re.compile(rf"(?<!\w){re.escape(name)}(?!\w)", re.IGNORECASE)
        holders = [s.name for s in skipped if word.search(s.text)]
        if holders:
            return (f"; {name} is named in {', '.join(holders)}, which could not be read "
                    f"(unreadable module)")
    return (f"; the task's unreadable module{'s' if len(skipped) > 1 else ''} "
            f"{', '.join(s.name for s in skipped)} may declare it")
