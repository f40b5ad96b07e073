"""The files of one RAPID or V+/AS unit through the object model: parsed, compensated as
one task; the new texts kept as text until written (a service request may hold characters
latin-1 cannot, given back as sent)."""

from __future__ import annotations

from ...compensation.files import CompensationRun, FilesResult, ProgramFiles
from .. import loads
from .task import compensate_task


def object_model_result(files: ProgramFiles, texts: list[str],
                        run: CompensationRun) -> FilesResult:
    """The result of programs of the named-target object model
    (:class:`~olp_compensate.programs.targets.Program`: RAPID, V+/AS), compensated as one
    task (:func:`.task.compensate_task`)."""
    programs = [loads(t, files.dialect, n) for t, n in zip(texts, files.names)]
    new, report = compensate_task(programs, run.comp, emit=run.emit, unused=run.unused,
                                  taught_on=run.taught_on)
    return FilesResult(new=tuple(new), report=report)    # text: encoded when written
