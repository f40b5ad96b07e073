"""Compensation of program files as a controller holds them: one module, a KRL ``.src``
with its ``.dat``, a VAL3 data file, a URScript, a FANUC ``.ls``.

:func:`compensate_files` reads the files of one :class:`ProgramFiles` together (latin-1,
every byte kept), compensates them with the dialect's machinery (RAPID and V+/AS:
:mod:`.program`; KRL, FANUC TP, VAL3, URScript: :mod:`.dialect_program`) and returns the
new bytes of each file and one report whose rows name the files as the user knows them.
"""

from __future__ import annotations

import functools
import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..calibration.calibration import Calibration
from ..errors import DataError, ModelError, ParseError
from ..programs.backup_files import BackupFiles, backup_files
from .pose import Compensator
from .report import CompensationReport

if TYPE_CHECKING:
    from ..programs.emit import SplicedText

ENCODING = "latin-1"
POSE_DIALECTS = ("krl", "fanuc", "val3", "urscript")
TEXT_DIALECTS = ("rapid", "vplus")
DIALECTS = TEXT_DIALECTS + POSE_DIALECTS
EXTENSIONS = {".mod": "rapid", ".modx": "rapid", ".prg": "rapid", ".sys": "rapid",
              ".pg": "vplus", ".v2": "vplus", ".lc": "vplus", ".loc": "vplus", ".as": "vplus",
              ".src": "krl", ".dat": "krl", ".ls": "fanuc", ".dtx": "val3",
              ".script": "urscript", ".urscript": "urscript"}
"""File extension (any case) -> dialect."""


@dataclass(frozen=True)
class ProgramFiles:
    """Files read and compensated together.

    dialect : one of :data:`DIALECTS`.
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

    new : each file's new bytes, or its text with the edits still to splice
        (:class:`~olp_compensate.programs.emit.SplicedText`, a RAPID module: a big one is
        written by :meth:`pieces` without its new text ever held whole).
    """

    new: tuple[bytes | SplicedText, ...]
    report: CompensationReport

    @functools.cached_property
    def data(self) -> tuple[bytes, ...]:
        """The new bytes of each file (spliced on first access, then kept)."""
        return tuple(n if isinstance(n, bytes) else n.encode(ENCODING) for n in self.new)

    def pieces(self, i: int) -> bytes | Iterator[bytes]:
        """The new bytes of file ``i``, whole or in consecutive pieces (to write)."""
        new = self.new[i]
        return new if isinstance(new, bytes) else new.blocks(ENCODING)


def dialect_of(path: str | Path) -> str:
    """The dialect of a file from its extension (:data:`EXTENSIONS`)."""
    ext = Path(path).suffix.lower()
    if ext not in EXTENSIONS:
        raise ParseError(f"unknown program extension {ext or '(none)'!r}; expected one of "
                         f"{', '.join(sorted(EXTENSIONS))} or an explicit dialect", str(path))
    return EXTENSIONS[ext]


def _read(path: Path) -> str:
    try:
        return path.read_bytes().decode(ENCODING)
    except OSError as exc:
        raise ParseError(f"cannot read the file: {exc.strerror or exc}", str(path)) from None


def compensate_files(files: ProgramFiles, calibration: Calibration | Compensator, *,
                     emit: str = "pose", unused: str = "skip",
                     taught_on: Calibration | Compensator | None = None,
                     frames_path: str | Path | None = None, jobs: int = 1) -> FilesResult:
    """Compensate the files of ``files`` (see the module docstring).

    emit, unused : as :func:`.program.compensate_program` (RAPID and V+ only).
    taught_on : the calibration of the robot the targets were taught on: the pose to reach
        is where that robot's real tool went (robot-to-robot transfer).
    frames_path : the controller's files (a path, several, or a
        :class:`~olp_compensate.programs.backup_files.BackupFiles` with stated conventions):
        KRL ``$config.dat`` with ``TOOL_DATA``, ``BASE_DATA`` and its points; FANUC
        ``SYSFRAME.VA`` (or ``SYSTEM.VA``) with ``$MNUFRAME`` and ``$MNUTOOL``,
        ``SYSMAST.VA`` with the turn axes, ``POSREG.VA`` with the position registers.
    jobs : processes a big RAPID module's targets may be shared among (at most two, see
        :func:`~.module_columns.compensate_rapid_task`); the result is the same.
    """
    comp = calibration if isinstance(calibration, Compensator) else Compensator(calibration)
    texts = [_read(p) for p in files.paths]
    if files.dialect == "rapid" and len(texts) > 1:
        from .unreadable import compensate_readable

        return compensate_readable(
            texts, files.names, lambda keep: _compensate_texts(
                ProgramFiles(files.dialect, tuple(files.paths[k] for k in keep),
                             tuple(files.names[k] for k in keep)),
                [texts[k] for k in keep], comp, emit, unused, taught_on, frames_path, jobs),
            ENCODING)
    return _compensate_texts(files, texts, comp, emit, unused, taught_on, frames_path, jobs)


