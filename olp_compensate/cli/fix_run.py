"""``olp-fix`` on programs: its options, and a run over the units of the paths given (one
unit in this process, several through :mod:`.fix_batch`)."""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

from .. import __version__
from ..errors import DataError, OlpError
from ..programs.languages import extensions, languages, names
from .common import THREADS_HELP, no_gc, refuse_clashes, silence_stdout
from .fix_models import add_options as add_model_options
from .fix_unit import (ROBOT_COMMENT_SPAN, check_not_cut_short, check_robot, load_calibrations,
                       loadable_outputs, make_compensator)

DESCRIPTION = ("``olp-fix``: rewrite robot programs so the real (calibrated) robot reaches "
               "what they meant.")
"""The first line of ``olp-fix --help`` (the command's module docstring says the same)."""
SHOWN_PROBLEMS = 20
EMIT_MODES = ("pose", "joints")
"""As :data:`olp_compensate.programs.object_model.program.EMIT_MODES` (a test checks),
spelled here so that ``olp-fix --version`` and ``--help`` import nothing heavy."""


def _languages_help() -> str:
    """Each language and its extensions, for ``--help``."""
    return "; ".join(f"{lang.title} {' '.join(lang.extensions)}" for lang in languages())


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="olp-fix", description=DESCRIPTION)
    p.add_argument("program", nargs="+", metavar="PATH",
                   help=f"program files ({_languages_help()}), task folders or "
                        f"controller backups")
    p.add_argument("--model", required=True, help="calib.json from olp-cal identify/nominal")
    p.add_argument("-o", "--output", help="with one program: the compensated program to "
                                          "write (KRL: OUT.src, and OUT.dat beside it); "
                                          "with several or a folder: a folder mirroring the "
                                          "input tree; default: beside each input, "
                                          "NAME_compensated.EXT; never an input")
    p.add_argument("--emit", choices=EMIT_MODES, default="pose",
                   help="'pose': rewrite Cartesian targets (default); 'joints': turn them "
                        "into joint targets (jointtarget + MoveAbsJ, V+ precision points)")
    p.add_argument("--report", help="CSV with one row per target use (mm, deg)")
    p.add_argument("--dialect", choices=names(), help="default: from the file extension")
    p.add_argument("--robot", help="refuse a calibration that is not of this robot (bundled "
                                   "name or URDF path)")
    p.add_argument("--taught-on", metavar="A.json",
                   help="calibration of the robot the targets were taught on (robot-to-robot "
                        "transfer: the real robot of --model reaches where that robot's real "
                        "tool went); both of the same robot model")
    add_model_options(p)
    p.add_argument("--config", metavar="FILE", action="append",
                   help="a controller file the programs rely on (repeat for several): KRL: "
                        "the controller's $config.dat with TOOL_DATA[n], BASE_DATA[n] and "
                        "its points (XHOME); FANUC: the backup's SYSFRAME.VA (or SYSTEM.VA) "
                        "with $MNUFRAME and $MNUTOOL (user and tool frames of group 1), "
                        "SYSMAST.VA (or SYMOTN.VA) with $SCR_GRP[1].$TURN_AXIS, POSREG.VA with the "
                        "position "
                        "registers")
    p.add_argument("--fanuc-turn-axes", metavar="A,B,C",
                   help="FANUC: the axes the turn numbers of CONFIG belong to, as the "
                        "controller's $SCR_GRP[1].$TURN_AXIS (default: SYSMAST.VA's when "
                        "given with --config, else 4,5,6)")
    p.add_argument("--region", metavar="NAME",
                   help="use this region's local model for every target ('global': the global "
                        "model); default: each target's region by its position, when the "
                        "calibration has regions (olp-cal identify --per-region)")
    p.add_argument("-j", "--jobs", type=int, default=None, metavar="N",
                   help="programs compensated in N processes (default: the number of cores; "
                        "one program runs in this process, the targets of a big RAPID "
                        "module in two when N > 1, on Linux)")
    p.add_argument("--unused", choices=("skip", "tool0"), default="skip",
                   help="targets never moved to in this file: leave them ('skip', default) "
                        "or compensate them with tool0/wobj0 ('tool0')")
    p.epilog = (f"Also: 'olp-fix serve [--http HOST:PORT] [--root DIR]' (a compensation "
                f"service, see 'olp-fix serve --help') and 'olp-fix --manifest plant.csv "
                f"[--changed-only]' (a plant's robots in one run). "
                f"A comment '! olp-robot: NAME' (RAPID) or '; olp-robot: NAME' (V+) in the "
                f"first {ROBOT_COMMENT_SPAN // 1024} KB of the program names the robot it is "
                f"for; a calibration of another robot is then refused. {THREADS_HELP}.")
    p.add_argument("-q", "--quiet", action="store_true", help="no summary on the terminal")
    p.add_argument("--version", action="version", version=f"olp-fix {__version__}")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="more logging; -v also shows tracebacks")
    return p


