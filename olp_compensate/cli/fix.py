"""``olp-fix``: rewrite a robot program so the real (calibrated) robot reaches what it meant.

Exit codes: 0 every target compensated (joint targets need none); 2 some targets were not
(each in the report); 1 bad input (parse error with file:line:column and a caret, unknown
robot, a calibration of another robot).
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
from pathlib import Path

from .. import __version__
from ..errors import DataError, ParseError
from ..io.atomic import write_bytes_atomic, write_text_atomic
from ..io.calibration_file import read_calibration
from ..compensation.pose import COMPENSATED
from ..compensation.program import EMIT_MODES, KEPT, compensate_program
from ..programs import DIALECTS, ENCODING, dialect_for, load
from ..programs.grammar import no_gc
from ..kinematics.robot import load_robot
from .common import exit_now, run_guarded, silence_stdout

SHOWN_PROBLEMS = 20


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
    p.add_argument("-q", "--quiet", action="store_true", help="no summary on the terminal")
    p.add_argument("--version", action="version", version=f"olp-fix {__version__}")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="more logging; -v also shows tracebacks")
    return p


def default_output(path: Path) -> Path:
    """``cell.mod`` -> ``cell_compensated.mod`` in the same folder."""
    return path.with_name(f"{path.stem}_compensated{path.suffix}")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (b.exists() and a.samefile(b))
    except OSError:
        return False


def run(args, retain: list | None = None) -> int:
    """Run olp-fix on parsed arguments; returns the exit code. ``retain``: a list that
    receives the run's program and report, so the caller decides when they are freed."""
    # a short batch run over millions of small acyclic records: the cyclic collector's
    # full scans (each time it comes back on between stages) would only cost time
    with no_gc():
        return _run(args, retain)


def _run(args, retain: list | None) -> int:
    started = time.perf_counter()
    path = Path(args.program)
    out = Path(args.output) if args.output else default_output(path)
    if _same_file(path, out):
        raise DataError(f"{out}: refusing to overwrite the input program; choose another -o")
    if args.report and _same_file(path, Path(args.report)):
        raise DataError(f"{args.report}: refusing to overwrite the input program")
    dialect = args.dialect or dialect_for(path)
    robot = load_robot(args.robot) if args.robot else None
    calibration = read_calibration(args.model, robot)
    try:
        program = load(path, dialect)
    except ParseError as exc:
        if exc.context:
            print(exc.context, file=sys.stderr)
        raise
    text, report = compensate_program(program, None, calibration, emit=args.emit,
                                      unused=args.unused)
    if retain is not None:
        retain += [program, text, report]
    write_bytes_atomic(out, text.encode(ENCODING))
    if args.report:
        write_text_atomic(args.report, report.to_csv())
    if not args.quiet:
        try:
            _summary(report, out, args.report, time.perf_counter() - started)
        except BrokenPipeError:   # `olp-fix ... | head`: the files are written all the same
            silence_stdout()
    return report.exit_code


def _summary(report, out: Path, report_path: str | None, seconds: float) -> None:
    rows = report.rows
    counts = report.counts()
    parts = ", ".join(f"{v} {k}" for k, v in sorted(counts.items()))
    print(f"olp-fix: {report.file}: {len(rows)} target uses ({parts}) in {seconds:.2f} s")
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
