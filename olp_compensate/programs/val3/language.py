"""Stäubli VAL3 as the pipeline sees it: a project's data file (``.dtx``) with the ``.pgx``
programs of its folder."""

from __future__ import annotations

from ..languages import Language


def compensate(files, texts: list[str], run):
    """Read the data file with its project's programs; solve and write the data file."""
    from ...compensation.files import pose_program_result
    from .project import project_programs
    from .reader import parse_val3
    from .rules import VAL3

    program = parse_val3(dict(zip(files.names, texts)), programs=project_programs(files))
    return pose_program_result(files, program, VAL3, run)


LANGUAGE = Language(name="val3", title="Stäubli VAL3", extensions=(".dtx",),
                    compensate=compensate)
