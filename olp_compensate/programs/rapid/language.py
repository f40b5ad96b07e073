"""ABB RAPID as the pipeline sees it: a module or a task of modules (``.mod``, ``.modx``,
``.prg``, ``.sys``), compensated through the column path (:mod:`.module_columns`), or the
object model when targets are written as joints."""

from __future__ import annotations

import re
from pathlib import Path

from ..languages import Language, lazy

EXTENSIONS = (".mod", ".modx", ".prg", ".sys")


def task_root(path: Path, given_alone: bool) -> Path | None:
    """The folder whose RAPID modules form one task with ``path``: the ``TASKn`` folder of
    a backup, else the module's folder; None for modules named on the command line (they
    form one task together)."""
    if given_alone:
        return None
    for parent in path.parents:
        if re.fullmatch(r"TASK\d+", parent.name, re.IGNORECASE):
            return parent
    return path.parent


def compensate(files, texts: list[str], run):
    """A task: every readable module compensated together, an unreadable one copied with
    its row (:mod:`.unreadable`); one module alone as it is."""
    if len(texts) == 1:
        return _readable(files, texts, run)
    from ...compensation.files import ProgramFiles
    from .unreadable import compensate_readable

    def some(keep: list[int]):
        subset = ProgramFiles(files.dialect, tuple(files.paths[k] for k in keep),
                              tuple(files.names[k] for k in keep))
        return _readable(subset, [texts[k] for k in keep], run)

    return compensate_readable(texts, files.names, some)


def _readable(files, texts: list[str], run):
    from ...compensation.files import FilesResult
    from ..object_model.units import object_model_result

    if run.emit != "pose":
        return object_model_result(files, texts, run)
    from ..object_model.program import check_options
    from ..object_model.task import teacher_of
    from .module_columns import compensate_rapid_task

    check_options(run.emit, run.unused)
    new, report = compensate_rapid_task(texts, list(files.names), run.comp, unused=run.unused,
                                        teacher=teacher_of(run.taught_on, run.comp),
                                        jobs=run.jobs)
    return FilesResult(new=tuple(new), report=report)


def _warm_up() -> None:
    """The parser loaded and the object model imported (a pool's workers inherit them)."""
    from .. import loads
    from ..object_model import task  # noqa: F401

    loads("MODULE Warm\nENDMODULE\n", "rapid", "<warm-up>")


LANGUAGE = Language(
    name="rapid", title="ABB RAPID", extensions=EXTENSIONS, compensate=compensate,
    unit_key=task_root,
    member_order=lambda path, name: (path.suffix.lower() != ".sys", name.lower()),
    stated_loads=lazy(".payload", "stated_loads", __package__), warm_up=_warm_up,
    emits_joints=True)