def _compensate_texts(files: ProgramFiles, texts: list[str], comp: Compensator, emit: str,
                      unused: str, taught_on, frames_path, jobs: int) -> FilesResult:
    """:func:`compensate_files` of the decoded ``texts`` of ``files``."""
    if files.dialect == "rapid" and emit == "pose":
        from .module_columns import compensate_rapid_task
        from .program import check_options
        from .task import _teacher

        check_options(emit, unused)
        new, report = compensate_rapid_task(texts, list(files.names), comp, unused=unused,
                                            teacher=_teacher(taught_on, comp), jobs=jobs)
        return FilesResult(new=tuple(new), report=report)
    if files.dialect in TEXT_DIALECTS:
        from ..programs import loads
        from .task import compensate_task

        programs = [loads(t, files.dialect, n) for t, n in zip(texts, files.names)]
        new, report = compensate_task(programs, comp, emit=emit, unused=unused,
                                      taught_on=taught_on)
        if files.dialect == "vplus":
            check_taught_joints(report, comp.robot)
        return FilesResult(new=tuple(t.encode(ENCODING) for t in new), report=report)
    if emit != "pose":
        raise DataError(f"{files.names[0]}: emit={emit!r}: joint targets are written for "
                        f"RAPID and V+ programs only")
    from .dialect_program import compensate_pose_program

    program, rules = _parse_pose_dialect(files, texts, frames_path)
    new, report = compensate_pose_program(program, rules, comp, taught_on=taught_on)
    return FilesResult(new=tuple(new[name].encode(ENCODING) for name in files.names),
                       report=report)


KRL_NAME_LIMIT = 24
"""Characters of a KRL name (KSS refuses longer module names)."""


def match_krl_names(paths, outputs, data: list[bytes]) -> tuple[list[bytes], list[str]]:
    """KRL files' new bytes with the main ``DEF`` (``.src``) and the ``DEFDAT`` (``.dat``)
    renamed after the output file when its name differs from the input's (KSS loads a
    module only when the names inside match the file names); every other byte kept.
    Returns ``(data, notes)``: one note per file renamed, and per name KSS would refuse."""
    new, notes = [], []
    for path, out, text in zip(paths, outputs, data):
        old_name, new_name = Path(path).stem, Path(out).stem
        if old_name.lower() == new_name.lower():
            new.append(text)
            continue
        word = "DEFDAT" if Path(path).suffix.lower() == ".dat" else "DEF"
        pattern = (rb"^([ \t]*DEFDAT[ \t]+)(%s)(?![\w$])" if word == "DEFDAT" else
                   rb"^([ \t]*(?:GLOBAL[ \t]+)?DEF(?:FCT[ \t]+[\w$]+(?:\[[^\]\r\n]*\])?)?"
                   rb"[ \t]+)(%s)(?=[ \t]*\()")
        found = re.compile(pattern % re.escape(old_name.encode("latin-1")),
                           re.IGNORECASE | re.MULTILINE).search(text)
        if found is None:
            new.append(text)
            continue
        new.append(text[:found.start(2)] + new_name.encode("latin-1") + text[found.end(2):])
        notes.append(f"{out}: {word} {found.group(2).decode('latin-1')} renamed {new_name} "
                     f"to match the file name (KSS loads a module only so); programs that "
                     f"call it by the old name need the new one")
        if not re.fullmatch(r"[A-Za-z_$][\w$]{0,%d}" % (KRL_NAME_LIMIT - 1), new_name,
                            re.ASCII):
            notes.append(f"{out}: {new_name!r} is no KRL name KSS accepts (a letter or _ "
                         f"first, at most {KRL_NAME_LIMIT} letters, digits or _): choose a "
                         f"shorter output name with -o")
    return new, notes


JOINT_SLACK_DEG = 1.0
"""A taught joint value this far outside a controller axis range (deg, or mm) is out."""


def check_taught_joints(report: CompensationReport, robot) -> None:
    """:class:`ModelError` when a precision point of the program (joints as taught, a
    ``joint_target`` row) cannot be of the calibration's robot: fewer values than its axes
    (a 6-axis program against a 7-axis arm; more are external axes, see
    :func:`.task._external_axes_in_notes`), or a value outside a controller axis range
    (a PUMA's ``#ready`` on an IRB 2400): the program is for another robot."""
    ranges = robot.controller_ranges
    scale = np.array([1e3 if j.kind == "prismatic" else math.degrees(1.0)
                      for j in robot.joints])
    low, high = ranges[:, 0] * scale - JOINT_SLACK_DEG, ranges[:, 1] * scale + JOINT_SLACK_DEG
    for row in report.rows:
        if row.status != "joint_target" or not row.joints:
            continue
        where = f"{row.file}:{row.line}:{row.column}: {row.target}"
        if len(row.joints) < robot.n_joints:
            raise ModelError(f"{where}: {len(row.joints)} joint values, but the calibration's "
                             f"robot {robot.name} has {robot.n_joints} axes: the program is "
                             f"for another robot")
        q = np.asarray(row.joints, float)
        out = np.flatnonzero((q < low) | (q > high))
        if len(out):
            k = int(out[0])
            raise ModelError(f"{where}: axis {k + 1} at {q[k]:g} is outside {robot.name}'s "
                             f"range {low[k] + JOINT_SLACK_DEG:g}..{high[k] - JOINT_SLACK_DEG:g}"
                             f": the program was taught on another robot (its header may "
                             f"say so: '; olp-robot: NAME')")