def run(args, retain: list | None = None) -> int:
    """Run olp-fix on parsed arguments; returns the exit code. ``retain``: a list that
    receives the run's program and report, so the caller decides when they are freed."""
    from .fix_inputs import plan_units

    if args.jobs is not None and args.jobs < 1:
        raise DataError(f"-j/--jobs: expected a positive number of processes, got {args.jobs}")
    skipped: list[str] = []
    units = plan_units(args.program, args.dialect, args.output, extensions(), skipped)
    for line in skipped:
        print(f"olp-fix: warning: {line}", file=sys.stderr)
    args.config = _backup(args.config, getattr(args, "fanuc_turn_axes", None))
    refuse_clashes([*(("program", p) for u in units for p in u.paths), ("--model", args.model),
                    ("--robot", args.robot), ("--taught-on", args.taught_on),
                    *(("--config", c) for c in args.config.paths),
                    ("--controller", args.controller)],
                   [*(("-o" if args.output else "the default output", o)
                      for u in units for o in u.outputs), ("--report", args.report)])
    # a short batch run over millions of small acyclic records: the cyclic collector's
    # full scans (each time it comes back on between stages) would only cost time
    with no_gc():
        if len(units) == 1:
            return _run_one(args, units[0], retain)
        from .fix_batch import run_batch

        return run_batch(args, units)


def _backup(config, turn_axes: str | None):
    """The ``--config`` files and stated conventions as one
    :class:`~olp_compensate.programs.backup_files.BackupFiles` (workers receive it whole)."""
    from ..programs.backup_files import BackupFiles, backup_files, parse_turn_axes

    given = backup_files(config)
    for path in given.paths:
        if not os.path.isfile(path):
            raise DataError(f"--config {path}: no such file")
    axes = parse_turn_axes(turn_axes) if turn_axes is not None else None
    return BackupFiles(given.paths, axes)


def _run_one(args, unit, retain: list | None) -> int:
    started = time.perf_counter()
    from ..compensation.files import ProgramFiles, compensate_files
    from ..io.atomic import write_files_atomic

    from .fix_models import (load_sensitive, read_controller, unit_load,
                             warn_no_controller_model, with_load_notes)

    calibration, taught_on = load_calibrations(args)
    controller = read_controller(args, calibration)
    for path in unit.paths:
        check_robot(path, calibration, args.model)
    warn_no_controller_model(unit.dialect, controller)
    try:
        load, load_notes = unit_load(args, calibration, unit.dialect, unit.paths, unit.names)
        result = compensate_files(
            ProgramFiles(dialect=unit.dialect, paths=unit.paths, names=unit.names),
            make_compensator(calibration, args.region, controller, load), emit=args.emit,
            unused=args.unused, taught_on=taught_on,
            frames_path=args.config, jobs=args.jobs or os.cpu_count() or 1)
    except OlpError as exc:
        if getattr(exc, "context", None):
            print(exc.context, file=sys.stderr)
        raise
    report = with_load_notes(result.report, load, load_notes, load_sensitive(calibration))
    if retain is not None:
        retain += [result, report]
    if not report.rows:
        check_not_cut_short(unit.dialect, unit.paths, unit.names)   # data-only: written as is
    if unit.mirrored:                    # -o OUTDIR (or FOLDER_compensated) mirrors the input
        for out in unit.outputs:
            out.parent.mkdir(parents=True, exist_ok=True)
    files = list(zip(unit.outputs, loadable_outputs(
        unit, [result.pieces(i) for i in range(len(unit.outputs))])))
    if args.report:
        files.append((Path(args.report), (piece.encode("utf-8")
                                          for piece in report.csv_chunks())))
    write_files_atomic(files)   # all or, on a failure, none of a run's files renamed
    if not args.quiet:
        try:
            label = (report.file if len(unit.paths) == 1 else
                     f"{' '.join(args.program)} ({len(unit.paths)} files: "
                     f"{', '.join(unit.names)})")
            _summary(dataclasses.replace(report, file=label), unit.outputs, args.report,
                     time.perf_counter() - started,
                     f"  robot {calibration.robot.name} (calibration {args.model}"
                     + (f"; controller model {args.controller})" if args.controller else ")"))
        except BrokenPipeError:   # `olp-fix ... | head`: the files are written all the same
            silence_stdout()
    return report.exit_code


def _summary(report, outputs, report_path: str | None, seconds: float,
             robot_line: str) -> None:
    rows = report.rows
    counts = report.counts()
    parts = (", ".join(f"{v} {k}" for k, v in sorted(counts.items())) if rows
             else "no location data: written as it is")
    print(f"olp-fix: {report.file}: {len(rows)} target uses ({parts}) in {seconds:.2f} s")
    print(robot_line)
    largest = report.largest_correction()
    problems = report.problem_rows()
    if largest is not None:
        shift, turn, dq = largest
        print(f"  largest correction {shift:.3f} mm and {turn:.4f} deg; largest joint "
              f"change {dq:.4f} deg")
    for r in problems[:SHOWN_PROBLEMS]:
        print(f"  {r.file}:{r.line}:{r.column}: {r.target}: {r.status}"
              + (f" ({r.note})" if r.note else ""))
    if len(problems) > SHOWN_PROBLEMS:
        print(f"  ... and {len(problems) - SHOWN_PROBLEMS} more (see --report)")
    for w in report.warnings[:SHOWN_PROBLEMS]:
        print(f"  warning: {w}")
    written = (" and ".join(str(o) for o in outputs) if len(outputs) <= 2 else
               f"{len(outputs)} files ({outputs[0]}, ...)")
    print(f"  wrote {written}" + (f" and {report_path}" if report_path else ""))
