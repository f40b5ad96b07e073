"""Identification: the robot's geometry (and effects) from measured points.

The stages of :func:`identify`, each a function below: check the data, freeze what is
redundant by construction (:mod:`.identifiability`), register the device frame and start
the tools (:mod:`.registration`), fit (Levenberg-Marquardt as in Motta 2006, eq. 52,
:mod:`.lm`), freeze what the poses cannot separate and refit, reject outliers (on request),
compute the statistics (:mod:`.statistics`) and cross-validate (:mod:`.cross_validation`).

The unknowns (:mod:`.unknowns`) are the device frame (6: ``base.tx .. base.rz``, the robot
base in the device frame), the free geometric parameters of the model, one 3-vector per
measured tool point (``tool.NAME.x``...), the rotation of each tool whose rows carry an
orientation (``tool.NAME.rx/ry/rz``) and the parameters of the non-geometric effects asked
for (``joint_compliance j2.c``..., :mod:`.effects`). Residuals (:mod:`.problem`) are
predicted minus measured positions in the device frame.

Full-pose rows (``Measurements.orientation``, see :mod:`olp_compensate.io.measurements`) add
three equations each: the rotation vector ``Log(R_meas^T R_pred)`` (rad) from the measured
to the predicted frame of the tool, ``R_pred = R_device_base R_flange R_tool``, where
``R_tool`` is the tool's constant, unknown rotation in the flange frame (started from the
chordal mean of ``R_flange^T R_device_base^T R_meas`` after registration; the unknowns are a
small rotation ``R_tool = R_tool0 Exp(r)`` about the tool's axes). They are weighted by
``position_sigma_mm / orientation_sigma_deg`` (in m/rad), so the fit and sigma^2 =
RSS / (m - n) are in position-equivalent units, m counting both kinds of equations; the
position residuals (mm) and the orientation residuals (deg) are reported apart.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..errors import DataError
from ..kinematics.conventions import quat_wxyz_from_matrix
from ..kinematics.model import KinematicModel, build_model, forward
from ..kinematics.robot import Robot
from .calibration import Calibration, ToolPoint, Validation
from .cross_validation import HeldOut, cross_validate, pose_folds
from .identifiability import Identifiability, analyse_identifiability, structural_freeze
from .identify_checks import check_data, check_effects, check_options
from .lm import levenberg_marquardt
from .measurements import Measurements, check_spread, row_sigma_scales
from .problem import IdentificationProblem, oriented_rows, point_index, tool_rotation_start
from .registration import register_device
from .statistics import FitStatistics, fit_statistics, inlier_weight
from .unknowns import UnknownLayout

if TYPE_CHECKING:  # the effects' module loads when effects are fitted (5-9 ms, issue 32)
    from .effects import Effect, EffectInputs

STEP_TOLERANCE_SIGMA = 1e-4
"""The fit has converged when the remaining step is shorter than this many standard
deviations of the estimate (see :func:`solve`)."""
ROBUST_ROUNDS = 5
"""At most this many rounds of outlier rejection and refit."""


@dataclass(frozen=True)
class IdentificationOptions:
    """Choices of an identification: ``convention`` 'auto' or 'dh'; ``solver`` 'lm' (ours,
    eq. 52) or 'trf' (scipy's trust region, analytic Jacobian); ``robust`` rejects rows whose
    residual exceeds the 99.9 % noise quantile and refits; ``folds`` for cross-validation
    (0 or 1: none); ``freeze``: parameter names the user holds at nominal; ``effects``:
    non-geometric terms fitted together with the geometry (their values are ignored).
    ``position_sigma_mm`` (per axis) and ``orientation_sigma_deg`` (per axis of the rotation
    vector): the device's noise; orientation residuals are weighted by their ratio so both
    kinds count alike (only the ratio matters; without orientation rows they play no part).
    The defaults (0.05 mm, 0.01 deg) suit a laser tracker with a 6-DoF probe."""

    convention: str = "auto"
    solver: str = "lm"
    robust: bool = False
    folds: int = 5
    freeze: tuple[str, ...] = ()
    max_iterations: int = 100
    effects: tuple[Effect, ...] = ()
    position_sigma_mm: float = 0.05
    orientation_sigma_deg: float = 0.01

    @property
    def orientation_weight(self) -> float:
        """Factor on orientation residuals (rad) that makes them comparable to positions, m/rad."""
        return self.position_sigma_mm * 1e-3 / np.radians(self.orientation_sigma_deg)


@dataclass(frozen=True)
class IdentificationResult:
    """Outcome of :func:`identify`; lengths in metres, angles in radians. ``residual_*`` and
    ``heldout_*`` are position errors (3-D distance per row); ``orientation_*`` the angle of
    the rotation between measured and predicted tool frames over the rows with an
    orientation (None without); ``n_equations`` counts 3 per position and 3 per orientation."""

    calibration: Calibration
    identifiability: Identifiability
    residual_rms: float
    residual_max: float
    heldout_rms: float | None
    heldout_max: float | None
    n_equations: int
    n_unknowns: int
    n_poses: int
    iterations: int
    message: str
    outlier_rows: list[int] = field(default_factory=list)
    unknown_names: list[str] = field(default_factory=list)
    unknown_std: np.ndarray | None = None
    dropped_effects: dict[str, str] = field(default_factory=dict)
    heldout_errors: np.ndarray | None = None
    """(m,) held-out error of each row, m (NaN for rejected outliers); None without folds."""
    orientation_rms: float | None = None
    orientation_max: float | None = None
    heldout_orientation_rms: float | None = None
    heldout_orientation_max: float | None = None
    n_orientation_rows: int = 0
    layout: UnknownLayout | None = None
    """Where each group of unknowns sits in ``unknown_names`` and ``unknown_std``."""


class Fit(NamedTuple):
    """A solver's outcome: ``x`` the unknowns, ``iterations`` (LM steps, or trf's function
    evaluations), its ``message``, and (residuals, Jacobian, J^T J) at x when the solver
    left them (else None)."""

    x: np.ndarray
    iterations: int
    message: str
    evaluation: tuple[np.ndarray, np.ndarray, np.ndarray] | None


def solve(problem: IdentificationProblem, x0: np.ndarray, options: IdentificationOptions,
          initial: tuple[np.ndarray, ...] | None = None) -> Fit:
    """Fit ``problem`` from x0 with ``options.solver``; ``initial``: the residuals and
    Jacobian (and J^T J) at x0 when known.

    LM stops once the decrease of the cost still to come (Gauss-Newton's prediction) or that
    of the last step is below STEP_TOLERANCE_SIGMA^2 / dof of the cost: with
    sigma^2 = 2 cost / dof, a step shorter than STEP_TOLERANCE_SIGMA standard deviations of
    the estimate (Mahalanobis length), far below what the data resolve."""
    view = problem.held_view(x0)  # held unknowns (problem.held) stay at their x0 values
    if options.solver == "lm":
        dof = 3 * len(problem.measured) + 3 * problem.n_oriented - problem.n_unknowns
        result = levenberg_marquardt(view.residuals_and_jacobian, view.reduce(x0),
                                     max_iterations=options.max_iterations,
                                     ftol=STEP_TOLERANCE_SIGMA**2 / max(dof, 1),
                                     residuals=view.residuals, initial=view.cut(initial))
        return Fit(x=view.full(result.x), iterations=result.iterations, message=result.message,
                   evaluation=(result.residuals, result.jacobian, result.normal))
    from scipy.optimize import least_squares  # only for --solver trf: 0.2 s of import saved

    result = least_squares(view.residuals, view.reduce(x0),
                           jac=lambda x: view.residuals_and_jacobian(x)[1],
                           method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    return Fit(x=view.full(result.x), iterations=int(result.nfev), message=result.message,
               evaluation=None)


@dataclass(frozen=True)
class _Setup:
    """What every stage of :func:`identify` reads: ``meas`` with URDF joints (rad, m),
    ``meas_controller`` as given (controller axes), the model, the checked effects, the
    measured tool points and the tools whose rotation is measured (sorted names)."""

    robot: Robot
    meas: Measurements
    meas_controller: Measurements
    model: KinematicModel
    options: IdentificationOptions
    effects: tuple[Effect, ...]
    tool_names: list[str]
    rotated_tools: list[str]


@dataclass(frozen=True)
class _Start:
    """Start values: ``device_T_base`` (4, 4) from the registration, ``tools`` (T, 3) in the
    flange frame, m, tool ``rotations`` (name -> (3, 3)), the effects' ``inputs``."""

    device_T_base: np.ndarray
    tools: np.ndarray
    rotations: dict[str, np.ndarray]
    inputs: EffectInputs | None


@dataclass(frozen=True)
class _Refrozen:
    """The problem over the unknowns the data separate, its start ``x0`` and the
    evaluation there (residuals, Jacobian, J^T J); ``frozen``: every parameter held at
    nominal, name -> reason; ``dropped``: effects not fitted, label -> reason."""

    problem: IdentificationProblem
    x0: np.ndarray
    at_x0: tuple[np.ndarray, np.ndarray, np.ndarray]
    frozen: dict[str, str]
    dropped: dict[str, str]
    motions: dict = field(default_factory=dict)
    """Held device-frame unknown -> its undetermined rigid motion (:mod:`.device_motions`)."""


def _checked_setup(robot: Robot, meas: Measurements, options: IdentificationOptions) -> _Setup:
    """Stage 1, check the data: options, effects against the columns, joints within the
    limits; the model; the measured tools."""
    check_options(options)
    effects = check_effects(robot, meas, options.effects)
    meas_urdf = dataclasses.replace(meas, joints=robot.joints_from_controller(meas.joints))
    check_data(robot, meas_urdf)
    return _Setup(robot=robot, meas=meas_urdf, meas_controller=meas,
                  model=build_model(robot, options.convention), options=options,
                  effects=effects, tool_names=sorted(set(meas_urdf.point_names)),
                  rotated_tools=sorted(set(meas_urdf.point_names[oriented_rows(meas_urdf)])))


def _structural_freeze(setup: _Setup) -> dict[str, str]:
    """Stage 2, structural freeze: the parameters redundant by construction and the user's
    (name -> reason); DataError when the equations cannot outnumber the unknowns."""
    meas, model = setup.meas, setup.model
    frozen = structural_freeze(model, meas, setup.tool_names, setup.options.freeze,
                               setup.rotated_tools)
    layout = UnknownLayout.build(
        geometry_names=[name for name in model.names if name not in frozen],
        tool_names=setup.tool_names, rotated_tools=setup.rotated_tools,
        effect_names=[e.parameter_names for e in setup.effects])
    oriented = int(oriented_rows(meas).sum())
    n_equations = 3 * meas.n_rows + 3 * oriented
    if n_equations <= layout.size:
        per_row = 6 if oriented == meas.n_rows else 3
        orientations = f" + {oriented} orientations x 3" if oriented else ""
        raise DataError(
            f"{meas.source}: {n_equations} equations ({meas.n_rows} measured points x 3"
            f"{orientations}) for {layout.size} unknowns; measure at least "
            f"{-(-(layout.size + 1 - n_equations) // per_row)} more "
            f"points (poses in the same count, spread over the workspace)")
    return frozen


def _start_values(setup: _Setup) -> _Start:
    """Stage 3, registration and start values: the device frame and tool points from the
    nominal model (:func:`register_device`), the tool rotations, the effects' inputs."""
    meas = setup.meas
    nominal_flange = forward(setup.model, setup.model.nominal, meas.joints).flange
    device_T_base, tools = register_device(nominal_flange, meas.points,
                                           point_index(meas.point_names, setup.tool_names),
                                           len(setup.tool_names))
    rotations = tool_rotation_start(nominal_flange, device_T_base, meas, setup.rotated_tools)
    inputs = None
    if setup.effects:
        inputs = measurement_inputs(setup.robot, setup.meas_controller,
                                    dict(zip(setup.tool_names, tools)), setup.effects)
    return _Start(device_T_base=device_T_base, tools=tools, rotations=rotations, inputs=inputs)


def _problem(setup: _Setup, start: _Start, free: np.ndarray, effects: tuple[Effect, ...],
             rows: np.ndarray | None = None, reference: np.ndarray | None = None,
             ) -> IdentificationProblem:
    """The identification problem over the rows of a mask (default all), ``free``
    parameters and ``effects``, relative to the registration ``reference`` (default the
    start's)."""
    meas, inputs = setup.meas, start.inputs
    if rows is not None:
        meas = meas.subset(rows)
        inputs = None if inputs is None else inputs.subset(rows)
    options = setup.options
    return IdentificationProblem(
        setup.model, meas, setup.model.nominal, free, setup.tool_names,
        start.device_T_base if reference is None else reference, effects, inputs,
        setup.robot.urdf_from_controller, start.rotations, options.orientation_weight,
        row_sigma_scales(meas, options.position_sigma_mm * 1e-3,
                         np.radians(options.orientation_sigma_deg)))


def _refreeze(setup: _Setup, start: _Start, frozen: dict[str, str]) -> _Refrozen:
    """Stage 4, identifiability and refreeze: the SVD of the scaled Jacobian at the start
    (:func:`analyse_identifiability`) over every candidate unknown; what the data cannot
    separate is frozen (effects: dropped; device-frame and tool unknowns: held at their start
    values, ``problem.held``) and the problem rebuilt without it, with the start's
    evaluation cut to the remaining columns."""
    model = setup.model
    candidate = np.array([k for k, p in enumerate(model.parameters) if p.name not in frozen],
                         dtype=int)
    problem = _problem(setup, start, candidate, setup.effects)
    x0 = problem.pack(model.nominal, start.device_T_base, start.tools,
                      [np.zeros(e.n_parameters) for e in setup.effects])
    residual0, jac0 = problem.residuals_and_jacobian(x0)  # for the analysis and the fit
    at_x0 = (residual0, jac0, jac0.T @ jac0)
    ident, keep = analyse_identifiability(problem, x0, at_x0[1], at_x0[2])
    dropped = {e.label: ident.frozen.pop(e.label) for e in setup.effects
               if e.label in ident.frozen}
    frozen = {**frozen, **ident.frozen}
    free = candidate[keep[problem.layout.geometry]]
    effects = tuple(e for e in setup.effects if e.label not in dropped)
    names_all = problem.names()
    problem = _problem(setup, start, free, effects)
    problem.held = np.isin(problem.names(), [n for n in ident.frozen if n in names_all])
    # The same state (effects at zero), fewer unknowns: x0, the start's Jacobian cut to them.
    column = {name: k for k, name in enumerate(names_all)}
    columns = [column[n] for n in problem.names()]
    x0 = x0[columns]
    if columns != list(range(len(names_all))):
        at_x0 = (at_x0[0], at_x0[1][:, columns], at_x0[2][np.ix_(columns, columns)])
    return _Refrozen(problem=problem, x0=x0, at_x0=at_x0, frozen=frozen, dropped=dropped,
                     motions=ident.motions)


def _reject_outliers(problem: IdentificationProblem, fit: Fit,
                     options: IdentificationOptions) -> Fit:
    """Stage 6, robust rejection: rows beyond the 99.9 % noise quantile get weight 0
    (:func:`inlier_weight`, ``problem.row_weight`` is updated) and the problem is refitted,
    until the set of rejected rows is stable."""
    for _ in range(ROBUST_ROUNDS):
        new_weight = inlier_weight(problem, fit.x)
        if np.array_equal(new_weight, problem.row_weight):
            break
        problem.row_weight = new_weight
        fit = solve(problem, fit.x, options)
    return fit


def _cross_validation(setup: _Setup, start: _Start, problem: IdentificationProblem,
                      x: np.ndarray, n_poses: int) -> HeldOut | None:
    """Stage 8, k-fold cross-validation by pose (``options.folds``, at most one fold per
    pose; None below 2 folds or when a training set is too small)."""
    k = min(setup.options.folds, n_poses)
    if k < 2:
        return None

    def subproblem(rows: np.ndarray, reference: np.ndarray) -> IdentificationProblem:
        sub = _problem(setup, start, problem.free, tuple(problem.effects), rows, reference)
        sub.held = problem.held  # the folds hold what the full fit holds
        return sub

    def refit(sub: IdentificationProblem, x0: np.ndarray) -> np.ndarray:
        return solve(sub, x0, setup.options).x

    return cross_validate(problem, x, pose_folds(setup.meas.pose_ids, k), subproblem, refit)


def identify(robot: Robot, meas: Measurements,
             options: IdentificationOptions = IdentificationOptions()) -> IdentificationResult:
    """Identify the geometry of ``robot`` (and the effects in ``options.effects``) from
    measured points, and orientations where the rows have them (see module docstring).
    ``meas.joints`` are controller axis values; the model works in URDF joints."""
    setup = _checked_setup(robot, meas, options)                     # 1. check the data
    frozen = _structural_freeze(setup)                                # 2. structural freeze
    start = _start_values(setup)                                      # 3. registration
    refrozen = _refreeze(setup, start, frozen)                        # 4. identifiability
    problem = refrozen.problem
    check_spread(meas, problem.n_unknowns)      # enough distinct poses for those unknowns
    fit = solve(problem, refrozen.x0, options, refrozen.at_x0)        # 5. the fit
    if options.robust:
        fit = _reject_outliers(problem, fit, options)                 # 6. robust rejection
    statistics = _final_statistics(problem, fit)                      # 7. statistics
    n_poses = len(set(meas.pose_ids.tolist()))  # = meas.n_poses, without sorting strings
    heldout = _cross_validation(setup, start, problem, fit.x, n_poses)  # 8. cross-validation
    return _result(setup, problem, fit, statistics, heldout, refrozen, n_poses)  # 9. result


def _final_statistics(problem: IdentificationProblem, fit: Fit) -> FitStatistics:
    """Stage 7, statistics at the solution, from the solver's last evaluation when it left
    one (LM), else from a new one (trf)."""
    evaluation = fit.evaluation
    if evaluation is None:
        evaluation = (*problem.residuals_and_jacobian(fit.x), None)
    return fit_statistics(problem, fit.x, evaluation)


def _degrees(angle_rad: float | None) -> float | None:
    return None if angle_rad is None else float(np.degrees(angle_rad))


def _validation(statistics: FitStatistics, heldout: HeldOut | None, n_poses: int) -> Validation:
    """The validation figures a calibration carries (mm, deg)."""
    return Validation(
        method=f"{heldout.folds}-fold cross-validation by pose" if heldout else "none",
        poses=n_poses, residual_rms_mm=statistics.residual_rms * 1e3,
        residual_max_mm=statistics.residual_max * 1e3,
        heldout_rms_mm=None if heldout is None else heldout.rms * 1e3,
        heldout_max_mm=None if heldout is None else heldout.max * 1e3,
        condition_number=statistics.condition_number,
        orientation_rms_deg=_degrees(statistics.orientation_rms),
        orientation_max_deg=_degrees(statistics.orientation_max),
        heldout_orientation_rms_deg=_degrees(None if heldout is None else heldout.orientation_rms),
        heldout_orientation_max_deg=_degrees(None if heldout is None else heldout.orientation_max))


def _calibration(setup: _Setup, problem: IdentificationProblem, x: np.ndarray,
                 std_unknowns: np.ndarray, frozen: dict[str, str],
                 validation: Validation) -> Calibration:
    """The identified calibration: values, standard deviations, device frame, tools with
    their rotations, fitted effects."""
    layout = problem.layout
    values, pose, tools = problem.unpack(x)
    std = np.full(setup.model.n_parameters, np.nan)
    std[problem.free] = std_unknowns[layout.geometry]
    held_zero = np.where(problem.held, 0.0, std_unknowns)  # held: listed in frozen, std 0
    tool_std = held_zero[layout.tool_points].reshape(-1, 3)
    rotation_std = held_zero[layout.tool_rotations].reshape(-1, 3)
    rotations = problem.tool_rotations(x)
    tool_points = {}
    for t, name in enumerate(setup.tool_names):
        quat = rot_std = None
        if name in layout.rotated_tools:
            r = layout.rotated_tools.index(name)
            quat, rot_std = quat_wxyz_from_matrix(rotations[r]), rotation_std[r]
        tool_points[name] = ToolPoint(xyz_m=tools[t], std_m=tool_std[t], quat_wxyz=quat,
                                      rot_std_rad=rot_std)
    effects = tuple(e.with_values(x[cols], std_unknowns[cols])
                    for e, cols in zip(problem.effects, layout.effects))
    return Calibration(robot=setup.robot, model=setup.model, values=values, std=std,
                       device_T_base=pose, frozen=frozen, tools=tool_points, effects=effects,
                       validation=validation)


def _result(setup: _Setup, problem: IdentificationProblem, fit: Fit,
            statistics: FitStatistics, heldout: HeldOut | None, refrozen: _Refrozen,
            n_poses: int) -> IdentificationResult:
    """Stage 9, the result: the calibration and every figure of the identification."""
    ident = Identifiability(condition_number=statistics.condition_number,
                            frozen={**refrozen.frozen, **refrozen.dropped},
                            weak=statistics.weak, singular_values=statistics.singular_values,
                            motions=refrozen.motions)
    calibration = _calibration(setup, problem, fit.x, statistics.std, refrozen.frozen,
                               _validation(statistics, heldout, n_poses))
    meas = setup.meas
    outliers = [int(meas.rows[k]) if meas.rows is not None else k
                for k in np.flatnonzero(problem.row_weight == 0)] if setup.options.robust else []
    return IdentificationResult(
        calibration=calibration, identifiability=ident,
        residual_rms=statistics.residual_rms, residual_max=statistics.residual_max,
        heldout_rms=None if heldout is None else heldout.rms,
        heldout_max=None if heldout is None else heldout.max,
        n_equations=statistics.n_equations, n_unknowns=problem.n_unknowns, n_poses=n_poses,
        iterations=fit.iterations, message=fit.message, outlier_rows=outliers,
        unknown_names=problem.names(), unknown_std=statistics.std,
        dropped_effects=refrozen.dropped,
        heldout_errors=None if heldout is None else heldout.errors,
        orientation_rms=statistics.orientation_rms, orientation_max=statistics.orientation_max,
        heldout_orientation_rms=None if heldout is None else heldout.orientation_rms,
        heldout_orientation_max=None if heldout is None else heldout.orientation_max,
        n_orientation_rows=statistics.n_orientation_rows, layout=problem.layout)


def measurement_inputs(robot: Robot, meas: Measurements, tools: dict[str, np.ndarray],
                       effects=(), derivatives: bool = False) -> EffectInputs:
    """The inputs of ``effects`` at the measured rows (``meas.joints`` in controller axes):
    gravity torque with ``payload_kg`` at the tool point 'tcp' (else at the row's own point,
    positions from ``tools``, flange frame), temperatures and approach directions."""
    from .effects import Conditions, effect_inputs, needs_torque

    point = None
    if meas.payload_kg is not None:
        where = ["tcp"] * meas.n_rows if "tcp" in tools else list(meas.point_names)
        point = np.array([tools[name] for name in where]).reshape(-1, 3)
    conditions = Conditions(payload_kg=meas.payload_kg, payload_point_m=point,
                            temperature_c=meas.temperature_c, directions=meas.directions)
    return effect_inputs(robot, meas.joints, conditions, torque=needs_torque(effects),
                         derivatives=derivatives)
