"""Compensate RAPID modules and tasks with their plain targets held as columns (big modules).

A generated module is mostly module-level ``CONST robtarget p := [...];`` each moved to
by one plain ``MoveL p, v, z, tool\\WObj:=w;``. Parsed in columns
(:func:`~olp_compensate.programs.rapid.reader.parse_rapid_columns`), those targets are
resolved, solved, reported and written here as arrays, a chunk of :data:`CHUNK` targets at
a time, without an object per target; everything else of the module goes through
:func:`~.program.module_rows_and_edits` as always. The text and report are those
:func:`~.task.compensate_task` of the module gives (tests compare them byte for byte);
only a target solved in another batch (past :data:`CHUNK` targets, or retried) can differ
in the last digits of its joints, as numpy's vector and scalar loops round differently.

The column path is taken target by target where a target's meaning is plain: declared
once (at module level, or ``VAR``/``CONST`` in a routine: a row with its routine), named by
no other statement than its module's table motions and motions that displace it at run
time (``MoveL Offs(p, ...)``, ``RelTool``: their own ``runtime`` report rows; in a module
alone, rows of the column parse, :mod:`.displaced`, made objects only where their target
leaves the table), with no
routine parameter, copy, assignment, other run-time expression or routine call naming it,
moved to by name without an index, from its own routine (a routine's target), and with
one tool/work-object pair (tools and work objects may be declared in any module). A
target that is not plain goes to the object path with its motions
(:func:`.column_plans.plain_rows`),
and so does a table motion to a target outside the table; the module's other targets stay
in columns. In a task whose modules declare or move to each other's table targets, such a
module is compensated as objects whole.

With ``jobs`` > 1 a big module's chunks (and the retries' batches) are shared with a forked
process (:mod:`.forked`); the batches are the same, so the result is one process's, byte
for byte.
"""

from __future__ import annotations

import functools
import operator
from array import array
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from ...compensation.failures import FailureReport
from ...compensation.ik.solver import SolverState
from ...compensation.pose import Compensator
from ...compensation.report import (LINE_COLUMN, NOT_MOVED, ChainedRows, CompensationReport,
                                    ReportRows, TargetReport, config_text, config_texts,
                                    row_source)
from ...compensation.row_columns import RowColumns
from ...kinematics.conventions import (MM, invert_pose, matrix_from_quat_wxyz,
                                       pose_from_rotation_translation, quat_wxyz_from_matrix)
from ..emit import EditColumns, EditsInTurn, SplicedText, target_edits
from ..emit_batch import edits_for_spans
from ..object_model.program import module_rows_and_edits, solve_entries
from ..object_model.rows import failure_note, solved_note, written_row
from .column_plans import Plan, modules_sharing_names, plain_rows, task_plans
from ..semantics import resolve_task
from ..target_values import bad_values, value_problem
from ..targets import Program
from .columns import ModuleColumns, TargetTable, split, with_objects
from .displaced import DisplacedMoves, RowsWithDisplaced, with_displaced
from .reader import parse_rapid_columns

__all__ = ["compensate_rapid_module", "compensate_rapid_task", "CHUNK", "PARALLEL_MIN"]

CHUNK = 8192
"""Targets resolved and solved together: bounds the memory of the arrays per target."""
PARALLEL_MIN = 2 * CHUNK
"""Table targets from which ``jobs`` > 1 splits a module's chunks between two processes
(two chunks at least; the whole olp-fix took 0.89x the time of ``-j 1`` at 17,000
targets, 0.82x at 100,000, on two cores)."""
RETRY_CHUNK = 8192
"""Targets retried together (the solver's multi-start takes them 2,048 at a time, the rule's
search in spans): a batch's few slow targets iterate with the others' (the benchmark's
100,000 failing targets: 0.89x the retry's CPU of 2,048 at a time; its realistic module 0.78x)."""
_START = operator.itemgetter(0)


def compensate_rapid_module(text: str, file: str, comp: Compensator, *, unused: str = "skip",
                            teacher: Compensator | None = None, chunk: int = CHUNK,
                            jobs: int = 1) -> tuple[str, CompensationReport]:
    """Compensate one RAPID module (``text`` decoded, named ``file``) with ``emit='pose'``:
    ``(new text, report)``, as :func:`~.task.compensate_task` of the parsed module gives;
    in columns where the module allows it (see the module docstring; ``jobs``: as
    :func:`compensate_rapid_task`)."""
    (new,), report = compensate_rapid_task([text], [file], comp, unused=unused,
                                           teacher=teacher, chunk=chunk, jobs=jobs)
    return new.spliced(), report


