"""Motions that displace a named target at run time, held as rows of a column parse.

``MoveL Offs(p, 0, 0, 50), v, z, tool\\WObj:=w;`` and ``RelTool(p, ...)`` of the plainest
form (what fast.py's ``_DISPLACED_MOVE`` reads) are not compensated: each is one
``runtime`` report row. A real module holds tens of thousands of them; as objects
(:class:`~..targets.MotionUse`, :class:`~..targets.RuntimeTarget`, their report row) they
took about 1 KB each. Here they are rows: offsets in one integer array, the repeated words
(instruction, tool, work object, routine, reason) stored once; the objects and the report
row are made on access, exactly as the object parse makes them.
"""

from __future__ import annotations

import copy
import dataclasses
import heapq
import re
from array import array
from collections.abc import Sequence
from itertools import repeat
from sys import intern

import numpy as np

from ...compensation.report import (COMPENSATED, MergedRows, PickedRows, RowSource,
                                    TargetReport, merged)
from ...compensation.report_csv import CsvRows
from ..targets import MotionUse, Program, RuntimeTarget, SourceLocation
from .columns import _END, _GROUP, _START, INSTRUCTION, lines_and_columns
from .instructions import RUNTIME_FUNCS

GROUPS = (1, 2, 3, 4, 8, 9, 10)
"""fast.py ``_MIXED_MOVE``'s groups of a displaced move: instruction, target expression,
function, the displaced target's name, tool, wobj, where the arguments end."""
_WIDTH = 10
"""Integers per row: line, column, instruction (start, end), statement (start, end),
target expression (start, end), the displaced target's name (start, end)."""


