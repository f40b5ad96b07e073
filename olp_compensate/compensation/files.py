"""Compensation of program files as a controller holds them: one module, a task of
several, a KRL ``.src`` with its ``.dat``, a VAL3 data file, a URScript, a FANUC ``.ls``.

:func:`compensate_files` reads the files of one :class:`ProgramFiles` together (latin-1,
every byte kept) and hands them to their language
(:func:`~olp_compensate.programs.languages.language_named`), which compensates them with
the shared machinery (:func:`pose_program_result` for six-number targets;
:mod:`olp_compensate.programs.object_model` for RAPID and V+/AS) and returns the new bytes of
each file and one report whose rows name the files as the user knows them.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..calibration.calibration import Calibration
from ..errors import DataError, ParseError
from ..programs.backup_files import BackupFiles, backup_files
from ..programs.languages import language_named, language_of
from .pose import Compensator
from .report import CompensationReport

if TYPE_CHECKING:
    from ..programs.emit import SplicedText

ENCODING = "latin-1"


@dataclass(frozen=True)
class ProgramFiles:
    """Files read and compensated together.

    dialect : a language's name (:func:`~olp_compensate.programs.languages.names`).
    paths : the files, in the order their outputs are returned (KRL: ``.src`` then ``.dat``;
        a RAPID task: its modules, system modules first, the order PERS values are taken in).
    names : how the report names each file (as given, or relative to the folder given).
    """

    dialect: str
    paths: tuple[Path, ...]
    names: tuple[str, ...]


@dataclass(frozen=True)
class FilesResult:
    """The new content of each file (same order as ``ProgramFiles.paths``) and the report.

    new : each file's new bytes, its new text (``str``: a text given to the service may
        hold characters no latin-1 file can), or its text with the edits still to splice
        (:class:`~olp_compensate.programs.emit.SplicedText`, a RAPID module: a big one is
        written by :meth:`pieces` without its new text ever held whole).
    """

    new: tuple[bytes | str | SplicedText, ...]
    report: CompensationReport

    @functools.cached_property
    def data(self) -> tuple[bytes, ...]:
        """The new bytes of each file (spliced on first access, then kept)."""
        return tuple(n if isinstance(n, bytes) else n.encode(ENCODING) for n in self.new)

    def pieces(self, i: int) -> bytes | Iterator[bytes]:
        """The new bytes of file ``i``, whole or in consecutive pieces (to write)."""
        new = self.new[i]
        if isinstance(new, (bytes, str)):
            return new if isinstance(new, bytes) else new.encode(ENCODING)
        return new.blocks(ENCODING)

    def text(self, i: int) -> str:
        """The new text of file ``i`` (bytes decoded as latin-1)."""
        new = self.new[i]
        if isinstance(new, (bytes, str)):
            return new if isinstance(new, str) else new.decode(ENCODING)
        return new.spliced()


@dataclass(frozen=True)
class CompensationRun:
    """What one run asks of every unit: the compensator and the options.

    comp : the calibrated arm (and controller model, load) targets are solved on.
    emit : ``"pose"`` or ``"joints"`` (targets written as joints, where the language can).
    unused : ``"skip"`` or ``"all"`` (targets no motion uses).
    taught_on : the calibration (or compensator) of the robot the targets were taught on,
        or None.
    frames : the controller files given with ``--config`` (paths or a
        :class:`~olp_compensate.programs.backup_files.BackupFiles`), or None.
    jobs : processes a big program's targets may be shared among.
    """

    comp: Compensator
    emit: str = "pose"
    unused: str = "skip"
    taught_on: Calibration | Compensator | None = None
    frames: object = None
    jobs: int = 1

    @property
    def backup(self) -> BackupFiles:
        """The ``--config`` files with their stated conventions."""
        return backup_files(self.frames)


def dialect_of(path: str | Path) -> str:
    """The language name of a file from its extension (:func:`.languages.language_of`)."""
    return language_of(path).name


def read_text(path: Path) -> str:
    """A file's text, latin-1 (every byte kept); :class:`ParseError` naming it if unreadable."""
    try:
        return Path(path).read_bytes().decode(ENCODING)
    except OSError as exc:
        raise ParseError(f"cannot read the file: {exc.strerror or exc}", str(path)) from None


def compensate_files(files: ProgramFiles, calibration: Calibration | Compensator, *,
                     emit: str = "pose", unused: str = "skip",
                     taught_on: Calibration | Compensator | None = None,
                     frames_path: str | Path | None = None, jobs: int = 1) -> FilesResult:
    """Compensate the files of ``files`` with their language's machinery.

    emit, unused : as :func:`~olp_compensate.programs.object_model.task.compensate_program`
        (``emit="joints"`` only where the language can write joints).
    taught_on : the calibration of the robot the targets were taught on: the pose to reach
        is where that robot's real tool went (robot-to-robot transfer).
    frames_path : the controller's files (a path, several, or a
        :class:`~olp_compensate.programs.backup_files.BackupFiles` with stated conventions):
        KRL ``$config.dat`` with ``TOOL_DATA``, ``BASE_DATA`` and its points; FANUC
        ``SYSFRAME.VA`` (or ``SYSTEM.VA``) with ``$MNUFRAME`` and ``$MNUTOOL``,
        ``SYSMAST.VA`` with the turn axes, ``POSREG.VA`` with the position registers.
    jobs : processes a big program's targets may be shared among; the result is the same.
    """
    comp = calibration if isinstance(calibration, Compensator) else Compensator(calibration)
    language = language_named(files.dialect)
    if emit != "pose" and not language.emits_joints:
        raise DataError(f"{files.names[0]}: emit={emit!r}: joint targets are not written for "
                        f"{language.title} programs")
    texts = [read_text(p) for p in files.paths]
    run = CompensationRun(comp, emit, unused, taught_on, frames_path, jobs)
    return language.compensate(files, texts, run)


def pose_program_result(files: ProgramFiles, program, rules, run: CompensationRun) -> FilesResult:
    """The result of a six-number-target program (a
    :class:`~olp_compensate.programs.pose_dialects.PoseProgram` read with its language's
    :class:`~.dialect_rules.DialectRules`): solved, edited, one report."""
    from .dialect_program import compensate_pose_program

    new, report = compensate_pose_program(program, rules, run.comp, taught_on=run.taught_on)
    return FilesResult(new=tuple(new[name] for name in files.names), report=report)
