"""``olp-fix``: rewrite robot programs so the real (calibrated) robot reaches what they meant.

Each PATH is a program file, a task folder or a controller backup (searched for the program
files of every dialect). Exit codes: 0 every target compensated (joint targets need none);
2 some targets were not (each in the report); 1 bad input (parse error with
file:line:column and a caret, unknown robot, a calibration of another robot); with several
files, a file that fails is reported and the others go on (exit 1 at the end).
"""

from __future__ import annotations

import gc
import sys

from .common import exit_now, run_guarded
from .fix_run import EMIT_MODES, build_parser, run
from .fix_unit import program_robot

__all__ = ["main", "console", "build_parser", "run", "EMIT_MODES", "program_robot"]


def other_command(argv: list[str]):
    """The entry point of ``olp-fix serve ...`` (:mod:`.fix_serve`) or ``olp-fix --manifest
    ...`` (:mod:`.fix_manifest`) for these arguments, or None for a run on programs. A
    program file named ``serve`` is still given as ``./serve``."""
    if argv and argv[0] == "serve":
        from .fix_serve import main as serve

        return lambda: serve(argv[1:])
    if any(a == "--manifest" or a.startswith("--manifest=") for a in argv):
        from .fix_manifest import main as manifest

        return lambda: manifest(argv)
    return None


def main(argv: list[str] | None = None) -> int:
    """olp-fix as a function (argv without the program name); returns the exit code."""
    other = other_command(sys.argv[1:] if argv is None else argv)
    if other is not None:
        return other()
    args = build_parser().parse_args(argv)
    return run_guarded(lambda: run(args), args.verbose, "olp-fix")


def console() -> None:
    """The ``olp-fix`` command: :func:`main`, then the process ends without freeing the
    run's objects one by one (see :func:`~olp_compensate.cli.common.exit_now`). The
    cyclic garbage collector stays off: switched back on after a big run, its next pass
    would scan every object the run made (0.4 s for 100,000 targets) just before exit."""
    other = other_command(sys.argv[1:])
    if other is not None:          # a long-running service keeps its garbage collector
        sys.exit(other())
    gc.disable()
    args = build_parser().parse_args()
    retained: list = []
    exit_now(run_guarded(lambda: run(args, retained), args.verbose, "olp-fix"))


if __name__ == "__main__":
    console()