def compensate_rapid_task(texts: list[str], files: list[str], comp: Compensator, *,
                          unused: str = "skip", teacher: Compensator | None = None,
                          chunk: int = CHUNK, jobs: int = 1
                          ) -> tuple[list[SplicedText], CompensationReport]:
    """Compensate the modules of one RAPID task (decoded ``texts`` named ``files``, in the
    order the controller loads them) with ``emit='pose'``: ``(new modules, report)``, as
    :func:`~.task.compensate_task` gives; each module's plain targets in columns where
    their meaning is plain within the whole task (no other module declares or names
    them), the rest as objects. The new modules are spliced when read (a big one is
    written without its new text ever held whole). ``jobs`` > 1: a module of
    :data:`PARALLEL_MIN` table targets or more has half its chunks compensated in a
    forked process (where the platform forks), and half its retry batches where there
    are two or more, with the same result."""
    from ..object_model.task import NOT_MOVED_IN_TASK, _calls_to_task_routines, compensate_task

    # one module alone: its plain Offs()/RelTool() motions are rows (displaced.py)
    tables = [DisplacedMoves() if len(texts) == 1 else None for _ in texts]
    parsed = [parse_rapid_columns(text, file, table)
              for text, file, table in zip(texts, files, tables)]
    parsed = _plain_parts(parsed, tables)
    plans = task_plans([p for p, _ in parsed], [c for _, c in parsed])
    for m, plan in enumerate(plans):
        if plan is None and tables[m] is not None:   # objects, all of them
            parsed[m] = (with_displaced(parsed[m][0], tables[m]), parsed[m][1])
            tables[m] = None
    programs = [p if plan is not None else with_objects(p, c)
                for (p, c), plan in zip(parsed, plans)]
    if all(plan is None for plan in plans):
        new_texts, report = compensate_task(programs, comp, unused=unused, taught_on=teacher)
        return [SplicedText(t) for t in new_texts], report
    resolutions = resolve_task(programs)
    if len(programs) > 1:
        programs = _calls_to_task_routines(programs)
    not_moved = NOT_MOVED if len(programs) == 1 else NOT_MOVED_IN_TASK
    new_texts, parts, warnings, count = [], [], [], 0
    for m, (program, res) in enumerate(zip(programs, resolutions)):
        rows, module_warnings, edits = module_rows_and_edits(
            program, res, comp, emit="pose", unused=unused, teacher=teacher,
            not_moved=not_moved)
        warnings += module_warnings
        if plans[m] is None:
            new_texts.append(SplicedText(program.text, [edits]))
            parts.append(tuple(rows))
            count += len(edits)
            continue
        table = _TablePart(program, parsed[m][1].targets, plans[m], comp, unused, teacher,
                           not_moved)
        parsed[m] = None   # the motions' table is read: only the targets' is needed now
        table.compensate_all(chunk, jobs)
        count += len(edits) + sum(map(len, table.edits))
        others = sorted(rows + table.others, key=LINE_COLUMN)
        if tables[m] is not None and len(tables[m]):
            others = RowsWithDisplaced(others, tables[m], program.text, program.file)
        parts.append(table.rows(others))
        new_texts.append(SplicedText(program.text, [edits, *table.edits]))
    report = CompensationReport(
        file=files[0], rows=parts[0] if len(parts) == 1 else ChainedRows(parts),
        warnings=tuple(warnings), n_joints=comp.robot.n_joints, emit="pose", edits=count)
    return new_texts, report


