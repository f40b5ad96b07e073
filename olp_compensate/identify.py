"""Identification: device registration, Levenberg-Marquardt, statistics, identifiability.

The unknowns are the device frame (6: ``base.tx .. base.rz``, the robot base in the device
frame), the free geometric parameters of the model, and one 3-vector per measured tool point
(``tool.NAME.x``...). Residuals are predicted minus measured positions in the device frame.

Identifiability (Motta 2006, section 5; Schroer): parameters redundant by construction are
frozen with the reason (the first joint's zero and height define the base frame; one measured
point and no orientation cannot see the last joint's zero). Then the SVD of the column-scaled
Jacobian over the actual poses finds combinations the data cannot separate; the pivoted QR
chooses which parameter of each to freeze, and the report names the combination.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import qr
from scipy.optimize import least_squares

from .calibration import Calibration, ToolPoint, Validation
from .conventions import rotation_from_rotvec, rotvec_from_rotation, skew
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
REGISTRATION_NAMES = ("base.tx", "base.ty", "base.tz", "base.rx", "base.ry", "base.rz")


@dataclass(frozen=True)
class IdentificationOptions:
    """Choices of an identification: ``convention`` 'auto' or 'dh'; ``solver`` 'lm' (ours,
    eq. 52) or 'trf' (scipy's trust region, analytic Jacobian); ``robust`` rejects rows whose
    residual exceeds the 99.9 % noise quantile and refits; ``folds`` for cross-validation
    (0 or 1: none); ``freeze``: parameter names the user holds at nominal."""

    convention: str = "auto"
    solver: str = "lm"
    robust: bool = False
    folds: int = 5
    freeze: tuple[str, ...] = ()
    max_iterations: int = 100


@dataclass(frozen=True)
class Identifiability:
    """What the poses can and cannot tell apart.

    ``frozen``: parameter name -> reason; ``weak``: descriptions of barely observable
    combinations; ``condition_number`` of the unit-column-scaled Jacobian of the unknowns.
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


def _so3_right_jacobian(phi: np.ndarray) -> np.ndarray:
    theta = np.linalg.norm(phi)
    k = skew(phi)
    if theta < 1e-8:
        return np.eye(3) - 0.5 * k
    return (np.eye(3) - (1 - np.cos(theta)) / theta**2 * k
            + (theta - np.sin(theta)) / theta**3 * (k @ k))


class IdentificationProblem:
    """Residuals and analytic Jacobian of one identification (state: the fixed data).

    Unknown vector x = [registration (6) | free geometric parameters | tool points (3 each)];
    the registration is ``device_T_base = (R0 Exp(phi), t0 + R0 rho)`` with x[:6] = (rho, phi).
    """

    def __init__(self, model: KinematicModel, meas: Measurements, values: np.ndarray,
                 free: np.ndarray, tool_names: list[str], device_T_base0: np.ndarray):
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

    @property
    def n_unknowns(self) -> int:
        return 6 + len(self.free) + 3 * len(self.tool_names)

    def names(self) -> list[str]:
        tools = [f"tool.{n}.{a}" for n in self.tool_names for a in "xyz"]
        return list(REGISTRATION_NAMES) + [self.model.parameters[k].name for k in self.free] + tools

    def unpack(self, x: np.ndarray):
        """(values (P,), device_T_base (4, 4), tools (T, 3)) for an unknown vector."""
        values = self.values.copy()
        values[self.free] = x[6:6 + len(self.free)]
        tools = x[6 + len(self.free):].reshape(-1, 3)
        pose = np.eye(4)
        pose[:3, :3] = self.r0 @ rotation_from_rotvec(x[3:6])
        pose[:3, 3] = self.t0 + self.r0 @ x[:3]
        return values, pose, tools

    def pack(self, values: np.ndarray, device_T_base: np.ndarray, tools: np.ndarray) -> np.ndarray:
        """Unknown vector for the given state, relative to the reference registration."""
        rho = self.r0.T @ (device_T_base[:3, 3] - self.t0)
        phi = rotvec_from_rotation(self.r0.T @ device_T_base[:3, :3])
        return np.concatenate([rho, phi, values[self.free], np.asarray(tools).ravel()])

    def predict(self, x: np.ndarray, jacobian: bool = True):
        values, pose, tools = self.unpack(x)
        chain = forward(self.model, values, self.q, tools[self.point_index], jacobian=jacobian)
        rotation = pose[:3, :3]
        predicted = chain.points @ rotation.T + pose[:3, 3]
        return values, pose, tools, chain, predicted

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Weighted residuals (3m,), predicted minus measured, device frame, m."""
        *_, predicted = self.predict(x, jacobian=False)
        return ((predicted - self.measured) * self.row_weight[:, None]).ravel()

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
    over the unknowns that are kept (inseparable ones dropped by pivoted QR)."""
    _, jac = problem.residuals_and_jacobian(x)
    names = problem.names()
    norms = np.linalg.norm(jac, axis=0)
    frozen = {}
    keep = norms > 1e-12 * max(norms.max(), 1e-300)
    for k in np.flatnonzero(~keep):
        frozen[names[k]] = "has no effect on the measured points with these poses"
    js = jac[:, keep] / norms[keep]
    r, pivots = qr(js, mode="r", pivoting=True)
    r = r[:js.shape[1]]
    diag = np.abs(np.diag(r))
    rank = int(np.sum(diag > RANK_TOLERANCE * diag[0]))
    kept_idx = np.flatnonzero(keep)
    if rank < len(kept_idx):
        # J P = Q R, so the right singular vectors of J are those of R with rows un-pivoted.
        _, _, vt_r = np.linalg.svd(r)
        vt_all = np.empty_like(vt_r)
        vt_all[:, pivots] = vt_r
        null = vt_all[rank:]
        sub_names = [names[k] for k in kept_idx]
        for col in pivots[rank:]:
            contribution = np.abs(null[:, col])
            v = null[int(np.argmax(contribution))]
            frozen[names[kept_idx[col]]] = (
                f"cannot be separated with these poses (combination {_describe(v, sub_names)})")
        keep[kept_idx[pivots[rank:]]] = False
    js = jac[:, keep] / norms[keep]
    _, s, vt = np.linalg.svd(np.linalg.qr(js, mode="r"))
    kept_names = [names[k] for k in np.flatnonzero(keep)]
    weak = [f"{_describe(vt[k], kept_names)} (relative singular value {s[k] / s[0]:.1e})"
            for k in range(len(s)) if s[k] < WEAK_TOLERANCE * s[0]]
    return Identifiability(condition_number=float(s[0] / s[-1]), frozen=frozen, weak=weak,
                           singular_values=s), keep


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


def _folds(pose_ids: np.ndarray, k: int) -> list[np.ndarray]:
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


def identify(robot: Robot, meas: Measurements,
             options: IdentificationOptions = IdentificationOptions()) -> IdentificationResult:
    """Identify the geometry of ``robot`` from measured points (see module docstring).
    ``meas.joints`` are controller axis values; the model works in URDF joints."""
    meas = dataclasses.replace(meas, joints=robot.joints_from_controller(meas.joints))
    _check_data(robot, meas)
    model = build_model(robot, options.convention)
    tool_names = sorted(set(meas.point_names))
    frozen = _structural_freeze(model, meas, tool_names, options.freeze)
    candidate = np.array([k for k, p in enumerate(model.parameters) if p.name not in frozen], dtype=int)
    n_unknowns = 6 + len(candidate) + 3 * len(tool_names)
    n_equations = 3 * meas.n_rows
    if n_equations <= n_unknowns:
        raise DataError(
            f"{meas.source}: {n_equations} equations ({meas.n_rows} measured points x 3) for "
            f"{n_unknowns} unknowns; measure at least {n_unknowns // 3 + 1 - meas.n_rows} more "
            f"points (poses in the same count, spread over the workspace)")

    nominal_flange = forward(model, model.nominal, meas.joints).flange
    point_index = np.array([tool_names.index(n) for n in meas.point_names])
    device_T_base, tools0 = register_device(nominal_flange, meas.points, point_index, len(tool_names))

    problem = IdentificationProblem(model, meas, model.nominal, candidate, tool_names, device_T_base)
    x0 = problem.pack(model.nominal, device_T_base, tools0)
    ident, keep = analyse_identifiability(problem, x0)
    frozen.update(ident.frozen)
    names_all = problem.names()
    free = np.array([model.index(n) for n, k in zip(names_all, keep)
                     if k and n in model.names], dtype=int)
    problem = IdentificationProblem(model, meas, model.nominal, free, tool_names, device_T_base)
    x0 = problem.pack(model.nominal, device_T_base, tools0)

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
    ident = Identifiability(condition_number=float(s[0] / s[-1]), frozen=frozen,
                            weak=weak, singular_values=s)

    values, pose, tools = problem.unpack(x)
    std = np.full(model.n_parameters, np.nan)
    std[free] = std_unknowns[6:6 + len(free)]
    tool_std = std_unknowns[6 + len(free):].reshape(-1, 3)
    errors = _row_errors(problem, x)[used]
    residual_rms = float(np.sqrt(np.mean(errors**2)))
    residual_max = float(errors.max())

    heldout_rms = heldout_max = None
    k = min(options.folds, meas.n_poses)
    if k >= 2:
        held = []
        for test in _folds(meas.pose_ids, k):
            train = ~test & used
            if 3 * train.sum() <= problem.n_unknowns:
                held = []
                break
            sub = IdentificationProblem(model, meas.subset(train), model.nominal, free,
                                        tool_names, pose)
            x_fold, _, _ = _fit(sub, sub.pack(values, pose, tools), options)
            fold_values, fold_pose, fold_tools = sub.unpack(x_fold)
            pred = forward(model, fold_values, meas.joints[test & used],
                           fold_tools[point_index[test & used]]).points
            pred = pred @ fold_pose[:3, :3].T + fold_pose[:3, 3]
            held.append(np.linalg.norm(pred - meas.points[test & used], axis=1))
        if held:
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
        validation=validation)
    return IdentificationResult(
        calibration=calibration, identifiability=ident, residual_rms=residual_rms,
        residual_max=residual_max, heldout_rms=heldout_rms, heldout_max=heldout_max,
        n_equations=m_eq, n_unknowns=problem.n_unknowns, n_poses=meas.n_poses,
        iterations=iterations, message=message, outlier_rows=outliers,
        unknown_names=problem.names(), unknown_std=std_unknowns)
