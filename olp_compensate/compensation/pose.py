"""Pose compensation: the target that makes the nominal controller drive the real robot
to where the program meant.

The controller turns a target into joints with the data-sheet (nominal) kinematics. The real
arm is the calibrated model. For a desired tool pose we therefore

1. solve the joints ``q`` at which the *calibrated* arm (its effects included) puts its real
   tool on the desired pose, on the configuration the program asks for
   (:func:`olp_compensate.compensation.ik.solve`: the nominal closed form, then Newton on the model);
2. write the target the *nominal* controller maps to exactly those joints: the nominal
   forward kinematics of ``q``, through the program's own tool and work object, with the
   configuration (ABB ``confdata``) of ``q``.

Between the two, where the calibration holds parts fitted in a joint range (named effects
beside their geometric fallback, a residual map), ``q`` follows the one rule on them
(:meth:`Compensator.fitted_parts`), which every caller applies.

All poses are 4x4 in metres; joints are controller axes in rad (m for prismatic axes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..calibration.calibration import Calibration
from ..calibration.effects import joint_effects
from ..errors import DataError, ModelError
from ..kinematics.conventions import invert_pose, rotation_angle_between
from ..kinematics.model import FixedChain, fixed_chain, forward
from .config_rule import decide
from .controller import Load, controller_model_chain, refine_on_controller
from .failures import FailureReport, explain_failures
from .ik import (IKSolution, OPWParameters, ReachBound, URParameters, branch_of,
                 closed_form_inverse, fit_family, nominal_joints_on_branch, solve,
                 solve_with_nominal)
from .residual_map import FittedParts, apply_fitted_parts

__all__ = ["Compensator", "PoseCompensation", "BatchCompensation", "compensate_pose",
           "compensate_poses", "COMPENSATED"]

COMPENSATED = ("ok", "singular")
"""IK reasons that count as compensated ('singular': reached, but near a singularity)."""


@dataclass(frozen=True)
class BatchCompensation:
    """Compensation of m poses.

    poses : (m, 4, 4) the targets to write, in the frame the inputs were given in, m.
    joints : (m, n) controller axes the real robot takes, rad/m (NaN where not solved).
    nominal_joints : (m, n) controller axes the nominal controller gives the original
        targets, rad/m (NaN where the nominal arm cannot reach them).
    config : (m, 4) int, ABB confdata (cf1, cf4, cf6, cfx) of ``joints``.
    status : (m,) str, the reasons of :data:`olp_compensate.compensation.ik.REASONS`.
    position_error_m, rotation_error_rad : (m,) how closely the calibrated model reaches.
    model_notes : m strings, which of the calibration's fitted-in-a-range parts did not
        apply or did (geometric model outside the named effects' fitted ranges, residual
        map; :meth:`Compensator.fitted_parts`), '' where all of it applied.
    """

    poses: np.ndarray
    joints: np.ndarray
    nominal_joints: np.ndarray
    config: np.ndarray
    status: np.ndarray
    position_error_m: np.ndarray
    rotation_error_rad: np.ndarray
    model_notes: tuple[str, ...] = ()

    @property
    def success(self) -> np.ndarray:
        """(m,) bool, where the target was compensated."""
        return np.isin(self.status, COMPENSATED)


@dataclass(frozen=True)
class PoseCompensation:
    """One compensated pose: ``pose`` (4, 4) m to write, ``joints`` (n,) controller axes
    rad/m the real robot takes, ``config`` ABB confdata, ``status`` ('ok', 'singular' or
    the reason it failed), and the change of the target (mm, degrees)."""

    pose: np.ndarray
    joints: np.ndarray
    config: tuple[int, int, int, int]
    status: str
    correction_mm: np.ndarray
    correction_deg: float
    note: str = ""
    """Why the target was not compensated (axis, value and range; configurations; distance
    out of reach), empty when it was."""
    model_note: str = ""
    """Where it was compensated: which fitted-in-a-range parts of the calibration did not
    apply or did (:meth:`Compensator.fitted_parts`), empty when all of it applied."""

    @property
    def success(self) -> bool:
        return self.status in COMPENSATED


class Compensator:
    """Joint solutions of the real (calibrated) arm and of the nominal controller.

    Internally joints are URDF axes (the closed forms are fitted on them); the public
    methods that say so take and return controller axes. ``controller``: a calibration of
    the model the robot's controller runs (None: the data sheet; see
    :mod:`.controller`), through which targets are read and written; ``load``: the
    :class:`~.controller.Load` the arm carries, fed to its load-dependent effects.
    """

    def __init__(self, calibration: Calibration, controller: Calibration | None = None,
                 load: Load | None = None):
        self.calibration = calibration
        self.robot = calibration.robot
        self.model = calibration.model
        self.controller = controller
        """The model the robot's controller runs (None: the data sheet): targets are read
        and written through it (:mod:`.controller`)."""
        if self.robot.n_joints != 6:
            raise ModelError(f"{self.robot.name}: compensation needs a 6-axis arm, this one "
                             f"has {self.robot.n_joints} axes")
        self._chain = fixed_chain(self.model, calibration.values)
        self._nominal_chain = fixed_chain(self.model, self.model.nominal)
        family = fit_family(self.nominal_flange)
        if family is None:
            raise ModelError(f"{self.robot.name}: no closed-form family (spherical-wrist OPW "
                             f"or UR) fits this arm, so program configurations cannot be "
                             f"chosen")
        self.family: OPWParameters | URParameters = family
        if controller is not None:    # the closed form stays the data sheet's (a start)
            self._nominal_chain = controller_model_chain(controller, calibration)
        self.load = load
        """The load the arm carries (None: none), fed to load-dependent effects."""
        self.limits = np.stack([self.robot.lower_limits, self.robot.upper_limits], 1)
        """(n, 2) URDF joint limits, rad: what the IK checks."""
        self.axis_ranges = self.robot.controller_ranges
        """(n, 2) the controller's axis ranges, rad, controller axes: checked after solving."""
        self.reach = _reach_bound(self._chain, calibration)
        self._fallback: Compensator | None = None

    # -- the parts of the calibration fitted in a range -----------------------------------

    def fallback_compensator(self) -> Compensator | None:
        """The compensator of the calibration's geometric fallback (same controller and
        load; built on first use), None without one."""
        if self.calibration.geometric_fallback is None:
            return None
        if self._fallback is None:
            self._fallback = Compensator(self.calibration.geometric_fallback,
                                         self.controller, self.load)
        return self._fallback

    def fitted_parts(self, desired_real_flange: np.ndarray, q_urdf: np.ndarray,
                     flange: np.ndarray, ok: np.ndarray, notes: list | None = None
                     ) -> FittedParts:
        """The one rule on the fitted-in-a-range parts of the calibration, applied to
        what :meth:`compensate_flanges` solved (``q_urdf`` (m, n), ``flange`` (m, 4, 4),
        ``ok`` (m,) the rows compensated) for ``desired_real_flange`` (m, 4, 4): rows
        outside the named effects' fitted ranges solved on the geometric fallback, the
        residual map inside its region, a note on each row where a part did not apply
        (:func:`~.residual_map.apply_fitted_parts`; ``notes`` appended to in place).
        Every compensation goes through it; a compensator whose rows may come from
        other calibrations (regions) leaves them as solved."""
        if getattr(self, "region_names", ()):
            return FittedParts.unchanged(q_urdf, flange, notes)
        return apply_fitted_parts(self, desired_real_flange, q_urdf, flange,
                                  np.asarray(ok, dtype=bool), notes)

    # -- kinematics, URDF axes ------------------------------------------------------------

    def nominal_flange(self, q_urdf: np.ndarray) -> np.ndarray:
        """Flange poses (m, 4, 4) of the controller's model (the data-sheet arm by
        default), base frame, m."""
        q_urdf = np.asarray(q_urdf, dtype=float)
        if self._nominal_chain is not None and (q_urdf.ndim == 2 or self.controller is not None):
            return self._nominal_chain.flange(np.atleast_2d(q_urdf))
        return forward(self.model, self.model.nominal, q_urdf).flange

    def real_flange_and_jacobian(self, q_urdf: np.ndarray):
        """Flange poses (m, 4, 4) of the calibrated arm and its geometric Jacobian
        (m, 6, n) (flange-origin velocity, then angular velocity, base frame) with respect
        to the commanded joints, effects included."""
        q_actual, dactual = self.calibration.actual_joints(
            q_urdf, jacobian=True, conditions=None if self.load is None
            else self.load.conditions(len(np.atleast_2d(q_urdf))))
        if self._chain is not None and np.ndim(q_actual) == 2:
            flange, jac = self._chain.flange_and_jacobian(q_actual)
        else:
            chain = forward(self.model, self.calibration.values, q_actual, jacobian=True)
            flange, jac = chain.flange, np.concatenate([chain.dpoint_dq, chain.drot_dq], axis=1)
        if dactual is not None:
            jac = jac @ dactual
        return flange, jac

    def solve_real(self, base_T_flange: np.ndarray, confdata: np.ndarray | None, *,
                   retries: bool = True, asked=None) -> IKSolution:
        """Joints (URDF axes) at which the calibrated arm reaches ``base_T_flange``
        (m, 4, 4), on ``confdata`` (m, 4) (None: nearest to zero, any configuration), to
        1e-9 m and 1e-9 rad, inside the URDF limits and the controller's axis ranges
        (:meth:`check_axis_ranges`); ``retries`` as :func:`~.ik.solve`. With ``retries``,
        the rows not reached as asked get their status by the configuration rule
        (:func:`~.config_rule.decide`; ``asked``: its predicate of the configuration asked
        for, default ``confdata``'s)."""
        solution = self.check_axis_ranges(solve(self.family, self.real_flange_and_jacobian,
                                                base_T_flange, confdata, self.limits,
                                                reach=self.reach, retries=retries,
                                                ruled=retries))
        return decide(self, solution, base_T_flange, confdata, asked) if retries else solution

    def check_axis_ranges(self, solution: IKSolution) -> IKSolution:
        """``solution`` with every reached row whose controller axes lie outside the
        controller's ranges marked 'joint_limit' (its joints kept: the best found)."""
        rows = np.flatnonzero(solution.success)
        if not len(rows):
            return solution
        q_ctrl = self.robot.controller_from_joints(solution.q[rows])
        outside = self.robot.outside_ranges(q_ctrl).any(axis=1)
        if np.any(outside):
            # another turn of an arm axis (2, 3 or 5; 1, 4 and 6 follow the confdata's
            # quadrants) gives the same pose: a coupled axis 3 may be in range one turn on
            turned = self._turn_into_ranges(q_ctrl[outside])
            now_inside = ~self.robot.outside_ranges(turned).any(axis=1)
            fixed = rows[outside][now_inside]
            solution.q[fixed] = self.robot.joints_from_controller(turned[now_inside])
            outside[np.flatnonzero(outside)[now_inside]] = False
        solution.reason[rows[outside]] = "joint_limit"
        solution.success[rows[outside]] = False
        return solution

    def _turn_into_ranges(self, q_ctrl: np.ndarray) -> np.ndarray:
        """``q_ctrl (k, n)`` with revolute axes 2, 3 and 5 turned by whole turns into the
        controller's ranges where one turn lands inside."""
        q = q_ctrl.copy()
        ranges = self.axis_ranges
        for a in (1, 2, 4):
            if self.robot.joints[a].kind != "revolute" or not np.all(np.isfinite(ranges[a])):
                continue
            lo, hi = ranges[a]
            turns = np.ceil((lo - q[:, a]) / (2 * np.pi) - 1e-12)
            candidate = q[:, a] + 2 * np.pi * turns
            q[:, a] = np.where(candidate <= hi, candidate, q[:, a])
        return q

    def solve_nominal(self, base_T_flange: np.ndarray, confdata: np.ndarray | None) -> np.ndarray:
        """Joints (m, n) (URDF axes) the nominal controller takes for ``base_T_flange``:
        the closed form on the requested branch (NaN where unreachable); with a
        controller model, refined on it (:meth:`controller_joints`)."""
        return self.controller_joints(self._solve_datasheet(base_T_flange, confdata),
                                      base_T_flange)

    def controller_joints(self, q_urdf: np.ndarray, base_T_flange: np.ndarray) -> np.ndarray:
        """The joints (m, n) URDF axes, near ``q_urdf`` (the data sheet's), at which the
        controller's model puts its flange on ``base_T_flange`` (m, 4, 4); ``q_urdf`` itself
        without a controller model (NaN where it does not converge)."""
        if self.controller is None:
            return q_urdf
        return refine_on_controller(self._nominal_chain, q_urdf, base_T_flange)

    def _solve_datasheet(self, base_T_flange: np.ndarray, confdata: np.ndarray | None
                         ) -> np.ndarray:
        if confdata is not None:
            confdata = np.asarray(confdata, dtype=int).reshape(-1, 4)
            return nominal_joints_on_branch(self.family, base_T_flange, confdata, self.limits)
        solutions = closed_form_inverse(self.family, base_T_flange)
        # each branch turned by 2 pi towards zero, then the one inside the limits
        # nearest zero
        turned = solutions - 2 * np.pi * np.round(solutions / (2 * np.pi))
        lower, upper = self.limits[:, 0], self.limits[:, 1]
        turned = np.where(turned < lower, turned + 2 * np.pi, turned)
        turned = np.where(turned > upper, turned - 2 * np.pi, turned)
        m, branches, n = turned.shape
        ctrl = self.robot.controller_from_joints(turned.reshape(-1, n))
        inside = ~self.robot.outside_ranges(ctrl).any(axis=1).reshape(m, branches)
        norm = np.where(inside, np.sum(turned ** 2, axis=2), np.inf)
        pick = np.argmin(norm, axis=1)
        q = turned[np.arange(len(turned)), pick]
        q[~np.isfinite(norm[np.arange(len(norm)), pick])] = np.nan
        return q

    def confdata(self, q_urdf: np.ndarray) -> np.ndarray:
        """ABB confdata (m, 4) int of joints (URDF axes): quadrants of controller axes 1, 4
        and 6, and the branch index cfx."""
        q_ctrl = self.robot.controller_from_joints(q_urdf)
        quadrants = np.floor(q_ctrl[:, [0, 3, 5]] / (np.pi / 2) + 1e-12).astype(int)
        return np.concatenate([quadrants, branch_of(self.family, q_urdf)[:, None]], 1)

    # -- poses ----------------------------------------------------------------------------

    def compensate_flanges(self, desired_real_flange: np.ndarray,
                           requested_flange: np.ndarray | None = None,
                           confdata: np.ndarray | None = None, *, retries: bool = True,
                           asked=None, keep: list | None = None, resume=None):
        """Solve the real arm for ``desired_real_flange`` (m, 4, 4); return
        (joints URDF (m, n), nominal flange at those joints (m, 4, 4), IKSolution,
        nominal joints of ``requested_flange`` (URDF, m, n) or None). ``retries`` as
        :func:`~.ik.solve`; with them, the failed rows' status is the configuration rule's
        (:func:`~.config_rule.decide`, ``asked`` its predicate of the configuration asked
        for, default ``confdata``'s), without them it is left for the caller's retry.
        ``keep`` (a list; the caller retries the failed rows with the rule): where the
        requested and desired poses are the same, the solver's
        :class:`~.ik.solver.SolverState` is appended to it, and ``resume`` (that state of
        the rows solved now) goes on from it (:func:`~.ik.solver.solve_with_nominal`)."""
        if (requested_flange is not None and confdata is not None
                and np.shape(requested_flange) == np.shape(desired_real_flange)
                and np.array_equal(requested_flange, desired_real_flange)):
            # the same poses: the nominal joints are the closed form solve starts from
            solution, nominal = solve_with_nominal(
                self.family, self.real_flange_and_jacobian, desired_real_flange, confdata,
                self.limits, reach=self.reach, retries=retries,
                ruled=retries or keep is not None, keep=keep, resume=resume)
            solution = self.check_axis_ranges(solution)
            nominal = self.controller_joints(nominal, requested_flange)
            if retries:
                solution = decide(self, solution, desired_real_flange, confdata, asked)
        else:
            solution = self.solve_real(desired_real_flange, confdata, retries=retries,
                                       asked=asked)
            nominal = None
            if requested_flange is not None:
                nominal = self.solve_nominal(requested_flange, confdata)
        q = np.where(solution.success[:, None], solution.q, np.nan)
        ok = solution.success
        if self._nominal_chain is not None:       # all rows at once, NaN where not solved
            flange = self._nominal_chain.flange(q)
            flange[~ok] = np.nan
        else:
            flange = np.full((len(q), 4, 4), np.nan)
            if np.any(ok):
                flange[ok] = self.nominal_flange(q[ok])
        return q, flange, solution, nominal


