"""Universal Robots URScript as the pipeline sees it: one script (``.script``,
``.urscript``); UR controllers run their own factory calibration, so a run without the
controller's model is warned."""

from __future__ import annotations

from ..languages import Language, lazy

NO_CONTROLLER_MODEL = (
    "warning: UR controllers run their own factory calibration (calibration.conf), not the "
    "data sheet: without --controller the targets are written for the data-sheet model and "
    "miss by the difference (about 1-2 mm); write controller.json with 'olp-cal controller "
    "calibration.conf --robot NAME' and pass --controller")


def compensate(files, texts: list[str], run):
    """Read the script's pose literals, solve and write it."""
    from ...compensation.files import pose_program_result
    from .reader import parse_urscript
    from .rules import URSCRIPT

    return pose_program_result(files, parse_urscript(texts[0], files.names[0]), URSCRIPT, run)


LANGUAGE = Language(
    name="urscript", title="URScript", extensions=(".script", ".urscript"),
    compensate=compensate, stated_loads=lazy(".payload", "stated_loads", __package__),
    controller_warning=lambda controller: NO_CONTROLLER_MODEL if controller is None else None)
