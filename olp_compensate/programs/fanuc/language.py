"""FANUC TP as the pipeline sees it: one ``.ls`` with the backup's ``.VA`` files given with
``--config`` (frames, position registers, turn axes)."""

from __future__ import annotations

from ..languages import Language, lazy


def compensate(files, texts: list[str], run):
    """Read the program with the backup's frames and registers, under the backup's (or the
    stated) turn axes; solve and write it."""
    from ...compensation.files import pose_program_result
    from .controller_backup import read_backup
    from .reader import parse_fanuc_tp
    from .rules import fanuc_rules

    backup = read_backup(run.backup)
    program = parse_fanuc_tp(texts[0], files.names[0], system_frames=backup.frames,
                             registers=backup.registers)
    if backup.turn_note:
        program.notes.append(backup.turn_note)
    return pose_program_result(files, program, fanuc_rules(backup.turn_axes), run)


LANGUAGE = Language(name="fanuc", title="FANUC TP", extensions=(".ls",),
                    compensate=compensate,
                    stated_loads=lazy(".payload", "stated_loads", __package__))
