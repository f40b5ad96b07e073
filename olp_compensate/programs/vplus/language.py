"""Adept V+ and Kawasaki AS as the pipeline sees them: one location file or program
(``.pg``, ``.v2``, ``.lc``, ``.loc``, ``.as``) through the object model."""

from __future__ import annotations

import re

from ...errors import DataError
from ..languages import Language

EXTENSIONS = (".pg", ".v2", ".lc", ".loc", ".as")
SECTION_END = re.compile(rb"^[ \t]*\.END[ \t]*\r?$", re.MULTILINE | re.IGNORECASE)
"""The line closing a V+/AS section (``.END``)."""


def compensate(files, texts: list[str], run):
    """The object model's result, refused when a precision point cannot be of the
    calibration's robot (:func:`.taught_joints.check_taught_joints`)."""
    from ..object_model.units import object_model_result
    from .taught_joints import check_taught_joints

    result = object_model_result(files, texts, run)
    check_taught_joints(result.report, run.comp.robot)
    return result


def check_complete(names: list[str], data: list[bytes]) -> None:
    """:class:`DataError` for an AS save holding only its header, or files without one
    complete ``.END``-closed section (cut short)."""
    if all(d.strip() for d in data) and all(
            not line.strip() or line.lstrip().startswith(b".*")
            for d in data for line in d.splitlines()):
        raise DataError(f"{names[0]}: an AS save holding only its header ('.*' comment lines): "
                        f"no program nor location data in it; nothing written")
    if not any(SECTION_END.search(d) for d in data):
        raise DataError(f"{names[0]}: no robot target in the program (empty or cut "
                        f"short?); nothing written")


def _warm_up() -> None:
    """The parser loaded and the object model imported (a pool's workers inherit them)."""
    from .. import loads
    from ..object_model import task  # noqa: F401

    loads(".PROGRAM warm()\n.END\n", "vplus", "<warm-up>")


LANGUAGE = Language(
    name="vplus", title="Adept V+ / Kawasaki AS", extensions=EXTENSIONS,
    compensate=compensate, check_complete=check_complete, warm_up=_warm_up,
    emits_joints=True)
