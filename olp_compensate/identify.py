"""Identification: device registration, Levenberg-Marquardt, statistics, identifiability.

The unknowns are the device frame (6: ``base.tx .. base.rz``, the robot base in the device
frame), the free geometric parameters of the model, one 3-vector per measured tool point
(``tool.NAME.x``...) and the parameters of the non-geometric effects asked for
(``joint_compliance j2.c``..., :mod:`olp_compensate.effects`). Residuals are predicted minus
measured positions in the device frame.

Identifiability (Motta 2006, section 5; Schroer): parameters redundant by construction are
frozen with the reason (the first joint's zero and height define the base frame; one measured
point and no orientation cannot see the last joint's zero). Then the SVD of the column-scaled
Jacobian over the actual poses finds combinations the data cannot separate; the pivoted QR
chooses which parameter of each to freeze, and the report names the combination. Effects
come after the geometry: an effect whose columns the kept geometry (and the effects before
it) nearly spans (relative singular value of its projected columns below
``EFFECT_SEPARATION``) is reported and not fitted, so an effect never displaces geometry.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import qr
from scipy.optimize import least_squares

from .calibration import Calibration, ToolPoint, Validation
from .conventions import rotation_from_rotvec, rotvec_from_rotation, skew
from .effects import (Conditions, Effect, EffectInputs, ThermalExpansion, effect_inputs,
                      needs_torque)
from .errors import DataError
from .io.measurements import Measurements
from .lm import levenberg_marquardt
from .model import KinematicModel, build_model, forward
from .registration import register_device
from .robot import Robot

RANK_TOLERANCE = 1e-8
"""Singular values below this fraction of the largest mark an inseparable combination."""
WEAK_TOLERANCE = 1e-4
"""Singular values below this fraction of the largest mark a barely observable combination."""
OUTLIER_QUANTILE_SIGMA = 4.03
"""99.9 % quantile of the norm of a 3-D Gaussian error, in units of the per-axis sigma."""
EFFECT_SEPARATION = 1e-3
"""An effect whose unit-scaled columns keep less than this fraction (smallest singular value)
outside the span of the geometry is reported as inseparable, not fitted."""
REGISTRATION_NAMES = ("base.tx", "base.ty", "base.tz", "base.rx", "base.ry", "base.rz")


@dataclass(frozen=True)
class IdentificationOptions:
    """Choices of an identification: ``convention`` 'auto' or 'dh'; ``solver`` 'lm' (ours,
    eq. 52) or 'trf' (scipy's trust region, analytic Jacobian); ``robust`` rejects rows whose
    residual exceeds the 99.9 % noise quantile and refits; ``folds`` for cross-validation
    (0 or 1: none); ``freeze``: parameter names the user holds at nominal; ``effects``:
    non-geometric terms fitted together with the geometry (their values are ignored)."""

    convention: str = "auto"
    solver: str = "lm"
    robust: bool = False
    folds: int = 5
    freeze: tuple[str, ...] = ()
    max_iterations: int = 100
    effects: tuple[Effect, ...] = ()


@dataclass(frozen=True)
class Identifiability:
    """What the poses can and cannot tell apart.

    ``frozen``: parameter name -> reason; ``weak``: descriptions of barely observable
    combinations; ``condition_number`` of the unit-column-scaled Jacobian of the unknowns.
    ``frozen`` also holds effects (by label) that the data cannot separate from the geometry.
    """

    condition_number: float
    frozen: dict[str, str]
    weak: list[str]
    singular_values: np.ndarray


@dataclass(frozen=True)
class IdentificationResult:
    """Outcome of :func:`identify`; lengths in metres."""

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


def _so3_right_jacobian(phi: np.ndarray) -> np.ndarray:
    theta = np.linalg.norm(phi)
    k = skew(phi)
    if theta < 1e-8:
        return np.eye(3) - 0.5 * k
    return (np.eye(3) - (1 - np.cos(theta)) / theta**2 * k
            + (theta - np.sin(theta)) / theta**3 * (k @ k))


class IdentificationProblem:
    """Residuals and analytic Jacobian of one identification (state: the fixed data).

    Unknown vector x = [registration (6) | free geometric parameters | tool points (3 each) |
    effect parameters]; the registration is ``device_T_base = (R0 Exp(phi), t0 + R0 rho)``
    with x[:6] = (rho, phi). Joint effects deflect the controller axes (``inputs.q``) before
    the chain is evaluated; thermal expansion scales the flange position in the base frame.
    """

    def __init__(self, model: KinematicModel, meas: Measurements, values: np.ndarray,
                 free: np.ndarray, tool_names: list[str], device_T_base0: np.ndarray,
                 effects=(), inputs: EffectInputs | None = None,
                 urdf_from_controller: np.ndarray | None = None):
        self.model = model
        self.q = meas.joints
        self.measured = meas.points
        self.values = np.array(values, dtype=float)
        self.free = np.asarray(free, dtype=int)
        self.tool_names = list(tool_names)
        lookup = {name: k for k, name in enumerate(self.tool_names)}
        self.point_index = np.fromiter((lookup[n] for n in meas.point_names), int, len(meas.point_names))
        self.r0 = device_T_base0[:3, :3].copy()
        self.t0 = device_T_base0[:3, 3].copy()
        self.row_weight = np.ones(len(self.measured))
        self.effects: list[Effect] = list(effects)
        if self.effects and inputs is None:
            raise ValueError("effects need their inputs (olp_compensate.effects.effect_inputs)")
        self.inputs = inputs
        self.coupling = urdf_from_controller
        # Effects are linear in their parameters: precompute each basis (m, p) once.
        self._bases = [e.basis(inputs) for e in self.effects]
        n_geo = 6 + len(self.free) + 3 * len(self.tool_names)
        sizes = [e.n_parameters for e in self.effects]
        starts = n_geo + np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.effect_slices = [slice(int(a), int(b)) for a, b in zip(starts[:-1], starts[1:])]

    @property
    def n_effect_parameters(self) -> int:
        return sum(e.n_parameters for e in self.effects)

    @property
    def n_unknowns(self) -> int:
        return 6 + len(self.free) + 3 * len(self.tool_names) + self.n_effect_parameters

    def names(self) -> list[str]:
        tools = [f"tool.{n}.{a}" for n in self.tool_names for a in "xyz"]
        effects = [f"{e.label}.{p}" for e in self.effects for p in e.parameter_names]
        return (list(REGISTRATION_NAMES) + [self.model.parameters[k].name for k in self.free]
                + tools + effects)

    def unpack(self, x: np.ndarray):
        """(values (P,), device_T_base (4, 4), tools (T, 3)) for an unknown vector."""
        values = self.values.copy()
        values[self.free] = x[6:6 + len(self.free)]
        start = 6 + len(self.free)
        tools = x[start:start + 3 * len(self.tool_names)].reshape(-1, 3)
        pose = np.eye(4)
        pose[:3, :3] = self.r0 @ rotation_from_rotvec(x[3:6])
        pose[:3, 3] = self.t0 + self.r0 @ x[:3]
        return values, pose, tools

    def effect_values(self, x: np.ndarray) -> list[np.ndarray]:
        """The parameters of each effect, in the order of ``effects``."""
        return [x[s] for s in self.effect_slices]

    def pack(self, values: np.ndarray, device_T_base: np.ndarray, tools: np.ndarray,
             effect_values=None) -> np.ndarray:
        """Unknown vector for the given state, relative to the reference registration;
        ``effect_values`` default to the values the effects carry."""
        rho = self.r0.T @ (device_T_base[:3, 3] - self.t0)
        phi = rotvec_from_rotation(self.r0.T @ device_T_base[:3, :3])
        if effect_values is None:
            effect_values = [np.array(e.values) for e in self.effects]
        return np.concatenate([rho, phi, values[self.free], np.asarray(tools).ravel(),
                               *[np.asarray(v, float) for v in effect_values]])

    def _actual_joints(self, x: np.ndarray) -> np.ndarray:
        joint = [(e, b, x[s]) for e, b, s in zip(self.effects, self._bases, self.effect_slices)
                 if e.acts_on_joint]
        if not joint:
            return self.q
        dq = np.zeros_like(self.q)
        for e, basis, theta in joint:
            dq[:, e.joint] += basis @ theta
        return self.q + (dq if self.coupling is None else dq @ self.coupling.T)

    def _scale(self, x: np.ndarray) -> np.ndarray | None:
        terms = [b @ x[s] for e, b, s in zip(self.effects, self._bases, self.effect_slices)
                 if not e.acts_on_joint]
        return None if not terms else 1.0 + np.sum(terms, axis=0)

    def predict(self, x: np.ndarray, jacobian: bool = True):
        """(values, pose, tools, chain, predicted (m, 3)); with effects, ``chain`` is the
        chain at the deflected joints and, under thermal expansion, its flange, points and
        derivatives are those of the scaled arm."""
        values, pose, tools = self.unpack(x)
        q = self._actual_joints(x)
        chain = forward(self.model, values, q, tools[self.point_index], jacobian=jacobian)
        scale = self._scale(x)
        if scale is not None:
            origin = forward(self.model, values, q, jacobian=jacobian)
            grow = (scale - 1.0)[:, None]
            flange = chain.flange.copy()
            flange[:, :3, 3] *= scale[:, None]
            chain = dataclasses.replace(
                chain, points=chain.points + grow * origin.points, flange=flange,
                dpoint_dparam=None if not jacobian
                else chain.dpoint_dparam + grow[:, :, None] * origin.dpoint_dparam,
                dpoint_dq=None if not jacobian
                else chain.dpoint_dq + grow[:, :, None] * origin.dpoint_dq)
        rotation = pose[:3, :3]
        predicted = chain.points @ rotation.T + pose[:3, 3]
        return values, pose, tools, chain, predicted

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Weighted residuals (3m,), predicted minus measured, device frame, m."""
        *_, predicted = self.predict(x, jacobian=False)
        return ((predicted - self.measured) * self.row_weight[:, None]).ravel()

    def effect_columns(self, effect: Effect, basis: np.ndarray, chain, pose: np.ndarray,
                       origin: np.ndarray | None = None) -> np.ndarray:
        """d predicted / d parameters of ``effect`` (m, 3, p), device frame, at ``chain``
        (a chain evaluated with ``jacobian=True``); ``origin``: the unscaled flange positions
        (m, 3), base frame, for thermal expansion."""
        rotation = pose[:3, :3]
        if effect.acts_on_joint:
            coupling = np.eye(self.model.n_joints) if self.coupling is None else self.coupling
            axis = coupling[:, effect.joint]  # URDF joint motion per unit of the axis
            dpoint = np.einsum("ij,mjk,k->mi", rotation, chain.dpoint_dq, axis)
            return dpoint[:, :, None] * basis[:, None, :]
        if origin is None:
            origin = chain.flange[:, :3, 3]
        return np.einsum("ij,mj->mi", rotation, origin)[:, :, None] * basis[:, None, :]

    def residuals_and_jacobian(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (3m,) and their Jacobian (3m, n_unknowns), analytic."""
        values, pose, tools, chain, predicted = self.predict(x)
        m = len(self.measured)
        rotation = pose[:3, :3]
        jac = np.zeros((m, 3, self.n_unknowns))
        jac[:, :, 0:3] = self.r0
        jac[:, :, 3:6] = -np.einsum("ij,mjk,kl->mil", rotation, skew(chain.points),
                                   _so3_right_jacobian(x[3:6]))
        k = len(self.free)
        jac[:, :, 6:6 + k] = np.einsum("ij,mjk->mik", rotation, chain.dpoint_dparam[:, :, self.free])
        tool_block = np.einsum("ij,mjk->mik", rotation, chain.flange[:, :3, :3])
        for t in range(len(self.tool_names)):
            rows = self.point_index == t
            jac[rows, :, 6 + k + 3 * t:6 + k + 3 * t + 3] = tool_block[rows]
        scale = self._scale(x)
        origin = None if scale is None else chain.flange[:, :3, 3] / scale[:, None]
        for effect, basis, cols in zip(self.effects, self._bases, self.effect_slices):
            jac[:, :, cols] = self.effect_columns(effect, basis, chain, pose, origin)
        w = self.row_weight[:, None]
        residual = ((predicted - self.measured) * w).ravel()
        jac *= w[:, :, None]
        return residual, jac.reshape(3 * m, -1)


def _structural_freeze(model: KinematicModel, meas: Measurements, tool_names: list[str],
                       user_freeze: tuple[str, ...]) -> dict[str, str]:
    frozen = {}
    for name in ("j1.theta", "j1.d"):
        if name in model.names:
            frozen[name] = ("redundant with the device registration (the base frame is defined "
                            "by axis 1: its zero and height)")
    last = model.n_joints
    if len(tool_names) == 1 and meas.orientation is None and model.joint_kinds[-1] == "revolute":
        frozen[f"j{last}.theta"] = ("redundant with the tool point: one point per pose and no "
                                    "orientation cannot see the last joint's zero (measure "
                                    "several points per pose to identify it)")
    for name in user_freeze:
        if name not in model.names:
            raise DataError(f"--freeze: no parameter named '{name}' (known: {', '.join(model.names)})")
        frozen[name] = "held at nominal on request"
    return frozen


def _describe(vector: np.ndarray, names: list[str]) -> str:
    order = np.argsort(-np.abs(vector))
    parts = [names[k] for k in order[:4] if abs(vector[k]) > 0.15 * abs(vector[order[0]])]
    return " + ".join(parts)


def analyse_identifiability(problem: IdentificationProblem, x: np.ndarray,
                            ) -> tuple[Identifiability, np.ndarray]:
    """SVD of the unit-column-scaled Jacobian at x; returns the analysis and a boolean mask
    over the unknowns that are kept (inseparable ones dropped by pivoted QR; effects that
    the kept geometry nearly spans dropped by :func:`effect_separation`)."""
    _, jac = problem.residuals_and_jacobian(x)
    names = problem.names()
    n_geo = problem.n_unknowns - problem.n_effect_parameters
    norms = np.linalg.norm(jac, axis=0)
    frozen = {}
    keep = norms > 1e-12 * max(norms.max(), 1e-300)
    for k in np.flatnonzero(~keep[:n_geo]):
        frozen[names[k]] = "has no effect on the measured points with these poses"
    keep[n_geo:] = False  # effects join one by one below, after the geometry
    geo = np.flatnonzero(keep[:n_geo])
    js = jac[:, geo] / norms[geo]
    r, pivots = qr(js, mode="r", pivoting=True)
    r = r[:js.shape[1]]
    diag = np.abs(np.diag(r))
    rank = int(np.sum(diag > RANK_TOLERANCE * diag[0]))
    if rank < len(geo):
        # J P = Q R, so the right singular vectors of J are those of R with rows un-pivoted.
        _, _, vt_r = np.linalg.svd(r)
        vt_all = np.empty_like(vt_r)
        vt_all[:, pivots] = vt_r
        null = vt_all[rank:]
        sub_names = [names[k] for k in geo]
        for col in pivots[rank:]:
            contribution = np.abs(null[:, col])
            v = null[int(np.argmax(contribution))]
            frozen[names[geo[col]]] = (
                f"cannot be separated with these poses (combination {_describe(v, sub_names)})")
        keep[geo[pivots[rank:]]] = False
    for effect, cols in zip(problem.effects, problem.effect_slices):
        reason = effect_separation(jac[:, np.flatnonzero(keep)], jac[:, cols],
                                   [names[k] for k in np.flatnonzero(keep)])
        if reason is None:
            keep[cols] = True
        else:
            frozen[effect.label] = reason
    js = jac[:, keep] / norms[keep]
    _, s, vt = np.linalg.svd(np.linalg.qr(js, mode="r"))
    kept_names = [names[k] for k in np.flatnonzero(keep)]
    weak = [f"{_describe(vt[k], kept_names)} (relative singular value {s[k] / s[0]:.1e})"
            for k in range(len(s)) if s[k] < WEAK_TOLERANCE * s[0]]
    return Identifiability(condition_number=float(s[0] / s[-1]), frozen=frozen, weak=weak,
                           singular_values=s), keep


def effect_separation(kept: np.ndarray, block: np.ndarray, kept_names: list[str]) -> str | None:
    """Why an effect with Jacobian columns ``block`` (3m, p) cannot be fitted beside the
    ``kept`` columns (3m, k), or None when it can. The test is on unit-scaled columns: the
    smallest singular value of the part of ``block`` outside the span of ``kept`` must
    reach ``EFFECT_SEPARATION``."""
    norms = np.linalg.norm(block, axis=0)
    reference = np.linalg.norm(kept, axis=0).max() if kept.size else 1.0
    if np.any(norms <= 1e-12 * reference):
        return "has no effect on the measured points with these data"
    unit = block / norms
    kept_unit = kept / np.linalg.norm(kept, axis=0)
    q, _ = np.linalg.qr(kept_unit)
    outside = unit - q @ (q.T @ unit)
    u, s, vt = np.linalg.svd(outside, full_matrices=False)
    if s[-1] >= EFFECT_SEPARATION:
        return None
    direction = unit @ vt[-1]
    coefficients, *_ = np.linalg.lstsq(kept_unit, direction, rcond=None)
    return (f"cannot be separated from the geometry with these poses (it looks like "
            f"{_describe(coefficients, kept_names)}; {s[-1]:.1e} of it is distinct)")


def _fit(problem: IdentificationProblem, x0: np.ndarray, options: IdentificationOptions):
    if options.solver == "lm":
        result = levenberg_marquardt(problem.residuals_and_jacobian, x0,
                                     max_iterations=options.max_iterations)
        return result.x, result.iterations, result.message
    if options.solver == "trf":
        result = least_squares(problem.residuals, x0,
                               jac=lambda x: problem.residuals_and_jacobian(x)[1],
                               method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12)
        return result.x, int(result.nfev), result.message
    raise ValueError(f"solver must be 'lm' or 'trf', got {options.solver!r}")


def _row_errors(problem: IdentificationProblem, x: np.ndarray) -> np.ndarray:
    *_, predicted = problem.predict(x, jacobian=False)
    return np.linalg.norm(predicted - problem.measured, axis=1)


def pose_folds(pose_ids: np.ndarray, k: int) -> list[np.ndarray]:
    """k boolean row masks (the held-out rows of each fold) that split the poses at random
    (seed 0), every row of one pose in the same fold."""
    unique = np.unique(pose_ids)
    order = np.random.default_rng(0).permutation(len(unique))
    groups = np.array_split(unique[order], k)
    return [np.isin(pose_ids, g) for g in groups]


def _check_data(robot: Robot, meas: Measurements) -> None:
    if meas.joints.shape[1] != robot.n_joints:
        raise DataError(f"{meas.source}: {meas.joints.shape[1]} joint columns, but "
                        f"{robot.name} has {robot.n_joints} joints")
    lower, upper = robot.lower_limits, robot.upper_limits
    slack = 1e-6
    outside = (meas.joints < lower - slack) | (meas.joints > upper + slack)
    if np.any(outside):
        row, joint = np.argwhere(outside)[0]
        line = meas.rows[row] if meas.rows is not None else row + 1
        value = robot.to_degrees_or_mm(meas.joints[row])[joint]
        raise DataError(f"{meas.source}:{line}: q{joint + 1} = {value:.3f} is outside the joint "
                        f"limits of {robot.name}; wrong robot for these measurements?")


def _check_effects(robot: Robot, meas: Measurements, effects) -> tuple[Effect, ...]:
    """Validate the effects against the data; fix thermal expansion's reference temperature
    (the mean of the measurements) when it is not given."""
    out = []
    for effect in effects:
        if effect.joint is not None and not 0 <= effect.joint < robot.n_joints:
            raise DataError(f"{effect.label}: {robot.name} has joints 1..{robot.n_joints}")
        if isinstance(effect, ThermalExpansion):
            if meas.temperature_c is None:
                raise DataError(f"{meas.source}: thermal_expansion needs the 'temperature_c' "
                                f"column, which the measurements do not have")
            if effect.reference_temperature_c is None:
                effect = dataclasses.replace(
                    effect, reference_temperature_c=float(np.mean(meas.temperature_c)))
        if effect.key in {e.key for e in out}:
            raise DataError(f"{effect.label} is asked for twice")
        out.append(effect)
    return tuple(out)


def measurement_inputs(robot: Robot, meas: Measurements, tools: dict[str, np.ndarray],
                       effects=(), derivatives: bool = False) -> EffectInputs:
    """The inputs of ``effects`` at the measured rows (``meas.joints`` in controller axes):
    gravity torque with ``payload_kg`` at the tool point 'tcp' (else at the row's own point,
    positions from ``tools``, flange frame), temperatures and approach directions."""
    point = None
    if meas.payload_kg is not None:
        where = ["tcp"] * meas.n_rows if "tcp" in tools else list(meas.point_names)
        point = np.array([tools[name] for name in where]).reshape(-1, 3)
    conditions = Conditions(payload_kg=meas.payload_kg, payload_point_m=point,
                            temperature_c=meas.temperature_c, directions=meas.directions)
    return effect_inputs(robot, meas.joints, conditions, torque=needs_torque(effects),
                         derivatives=derivatives)


def identify(robot: Robot, meas: Measurements,
             options: IdentificationOptions = IdentificationOptions()) -> IdentificationResult:
    """Identify the geometry of ``robot`` (and the effects in ``options.effects``) from
    measured points (see module docstring). ``meas.joints`` are controller axis values; the
    model works in URDF joints."""
    effects = _check_effects(robot, meas, options.effects)
    meas_ctrl = meas
    meas = dataclasses.replace(meas, joints=robot.joints_from_controller(meas.joints))
    _check_data(robot, meas)
    model = build_model(robot, options.convention)
    tool_names = sorted(set(meas.point_names))
    frozen = _structural_freeze(model, meas, tool_names, options.freeze)
    candidate = np.array([k for k, p in enumerate(model.parameters) if p.name not in frozen], dtype=int)
    n_unknowns = 6 + len(candidate) + 3 * len(tool_names) + sum(e.n_parameters for e in effects)
    n_equations = 3 * meas.n_rows
    if n_equations <= n_unknowns:
        raise DataError(
            f"{meas.source}: {n_equations} equations ({meas.n_rows} measured points x 3) for "
            f"{n_unknowns} unknowns; measure at least {n_unknowns // 3 + 1 - meas.n_rows} more "
            f"points (poses in the same count, spread over the workspace)")

    nominal_flange = forward(model, model.nominal, meas.joints).flange
    point_index = np.array([tool_names.index(n) for n in meas.point_names])
    device_T_base, tools0 = register_device(nominal_flange, meas.points, point_index, len(tool_names))
    inputs = None
    if effects:
        inputs = measurement_inputs(robot, meas_ctrl, dict(zip(tool_names, tools0)), effects)
    coupling = robot.urdf_from_controller

    def make_problem(rows_meas, rows_inputs, free_, effects_, reference):
        return IdentificationProblem(model, rows_meas, model.nominal, free_, tool_names,
                                     reference, effects_, rows_inputs, coupling)

    problem = make_problem(meas, inputs, candidate, effects, device_T_base)
    x0 = problem.pack(model.nominal, device_T_base, tools0,
                      [np.zeros(e.n_parameters) for e in effects])
    ident, keep = analyse_identifiability(problem, x0)
    dropped = {e.label: ident.frozen.pop(e.label) for e in effects if e.label in ident.frozen}
    frozen.update(ident.frozen)
    names_all = problem.names()
    free = np.array([model.index(n) for n, k in zip(names_all, keep)
                     if k and n in model.names], dtype=int)
    effects = tuple(e for e in effects if e.label not in dropped)
    problem = make_problem(meas, inputs, free, effects, device_T_base)
    x0 = problem.pack(model.nominal, device_T_base, tools0,
                      [np.zeros(e.n_parameters) for e in effects])

    x, iterations, message = _fit(problem, x0, options)
    outliers: list[int] = []
    if options.robust:
        for _ in range(5):
            errors = _row_errors(problem, x)
            inliers = problem.row_weight > 0
            dof = max(3 * inliers.sum() - problem.n_unknowns, 1)
            sigma = np.sqrt(np.sum(errors[inliers] ** 2) / dof)
            med_sigma = np.median(errors[inliers]) / 1.5382
            threshold = OUTLIER_QUANTILE_SIGMA * min(sigma, med_sigma)
            new_weight = (errors <= threshold).astype(float)
            if np.array_equal(new_weight, problem.row_weight):
                break
            problem.row_weight = new_weight
            x, iterations, message = _fit(problem, x, options)
        outliers = [int(meas.rows[k]) if meas.rows is not None else k
                    for k in np.flatnonzero(problem.row_weight == 0)]

    residual, jac = problem.residuals_and_jacobian(x)
    used = problem.row_weight > 0
    m_eq = 3 * int(used.sum())
    dof = m_eq - problem.n_unknowns
    sigma2 = float(residual @ residual) / max(dof, 1)
    norms = np.linalg.norm(jac, axis=0)
    norms[norms == 0] = 1.0
    r_factor = np.linalg.qr(jac / norms, mode="r")
    _, s, vt = np.linalg.svd(r_factor)
    # (J^T J)^-1 = V S^-2 V^T on the scaled columns; pseudo-inverse guards near-rank loss.
    inv_s2 = np.where(s > RANK_TOLERANCE * s[0], 1.0 / np.maximum(s, 1e-300) ** 2, 0.0)
    cov_scaled = (vt.T * inv_s2) @ vt
    std_unknowns = np.sqrt(np.clip(np.diag(cov_scaled), 0, None) * sigma2) / norms
    names = problem.names()
    weak = [f"{_describe(vt[k], names)} (relative singular value {s[k] / s[0]:.1e})"
            for k in range(len(s)) if s[k] < WEAK_TOLERANCE * s[0]]
    ident = Identifiability(condition_number=float(s[0] / s[-1]), frozen={**frozen, **dropped},
                            weak=weak, singular_values=s)

    values, pose, tools = problem.unpack(x)
    std = np.full(model.n_parameters, np.nan)
    std[free] = std_unknowns[6:6 + len(free)]
    n_tool = 3 * len(tool_names)
    tool_std = std_unknowns[6 + len(free):6 + len(free) + n_tool].reshape(-1, 3)
    fitted_effects = tuple(e.with_values(x[sl], std_unknowns[sl])
                           for e, sl in zip(effects, problem.effect_slices))
    errors = _row_errors(problem, x)[used]
    residual_rms = float(np.sqrt(np.mean(errors**2)))
    residual_max = float(errors.max())

    heldout_rms = heldout_max = heldout_errors = None
    k = min(options.folds, meas.n_poses)
    if k >= 2:
        held = []
        heldout_errors = np.full(meas.n_rows, np.nan)
        for test in pose_folds(meas.pose_ids, k):
            train = ~test & used
            if 3 * train.sum() <= problem.n_unknowns:
                held = []
                break
            sub = make_problem(meas.subset(train), None if inputs is None else inputs.subset(train),
                               free, effects, pose)
            x_fold, _, _ = _fit(sub, sub.pack(values, pose, tools, problem.effect_values(x)), options)
            rows = test & used
            check = make_problem(meas.subset(rows), None if inputs is None else inputs.subset(rows),
                                 free, effects, pose)
            *_, pred = check.predict(x_fold, jacobian=False)
            held.append(np.linalg.norm(pred - meas.points[rows], axis=1))
            heldout_errors[rows] = held[-1]
        if not held:
            heldout_errors = None
        else:
            held_all = np.concatenate(held)
            heldout_rms = float(np.sqrt(np.mean(held_all**2)))
            heldout_max = float(held_all.max())

    validation = Validation(
        method=f"{k}-fold cross-validation by pose" if heldout_rms is not None else "none",
        poses=meas.n_poses, residual_rms_mm=residual_rms * 1e3, residual_max_mm=residual_max * 1e3,
        heldout_rms_mm=None if heldout_rms is None else heldout_rms * 1e3,
        heldout_max_mm=None if heldout_max is None else heldout_max * 1e3,
        condition_number=ident.condition_number)
    calibration = Calibration(
        robot=robot, model=model, values=values, std=std, device_T_base=pose, frozen=frozen,
        tools={name: ToolPoint(xyz_m=tools[t], std_m=tool_std[t]) for t, name in enumerate(tool_names)},
        effects=fitted_effects, validation=validation)
    return IdentificationResult(
        calibration=calibration, identifiability=ident, residual_rms=residual_rms,
        residual_max=residual_max, heldout_rms=heldout_rms, heldout_max=heldout_max,
        n_equations=m_eq, n_unknowns=problem.n_unknowns, n_poses=meas.n_poses,
        iterations=iterations, message=message, outlier_rows=outliers,
        unknown_names=problem.names(), unknown_std=std_unknowns, dropped_effects=dropped,
        heldout_errors=heldout_errors)


def problem_at(calibration: Calibration, meas: Measurements, inputs: EffectInputs | None,
               extra_effects=()) -> tuple[IdentificationProblem, np.ndarray]:
    """The identification problem at a calibration's solution, and its unknown vector:
    free = the parameters with a standard deviation, tools and effects as calibrated, plus
    ``extra_effects`` at zero (their Jacobian columns come last). ``meas.joints`` are
    controller axis values; ``inputs`` as from :func:`measurement_inputs`."""
    robot = calibration.robot
    meas_urdf = dataclasses.replace(meas, joints=robot.joints_from_controller(meas.joints))
    free = np.flatnonzero(~np.isnan(calibration.std))
    tool_names = sorted(calibration.tools)
    effects = tuple(calibration.effects) + tuple(e.with_values(np.zeros(e.n_parameters))
                                                 for e in extra_effects)
    problem = IdentificationProblem(calibration.model, meas_urdf, calibration.values, free,
                                    tool_names, calibration.device_T_base, effects, inputs,
                                    robot.urdf_from_controller)
    tools = np.array([calibration.tools[n].xyz_m for n in tool_names])
    return problem, problem.pack(calibration.values, calibration.device_T_base, tools)
