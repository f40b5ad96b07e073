"""``olp-cal``: measure, identify and inspect robot calibrations.

Exit codes: 0 success, 1 bad input (one line on stderr naming file, row or column).
"""

from __future__ import annotations

import argparse

from .. import __version__
from . import cal_export_urdf, cal_identify, cal_nominal, cal_predict, cal_simulate
from . import cal_merge, cal_record, cal_tool
from . import cal_diagnose
from . import cal_plan
from .common import run_guarded

COMMANDS = {
    "plan": cal_plan,
    "simulate": cal_simulate,
    "identify": cal_identify,
    "diagnose": cal_diagnose,
    "predict": cal_predict,
    "nominal": cal_nominal,
    "export-urdf": cal_export_urdf,
    "tool": cal_tool,
    "record": cal_record,
    "merge": cal_merge,
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="olp-cal", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"olp-cal {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more logging; -v also shows tracebacks")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, module in COMMANDS.items():
        module.add_arguments(sub.add_parser(name, help=module.HELP, description=module.HELP))
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run_guarded(lambda: COMMANDS[args.command].run(args), args.verbose, "olp-cal")


if __name__ == "__main__":
    raise SystemExit(main())
