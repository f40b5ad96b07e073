"""``olp-cal tool``: recalibrate a tool's TCP from touched marks, or with the wizard.

With ``--marks`` the touches come from a marks CSV (``mark, q1_deg..qN_deg, x_mm, y_mm,
z_mm[, frame]``; empty coordinates: fixed-point method). Without it the interactive wizard
runs, with joints typed from the pendant (stdin) or read live from a UR controller (``--ur``).
The TCP is found in the flange frame of the calibrated model (``--model``) or of the nominal
robot, and written into a calib.json (never over an input) and, with ``--update-program``,
into a copy of the RAPID program whose tooldata of the same name gets the new TCP (only those
numbers' bytes change).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..calibration.calibration import Calibration, ToolPoint, nominal_calibration
from ..kinematics.conventions import MM
from ..errors import DataError, ModelError
from ..io.atomic import write_bytes_atomic, write_text_atomic
from ..io.calibration_file import read_calibration, write_calibration
from ..io.rtde_source import RtdeJointSource, console_ask, console_say
from ..kinematics.robot import load_robot
from ..calibration.tool import (ToolCalibration, ToolRequest, calibrate_tool, check_tool_fit,
                                rapid_tooldata, tool_report)
from ..io.tool_marks import format_marks_csv, read_marks_csv
from .common import refuse_clashes
from .tool_wizard import BAD_POINT_MM, run_wizard

if TYPE_CHECKING:            # the programs package loads only when a program is rewritten
    from .. import programs

HELP = "recalibrate a tool's TCP from touched marks (--marks) or with the interactive wizard"

NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,31}")
PLACEHOLDER_MASS_KG = 1.0


def add_arguments(p) -> None:
    p.add_argument("--robot", help="bundled robot name or path to a URDF (required without "
                                    "--model; checked against it with --model)")
    p.add_argument("--model", help="calib.json whose kinematics to use (default: the nominal "
                                   "robot)")
    p.add_argument("--name", help="tool name as in the robot program (default with --marks: "
                                  "the file's '# tool:' line, else its stem; the wizard asks)")
    p.add_argument("--marks", help="marks CSV: mark, q1_deg..qN_deg, x_mm, y_mm, z_mm "
                                   "[, frame]; coordinates empty on every row for the "
                                   "fixed-point method. Without --marks the wizard runs")
    p.add_argument("--frame", choices=("base", "world"),
                   help="frame of the marks' coordinates when the file has no 'frame' "
                        "column (default base)")
    p.add_argument("-o", "--output", help="calib.json to write: the calibration (--model, "
                                          "else nominal) with the tool added or replaced "
                                          "(default with --model: MODEL_TOOL.json beside it)")
    p.add_argument("--update-program", metavar="PROGRAM",
                   help="RAPID module whose tooldata of the tool's name gets the new TCP; "
                        "written to --program-out, never over PROGRAM")
    p.add_argument("--program-out", metavar="PATH",
                   help="updated program (default: PROGRAM_TOOL.ext beside PROGRAM)")
    p.add_argument("--mass-kg", type=float,
                   help="tool mass for the printed tooldata (default: the program's; else a "
                        "1 kg placeholder)")
    p.add_argument("--cog-mm", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="tool centre of gravity for the printed tooldata, mm, flange frame")
    p.add_argument("--ur", metavar="HOST", help="wizard: read the joints live from a UR "
                                                "controller over RTDE (read-only)")
    p.add_argument("--connect-timeout-s", type=float, default=5.0,
                   help="--ur: give up connecting after this long, s")
    p.add_argument("--noise-mm", type=float, default=0.1,
                   help="expected touch noise, mm: a touch off by more than 3x that (or "
                        "1 mm) is flagged (by the wizard at once)")


# -- inputs and outputs -----------------------------------------------------------------------

def _calibration(args) -> tuple[Calibration, str]:
    """The kinematics to use and how to name them in messages."""
    robot = load_robot(args.robot) if args.robot else None
    if args.model:
        return read_calibration(args.model, robot), f"calibrated model {args.model}"
    if robot is None:
        raise DataError("give --robot NAME (nominal kinematics) or --model calib.json")
    return nominal_calibration(robot), f"nominal {robot.name} kinematics (no --model)"


def _check_name(name: str, hint: str) -> str:
    if not NAME_RE.fullmatch(name):
        raise DataError(f"tool name {name!r}: a name starts with a letter and holds up to 32 "
                        f"letters, digits or _ ({hint})")
    return name


@dataclass
class _ProgramTool:
    """The tooldata declaration to rewrite, and the program holding it."""

    program: programs.Program
    tool: programs.ToolData
    path: Path
    out: Path


def _program_tool(program, path: Path, out: Path, name: str) -> _ProgramTool:
    """The declaration of tooldata ``name`` (RAPID rules: case-insensitive) to rewrite."""
    if program.dialect != "rapid":
        raise DataError(f"{path}: --update-program rewrites RAPID tooldata declarations; this "
                        f"is a {program.dialect} file (its tools are written inline)")
    key = name.lower()
    found = [t for t in program.tools if t.name is not None and t.name.lower() == key
             and t.storage != "inline"]
    if not found:
        declared = sorted({t.name for t in program.tools if t.name and t.storage != "inline"})
        raise DataError(f"{path}: declares no tooldata named {name} (declared: "
                        f"{', '.join(declared) or 'none'})")
    if len(found) > 1:
        lines = ", ".join(str(t.location.line) for t in found)
        raise DataError(f"{path}: tooldata {name} is declared {len(found)} times (lines "
                        f"{lines}); keep one declaration or edit the program by hand")
    tool = found[0]
    where = f"{path}:{tool.location.line}"
    if not tool.defined:
        raise DataError(f"{where}: tooldata {name} has no literal value to rewrite")
    if tool.robhold is False:
        raise DataError(f"{where}: tooldata {name} is a stationary tool (robhold FALSE); its "
                        f"tframe is not in the flange frame, so a flange TCP cannot go there")
    return _ProgramTool(program, tool, path, out)


def _calib_out(args, name: str | None) -> Path | None:
    """-o, else MODEL_TOOL.json beside --model, else None (nothing to write)."""
    if args.output:
        return Path(args.output)
    if args.model and name:
        model = Path(args.model)
        return model.with_name(f"{model.stem}_{name}.json")
    return None


@dataclass
class _Plan:
    """Where the results go; every path checked against the inputs before any work."""

    calib_out: Path | None
    program: _ProgramTool | None


def _plan(args, name: str | None, inputs: list[tuple[str, str | None]]) -> _Plan:
    """Outputs for tool ``name`` (None: the wizard asks; then only -o is known yet)."""
    calib_out = _calib_out(args, name)
    program_path = Path(args.update_program) if args.update_program else None
    program_out = None
    if program_path is not None:
        program_out = Path(args.program_out) if args.program_out else \
            program_path.with_name(f"{program_path.stem}_{name}{program_path.suffix}")
    elif args.program_out:
        raise DataError("--program-out goes with --update-program PROGRAM")
    refuse_clashes(inputs + [("--update-program", program_path), ("--robot", args.robot)],
                   [("-o" if args.output else "the calibration output", calib_out),
                    ("--program-out" if args.program_out else "the program output",
                     program_out)])
    target = None
    if program_path is not None:
        from .. import programs

        target = _program_tool(programs.load(program_path), program_path, program_out, name)
    return _Plan(calib_out, target)


# -- results ----------------------------------------------------------------------------------

def _tooldata_line(result: ToolCalibration, args, cal: Calibration,
                   target: _ProgramTool | None) -> tuple[str, str | None]:
    """The RAPID declaration of the tool and a note when its load data is a placeholder."""
    from ..programs.targets import values

    known = cal.tools.get(result.name)
    quat = None if known is None or known.quat_wxyz is None else known.quat_wxyz
    storage, robhold, mass, cog, aom, inertia = "PERS", True, None, (0.0, 0.0, 0.0), \
        (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    if target is not None and target.program.dialect == "rapid":
        tool = target.tool
        storage = tool.storage if tool.storage in ("PERS", "CONST", "VAR") else "PERS"
        robhold = bool(tool.robhold)
        quat = values(tool.orientation)
        if tool.mass is not None and tool.mass.value > 0:
            mass = tool.mass.value
        cog = values(tool.cog) if tool.cog else cog
        aom = values(tool.load_orientation) if tool.load_orientation else aom
        inertia = values(tool.inertia) if len(tool.inertia) == 3 else inertia
    if args.cog_mm is not None:
        cog = args.cog_mm
    if args.mass_kg is not None:
        mass = args.mass_kg
    note = None
    if mass is None:
        mass = PLACEHOLDER_MASS_KG
        note = (f"load data is a placeholder ({PLACEHOLDER_MASS_KG:g} kg, centre of gravity "
                f"at the flange): give --mass-kg and --cog-mm, or keep your tool's load data")
    literal = rapid_tooldata(result, mass_kg=mass, cog_mm=cog, robhold=robhold,
                             quat_wxyz=quat, aom_wxyz=aom, inertia_kgm2=inertia)
    return f"{storage} tooldata {result.name} := {literal};", note


def _unique(path: Path) -> Path:
    """``path``, or ``stem_2.ext``, ``stem_3.ext``... when it exists (records are kept)."""
    candidate, k = path, 2
    while candidate.exists():
        candidate = path.with_name(f"{path.stem}_{k}{path.suffix}")
        k += 1
    return candidate


def _write(result: ToolCalibration, cal: Calibration, plan: _Plan,
           request: ToolRequest | None = None) -> list[Path]:
    """Write the touches (wizard only), the calibration and the program; return the paths."""
    written = []
    primary = plan.calib_out or (plan.program.out if plan.program is not None else None)
    if request is not None and primary is not None:  # the wizard's touches: never lost
        marks = _unique(primary.with_name(f"{primary.stem}_marks.csv"))
        write_text_atomic(marks, format_marks_csv(request))
        written.append(marks)
    if plan.calib_out is not None:
        known = cal.tools.get(result.name)
        quat = result.quat_wxyz if result.quat_wxyz is not None else (
            None if known is None else known.quat_wxyz)
        tools = dict(cal.tools)
        tools[result.name] = ToolPoint(xyz_m=np.array(result.xyz_m, dtype=float),
                                       std_m=np.array(result.xyz_std_m, dtype=float),
                                       quat_wxyz=quat, for_programs=True)
        write_calibration(plan.calib_out, replace(cal, tools=tools))
        written.append(plan.calib_out)
    if plan.program is not None:
        from .. import programs

        target = plan.program
        edits = programs.tool_edits(target.tool, position_mm=np.asarray(result.xyz_m) / MM,
                                    quat_wxyz=result.quat_wxyz)
        text = programs.dumps(target.program, edits)
        write_bytes_atomic(target.out, text.encode(programs.ENCODING))
        written.append(target.out)
    return written


def _print_outputs(result, args, cal, plan, written) -> None:
    line, note = _tooldata_line(result, args, cal, plan.program)
    print(f"RAPID: {line}")
    if note:
        print(f"  ({note})")
    for path in written:
        if path == plan.calib_out:
            print(f"wrote {path} (tools.{result.name}: TCP in the flange frame, mm)")
        elif plan.program is not None and path == plan.program.out:
            print(f"wrote {path} (tooldata {plan.program.tool.name}: new TCP; every other "
                  f"byte as in {plan.program.path})")
        else:
            print(f"wrote {path} (the touches, for olp-cal tool --marks)")
    if not written:
        print("not saved: give -o calib.json (or --model) to keep the tool")


# -- the two modes ----------------------------------------------------------------------------

def _run_marks(args, cal: Calibration, kinematics: str) -> int:
    if args.ur:
        raise DataError("--ur is for the wizard (without --marks); a marks file already "
                        "holds the joints")
    request = read_marks_csv(args.marks, cal.robot.n_joints, frame=args.frame)
    name = _check_name(args.name or request.name, "give --name TOOL")
    request = replace(request, name=name)
    plan = _plan(args, name, [("--marks", args.marks), ("--model", args.model)])
    where = f", marks in the {request.frame} frame" if request.method == "known_marks" else ""
    print(f"tool {name}: {len(request.joints)} touches from {args.marks} "
          f"({request.method.replace('_', ' ')}{where}); {kinematics}")
    result = calibrate_tool(request, cal.flange_poses)
    for line in tool_report(result, min(3.0 * args.noise_mm, BAD_POINT_MM) * MM):
        print(line)
    check_tool_fit(result)
    _print_outputs(result, args, cal, plan, _write(result, cal, plan))
    return 0


def _run_wizard(args, cal: Calibration, kinematics: str) -> int:
    if args.frame:
        raise DataError("--frame goes with --marks; the wizard asks for the frame")
    if args.name is not None:
        _check_name(args.name, "--name")
    if args.update_program and args.name is None:
        raise DataError("--update-program with the wizard needs --name TOOL (the tooldata "
                        "to rewrite), so that a missing declaration stops us before touching")
    plan = _plan(args, args.name, [("--model", args.model)])
    n = cal.robot.n_joints
    source = None

    def save(result, request):
        if plan.calib_out is None:
            plan.calib_out = _calib_out(args, result.name)
        return _write(result, cal, plan, request)

    def save_to(name):
        out = plan.calib_out or _calib_out(args, name)
        parts = [str(p) for p in (out, plan.program.out if plan.program else None) if p]
        return " and ".join(parts) + " (touches beside it)"

    can_save = bool(args.output or args.model or args.update_program)
    console_say(f"Kinematics: {kinematics}.")
    if not can_save:
        console_say("Nothing will be saved: give -o calib.json, --model or --update-program "
                    "to keep the result.")
    try:
        if args.ur:
            if n != 6:
                raise ModelError(f"--ur reads 6 joints from a UR controller; robot "
                                 f"{cal.robot.name} has {n}")
            console_say(f"Connecting to the UR controller at {args.ur} (RTDE, read-only)...")
            source = RtdeJointSource(args.ur, connect_timeout_s=args.connect_timeout_s)
        result = run_wizard(cal.flange_poses, console_ask, console_say, joint_source=source,
                            n_joints=n, name=args.name, expected_noise_mm=args.noise_mm,
                            save=save if can_save else None,
                            save_to=save_to if can_save else None)
    finally:
        if source is not None:
            source.close()
    if result is None:
        raise DataError("tool recalibration cancelled; nothing written")
    line, note = _tooldata_line(result, args, cal, plan.program)
    print(f"RAPID: {line}")
    if note:
        print(f"  ({note})")
    return 0


def run(args) -> int:
    # the outputs named on the command line, before anything is read (the defaults,
    # which need the tool's name, are checked again by _plan)
    refuse_clashes([("--marks", args.marks), ("--model", args.model),
                    ("--update-program", args.update_program), ("--robot", args.robot)],
                   [("-o", args.output), ("--program-out", args.program_out)])
    cal, kinematics = _calibration(args)
    odd = [j.name for j in cal.robot.joints if j.unit != "deg"]
    if odd:
        raise ModelError(f"olp-cal tool reads joints in degrees; robot {cal.robot.name} has "
                         f"prismatic joints ({', '.join(odd)})")
    if args.mass_kg is not None and not (args.mass_kg > 0 and np.isfinite(args.mass_kg)):
        raise DataError(f"--mass-kg: RAPID needs a tool mass > 0 kg, got {args.mass_kg}")
    if args.marks:
        return _run_marks(args, cal, kinematics)
    return _run_wizard(args, cal, kinematics)
