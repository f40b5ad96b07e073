"""What every olp-fix unit goes through, in the command's process and in its workers: the
calibrations read and checked, the robot a program names, a program that looks cut short,
the outputs' names inside, the compensator of a run."""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import DataError, ModelError
from ..programs.languages import language_named

ROBOT_COMMENT_SPAN = 65536
"""Only the program's first bytes are searched for the robot it names (its header)."""


def default_output(path: Path) -> Path:
    """``cell.mod`` -> ``cell_compensated.mod`` in the same folder."""
    return path.with_name(f"{path.stem}_compensated{path.suffix}")


def program_robot(path: Path) -> tuple[str, int] | None:
    """(robot name, 1-based line) the program's header names (an ``olp-robot:`` comment of
    any dialect, KRL ``&PARAM OLP_ROBOT``, FANUC ``/ATTR`` comment:
    :func:`~olp_compensate.kinematics.robot_names.robot_named_at`), or None."""
    from ..kinematics.robot_names import robot_named_at

    try:
        with open(path, "rb") as stream:
            head = stream.read(ROBOT_COMMENT_SPAN).decode("latin-1")
    except OSError:
        return None   # the parser says why it cannot read the file
    try:
        return robot_named_at(head)
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from None


def check_robot(path: Path, calibration, model: str) -> None:
    """:class:`ModelError` when the program names another robot than the calibration's."""
    named = program_robot(path)
    if named is not None and named[0].lower() != calibration.robot.name.lower():
        raise ModelError(f"{path}:{named[1]}: the program is for robot '{named[0]}' (its "
                         f"olp-robot comment), but {model} is a calibration of "
                         f"'{calibration.robot.name}'")


def load_calibrations(args):
    """(calibration, taught-on calibration or None) of the arguments, checked."""
    from ..io.calibration_file import read_calibration
    from ..kinematics.robot import load_robot

    robot = load_robot(args.robot) if args.robot else None
    calibration = read_calibration(args.model, robot)
    taught_on = None
    if args.taught_on:
        taught_on = read_calibration(args.taught_on, calibration.robot)
    return calibration, taught_on


def check_not_cut_short(dialect: str, paths, names) -> None:
    """:class:`DataError` for a program without any target that looks empty or cut short:
    every file blank, or what its language calls cut short (a V+/AS file without one
    complete ``.END``-closed section). A file that is complete but holds no location data
    (an AS dump of system data, a KRL data list without positions) passes: it is written
    back as it is."""
    data = [Path(p).read_bytes() for p in paths]
    if all(not d.strip() for d in data):
        raise DataError(f"{names[0]}: no robot target in the program (empty or cut "
                        f"short?); nothing written")
    check = language_named(dialect).check_complete
    if check is not None:
        check(list(names), data)


def loadable_outputs(unit, data: list) -> list:
    """The outputs' bytes with the names inside matching the file names where the
    controller requires it (the language's ``loadable_outputs``: KRL ``DEF``/``DEFDAT``),
    each rename said on stderr; other languages' data as given."""
    loadable = language_named(unit.dialect).loadable_outputs
    if loadable is None:
        return data
    data, notes = loadable(unit.paths, unit.outputs, data)
    for note in notes:
        print(f"olp-fix: warning: {note}", file=sys.stderr)
    return data


def make_compensator(calibration, region: str | None, controller=None, load=None):
    """The compensator of a run: the regional one when the calibration has regions (or
    ``--region`` forces one), else the plain one; ``controller``: the controller's model
    (None: the data sheet), ``load``: the load carried (None: none)."""
    if calibration.regions or region is not None:
        from ..compensation.regions import RegionalCompensator

        return RegionalCompensator(calibration, force=region, controller=controller,
                                   load=load)
    from ..compensation.pose import Compensator

    return Compensator(calibration, controller, load)
