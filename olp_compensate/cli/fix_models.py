"""The controller's model and the load of an ``olp-fix`` run (``--controller``,
``--payload-kg``, ``--payload-cog-mm``, the program's own load statements)."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from ..errors import DataError

def add_options(p) -> None:
    """The options of this module, on ``olp-fix``'s parser."""
    p.add_argument("--controller", metavar="CONTROLLER.json",
                   help="the model the robot's controller runs (olp-cal controller; same "
                        "robot model): targets are read through it and written for it; "
                        "default: the data sheet")
    p.add_argument("--payload-kg", type=float, metavar="M",
                   help="the load the arm carries, kg (overrides the program's tooldata, "
                        "$LOAD, set_payload); used when the calibration holds load-dependent "
                        "effects (joint compliance from olp-cal diagnose)")
    p.add_argument("--payload-cog-mm", metavar="X,Y,Z",
                   help="its centre of gravity in the flange frame, mm (default 0,0,0)")


def read_controller(args, calibration):
    """The controller's calibration of ``--controller`` (None without), checked to be of
    the same robot model as ``--model``."""
    if not getattr(args, "controller", None):
        return None
    from ..io.calibration_file import read_calibration

    controller = read_calibration(args.controller)
    if controller.robot.fingerprint != calibration.robot.fingerprint:
        raise DataError(f"{args.controller}: --controller is a model of "
                        f"{controller.robot.name}, but --model {args.model} is a calibration "
                        f"of {calibration.robot.name}; the controller's model must be of the "
                        f"same robot model")
    return controller


def _override(args):
    from ..compensation.controller import Load

    if args.payload_cog_mm is None:
        cog = (0.0, 0.0, 0.0)
    else:
        try:
            cog = tuple(float(v) for v in args.payload_cog_mm.split(","))
        except ValueError:
            cog = ()
        if len(cog) != 3:
            raise DataError(f"--payload-cog-mm: expected X,Y,Z in mm, got "
                            f"{args.payload_cog_mm!r}")
    return Load(args.payload_kg, [c * 1e-3 for c in cog], "--payload-kg")


def load_sensitive(calibration) -> bool:
    """Whether the calibration (or one of its regions) holds an effect the load changes."""
    from ..calibration.effects import joint_effects, needs_torque

    cals = [calibration, *(r.calibration for r in calibration.regions)]
    return any(needs_torque(joint_effects(c.effects)) for c in cals)


def unit_load(args, calibration, dialect: str, paths, names):
    """(Load or None, notes) of one program: the override, else the one load the program
    states, when the calibration holds load-dependent effects; several loads are refused
    (the targets would need different corrections)."""
    if args.payload_cog_mm is not None and args.payload_kg is None:
        raise DataError("--payload-cog-mm: give the mass with --payload-kg")
    sensitive = load_sensitive(calibration)
    if args.payload_kg is not None:
        notes = [] if sensitive else [
            "--payload-kg: the calibration holds no load-dependent effect (joint compliance "
            "from olp-cal diagnose): the payload changes nothing"]
        return _override(args), notes
    if not sensitive:
        return None, []
    stated = _stated(args, dialect, paths, names)
    if len(stated.loads) > 1:
        listed = "; ".join(f"{x.kg:g} kg ({x.source})" for x in stated.loads)
        raise DataError(f"{names[0]}: the program states several loads ({listed}) and the "
                        f"calibration's joint compliance deflects the arm differently under "
                        f"each; compensate with --payload-kg for one load at a time")
    from ..compensation.controller import Load

    load = None
    if stated.loads:
        first = stated.loads[0]
        load = Load(first.kg, [c * 1e-3 for c in first.cog_mm], first.source)
    words = "no payload" if load is None else load.words()
    notes = [f"{where}: the load changes here at run time; the targets are compensated for "
             f"{words}" for where in stated.runtime]
    return load, notes


def _stated(args, dialect, paths, names):
    from ..programs.payloads import program_loads

    texts = {name: Path(p).read_bytes().decode("latin-1") for p, name in zip(paths, names)}
    return program_loads(dialect, texts, args.config)


def with_load_notes(report, load, notes, sensitive: bool):
    """The report with the load named in each compensated row's note and the load
    notes among its warnings."""
    warnings = (*report.warnings, *notes)
    if not sensitive:
        return dataclasses.replace(report, warnings=warnings)
    words = "compensated with no payload" if load is None else f"compensated under {load.words()}"
    return dataclasses.replace(report, rows=_noted(report.rows, words), warnings=warnings)


def _noted(rows, words: str):
    """``rows`` (a tuple of rows, or rows held as columns) with ``words`` added to the note
    of every compensated row."""
    from ..compensation.pose import COMPENSATED
    from ..compensation.report import ChainedRows, ReportRows

    def note(text: str) -> str:
        return f"{text}; {words}" if text else words

    if isinstance(rows, ReportRows):
        columns = rows.columns
        notes = [note(n) if s in COMPENSATED else n for n, s in zip(columns.note, columns.status)]
        # the others renoted where they are held: rows a table holds (Offs/RelTool
        # motions) stay in their table, not one object each
        return ReportRows(dataclasses.replace(columns, note=notes),
                          rows.others.renoted(
                              lambda r: dataclasses.replace(r, note=note(r.note))),
                          rows.order)
    if isinstance(rows, ChainedRows):
        return ChainedRows([_noted(part, words) for part in rows.parts])
    return tuple(dataclasses.replace(r, note=note(r.note)) if r.status in COMPENSATED else r
                 for r in rows)


def warn_no_controller_model(dialect: str, controller) -> None:
    """The language's warning for a run without the controller's own model (stderr): a UR
    controller runs its factory calibration, not the data sheet."""
    from ..programs.languages import language_named

    warning = language_named(dialect).controller_warning
    text = None if warning is None else warning(controller)
    if text:
        print(text, file=sys.stderr)
