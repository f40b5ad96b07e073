"""``olp-cal``: measure, identify and inspect robot calibrations.

Exit codes: 0 success, 1 bad input (one line on stderr naming file, row or column).
"""

from __future__ import annotations

import argparse
import sys
from importlib import import_module

from .. import __version__
from .common import THREADS_HELP, exit_now, help_formatter, limit_threads, run_guarded

COMMANDS = {
    "plan": ("cal_plan", "plan the poses to measure (I- or D-optimal for the identification, "
                         "among random or given candidate poses) and write them as a joint CSV"),
    "simulate": ("cal_simulate", "write measurements of a virtual robot (random geometric "
                                 "errors) and its truth file"),
    "identify": ("cal_identify", "identify the robot's geometry from a measurement CSV (or an "
                                 "MCAP session with the device's points) and write calib.json"),
    "diagnose": ("cal_diagnose", "name the non-geometric effects (compliance, gear error, "
                                 "backlash, heat, scale) in the measurements, fit them and "
                                 "measure the gain on held-out poses"),
    "import": ("cal_import", "turn a measurement table as instruments and other tools write it "
                             "(; separators, decimal commas, Euler angles, rotation vectors, "
                             "radians, RoboDK's tables) into the measurement CSV"),
    "predict": ("cal_predict", "predict measured-point positions (device frame, mm) for joint "
                               "rows of a CSV; optional payload_kg, temperature_c and "
                               "direction_K columns feed the model's effects"),
    "nominal": ("cal_nominal", "write a calibration that is exactly the nominal robot (device "
                               "frame = base frame)"),
    "export-urdf": ("cal_export_urdf", "write a URDF whose joint origins carry the identified "
                                       "geometry"),
    "tool": ("cal_tool", "recalibrate a tool's TCP from touched marks (--marks) or with the "
                         "interactive wizard"),
    "record": ("cal_record", "record the joints at each measured pose into an MCAP session "
                             "(live from a UR controller with --ur, else typed on stdin)"),
    "merge": ("cal_merge", "join an MCAP session (joints) with the measuring device's points "
                           "into a measurement CSV"),
    "base": ("cal_base", "re-fit only the base frame (where the robot stands) from marks of "
                         "known coordinates touched with a calibrated tool"),
    "validate": ("cal_validate", "validate a calibration on measurements it never saw: position "
                                 "errors before (nominal, registered) and after (calibrated), "
                                 "overall and per region"),
    "iso9283": ("cal_iso9283", "ISO 9283 pose accuracy and repeatability: write the test "
                               "program, or report AP and RP"),
    "robots": ("cal_robots", "list the bundled robots (--json), or show one robot's parameters "
                             "and ranges (--show NAME)"),
    "controller": ("cal_controller", "write the model the robot controller runs (UR "
                                     "calibration.conf, .urp, ROS calibration .yaml, or a CSV "
                                     "of the poses it reports) as a calib.json"),
    "export": ("cal_export", "write a calibration in a maker's format: UR calibration.conf "
                             "deltas (ur-calibration) or a D-H/MDH table CSV (dh-table)"),
    "camera": ("cal_camera", "camera: make a dot board, calibrate a camera from views of it, "
                             "measure camera poses"),
}
"""Command -> (module in this package, one-line help). A command's module is imported only
when that command runs (or its --help is asked for): ``olp-cal --help`` imports none."""


def command_module(name: str):
    """The module of command ``name`` (``add_arguments(parser)`` and ``run(args)``)."""
    return import_module(f".{COMMANDS[name][0]}", __package__)


def _chosen(argv: list[str]) -> str | None:
    """The command named in ``argv`` (the first word that is not an option)."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser. When ``argv`` names a command, only that command's sub-parser is made
    (with its options): each sub-parser costs some 0.15 ms of gettext look-ups, 3 ms for
    all 19, 1.5 % of an ``olp-cal identify`` on 100 poses; the others would only serve
    ``olp-cal --help`` and the error for an unknown command, where ``argv`` names none and
    every command is listed (None: every command with its options)."""
    chosen = _chosen(argv) if argv is not None else None
    parser = argparse.ArgumentParser(prog="olp-cal", description=__doc__.splitlines()[0],
                                     epilog=THREADS_HELP + ".", formatter_class=help_formatter)
    parser.add_argument("--version", action="version", version=f"olp-cal {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more logging; -v also shows tracebacks")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (_, summary) in COMMANDS.items():
        if chosen is not None and name != chosen:
            continue
        command = sub.add_parser(name, help=summary, description=summary,
                                 formatter_class=help_formatter)
        if argv is None or name == chosen:
            command_module(name).add_arguments(command)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if "numpy" not in sys.modules:  # a new process: the environment limits the threads
        limit_threads()  # before numpy loads, for free (later it takes threadpoolctl: 10 ms)
    args = build_parser(argv).parse_args(argv)
    return run_guarded(lambda: command_module(args.command).run(args), args.verbose, "olp-cal")


def console() -> None:
    """The ``olp-cal`` command: :func:`main`, then the process ends once the standard
    streams are flushed, without the interpreter's teardown (20-25 ms of the 0.2 s of an
    ``olp-cal identify`` on 100 poses; see :func:`~olp_compensate.cli.common.exit_now`).
    Every command has closed its files, joined its processes and replaced its outputs
    before :func:`main` returns."""
    exit_now(main())


if __name__ == "__main__":
    console()
