"""``olp-fix``: rewrite a robot program so the real (calibrated) robot reaches what it meant.

Exit codes: 0 every target compensated (joint targets need none); 2 some targets were not
(each in the report); 1 bad input (parse error with file:line:column and a caret, unknown
robot, a calibration of another robot).
"""

from __future__ import annotations

import argparse
import gc
import re
import sys
import time
from pathlib import Path

from .. import __version__
from ..errors import DataError, ModelError, OlpError
from .common import (THREADS_HELP, exit_now, no_gc, refuse_clashes, run_guarded,
                     silence_stdout)

SHOWN_PROBLEMS = 20
EMIT_MODES = ("pose", "joints")
"""As :data:`olp_compensate.compensation.program.EMIT_MODES` (a test checks), spelled here so
that ``olp-fix --version`` and ``--help`` import nothing heavy."""
DIALECTS = ("rapid", "vplus")
"""As :data:`olp_compensate.programs.DIALECTS` (a test checks)."""
ROBOT_COMMENT = re.compile(rb"^[ \t]*[!;][ \t]*olp-robot[ \t]*:[ \t]*([A-Za-z0-9_.+-]+)",
                           re.MULTILINE | re.IGNORECASE)
"""The comment that says which robot a program is for: ``! olp-robot: abb_irb2400`` in
RAPID, ``; olp-robot: unimation_puma560`` in V+ (the robot's name as calib.json has it)."""
ROBOT_COMMENT_SPAN = 65536
"""Only the program's first bytes are searched for :data:`ROBOT_COMMENT` (its header)."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="olp-fix", description=__doc__.splitlines()[0])
    p.add_argument("program", help="ABB RAPID module (.mod .modx .prg .sys) or V+ location "
                                   "file (.pg .v2 .lc .loc .as)")
    p.add_argument("--model", required=True, help="calib.json from olp-cal identify/nominal")
    p.add_argument("-o", "--output", help="compensated program to write (default: beside the "
                                          "input, NAME_compensated.EXT); never the input")
    p.add_argument("--emit", choices=EMIT_MODES, default="pose",
                   help="'pose': rewrite Cartesian targets (default); 'joints': turn them "
                        "into joint targets (jointtarget + MoveAbsJ, V+ precision points)")
    p.add_argument("--report", help="CSV with one row per target use (mm, deg)")
    p.add_argument("--dialect", choices=DIALECTS, help="default: from the file extension")
    p.add_argument("--robot", help="refuse a calibration that is not of this robot (bundled "
                                   "name or URDF path)")
    p.add_argument("--unused", choices=("skip", "tool0"), default="skip",
                   help="targets never moved to in this file: leave them ('skip', default) "
                        "or compensate them with tool0/wobj0 ('tool0')")
    p.epilog = (f"A comment '! olp-robot: NAME' (RAPID) or '; olp-robot: NAME' (V+) in the "
                f"first {ROBOT_COMMENT_SPAN // 1024} KB of the program names the robot it is "
                f"for; a calibration of another robot is then refused. {THREADS_HELP}.")
    p.add_argument("-q", "--quiet", action="store_true", help="no summary on the terminal")
    p.add_argument("--version", action="version", version=f"olp-fix {__version__}")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="more logging; -v also shows tracebacks")
    return p


def default_output(path: Path) -> Path:
    """``cell.mod`` -> ``cell_compensated.mod`` in the same folder."""
    return path.with_name(f"{path.stem}_compensated{path.suffix}")


def program_robot(path: Path) -> tuple[str, int] | None:
    """(robot name, 1-based line) of the program's ``olp-robot`` comment, or None."""
    try:
        with open(path, "rb") as stream:
            head = stream.read(ROBOT_COMMENT_SPAN)
    except OSError:
        return None   # the parser says why it cannot read the file
    found = ROBOT_COMMENT.search(head)
    if found is None:
        return None
    return found.group(1).decode("ascii"), head.count(b"\n", 0, found.start()) + 1


def check_robot(path: Path, calibration, model: str) -> None:
    """:class:`ModelError` when the program names another robot than the calibration's."""
    named = program_robot(path)
    if named is not None and named[0].lower() != calibration.robot.name.lower():
        raise ModelError(f"{path}:{named[1]}: the program is for robot '{named[0]}' (its "
                         f"olp-robot comment), but {model} is a calibration of "
                         f"'{calibration.robot.name}'")


