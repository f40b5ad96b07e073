"""olp-compensate: calibrate industrial robots and correct their offline-written programs.

The front door: the names an offline-programming tool or a script needs, importable from the
package root. Units and frames follow one rule: SI inside (metres, radians, 0-based
joints), each file format's own units at its edge (mm, degrees; joints counted from 1);
poses are 4x4 homogeneous transforms named ``a_T_b`` (b's coordinates to a's). Joint
arrays are the robot *controller's* axes (for a parallel-linkage ABB arm, axis 3 as the
pendant shows it), rad (m for prismatic axes).

Robot and model
    load_robot(name_or_path) -> Robot
        A bundled robot (``"abb_irb2400"``; ``olp-cal robots`` lists them), a robot record
        (``*.robot.json``) or any serial-arm URDF (its controller's axis ranges from a
        ``NAME.controller.json`` beside it).
    Robot
        The serial chain, joint limits (rad), ``controller_ranges`` (n, 2) rad.

Measurements and identification
    read_measurements(path, robot) -> Measurements
        A measurement CSV (mm, degrees) as SI arrays: ``joints`` (m, n) rad, ``points``
        (m, 3) m in the device frame, optional ``orientation`` (m, 4) quaternions w first.
    Measurements
        The type every calibration stage takes; write_measurements(path, m, units) writes
        the CSV.
    identify(robot, measurements, options=IdentificationOptions()) -> IdentificationResult
        Device registration, Levenberg-Marquardt on the singularity-free model, statistics,
        k-fold held-out errors; ``IdentificationResult.calibration`` is a
        :class:`Calibration`.
    diagnose(robot, measurements) -> Diagnosis
        What the geometric model still gets wrong, named (joint compliance, gear error...).
    Calibration, nominal_calibration(robot)
        An identified (or the data-sheet) robot: ``predict_points(q, tool_names)`` gives
        points in the device frame, m.
    read_calibration(path) / write_calibration(path, calibration)
        calib.json (versioned, schema-checked, refused for another robot model).

Compensation
    Compensator(calibration, controller=None, load=None)
        Reusable solver of the real (calibrated) arm and of the controller's model (the
        data sheet, or ``controller``: a calibration of the model the controller runs);
        ``load`` a :class:`Load` for load-dependent effects (joint compliance).
    Load(kg, cog_m, source="")
        A payload: mass, kg, at its centre of gravity in the flange frame, m.
    fit_controller(robot, q_ctrl, base_T_tool, origin=...) -> ControllerFit
        The controller's own model fitted to the poses it reports (its base frame, m);
        ``ControllerFit.calibration`` is a :class:`Calibration` to pass as ``controller``.
    compensate_pose(calibration_or_compensator, wobj_T_target, tool=flange_T_tool,
                    wobj=base_T_wobj, config=(cf1, cf4, cf6, cfx)) -> PoseCompensation
        The target to write so the nominal controller drives the real arm onto the pose
        meant (4x4, m); ``PoseCompensation.status`` 'ok'/'singular' or why not, with
        ``note``.
    compensate_poses(...) -> BatchCompensation
        The same for m poses at once.
    compensate_program(text_or_program, dialect, calibration) -> (text, CompensationReport)
        A whole program rewritten losslessly; the report has one row per target.
    compensate_task(programs, calibration) -> (texts, CompensationReport)
        The modules of one RAPID task together (declarations resolved across modules);
        ``taught_on=`` transfers targets taught on another robot of the same model.
    RegionalCompensator(calibration, force=None)
        Each target solved on the local model of the region containing it
        (``olp-cal identify --per-region``).

Tool recalibration
    calibrate_tool(ToolRequest, flange_pose) -> ToolCalibration
        The tool's point (and frame) in the flange frame from a few touched marks.

Errors
    OlpError (base), DataError, ModelError, ParseError (file, line, column),
    UnreachableTarget. Every bad input raises one of these, never a bare exception.

Submodules load on first use of a name, so ``import olp_compensate`` costs almost nothing.
"""

from __future__ import annotations

from importlib import import_module

from .errors import DataError, ModelError, OlpError, ParseError, UnreachableTarget

__version__ = "0.1.0"

_WHERE = {
    "load_robot": "kinematics.robot",
    "Robot": "kinematics.robot",
    "Measurements": "calibration.measurements",
    "read_measurements": "io.measurements",
    "write_measurements": "io.measurements",
    "identify": "calibration.identify",
    "IdentificationOptions": "calibration.identify",
    "IdentificationResult": "calibration.identify",
    "diagnose": "calibration.diagnose",
    "Calibration": "calibration.calibration",
    "nominal_calibration": "calibration.calibration",
    "read_calibration": "io.calibration_file",
    "write_calibration": "io.calibration_file",
    "Compensator": "compensation.pose",
    "Load": "compensation.controller",
    "fit_controller": "calibration.controller_fit",
    "compensate_pose": "compensation.pose",
    "compensate_poses": "compensation.pose",
    "PoseCompensation": "compensation.pose",
    "BatchCompensation": "compensation.pose",
    "compensate_program": "programs.object_model.task",
    "compensate_task": "programs.object_model.task",
    "RegionalCompensator": "compensation.regions",
    "calibrate_tool": "calibration.tool",
    "ToolRequest": "calibration.tool",
    "ToolCalibration": "calibration.tool",
}

__all__ = sorted(_WHERE) + ["DataError", "ModelError", "OlpError", "ParseError",
                            "UnreachableTarget", "__version__"]


def __getattr__(name: str):
    """Load the module of a front-door name on first use (PEP 562)."""
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'olp_compensate' has no attribute {name!r}")
    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
