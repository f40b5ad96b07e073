"""The controller files given beside a program (``olp-fix --config``, repeatable) and the
conventions stated on the command line, passed as one small value to the readers.

KRL: ``$config.dat`` (``TOOL_DATA``, ``BASE_DATA`` and the points it declares, ``XHOME``);
FANUC: ``SYSFRAME.VA`` (user and tool frames), ``SYSMAST.VA`` (``$SCR_GRP[1].$TURN_AXIS``),
``POSREG.VA`` (position registers), recognised by what they hold, in any order.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass

from ..errors import DataError


@dataclass(frozen=True)
class BackupFiles:
    """paths : the controller files, as given. turn_axes : FANUC turn axes (1-based) stated
    by the user (``--fanuc-turn-axes``), which win over a ``SYSMAST.VA``'s."""

    paths: tuple[str, ...] = ()
    turn_axes: tuple[int, ...] | None = None


def backup_files(value: BackupFiles | str | os.PathLike | Sequence | None) -> BackupFiles:
    """``value`` as :class:`BackupFiles`: a path, several, or None (no file)."""
    if isinstance(value, BackupFiles):
        return value
    if value is None:
        return BackupFiles()
    if isinstance(value, (str, os.PathLike)):
        return BackupFiles((os.fspath(value),))
    return BackupFiles(tuple(os.fspath(v) for v in value))


def parse_turn_axes(text: str) -> tuple[int, ...]:
    """``"1,4,6"`` -> (1, 4, 6): up to three distinct axes 1..9 (``--fanuc-turn-axes``)."""
    parts = [p.strip() for p in text.split(",")]
    if not 1 <= len(parts) <= 3 or not all(re.fullmatch(r"[1-9]", p) for p in parts):
        raise DataError(f"--fanuc-turn-axes {text!r}: expected up to three axis numbers "
                        f"1..9 separated by commas, as $SCR_GRP[1].$TURN_AXIS (e.g. 4,5,6 "
                        f"or 1,4,6)")
    axes = tuple(int(p) for p in parts)
    if len(set(axes)) != len(axes):
        raise DataError(f"--fanuc-turn-axes {text!r}: an axis is named twice")
    return axes