def _plain_parts(parsed: list[tuple[Program, ModuleColumns]],
                 tables: list[DisplacedMoves | None] | None = None
                 ) -> list[tuple[Program, ModuleColumns]]:
    """Each module's column parse with the table rows whose meaning is not plain within the
    module (:func:`.column_plans.plain_rows`) made into objects: a run-time use, copy or routine
    argument of one target sends that target and its motions to the object path, not the
    whole module. Modules of a task whose tables share names are left whole (their plan
    is decided for the module, :func:`.column_plans.task_plans`). ``tables``: each
    module's Offs()/RelTool() motions held as rows (or None), narrowed in place to those
    that displace a target kept in the table; the others made objects of the program."""
    tables = tables or [None] * len(parsed)
    if len(parsed) > 1:
        shared = modules_sharing_names([p for p, _ in parsed], [c for _, c in parsed])
    else:
        shared = set()
    out = []
    for m, (program, columns) in enumerate(parsed):
        table = tables[m]
        bases = table.base_names(program.text) if table is not None else []
        if m in shared or not len(columns.targets):
            if table is not None:
                program, tables[m] = with_displaced(program, table), None
            out.append((program, columns))
            continue
        keep_targets, keep_moves, keep = plain_rows(program, columns, bases)
        program, columns = split(program, columns, keep_targets, keep_moves)
        if table is not None and not len(table):
            tables[m] = None
        elif table is not None:
            program = with_displaced(program, table, keep)
            tables[m] = table.subset(keep) if not keep.all() else table
        out.append((program, columns))
    return out


@dataclass(eq=False)
class _Chunk:
    """What :func:`~.program.solve_entries` reads of a resolution, for some table rows."""

    written: np.ndarray
    base_T_flange: np.ndarray
    wobj_T_target: np.ndarray
    entry_pairs: np.ndarray
    pairs: tuple