class DisplacedMoves:
    """The plain Offs()/RelTool() motions of one module, in text order."""

    __slots__ = ("numbers", "instructions", "reasons", "tools", "wobjs", "routines", "_words")

    def __init__(self):
        self.numbers = array("q")            # _WIDTH per row
        self.instructions: list[str] = []
        self.reasons: list[str] = []
        self.tools: list[str] = []
        self.wobjs: list[str | None] = []
        self.routines: list[str | None] = []
        self._words: dict = {}   # one string per distinct word and reason

    def __len__(self) -> int:
        return len(self.reasons)

    def add(self, m: re.Match, routine: str | None) -> None:
        """Add a row: a ``_MIXED_MOVE`` match ``m`` of a displaced move (fast.py; groups
        :data:`GROUPS`); its line and column are set by :meth:`place`."""
        regs = m.regs
        self.numbers.extend((0, 0, *regs[1], regs[0][0], regs[10][0], *regs[2], *regs[4]))
        instruction, function, tool, wobj = m.group(1, 3, 8, 9)
        words = self._words
        instruction = words.setdefault(instruction, instruction)
        key = (function, instruction)
        reason = words.get(key)
        if reason is None:
            reason = words[key] = intern(f"{RUNTIME_FUNCS[function.lower()]} ({instruction})")
        self.instructions.append(instruction)
        self.reasons.append(reason)
        self.tools.append(words.setdefault(tool, tool))
        self.wobjs.append(None if wobj is None else words.setdefault(wobj, wobj))
        self.routines.append(routine)

    def extend(self, ms: list, routine: str | None) -> None:
        """Add a row per ``_MIXED_MOVE`` match of ``ms`` (fast.py; each a displaced move,
        groups :data:`GROUPS`): the rows :meth:`add` gives of the same moves, in one
        batch (a short list row by row: arrays cost more than they save)."""
        if len(ms) < 8:
            for m in ms:
                self.add(m, routine)
            return
        instruction, expression, function, name, tool, wobj, stop = GROUPS
        words = self._words
        written = list(map(_GROUP, ms, repeat(instruction)))
        instructions = list(map(words.setdefault, written, written))
        keys = list(zip(map(_GROUP, ms, repeat(function)), instructions))
        for key in set(keys).difference(words):
            words[key] = intern(f"{RUNTIME_FUNCS[key[0].lower()]} ({key[1]})")
        tools = list(map(_GROUP, ms, repeat(tool)))
        wobjs = map(_GROUP, ms, repeat(wobj))
        self.instructions.extend(instructions)
        self.reasons.extend(map(words.__getitem__, keys))
        self.tools.extend(map(words.setdefault, tools, tools))
        self.wobjs.extend(None if w is None else words.setdefault(w, w) for w in wobjs)
        self.routines.extend(repeat(routine, len(ms)))
        n = len(ms)
        start = np.fromiter(map(_START, ms), np.int64, n)   # the instruction word's
        columns = [np.fromiter(map(method, ms, repeat(group)), np.int64, n) for method, group
                   in ((_START, stop), (_START, expression), (_END, expression),
                       (_START, name), (_END, name))]
        zero = np.zeros(n, np.int64)
        self.numbers.frombytes(np.column_stack(
            [zero, zero, start, start + INSTRUCTION, start, *columns]).tobytes())

    def place(self, line_starts: np.ndarray) -> None:
        """Set each row's 1-based line and column, of where its target expression starts,
        from the offsets where the text's lines start."""
        if len(self):
            s = np.frombuffer(self.numbers, np.int64).reshape(-1, _WIDTH)
            s[:, 0], s[:, 1] = lines_and_columns(s[:, 6], line_starts)

    def _row(self, i: int) -> array:
        return self.numbers[_WIDTH * i:_WIDTH * i + _WIDTH]

    def base_names(self, text: str) -> list[str]:
        """Lower-case name of each row's displaced target."""
        s = self.numbers
        return [text[a:b].lower() for a, b in zip(s[8::_WIDTH], s[9::_WIDTH])]

    def keys(self) -> np.ndarray:
        """(n,) int64: ``line << 32 | column`` of each row (the report's order)."""
        s = np.frombuffer(self.numbers, np.int64).reshape(-1, _WIDTH) if len(self) else \
            np.zeros((0, _WIDTH), np.int64)
        return (s[:, 0] << 32) | s[:, 1]

    def objects(self, i: int, text: str, file: str) -> tuple[MotionUse, RuntimeTarget]:
        """Row ``i`` as the (MotionUse, RuntimeTarget) the object parse makes."""
        line, col, i0, i1, s0, s1, t0, t1, b0, b1 = self._row(i)
        runtime = RuntimeTarget(
            expression=text[t0:t1], location=SourceLocation(file, line, col),
            reason=self.reasons[i], base_name=text[b0:b1], routine=self.routines[i],
            span=(t0, t1))
        use = MotionUse(
            instruction=self.instructions[i], source=(file, line, col), role="to",
            runtime=runtime, tool=self.tools[i], wobj=self.wobjs[i],
            routine=self.routines[i], instruction_span=(i0, i1), statement_span=(s0, s1),
            target_span=(t0, t1))
        return use, runtime

    def report_row(self, i: int, text: str, file: str) -> TargetReport:
        """Row ``i``'s report row: status ``runtime``, the reason as note (what
        object_model.rows.motion_row makes of the motion)."""
        line, col, _, _, _, _, t0, t1, _, _ = self._row(i)
        return TargetReport(target=text[t0:t1], file=file, line=line, column=col,
                            status="runtime", tool=self.tools[i] or "",
                            wobj=self.wobjs[i] or "", note=self.reasons[i])

    def csv_lines(self, rows: list[int], text: str, file: str, writer: CsvRows) -> list[str]:
        """The report's CSV lines of rows ``rows``: those of :meth:`report_row`, written
        without making the rows: the fields after the column, the same for every row of
        one tool, work object and reason, written once per such triple, and the target
        expression quoted as it is (an Offs()/RelTool() expression of this table holds
        commas and no quote: fast.py ``_OFFSET``)."""
        s, tools, wobjs, reasons = self.numbers, self.tools, self.wobjs, self.reasons
        quoted = writer.quoted
        line = ('"%s",' + quoted[file].replace("%", "%%") + ",%d,%d," + quoted["runtime"]
                + ",%s")
        ends: dict = {}    # (tool, wobj, reason) -> the line's end
        out = []
        for i in rows:
            k = _WIDTH * i
            key = (tools[i], wobjs[i], reasons[i])
            end = ends.get(key)
            if end is None:
                end = ends[key] = (f"{quoted[tools[i] or '']},{quoted[wobjs[i] or '']},,,,,,,,"
                                   f"{writer.empty_joints},{quoted[reasons[i]]}\n")
            out.append(line % (text[s[k + 6]:s[k + 7]], s[k], s[k + 1], end))
        return out

    def subset(self, keep: np.ndarray) -> DisplacedMoves:
        """A table of the rows where ``keep`` (n,) bool is true, in order."""
        out = DisplacedMoves()
        rows = np.flatnonzero(keep).tolist()
        for name in ("instructions", "reasons", "tools", "wobjs", "routines"):
            column = getattr(self, name)
            setattr(out, name, [column[k] for k in rows])
        s = np.frombuffer(self.numbers, np.int64).reshape(-1, _WIDTH) if len(self) else \
            np.zeros((0, _WIDTH), np.int64)
        out.numbers = array("q", s[keep].ravel().tolist())
        return out


