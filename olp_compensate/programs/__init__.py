"""Robot programs: one folder per robot language (``rapid/``, ``vplus/``, ``krl/``, ``fanuc/``,
``val3/``, ``urscript/``, registered in :mod:`.languages`) and what they share.

A façade like the ``json`` module::

    program = programs.load("cell_a.mod")            # dialect from the extension
    edits = programs.target_edits(program.targets[0], position_mm=[901.2, 0.5, 799.8])
    text = programs.dumps(program, edits)            # only those numbers' bytes change
    programs.dump(program, edits, "cell_a_compensated.mod")

Files are decoded as latin-1 (one character per byte, so every byte round-trips, including
Latin-1 comments and CR LF line ends) and encoded back the same way. Each stage is public
too: :mod:`.rapid.reader` and :mod:`.vplus.reader` (parse), :mod:`.semantics` (targets with
their tool and work object as poses in metres), :mod:`.emit` (edits and splicing).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import ParseError

if TYPE_CHECKING:
    from .targets import Program

_LAZY = {
    "edits_for_targets": "emit_batch", "format_like": "emit", "joint_emit_edits": "emit_joints",
    "joint_target_edits": "emit", "splice": "emit", "target_edits": "emit",
    "tool_edits": "emit", "parse_rapid": "rapid.reader", "parse_vplus": "vplus.reader",
    "Resolution": "semantics", "ResolvedTarget": "semantics", "resolve": "semantics",
    **{name: "targets" for name in (
        "CartesianTarget", "Edit", "JointTarget", "MotionUse", "NameReference", "Number",
        "Program", "Routine", "RuntimeTarget", "SourceLocation", "ToolData", "WorkObject")},
}
"""Public names loaded on first use (PEP 562): the language registry and ``olp-fix --help``
import this package without loading a parser."""

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
        from .rapid.reader import parse_rapid

        return parse_rapid(text, file)
    if dialect == "vplus":
        from .vplus.reader import parse_vplus

        return parse_vplus(text, file)
    raise ValueError(f"dialect: expected one of {DIALECTS}, got {dialect!r}")


def __getattr__(name: str):
    if name in _LAZY:
        from importlib import import_module

        value = getattr(import_module(f"{__name__}.{_LAZY[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def dumps(program: Program, edits=()) -> str:
    """The program text with ``edits`` applied (no edits: the text exactly as read)."""
    from .emit import splice

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