class _TablePart:
    """The table targets compensated chunk by chunk: their rows as columns (compensated)
    or objects (the others), and their edits (``edits``: :class:`EditColumns` in offset
    order, one per chunk, then one run for all chunks and one per retry batch; about
    half the memory of Edit records). With ``jobs`` > 1, half the chunks and half the
    retry batches are solved in a forked process (:meth:`_shared`).

    With a plain :class:`Compensator` the solver's retries of targets it did not reach at
    once (and the account of how close the arm comes) are left out of the chunks: the
    targets are gathered and solved again together by :meth:`retry_failed`, whose cost
    is per Newton step whatever the number of targets (on a 100,000-target module with
    1.2 % out of reach, 1.0 s in chunks of 8,192)."""

    def __init__(self, program: Program, table: TargetTable, plan: Plan,
                 comp: Compensator, unused: str, teacher: Compensator | None,
                 not_moved: str = NOT_MOVED):
        self.program, self.table, self.plan = program, table, plan
        self.comp, self.unused, self.teacher = comp, unused, teacher
        self.not_moved = not_moved
        self.spans = table.span_columns()
        self.parts: list[RowColumns] = []
        self.others: list[TargetReport] = []
        self.edits: list[EditColumns] = []
        self.defer = type(comp) is Compensator   # a RegionalCompensator retries at once
        self.failed: list[tuple] = []   # (rows, values, written, flange, poses, pair, state)
        self.pair_names = [(p.tool_name, p.wobj_name) for p in plan.pairs]
        self._notes = [p.notes for p in plan.pairs]
        self._words: dict[str, str] = {}   # one string per distinct status and note

    def target(self, k: int):
        return self.table.target(k, self.program.text, self.program.file)

    def notes(self, k: int, pair: int) -> tuple[str, ...]:
        """The resolution notes of table row ``k`` (as semantics.resolve gives them)."""
        return self._row_notes(self.plan.uses[k] == 0, pair)

    def _row_notes(self, unused: bool, pair: int) -> tuple[str, ...]:
        """The resolution notes of a row ``unused`` or not, of tool/work-object ``pair``."""
        return (("unused",) if unused else ()) + self._notes[pair]

    def compensate_all(self, chunk: int, jobs: int = 1) -> None:
        """Every row: :meth:`compensate_chunks`, then :meth:`retry_failed`."""
        self.compensate_chunks(chunk, jobs)
        self.retry_failed(jobs=jobs)

    def compensate_chunks(self, chunk: int, jobs: int = 1) -> None:
        """Every row, ``chunk`` at a time, the targets not reached gathered for
        :meth:`retry_failed`. With ``jobs`` > 1 and :data:`PARALLEL_MIN` rows or more,
        the second half of the chunks is compensated in a forked process at the same
        time as the first half here (see :meth:`_shared`), so that everything after
        (retries, rows, edits) is what one process gives."""
        n = len(self.table)
        bounds = [(a, min(a + chunk, n)) for a in range(0, n, chunk)]
        self._shared(bounds, self.compensate, jobs if n >= PARALLEL_MIN else 1)
        # the chunks' edits follow one another in the text: one run for the merge when
        # the module is written (a million targets: 130 runs merged in 0.68 s, 8 in 0.54)
        self.edits = [EditsInTurn(self.edits)] if self.edits else []

    def _shared(self, bounds: list[tuple[int, int]], run: Callable[[int, int], None],
                jobs: int) -> None:
        """``run(a, b)`` for each of ``bounds`` in order. With ``jobs`` > 1 and two bounds
        or more (where the platform forks), the second half runs in a forked process at
        the same time as the first half here; its rows, edits and gathered failures are
        appended after this process's, in order: the lists are those of one process.
        Where no process or temporary file can be had, everything runs here."""
        child = None
        if jobs > 1 and len(bounds) > 1:
            from ...compensation.forked import ForkedItems, can_fork

            mine, theirs = bounds[:len(bounds) // 2], bounds[len(bounds) // 2:]
            try:
                child = ForkedItems(self._results_of, run, theirs) if can_fork() else None
            except OSError:   # no process (a limit) or no temporary file (a full disk)
                child = None
        if child is None:
            for a, b in bounds:
                run(a, b)
            return
        with child:
            for a, b in mine:
                run(a, b)
            for parts, others, edits, failed in child.items():
                self.parts += parts
                self.others += others
                self.edits += edits
                self.failed += failed

    def _results_of(self, run: Callable[[int, int], None],
                    bounds: list[tuple[int, int]]) -> Iterator[tuple]:
        """(parts, others, edits, failed) of ``run(a, b)`` for each of ``bounds`` in turn,
        without what the lists held before, none kept (in a forked process: the parent
        has the lists as they were)."""
        for a, b in bounds:
            self.parts, self.others, self.edits, self.failed = [], [], [], []
            run(a, b)
            yield self.parts, self.others, self.edits, self.failed

    def compensate(self, a: int, b: int) -> None:
        """Rows ``a:b`` of the table: their report rows and edits kept, the targets not
        reached gathered for :meth:`retry_failed`."""
        plan, pairs = self.plan, self.plan.pairs
        values = self.table.values(self.program.text, a, b)
        written = values[:, :11].copy()
        pair = plan.pair[a:b]
        bad = bad_values(written)
        poses = np.full((b - a, 4, 4), np.nan)
        good = np.flatnonzero(~bad)
        poses[good] = pose_from_rotation_translation(
            matrix_from_quat_wxyz(written[good, 3:7]), written[good, :3] * MM)
        flange = np.full_like(poses, np.nan)
        for p, frames in enumerate(pairs):
            ks = good[pair[good] == p]
            if frames.problem or not len(ks):
                continue
            if frames.stationary_tool:
                flange[ks] = (frames.flange_T_tool @ invert_pose(poses[ks])
                              @ invert_pose(frames.base_T_wobj))
            else:
                flange[ks] = frames.base_T_wobj @ poses[ks] @ invert_pose(frames.flange_T_tool)
        job = self._rows_not_solved(a, bad, np.isfinite(flange[:, 0, 0]))
        if not job:
            return
        chunk = _Chunk(written=written, base_T_flange=flange, wobj_T_target=poses,
                       entry_pairs=pair, pairs=pairs)
        solved = solve_entries(self.comp, chunk, job, False, self.teacher,
                               retries=not self.defer)
        job = np.asarray(job)
        if self.defer and not solved.ok.all():
            j = job[~solved.ok]
            state = solved.state.rows(~solved.ok) if solved.state is not None else None
            self.failed.append((j + a, values[j], written[j], flange[j], poses[j], pair[j],
                                state))
        self._rows_solved(job + a, solved, values[job], failures=not self.defer)

    def retry_failed(self, chunk: int | None = None, jobs: int = 1) -> None:
        """Solve the gathered targets again, all stages, ``chunk`` at a time (default
        :data:`RETRY_CHUNK`); with ``jobs`` > 1, in batches of at most half of them (2,048
        at least), the second half of the batches in a forked process (each target's retry
        is its own: the same digits whatever the batches)."""
        if not self.failed:
            return
        states = [f[-1] for f in self.failed]
        gathered = tuple(np.concatenate(c) for c in zip(*(f[:-1] for f in self.failed)))
        # the solver's state of each, where every chunk kept one (the retries go on)
        gathered += (None if any(s is None for s in states) else SolverState.concatenate(states),)
        self.failed = []
        n = len(gathered[0])
        chunk = RETRY_CHUNK if chunk is None else chunk
        chunk = min(chunk, max(2048, -(-n // 2))) if jobs > 1 else chunk
        self._shared([(a, min(a + chunk, n)) for a in range(0, n, chunk)],
                     functools.partial(self._retry_batch, gathered), jobs)

    def _retry_batch(self, gathered: tuple, a: int, b: int) -> None:
        """Rows ``a:b`` of the ``gathered`` targets (rows, values, written, flange, poses,
        pair, solver state or None) solved again from where the first pass stopped, their
        rows and edits kept."""
        rows, values, written, flange, poses, pair = (c[a:b] for c in gathered[:-1])
        state = gathered[-1].rows(slice(a, b)) if gathered[-1] is not None else None
        batch = _Chunk(written=written, base_T_flange=flange, wobj_T_target=poses,
                       entry_pairs=pair, pairs=self.plan.pairs)
        solved = solve_entries(self.comp, batch, list(range(b - a)), False, self.teacher,
                               resume=state)
        self._rows_solved(rows, solved, values, failures=True)

    def _rows_not_solved(self, a: int, bad: np.ndarray, known: np.ndarray) -> list[int]:
        """Rows for the chunk's targets decided without solving; returns the others (the
        job, chunk indices)."""
        unused = (self.plan.uses[a:a + len(bad)] == 0) & (self.unused == "skip")
        job = ~bad & ~unused & known
        pairs = self.plan.pairs
        for i in np.flatnonzero(~job).tolist():
            k, p = a + i, int(self.plan.pair[a + i])
            t = self.target(k)
            if bad[i]:
                row = written_row(t, pairs[p], "bad_target", value_problem(t))
            elif unused[i]:
                row = written_row(t, pairs[p], "unused", self.not_moved)
            else:
                row = written_row(t, pairs[p], "unresolved", "; ".join(self.notes(k, p)))
            self.others.append(row)
        return np.flatnonzero(job).tolist()

    def _rows_solved(self, rows: np.ndarray, solved, values: np.ndarray,
                     failures: bool) -> None:
        """Rows and edits of the solved table ``rows`` (their numbers as written
        ``values``); ``failures``: the rows not compensated too (else they are left to
        :meth:`retry_failed`)."""
        table = self.table
        pair = self.plan.pair[rows]
        # the note of each row, made once per (unused, pair, real-tool note)
        notes = list(map(functools.lru_cache(None)(self._solved_note),
                         (self.plan.uses[rows] == 0).tolist(), pair.tolist(), solved.tool_note))
        ok = solved.ok
        if failures and not ok.all():
            self._rows_failed(rows, np.flatnonzero(~ok), pair, solved, notes)
        keep = np.flatnonzero(ok)
        if not len(keep):
            return
        mine = rows[keep]
        config_after = config_texts(solved.conf[keep])
        words = self._words
        self.parts.append(RowColumns(
            names=[table.names[k] for k in mine.tolist()], file=self.program.file,
            line=table.line[mine], column=table.column[mine],
            status=[words.setdefault(solved.reason[i], solved.reason[i])
                    for i in keep.tolist()], pair=pair[keep],
            pair_names=self.pair_names, correction_mm=solved.shift_mm[keep],
            correction_deg=solved.turn_deg[keep], joint_change=solved.change_deg[keep],
            config_before=[solved.config_before[i] for i in keep.tolist()],
            config_after=config_after, joints=solved.joints_deg[keep],
            note=[words.setdefault(notes[i], notes[i]) for i in keep.tolist()],
            compensated=np.ones(len(keep), bool)))
        edits = self._edits(mine, keep, solved, values[keep])
        self.edits.append(EditColumns(array("q", [e[0] for e in edits]),
                                      array("q", [e[1] for e in edits]), [e[2] for e in edits]))

    def _rows_failed(self, rows: np.ndarray, bad: np.ndarray, pair: np.ndarray, solved,
                     notes: list) -> None:
        """The rows of the solved table ``rows[bad]`` not compensated, as columns (what
        :func:`~.object_model.rows.failure_row` makes of each, row by row): joints
        converted in one batch, configurations written once per distinct one, notes
        joined once per distinct (failure note, row note)."""
        table, words, robot, job = self.table, self._words, self.comp.robot, bad.tolist()
        none = FailureReport("", np.full(robot.n_joints, np.nan), None)   # not explained
        failures = [solved.failures[i] or none for i in job]
        q = robot.to_degrees_or_mm(np.array([f.joints for f in failures], float)
                                   .reshape(len(job), robot.n_joints))
        q[~np.isfinite(q).all(axis=1)] = np.nan
        joined: dict = {}
        mine = rows[bad]
        self.parts.append(RowColumns(
            names=[table.names[k] for k in mine.tolist()], file=self.program.file,
            line=table.line[mine], column=table.column[mine],
            status=[words.setdefault(s, s) for s in (
                f.status or solved.reason[i] for f, i in zip(failures, job))],
            pair=pair[bad], pair_names=self.pair_names,
            correction_mm=np.full((len(job), 3), np.nan), correction_deg=np.full(len(job), np.nan),
            joint_change=np.full(len(job), np.nan),
            config_before=[solved.config_before[i] for i in job],
            config_after=["" if f.config is None else config_text(f.config) for f in failures],
            joints=q, compensated=np.zeros(len(job), bool),
            note=[joined.get(key) or joined.setdefault(key, failure_note(*key)) for key in zip(
                [f.note for f in failures], [notes[i] for i in job])]))

    def _solved_note(self, unused: bool, pair: int, tool_note: str) -> str:
        """The note of a solved row (:meth:`notes` of a row moved to ``unused`` or not)."""
        notes = self._row_notes(unused, pair)
        return solved_note(notes, tool_note) if notes else tool_note

    def _edits(self, mine: np.ndarray, keep: np.ndarray, solved, values: np.ndarray) -> list:
        """The edits writing the compensated table targets ``mine`` (job rows ``keep``,
        numbers as written ``values``), sorted."""
        new = solved.new_targets[keep]
        spans = self.spans[mine]
        edits = edits_for_spans(self.program.text, values, new[:, :3, 3] / MM,
                                quat_wxyz_from_matrix(new[:, :3, :3]), spans[:, 4],
                                spans[:, 5], _Targets(self, mine))
        conf = solved.conf[keep]
        changed = np.flatnonzero(np.any(conf != solved.written[keep], axis=1)
                                 & solved.has_conf[keep]).tolist()
        if changed:
            for j in changed:
                edits += target_edits(self.target(int(mine[j])), config=conf[j])
            edits.sort(key=_START)
        return edits

    def rows(self, others) -> ReportRows:
        """All rows of the module in text order: the table's compensated rows and
        ``others`` (a :class:`RowSource` or a list of rows, in text order)."""
        if self.parts:
            columns = RowColumns.concatenate(self.parts)
            self.parts = []
        else:
            columns = RowColumns.concatenate([_empty_columns(self.program.file,
                                                             self.comp.robot.n_joints)])
        others = row_source(others)
        key_columns = (columns.line << 32) | columns.column
        order = np.concatenate([np.arange(len(columns)), -1 - np.arange(len(others))])
        return ReportRows(columns, others, order[np.argsort(
            np.concatenate([key_columns, others.keys()]), kind="stable")])


class _Targets:
    """Table rows ``rows`` as a sequence of CartesianTarget made on access."""

    def __init__(self, part: _TablePart, rows: np.ndarray):
        self.part, self.rows = part, rows

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, i: int):
        return self.part.target(int(self.rows[i]))


def _empty_columns(file: str, n_joints: int) -> RowColumns:
    return RowColumns(names=[], file=file, line=np.zeros(0, np.int64),
                      column=np.zeros(0, np.int64), status=[], pair=np.zeros(0, np.intp),
                      pair_names=[], correction_mm=np.zeros((0, 3)),
                      correction_deg=np.zeros(0), joint_change=np.zeros(0),
                      config_before=[], config_after=[], joints=np.zeros((0, n_joints)),
                      note=[], compensated=np.zeros(0, bool))
