"""Robot programs: parse ABB RAPID and V+ location files, and write them back losslessly.

A façade like the ``json`` module::

    program = programs.load("cell_a.mod")            # dialect from the extension
    edits = programs.target_edits(program.targets[0], position_mm=[901.2, 0.5, 799.8])
    text = programs.dumps(program, edits)            # only those numbers' bytes change
    programs.dump(program, edits, "cell_a_compensated.mod")

Files are decoded as latin-1 (one character per byte, so every byte round-trips, including
Latin-1 comments and CR LF line ends) and encoded back the same way. Each stage is public
too: :mod:`.rapid` and :mod:`.vplus` (parse), :mod:`.semantics` (targets with their tool and
work object as poses in metres), :mod:`.emit` (edits and splicing).
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import ParseError
from .emit import (edits_for_targets, format_like, joint_emit_edits, joint_target_edits,
                   splice, target_edits, tool_edits)
from .rapid import parse_rapid
from .semantics import Resolution, ResolvedTarget, resolve
from .targets import (CartesianTarget, Edit, JointTarget, MotionUse, NameReference, Number,
                      Program, Routine, RuntimeTarget, SourceLocation, ToolData, WorkObject)

ENCODING = "latin-1"
DIALECTS = ("rapid", "vplus")
_EXTENSIONS = {".mod": "rapid", ".modx": "rapid", ".prg": "rapid", ".sys": "rapid",
               ".pg": "vplus", ".v2": "vplus", ".lc": "vplus", ".loc": "vplus", ".as": "vplus"}

__all__ = [
    "load", "loads", "dump", "dumps", "dialect_for", "parse_rapid", "parse_vplus", "resolve",
    "splice", "target_edits", "edits_for_targets", "joint_target_edits", "tool_edits",
    "joint_emit_edits",
    "format_like", "Program", "CartesianTarget", "JointTarget", "ToolData", "WorkObject",
    "MotionUse", "RuntimeTarget", "NameReference", "Routine", "Number", "Edit",
    "SourceLocation", "Resolution", "ResolvedTarget",
]


def dialect_for(path: str | os.PathLike) -> str:
    """'rapid' for .mod/.modx/.prg/.sys, 'vplus' for .pg/.v2/.lc/.loc/.as (any case)."""
    ext = Path(path).suffix.lower()
    try:
        return _EXTENSIONS[ext]
    except KeyError:
        raise ParseError(f"unknown program extension {ext or '(none)'!r}; expected one of "
                         f"{', '.join(sorted(_EXTENSIONS))} or an explicit dialect",
                         str(path)) from None


def load(path: str | os.PathLike, dialect: str | None = None) -> Program:
    """Read and parse a program file; ``dialect`` defaults to the one of its extension."""
    dialect = dialect or dialect_for(path)
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ParseError(f"cannot read the file: {exc.strerror or exc}", str(path)) from None
    return loads(data, dialect, str(path))


def loads(text: str | bytes, dialect: str, file: str = "<string>") -> Program:
    """Parse program text (str, or bytes decoded as latin-1) of ``dialect``."""
    if isinstance(text, (bytes, bytearray)):
        text = bytes(text).decode(ENCODING)
    if dialect == "rapid":
        return parse_rapid(text, file)
    if dialect == "vplus":
        from .vplus import parse_vplus

        return parse_vplus(text, file)
    raise ValueError(f"dialect: expected one of {DIALECTS}, got {dialect!r}")


def __getattr__(name: str):
    # the V+ reader is imported when first used: a RAPID run never needs it (PEP 562)
    if name == "parse_vplus":
        from .vplus import parse_vplus

        return parse_vplus
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def dumps(program: Program, edits=()) -> str:
    """The program text with ``edits`` applied (no edits: the text exactly as read)."""
    return splice(program.text, edits)


def dump(program: Program, edits, path: str | os.PathLike) -> None:
    """Write the edited program to ``path`` (latin-1), via a temporary file and a rename,
    so ``path`` is never half-written. Refuses to overwrite the program's own file."""
    path = Path(path)
    if program.file != "<string>" and path.resolve() == Path(program.file).resolve():
        raise ValueError(f"path: refusing to overwrite the input file {program.file}")
    data = dumps(program, edits).encode(ENCODING)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
