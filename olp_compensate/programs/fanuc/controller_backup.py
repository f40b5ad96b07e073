"""A FANUC controller backup as one program's run sees it: the ``.VA`` files given with
``--config`` read once per process (frames, position registers, turn axes), each file
recognised by what it holds."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from ...compensation.files import read_text
from ...errors import ParseError
from ..backup_files import BackupFiles
from ..text_checks import check_text
from .backup import read_position_registers, read_turn_axes
from .frames import read_system_frames


@dataclass(frozen=True)
class FanucBackup:
    """What a FANUC backup gives a program: frames, position registers, turn axes."""

    frames: object = None              # SystemFrames
    registers: object = None           # PositionRegisters
    turn_axes: tuple[int, ...] = (4, 5, 6)
    turn_note: str = ""


_BACKUPS: dict = {}
"""Backups read in this process, by their files' paths, sizes and times (a folder's
programs share one backup: read once)."""


def read_backup(backup: BackupFiles) -> FanucBackup:
    """The frames, position registers and turn axes of a FANUC backup's ``.VA`` files,
    each file recognised by what it holds; the stated turn axes win over SYSMAST.VA's."""
    try:
        stats = tuple((p, os.stat(p).st_size, os.stat(p).st_mtime_ns) for p in backup.paths)
    except OSError:
        stats = None
    if stats is not None and (stats, backup.turn_axes) in _BACKUPS:
        return _BACKUPS[stats, backup.turn_axes]
    read = _read_backup(backup)
    if stats is not None:
        _BACKUPS[stats, backup.turn_axes] = read
    return read


def _read_backup(backup: BackupFiles) -> FanucBackup:
    frames = registers = turn = None
    for path in backup.paths:
        text = read_text(Path(path))
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
        return FanucBackup(frames, registers)
    words = ", ".join(f"J{a}" for a in axes)
    return FanucBackup(frames, registers, axes,
                        f"CONFIG turn numbers read for the axes {words} ({note})")
