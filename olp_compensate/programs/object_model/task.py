"""Compensate a whole robot task: the modules a controller runs together.

A RAPID task is many modules (``CalibData.mod`` with the tools and work objects, user
modules with the motions, system modules such as ``user.sys``); a target's tool and work
object are often declared in another module than the motion. :func:`compensate_task`
resolves every module's targets with the controller's scope rules across the task
(:func:`~olp_compensate.programs.semantics.resolve_task`,
:mod:`olp_compensate.programs.rapid.task_scope`), compensates each module as
:mod:`.program` does, and gives one report over the task.
"""

from __future__ import annotations

import dataclasses

from ...calibration.calibration import Calibration
from ...compensation.pose import Compensator
from ...compensation.report import NOT_MOVED, CompensationReport
from ...errors import DataError
from .. import loads
from ..semantics import resolve_task
from ..targets import Program
from .program import check_options, compensate_module

__all__ = ["compensate_task", "NOT_MOVED_IN_TASK"]

NOT_MOVED_IN_TASK = ("not moved to in any module of the task: tool and work object unknown, "
                     "left as written")
"""The note of a target that no module of a task of several modules moves to."""


def compensate_task(programs: list[Program], calibration: Calibration | Compensator, *,
                    emit: str = "pose", unused: str = "skip",
                    taught_on: Calibration | Compensator | None = None
                    ) -> tuple[list[str], CompensationReport]:
    """Compensate the modules of one task together.

    programs : the parsed modules of the task, all of one dialect, in the order the
        controller loads them (it decides which declaration of a PERS declared in several
        modules gives its value: the first with a value).
    emit, unused : as :func:`~olp_compensate.programs.object_model.program.compensate_program`;
        a target is 'unused' when no module of the task moves to it.
    taught_on : the calibration (or Compensator) of the robot the targets were taught on,
        of the same robot model: the pose to reach is where that robot's real tool went at
        its nominal joints for the target (robot-to-robot transfer); None: the targets
        mean what they say.
    Returns ``(texts, report)``: the new text of each module, in the order given (a module
    without a compensated target comes back as it was, byte for byte), and one
    :class:`CompensationReport` whose rows name each module by its ``Program.file``, module
    by module in the order given and in text order within a module; its ``file`` is the
    first module's. A tool or work object declared in no module given makes its targets
    'unresolved', the note naming it.
    """
    check_options(emit, unused)
    programs = list(programs)
    if not programs:
        raise DataError("programs: expected at least one module, got none")
    for k, program in enumerate(programs):
        if not isinstance(program, Program):
            raise DataError(f"programs[{k}]: expected a parsed Program, got "
                            f"{type(program).__name__}")
    dialects = sorted({p.dialect for p in programs})
    if len(dialects) != 1:
        raise DataError(f"programs: expected modules of one dialect, got {', '.join(dialects)}")
    comp = calibration if isinstance(calibration, Compensator) else Compensator(calibration)
    teacher = teacher_of(taught_on, comp)
    not_moved = NOT_MOVED if len(programs) == 1 else NOT_MOVED_IN_TASK
    resolutions = resolve_task(programs)
    if len(programs) > 1:
        programs = _calls_to_task_routines(programs)
    texts, rows, warnings, edits = [], [], [], 0
    for program, res in zip(programs, resolutions):
        done = compensate_module(program, res, comp, emit=emit, unused=unused,
                                 teacher=teacher, not_moved=not_moved)
        texts.append(done.text)
        rows += done.rows
        warnings += done.warnings
        edits += done.edits
    _external_axes_in_notes(rows, comp.robot.n_joints)
    report = CompensationReport(file=programs[0].file, rows=tuple(rows),
                                warnings=tuple(warnings), n_joints=comp.robot.n_joints,
                                emit=emit, edits=edits)
    return texts, report


def _external_axes_in_notes(rows: list, n_joints: int) -> None:
    """Joint-target rows with more values than the robot has axes (a Kawasaki AS step
    ``#[j1,...,j7]`` of a 6-axis arm with a seventh, external axis): the report's columns
    hold the robot's axes, the others go to the note (the program keeps them as written)."""
    for row in rows:
        if row.status == "joint_target" and len(row.joints) > n_joints:
            extra = ", ".join(f"{v:g}" for v in row.joints[n_joints:])
            row.joints = row.joints[:n_joints]
            row.note += (f"; values beyond axis {n_joints} ({extra}): external axes, kept "
                         f"as written")


def _calls_to_task_routines(programs: list[Program]) -> list[Program]:
    """The programs without their 'unknown_instruction' problems that are calls of a
    routine of another module of the task (the parser of one module knows only its own
    routines): a target handed to a routine is what it is within one module."""
    routines = [{r.name.lower() for r in p.routines} for p in programs]
    out = []
    for m, program in enumerate(programs):
        elsewhere = set().union(*(names for k, names in enumerate(routines) if k != m))
        kept = tuple(p for p in program.problems
                     if not (p.status == "unknown_instruction"
                             and _called(p.reason) in elsewhere))
        out.append(program if len(kept) == len(program.problems)
                   else dataclasses.replace(program, problems=kept))
    return out


def _called(reason: str) -> str:
    """The routine name an 'unknown_instruction' problem's reason starts with (lower)."""
    return reason.split(" ", 1)[0].lower()


def teacher_of(taught_on, comp: Compensator) -> Compensator | None:
    """The Compensator of the teaching robot, checked to be of the same robot model."""
    if taught_on is None:
        return None
    teacher = (taught_on if isinstance(taught_on, Compensator)     # read through the same
               else Compensator(taught_on, comp.controller))        # controller's model
    if teacher.robot.name != comp.robot.name:
        raise DataError(f"taught_on: a calibration of {teacher.robot.name}, but the program "
                        f"is compensated for {comp.robot.name}: transfer needs one robot "
                        f"model")
    return teacher


def compensate_program(program: Program | str | bytes, dialect: str | None,
                       calibration: Calibration | Compensator, *, emit: str = "pose",
                       file: str = "<string>", unused: str = "skip",
                       taught_on: Calibration | Compensator | None = None):
    """Compensate every target of a program on a calibration.

    program : a parsed :class:`Program`, or its text (str or latin-1 bytes) of ``dialect``
        ('rapid' or 'vplus'), named ``file`` in messages.
    emit : 'pose' rewrites Cartesian targets; 'joints' turns them into joint targets
        (RAPID jointtarget + MoveAbsJ, V+ precision points) where every use allows it.
    unused : 'skip' leaves targets never moved to as written; 'tool0' compensates them with
        tool0 and wobj0 (for data modules whose motions live elsewhere).
    taught_on : the calibration of the robot the targets were taught on (robot-to-robot
        transfer; see :func:`compensate_task`).
    Returns ``(text, report)``: the compensated program text and a
    :class:`CompensationReport`. Raises :class:`~olp_compensate.errors.ParseError` for a
    malformed program and DataError for bad arguments. The same as
    :func:`compensate_task` of one module.
    """
    check_options(emit, unused)
    if not isinstance(program, Program):
        if dialect is None:
            raise DataError("dialect: needed when the program is given as text")
        program = loads(program, dialect, file)
    (text,), report = compensate_task([program], calibration, emit=emit, unused=unused,
                                      taught_on=taught_on)
    return text, report