class RowsWithDisplaced(RowSource, MergedRows):
    """Report rows held as objects (``objects``, in line/column order) and the rows of a
    :class:`DisplacedMoves` table of ``text`` (``file``), merged in line/column order
    (an object first where both are at the same place); a displaced row is made on
    access."""

    def __init__(self, objects: list, table: DisplacedMoves, text: str, file: str):
        self.objects, self.table, self.text, self.file = objects, table, text, file
        mine = np.fromiter(((r.line << 32) | r.column for r in objects), np.int64,
                           len(objects))
        keys = np.concatenate([mine, table.keys()])
        order = np.argsort(keys, kind="stable")
        self.sorted_keys = keys[order]
        self.order = np.where(order < len(objects), order, len(objects) - 1 - order)

    def first_row(self, j: int) -> TargetReport:
        return self.objects[j]

    def second_row(self, j: int) -> TargetReport:
        return self.table.report_row(j, self.text, self.file)

    def keys(self) -> np.ndarray:
        return self.sorted_keys

    def csv_lines(self, rows: list[int], writer: CsvRows) -> list[str]:
        """The CSV lines of rows ``rows``: the table's written without making its rows."""
        order = self.order[rows]
        mine = order >= 0
        objects, line = self.objects, writer.line
        return merged(mine, [line(objects[j]) + "\n" for j in order[mine].tolist()],
                      self.table.csv_lines((-1 - order[~mine]).tolist(), self.text,
                                           self.file, writer))

    def statuses(self):
        """The status of each row, in order, without making the table's rows."""
        objects = self.objects
        for j in self.order.tolist():
            yield objects[j].status if j >= 0 else "runtime"

    def compensated_rows(self):
        """The compensated rows (objects all: a run-time motion is not one), any order."""
        return (r for r in self.objects if r.status in COMPENSATED)

    def renoted(self, change) -> RowsWithDisplaced:
        """:meth:`RowSource.renoted` with the table's rows left rows of the table (none is
        compensated): the objects changed, the order kept."""
        out = copy.copy(self)
        out.objects = [change(r) if r.status in COMPENSATED else r for r in self.objects]
        return out

    def fine_mask(self) -> np.ndarray:
        """Which rows are compensated or need none, in order, without making the table's
        rows (a run-time motion is neither)."""
        objects, order = self.objects, self.order
        fine = np.fromiter((r.fine for r in objects), bool, len(objects))
        out = np.zeros(len(order), bool)
        out[order >= 0] = fine[order[order >= 0]]
        return out

    def problem_rows(self) -> Sequence:
        """The rows neither compensated nor needing none, in order, made on access (a
        run-time motion is one of them)."""
        objects = self.objects
        fine = np.fromiter((r.fine for r in objects), bool, len(objects))
        order = self.order
        mine = order >= 0
        picked = np.flatnonzero(~mine)
        if len(objects):
            picked = np.flatnonzero(~mine | ~fine[np.where(mine, order, 0)])
        return PickedRows(self, picked)


def with_displaced(program: Program, table: DisplacedMoves,
                   keep: np.ndarray | None = None) -> Program:
    """``program`` with the rows of ``table`` not kept (``keep`` (n,) bool; None: none
    kept) made objects, merged in text order into its motions and run-time targets: what
    the object parse of the module gives."""
    rows = range(len(table)) if keep is None else np.flatnonzero(~keep).tolist()
    if not len(rows):
        return program
    made = [table.objects(i, program.text, program.file) for i in rows]
    motions = tuple(heapq.merge(program.motions, [u for u, _ in made], key=_use_key))
    runtime = tuple(heapq.merge(program.runtime, [r for _, r in made], key=_span_key))
    return dataclasses.replace(program, motions=motions, runtime=runtime)


def _use_key(u: MotionUse):
    return u.target_span or u.statement_span


def _span_key(r: RuntimeTarget):
    return r.span or (0, 0)