def run(args, retain: list | None = None) -> int:
    """Run olp-fix on parsed arguments; returns the exit code. ``retain``: a list that
    receives the run's program and report, so the caller decides when they are freed."""
    path = Path(args.program)
    out = Path(args.output) if args.output else default_output(path)
    refuse_clashes([("program", path), ("--model", args.model), ("--robot", args.robot)],
                   [("-o" if args.output else "the default output", out),
                    ("--report", args.report)])
    # a short batch run over millions of small acyclic records: the cyclic collector's
    # full scans (each time it comes back on between stages) would only cost time
    with no_gc():
        return _run(args, retain)


def _run(args, retain: list | None) -> int:
    started = time.perf_counter()
    path = Path(args.program)
    out = Path(args.output) if args.output else default_output(path)
    from ..compensation.program import compensate_program
    from ..io.atomic import write_files_atomic
    from ..io.calibration_file import read_calibration
    from ..kinematics.robot import load_robot
    from ..programs import ENCODING, dialect_for, load

    dialect = args.dialect or dialect_for(path)
    robot = load_robot(args.robot) if args.robot else None
    calibration = read_calibration(args.model, robot)
    check_robot(path, calibration, args.model)
    try:
        program = load(path, dialect)
    except OlpError as exc:
        if exc.context:
            print(exc.context, file=sys.stderr)
        raise
    text, report = compensate_program(program, None, calibration, emit=args.emit,
                                      unused=args.unused)
    if retain is not None:
        retain += [program, text, report]
    if not report.rows:
        raise DataError(f"{path}: no robot target in the program (empty or cut short?); "
                        f"nothing written")
    files = [(out, text.encode(ENCODING))]
    if args.report:
        files.append((Path(args.report), report.to_csv().encode("utf-8")))
    write_files_atomic(files)   # both or, on a failure, neither of a run's files renamed
    if not args.quiet:
        try:
            _summary(report, out, args.report, time.perf_counter() - started,
                     f"  robot {calibration.robot.name} (calibration {args.model})")
        except BrokenPipeError:   # `olp-fix ... | head`: the files are written all the same
            silence_stdout()
    return report.exit_code


def _summary(report, out: Path, report_path: str | None, seconds: float,
             robot_line: str) -> None:
    from ..compensation.pose import COMPENSATED
    from ..compensation.program import KEPT

    rows = report.rows
    counts = report.counts()
    parts = ", ".join(f"{v} {k}" for k, v in sorted(counts.items()))
    print(f"olp-fix: {report.file}: {len(rows)} target uses ({parts}) in {seconds:.2f} s")
    print(robot_line)
    shift = turn = dq = -1.0
    problems = []
    for r in rows:
        if r.status in COMPENSATED:
            dx, dy, dz = r.correction_mm
            d2 = dx * dx + dy * dy + dz * dz
            if d2 > shift:
                shift = d2
            if r.correction_deg > turn:
                turn = r.correction_deg
            if r.joint_change > dq:   # False for NaN
                dq = r.joint_change
        elif r.status not in KEPT:
            problems.append(r)
    if shift >= 0:
        print(f"  largest correction {shift ** 0.5:.3f} mm and {turn:.4f} deg; largest joint "
              f"change {max(dq, 0.0):.4f} deg")
    for r in problems[:SHOWN_PROBLEMS]:
        print(f"  {r.file}:{r.line}:{r.column}: {r.target}: {r.status}"
              + (f" ({r.note})" if r.note else ""))
    if len(problems) > SHOWN_PROBLEMS:
        print(f"  ... and {len(problems) - SHOWN_PROBLEMS} more (see --report)")
    for w in report.warnings[:SHOWN_PROBLEMS]:
        print(f"  warning: {w}")
    print(f"  wrote {out}" + (f" and {report_path}" if report_path else ""))


def main(argv: list[str] | None = None) -> int:
    """olp-fix as a function (argv without the program name); returns the exit code."""
    args = build_parser().parse_args(argv)
    return run_guarded(lambda: run(args), args.verbose, "olp-fix")


def console() -> None:
    """The ``olp-fix`` command: :func:`main`, then the process ends without freeing the
    run's objects one by one (see :func:`~olp_compensate.cli.common.exit_now`). The
    cyclic garbage collector stays off: switched back on after a big run, its next pass
    would scan every object the run made (0.4 s for 100,000 targets) just before exit."""
    gc.disable()
    args = build_parser().parse_args()
    retained: list = []
    exit_now(run_guarded(lambda: run(args, retained), args.verbose, "olp-fix"))


if __name__ == "__main__":
    console()