def _reach_bound(chain: FixedChain | None, calibration: Calibration) -> ReachBound | None:
    """The calibrated arm's :class:`~olp_compensate.compensation.ik.ReachBound` (None without a chain)."""
    if chain is None:
        return None
    try:
        return ReachBound(*chain.frames(), branches=not joint_effects(calibration.effects))
    except ModelError:
        return None


def _stack(pose, m: int, name: str) -> np.ndarray:
    if pose is None:
        return np.broadcast_to(np.eye(4), (m, 4, 4))
    a = np.asarray(pose, dtype=float)
    if a.shape not in ((4, 4), (m, 4, 4)):
        raise DataError(f"{name}: expected shape (4, 4) or ({m}, 4, 4), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise DataError(f"{name}: poses must be finite")
    return np.broadcast_to(a, (m, 4, 4))


def compensate_poses(calibration: Calibration | Compensator, wobj_T_target, tool=None,
                     wobj=None, confdata=None, real_tool=None) -> BatchCompensation:
    """Compensate m targets of a robot-held tool (batched).

    wobj_T_target : (m, 4, 4) targets in their work object, m.
    tool : flange_T_tool the controller uses (the program's tooldata), (4, 4) or
        (m, 4, 4); default the flange.
    wobj : base_T_wobj, (4, 4) or (m, 4, 4); default the base frame.
    confdata : (m, 4) ABB (cf1, cf4, cf6, cfx) asked for, or None for the branch nearest
        zero (any configuration accepted).
    real_tool : flange_T_tool of the real tool (e.g. from calib.json); default ``tool``.
    """
    comp = calibration if isinstance(calibration, Compensator) else Compensator(calibration)
    targets = np.asarray(wobj_T_target, dtype=float)
    if targets.ndim == 2:
        targets = targets[None]
    m = len(targets)
    targets = _stack(targets, m, "wobj_T_target")
    tool = _stack(tool, m, "tool")
    wobj = _stack(wobj, m, "wobj")
    real_tool = tool if real_tool is None else _stack(real_tool, m, "real_tool")
    if confdata is not None:
        confdata = np.asarray(confdata, dtype=int).reshape(m, 4)
    tcp = wobj @ targets
    desired = tcp @ invert_pose(real_tool)
    requested = tcp @ invert_pose(tool)
    q, flange, solution, nominal = comp.compensate_flanges(desired, requested, confdata)
    parts = comp.fitted_parts(desired, q, flange, solution.success)
    q, flange = parts.q, parts.flange
    poses = invert_pose(wobj) @ flange @ tool
    config = np.full((m, 4), -99, dtype=int)
    ok = solution.success
    if np.any(ok):
        config[ok] = comp.confdata(q[ok])
    robot = comp.robot
    position, rotation = parts.errors(solution.position_error_m, solution.rotation_error_rad)
    return BatchCompensation(poses=poses, joints=robot.controller_from_joints(q),
                             nominal_joints=robot.controller_from_joints(nominal),
                             config=config, status=solution.reason.astype(str),
                             position_error_m=position, rotation_error_rad=rotation,
                             model_notes=tuple(parts.notes))


def compensate_pose(calibration: Calibration | Compensator, pose, tool=None, wobj=None,
                    config=None, real_tool=None) -> PoseCompensation:
    """Compensate one target for offline-programming software.

    pose : wobj_T_target (4, 4), m. tool : flange_T_tool the controller uses (4, 4), m.
    wobj : base_T_wobj (4, 4), m. config : ABB confdata (cf1, cf4, cf6, cfx) or None.
    real_tool : the calibrated tool if it differs from ``tool``.
    Returns the target to write (same frame as ``pose``), the joints the real robot will
    take (controller axes, rad) and a status; a failure is a status, not an exception.
    """
    comp = calibration if isinstance(calibration, Compensator) else Compensator(calibration)
    batch = compensate_poses(comp, np.asarray(pose, dtype=float)[None], tool, wobj,
                             None if config is None else [config], real_tool)
    original = np.asarray(pose, dtype=float)
    new = batch.poses[0]
    note, joints, conf = "", batch.joints[0], tuple(int(c) for c in batch.config[0])
    if batch.success[0]:
        correction_mm = (new[:3, 3] - original[:3, 3]) * 1e3
        correction_deg = float(np.degrees(rotation_angle_between(new[:3, :3], original[:3, :3])))
    else:
        new = original.copy()
        correction_mm, correction_deg = np.zeros(3), 0.0
        failure = _explain_one(comp, original, tool, wobj, config, real_tool)
        if failure is not None:
            note, joints = failure.note, failure.joints
            conf = failure.config if failure.config is not None else conf
    return PoseCompensation(pose=new, joints=joints, config=conf,
                            status=str(batch.status[0]), correction_mm=correction_mm,
                            correction_deg=correction_deg, note=note,
                            model_note=batch.model_notes[0])


def _explain_one(comp: Compensator, pose, tool, wobj, config, real_tool) -> FailureReport | None:
    """The :class:`FailureReport` of one pose that :func:`compensate_pose` could not
    compensate (solved again: failures are rare and the batch keeps no solution)."""
    tool = np.eye(4) if tool is None else np.asarray(tool, dtype=float)
    wobj = np.eye(4) if wobj is None else np.asarray(wobj, dtype=float)
    real = tool if real_tool is None else np.asarray(real_tool, dtype=float)
    desired = (wobj @ pose @ invert_pose(real))[None]
    confdata = None if config is None else np.asarray(config, dtype=int).reshape(1, 4)
    solution = comp.solve_real(desired, confdata)
    return explain_failures(comp, solution, desired, confdata)[0]