@dataclass(frozen=True)
class _FanucBackup:
    frames: object = None              # SystemFrames
    registers: object = None           # PositionRegisters
    turn_axes: tuple[int, ...] = (4, 5, 6)
    turn_note: str = ""


_BACKUPS: dict = {}
"""Backups read in this process, by their files' paths, sizes and times (a folder's
programs share one backup: read once)."""


def _fanuc_backup(backup: BackupFiles) -> _FanucBackup:
    """The frames, position registers and turn axes of a FANUC backup's ``.VA`` files,
    each file recognised by what it holds; the stated turn axes win over SYSMAST.VA's."""
    try:
        stats = tuple((p, os.stat(p).st_size, os.stat(p).st_mtime_ns) for p in backup.paths)
    except OSError:
        stats = None
    if stats is not None and (stats, backup.turn_axes) in _BACKUPS:
        return _BACKUPS[stats, backup.turn_axes]
    read = _read_fanuc_backup(backup)
    if stats is not None:
        _BACKUPS[stats, backup.turn_axes] = read
    return read


def _read_fanuc_backup(backup: BackupFiles) -> _FanucBackup:
    from ..programs.fanuc_backup import read_position_registers, read_turn_axes
    from ..programs.fanuc_frames import read_system_frames
    from ..programs.text_checks import check_text

    frames = registers = turn = None
    for path in backup.paths:
        text = _read(Path(path))
        check_text(text, path)
        upper = text.upper()
        found = False
        if "$MNUFRAME" in upper or "$MNUTOOL" in upper:
            frames, found = read_system_frames(text, path), True
        axes = read_turn_axes(text, path)
        if axes is not None:
            turn, found = axes, True
        posreg = read_position_registers(text, path)
        if posreg is not None:
            registers, found = posreg, True
        if not found and Path(path).suffix.lower() != ".va":
            continue                     # another maker's file (a KRL $config.dat)
        if not found:
            raise ParseError("holds none of $MNUFRAME/$MNUTOOL (SYSFRAME.VA), "
                             "$SCR_GRP[1].$TURN_AXIS (SYSMAST.VA) nor $POSREG (POSREG.VA)",
                             path, 1, 1)
    if backup.turn_axes is not None:
        axes, note = backup.turn_axes, "stated (--fanuc-turn-axes)"
    elif turn is not None:
        axes, note = turn.axes, f"$SCR_GRP[1].$TURN_AXIS, {turn.source}"
    else:
        return _FanucBackup(frames, registers)
    words = ", ".join(f"J{a}" for a in axes)
    return _FanucBackup(frames, registers, axes,
                        f"CONFIG turn numbers read for the axes {words} ({note})")


def _val3_programs(files: ProgramFiles) -> dict[str, str]:
    """The ``.pgx`` programs beside a VAL3 data file (its project's folder), by the names
    the report gives them (beside the data file's name)."""
    out = {}
    for path, name in zip(files.paths, files.names):
        for pgx in sorted(Path(path).parent.iterdir()):
            if pgx.suffix.lower() == ".pgx" and pgx.is_file():
                out[str(Path(name).parent / pgx.name) if Path(name).parent != Path(".")
                    else pgx.name] = _read(pgx)
    return out


def _parse_pose_dialect(files: ProgramFiles, texts: list[str], frames_path):
    """(PoseProgram, DialectRules) of the files of a pose dialect."""
    names = files.names
    if files.dialect == "krl":
        from ..programs.krl import parse_krl
        from .dialect_rules import KRL

        by_ext = {Path(n).suffix.lower(): (n, t) for n, t in zip(names, texts)}
        src, dat = by_ext.get(".src", (None, None)), by_ext.get(".dat", (None, None))
        configs = {path: _read(Path(path)) for path in backup_files(frames_path).paths
                   if Path(path).suffix.lower() != ".va"}        # FANUC's, not KRL's
        program = parse_krl(src[1], dat[1], src[0] or "<src>", dat[0] or "<dat>", configs)
        return program, KRL
    if files.dialect == "fanuc":
        from ..programs.fanuc_tp import parse_fanuc_tp
        from .rules_fanuc import fanuc_rules

        backup = _fanuc_backup(backup_files(frames_path))
        program = parse_fanuc_tp(texts[0], names[0], system_frames=backup.frames,
                                 registers=backup.registers)
        if backup.turn_note:
            program.notes.append(backup.turn_note)
        return program, fanuc_rules(backup.turn_axes)
    if files.dialect == "val3":
        from ..programs.val3 import parse_val3
        from .rules_val3 import VAL3

        return parse_val3(dict(zip(names, texts)), programs=_val3_programs(files)), VAL3
    from ..programs.urscript import parse_urscript
    from .rules_urscript import URSCRIPT

    return parse_urscript(texts[0], names[0]), URSCRIPT
