"""Identification: device registration, Levenberg-Marquardt, statistics, identifiability.

The unknowns are the device frame (6: ``base.tx .. base.rz``, the robot base in the device
frame), the free geometric parameters of the model, one 3-vector per measured tool point
(``tool.NAME.x``...), the rotation of each tool whose rows carry an orientation
(``tool.NAME.rx/ry/rz``, see below) and the parameters of the non-geometric effects asked for
(``joint_compliance j2.c``..., :mod:`olp_compensate.calibration.effects`). Residuals are predicted minus
measured positions in the device frame.

Full-pose rows (``Measurements.orientation``, see :mod:`olp_compensate.io.measurements`) add
three equations each: the rotation vector ``Log(R_meas^T R_pred)`` (rad) from the measured
to the predicted frame of the tool, ``R_pred = R_device_base R_flange R_tool``, where
``R_tool`` is the tool's constant, unknown rotation in the flange frame (started from the
chordal mean of ``R_flange^T R_device_base^T R_meas`` after registration; the unknowns are a
small rotation ``R_tool = R_tool0 Exp(r)`` about the tool's axes). They are weighted by
``position_sigma_mm / orientation_sigma_deg`` (in m/rad), so the fit and sigma^2 =
RSS / (m - n) are in position-equivalent units, m counting both kinds of equations; the
position residuals (mm) and the orientation residuals (deg) are reported apart.

Identifiability (Motta 2006, section 5; Schroer): parameters redundant by construction are
frozen with the reason (the first joint's zero and height define the base frame; the last
joint's zero turns everything after its axis, which the unknown tool points and tool
rotations absorb, with or without orientation rows). Then the SVD of the column-scaled
Jacobian over the actual poses finds combinations the data cannot separate; the pivoted QR
chooses which parameter of each to freeze, and the report names the combination. Effects
come after the geometry: an effect whose columns the kept geometry (and the effects before
it) nearly spans (relative singular value of its projected columns below
``EFFECT_SEPARATION``) is reported and not fitted, so an effect never displaces geometry.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import qr
from scipy.linalg.lapack import dpstrf
from scipy.optimize import least_squares

from .calibration import Calibration, ToolPoint, Validation
from ..kinematics.conventions import (matrix_from_quat_wxyz, quat_wxyz_from_matrix, rotation_from_rotvec,
                          rotvec_from_rotation, skew)
from .effects import (Conditions, Effect, EffectInputs, ThermalExpansion, effect_inputs,
                      needs_torque)
from ..errors import DataError
from .measurements import Measurements
from .lm import levenberg_marquardt
from ..kinematics.model import KinematicModel, build_model, forward, reusable_array
from .registration import register_device
from ..kinematics.robot import Robot

RANK_TOLERANCE = 1e-8
"""Singular values below this fraction of the largest mark an inseparable combination."""
WEAK_TOLERANCE = 1e-4
"""Singular values below this fraction of the largest mark a barely observable combination."""
OUTLIER_QUANTILE_SIGMA = 4.03
"""99.9 % quantile of the norm of a 3-D Gaussian error, in units of the per-axis sigma."""
EFFECT_SEPARATION = 1e-3
"""An effect whose unit-scaled columns keep less than this fraction (smallest singular value)
outside the span of the geometry is reported as inseparable, not fitted."""
CERTAIN_RANK = 1e-5
"""A pivoted Cholesky diagonal of the scaled J^T J above this fraction of the largest proves
full rank without the pivoted QR (J^T J resolves relative singular values down to ~1e-8,
the same order as RANK_TOLERANCE, so nearer cases go to the QR)."""
STEP_TOLERANCE_SIGMA = 1e-4
"""The fit has converged when the remaining step is shorter than this many standard
deviations of the estimate (see :func:`_fit`)."""
NORMAL_EQUATIONS_CONDITION = 1e5
"""Up to this condition number of the unit-scaled Jacobian, the final statistics use the
eigendecomposition of J^T J that the solver formed; beyond it, a QR of the Jacobian."""
REGISTRATION_NAMES = ("base.tx", "base.ty", "base.tz", "base.rx", "base.ry", "base.rz")


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


_LEVI_CIVITA = np.zeros((3, 3, 3))
for _i, _j, _k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _LEVI_CIVITA[_i, _j, _k], _LEVI_CIVITA[_i, _k, _j] = 1.0, -1.0


def _point_index(point_names: np.ndarray, tool_names: list[str]) -> np.ndarray:
    """(m,) position of each row's point name in ``tool_names`` (KeyError for a name not in
    it); one vectorized comparison per tool instead of a lookup per row."""
    names = np.asarray(point_names)
    index = np.full(len(names), -1, dtype=int)
    for k, name in enumerate(tool_names):
        index[names == name] = k
    if np.any(index < 0):
        raise KeyError(names[int(np.argmax(index < 0))])
    return index


def _so3_right_jacobian(phi: np.ndarray) -> np.ndarray:
    theta = math.sqrt(float(phi @ phi))
    k = skew(phi)
    if theta < 1e-8:
        return np.eye(3) - 0.5 * k
    return (np.eye(3) - (1 - math.cos(theta)) / theta**2 * k
            + (theta - math.sin(theta)) / theta**3 * (k @ k))


def _so3_right_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """Inverse right Jacobians (k, 3, 3) of SO(3) at rotation vectors (k, 3):
    ``Log(Exp(phi) Exp(d)) = phi + J_r^-1(phi) d`` to first order."""
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    k = skew(phi)
    small = theta < 1e-4
    t = np.where(small, 1.0, theta)
    c = np.where(small, 1.0 / 12.0 + theta**2 / 720.0,
                 1.0 / t**2 - (1.0 + np.cos(t)) / (2.0 * t * np.sin(t)))
    return np.eye(3) + 0.5 * k + c * (k @ k)


def oriented_rows(meas: Measurements) -> np.ndarray:
    """(m,) True for the rows that carry a measured orientation."""
    if meas.orientation is None:
        return np.zeros(meas.n_rows, dtype=bool)
    return np.all(np.isfinite(meas.orientation), axis=1)


def tool_rotation_start(flange: np.ndarray, device_T_base: np.ndarray, meas: Measurements,
                        names: list[str]) -> dict[str, np.ndarray]:
    """Closed-form rotation (3, 3) of each named tool in the flange frame: the chordal mean
    of ``R_flange^T R_device_base^T R_meas`` over its orientation rows; ``flange`` (m, 4, 4)
    base frame (nominal model), ``device_T_base`` from the registration."""
    rows = oriented_rows(meas)
    out = {}
    for name in names:
        sel = rows & (meas.point_names == name)
        measured = matrix_from_quat_wxyz(meas.orientation[sel])
        estimate = np.swapaxes(flange[sel, :3, :3], 1, 2) @ device_T_base[:3, :3].T @ measured
        u, _, vt = np.linalg.svd(estimate.sum(axis=0))
        d = np.sign(np.linalg.det(u @ vt))
        out[name] = u @ np.diag([1.0, 1.0, d]) @ vt
    return out


class IdentificationProblem:
    """Residuals and analytic Jacobian of one identification (state: the fixed data).

    Unknown vector x = [registration (6) | free geometric parameters | tool points (3 each) |
    tool rotations (3 each) | effect parameters]; the registration is
    ``device_T_base = (R0 Exp(phi), t0 + R0 rho)`` with x[:6] = (rho, phi); a tool rotation is
    ``R_tool0 Exp(r)``. Joint effects deflect the controller axes (``inputs.q``) before
    the chain is evaluated; thermal expansion scales the flange position in the base frame.

    Orientation rows (the rows of the tools in ``tool_rotations0``, name -> reference
    rotation (3, 3) in the flange frame, that carry an orientation) follow the 3m position
    residuals, 3 each, as rotation vectors (rad) times ``orientation_weight`` (m/rad).
    """

    def __init__(self, model: KinematicModel, meas: Measurements, values: np.ndarray,
                 free: np.ndarray, tool_names: list[str], device_T_base0: np.ndarray,
                 effects=(), inputs: EffectInputs | None = None,
                 urdf_from_controller: np.ndarray | None = None,
                 tool_rotations0: dict[str, np.ndarray] | None = None,
                 orientation_weight: float = 1.0):
        self.model = model
        self.q = meas.joints
        self.measured = meas.points
        self.values = np.array(values, dtype=float)
        self.free = np.asarray(free, dtype=int)
        self.tool_names = list(tool_names)
        self.point_index = _point_index(meas.point_names, self.tool_names)
        self.r0 = device_T_base0[:3, :3].copy()
        self.t0 = device_T_base0[:3, 3].copy()
        self.row_weight = np.ones(len(self.measured))
        self.effects: list[Effect] = list(effects)
        if self.effects and inputs is None:
            raise ValueError("effects need their inputs (olp_compensate.calibration.effects.effect_inputs)")
        self.inputs = inputs
        self.coupling = urdf_from_controller
        # Effects are linear in their parameters: precompute each basis (m, p) once.
        self._bases = [e.basis(inputs) for e in self.effects]
        rotations0 = tool_rotations0 or {}
        self.rotated_tools = [n for n in self.tool_names if n in rotations0]
        self.tool_r0 = np.array([rotations0[n] for n in self.rotated_tools]).reshape(-1, 3, 3)
        self.orientation_weight = float(orientation_weight)
        which = {name: k for k, name in enumerate(self.rotated_tools)}
        rows = np.zeros(len(self.measured), dtype=bool)
        if which and meas.orientation is not None:  # position-only problems skip the scan
            rows = oriented_rows(meas) & np.array([n in which for n in meas.point_names], dtype=bool)
        self.oriented_rows = np.flatnonzero(rows)
        self.rotation_index = np.array([which[n] for n in meas.point_names[rows]], dtype=int)
        self.measured_rotation = (matrix_from_quat_wxyz(meas.orientation[rows]) if rows.any()
                                  else np.zeros((0, 3, 3)))
        n_geo = 6 + len(self.free) + 3 * len(self.tool_names) + 3 * len(self.rotated_tools)
        sizes = [e.n_parameters for e in self.effects]
        starts = n_geo + np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.effect_slices = [slice(int(a), int(b)) for a, b in zip(starts[:-1], starts[1:])]

    @property
    def n_effect_parameters(self) -> int:
        return sum(e.n_parameters for e in self.effects)

    @property
    def n_unknowns(self) -> int:
        return (6 + len(self.free) + 3 * len(self.tool_names) + 3 * len(self.rotated_tools)
                + self.n_effect_parameters)

    @property
    def n_oriented(self) -> int:
        """Number of orientation rows (3 equations each)."""
        return len(self.oriented_rows)

    @property
    def rotation_start(self) -> int:
        """Index of the first tool-rotation unknown."""
        return 6 + len(self.free) + 3 * len(self.tool_names)

    def names(self) -> list[str]:
        tools = [f"tool.{n}.{a}" for n in self.tool_names for a in "xyz"]
        rotations = [f"tool.{n}.r{a}" for n in self.rotated_tools for a in "xyz"]
        effects = [f"{e.label}.{p}" for e in self.effects for p in e.parameter_names]
        return (list(REGISTRATION_NAMES) + [self.model.parameters[k].name for k in self.free]
                + tools + rotations + effects)

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

    def tool_rotations(self, x: np.ndarray) -> np.ndarray:
        """Rotations (T, 3, 3) in the flange frame of the tools in ``rotated_tools``."""
        start = self.rotation_start
        r = x[start:start + 3 * len(self.rotated_tools)].reshape(-1, 3)
        return self.tool_r0 @ rotation_from_rotvec(r)

    def effect_values(self, x: np.ndarray) -> list[np.ndarray]:
        """The parameters of each effect, in the order of ``effects``."""
        return [x[s] for s in self.effect_slices]

    def pack(self, values: np.ndarray, device_T_base: np.ndarray, tools: np.ndarray,
             effect_values=None, tool_rotations: np.ndarray | None = None) -> np.ndarray:
        """Unknown vector for the given state, relative to the reference registration;
        ``effect_values`` default to the values the effects carry, ``tool_rotations``
        ((T, 3, 3) for ``rotated_tools``) to the reference rotations."""
        rho = self.r0.T @ (device_T_base[:3, 3] - self.t0)
        phi = rotvec_from_rotation(self.r0.T @ device_T_base[:3, :3])
        if effect_values is None:
            effect_values = [np.array(e.values) for e in self.effects]
        if tool_rotations is None:
            r = np.zeros(3 * len(self.rotated_tools))
        else:
            r = rotvec_from_rotation(np.swapaxes(self.tool_r0, 1, 2) @ tool_rotations).ravel()
        return np.concatenate([rho, phi, values[self.free], np.asarray(tools).ravel(), r,
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
        """Weighted residuals (3m + 3k,), predicted minus measured, device frame, m; then
        the k orientation rows (see the class docstring)."""
        _, pose, _, chain, predicted = self.predict(x, jacobian=False)
        residual = ((predicted - self.measured) * self.row_weight[:, None]).ravel()
        if self.n_oriented:
            residual = np.concatenate([residual, self.orientation_rows(x, pose, chain)[0]])
        return residual

    def orientation_errors(self, x: np.ndarray, pose: np.ndarray | None = None, chain=None,
                           ) -> tuple[np.ndarray, np.ndarray]:
        """(errors (k, 3), predicted (k, 3, 3)) of the orientation rows: the rotation vector
        ``Log(R_meas^T R_pred)`` (rad, about the measured tool frame's axes) and the predicted
        tool frame's rotation in the device frame; unweighted. ``pose``, ``chain`` as from
        :meth:`predict` at x (computed when not given)."""
        if chain is None:
            _, pose, _, chain, _ = self.predict(x, jacobian=False)
        turn = self.tool_rotations(x)[self.rotation_index]
        predicted = pose[:3, :3] @ chain.flange[self.oriented_rows, :3, :3] @ turn
        errors = rotvec_from_rotation(np.swapaxes(self.measured_rotation, 1, 2) @ predicted)
        return errors.reshape(-1, 3), predicted

    def orientation_angles(self, x: np.ndarray) -> np.ndarray:
        """(m,) angle between measured and predicted tool frames, rad; NaN on rows without
        an orientation equation."""
        angles = np.full(len(self.measured), np.nan)
        if self.n_oriented:
            angles[self.oriented_rows] = np.linalg.norm(self.orientation_errors(x)[0], axis=1)
        return angles

    def orientation_rows(self, x: np.ndarray, pose: np.ndarray, chain, jacobian: bool = False,
                         ) -> tuple[np.ndarray, np.ndarray | None]:
        """Weighted orientation residuals (3k,) and, with ``jacobian``, their analytic
        Jacobian (3k, n_unknowns); ``pose``, ``chain`` from :meth:`predict` at x (with its
        Jacobian when ``jacobian``).

        With e = Log(R_meas^T R_pred) and R_pred = R_d F R_t, an angular velocity w of the
        flange (base frame) moves e by ``J_r^-1(e) R_t^T F^T w``; the registration rotation
        acts as w = J_r(phi) dphi, the tool rotation directly in the tool frame."""
        rows = self.oriented_rows
        errors, _ = self.orientation_errors(x, pose, chain)
        weight = (self.orientation_weight * self.row_weight[rows])[:, None]
        residual = (errors * weight).ravel()
        if not jacobian:
            return residual, None
        k = len(rows)
        turn = self.tool_rotations(x)[self.rotation_index]
        jr_inv = _so3_right_jacobian_inverse(errors)
        to_error = jr_inv @ np.swapaxes(turn, 1, 2) @ np.swapaxes(chain.flange[rows, :3, :3], 1, 2)
        jac = np.zeros((k, 3, self.n_unknowns))
        jac[:, :, 3:6] = to_error @ _so3_right_jacobian(x[3:6])
        n_free = len(self.free)
        jac[:, :, 6:6 + n_free] = to_error @ chain.drot_dparam[rows][:, :, self.free]
        start = self.rotation_start
        for t in range(len(self.rotated_tools)):
            sel = self.rotation_index == t
            cols = slice(start + 3 * t, start + 3 * t + 3)
            jac[sel, :, cols] = jr_inv[sel] @ _so3_right_jacobian(x[cols])
        coupling = np.eye(self.model.n_joints) if self.coupling is None else self.coupling
        for effect, basis, cols in zip(self.effects, self._bases, self.effect_slices):
            if effect.acts_on_joint:  # thermal expansion does not turn the flange
                omega = chain.drot_dq[rows] @ coupling[:, effect.joint]
                jac[:, :, cols] = (np.einsum("mij,mj->mi", to_error, omega)[:, :, None]
                                   * basis[rows][:, None, :])
        jac *= weight[:, :, None]
        return residual, jac.reshape(3 * k, -1)

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
        """Residuals (3m + 3k,) and their Jacobian (3m + 3k, n_unknowns), analytic (the k
        orientation rows last, see :meth:`orientation_rows`)."""
        values, pose, tools, chain, predicted = self.predict(x)
        m = len(self.measured)
        rotation = pose[:3, :3]
        # refilled at every evaluation of a fit: a released buffer is reused (page faults)
        jac = reusable_array("jacobian", (m, 3, self.n_unknowns), slots=3)
        jac.fill(0.0)
        jac[:, :, 0:3] = self.r0
        # -R [p]x J_r(phi): column l is a_l x (R p), a_l = R J_r(phi) e_l; as p @ (3, 9)
        cross = np.einsum("ijk,jl->kil", _LEVI_CIVITA, rotation @ _so3_right_jacobian(x[3:6]))
        jac[:, :, 3:6] = (chain.points @ (rotation.T @ cross.reshape(3, 9))).reshape(m, 3, 3)
        k = len(self.free)
        # R dp/dparam, on the (P, 3, m) layout forward computes (a view when free is a range)
        dpoint = chain.dpoint_dparam.transpose(2, 1, 0)
        contiguous = k > 0 and self.free[-1] - self.free[0] == k - 1
        free = slice(self.free[0], self.free[-1] + 1) if contiguous else self.free
        np.matmul(rotation, dpoint[free], out=jac[:, :, 6:6 + k].transpose(2, 1, 0))
        if len(self.tool_names) == 1:
            np.matmul(rotation, chain.flange[:, :3, :3], out=jac[:, :, 6 + k:9 + k])
        else:
            tool_block = np.matmul(rotation, chain.flange[:, :3, :3])
            for t in range(len(self.tool_names)):
                rows = self.point_index == t
                jac[rows, :, 6 + k + 3 * t:9 + k + 3 * t] = tool_block[rows]
        scale = self._scale(x)
        origin = None if scale is None else chain.flange[:, :3, 3] / scale[:, None]
        for effect, basis, cols in zip(self.effects, self._bases, self.effect_slices):
            jac[:, :, cols] = self.effect_columns(effect, basis, chain, pose, origin)
        w = self.row_weight[:, None]
        residual = ((predicted - self.measured) * w).ravel()
        if np.any(w != 1.0):
            jac *= w[:, :, None]
        jac = jac.reshape(3 * m, -1)
        if self.n_oriented:
            residual_o, jac_o = self.orientation_rows(x, pose, chain, jacobian=True)
            residual, jac = np.concatenate([residual, residual_o]), np.vstack([jac, jac_o])
        return residual, jac


def structural_freeze(model: KinematicModel, meas: Measurements, tool_names: list[str],
                      user_freeze: tuple[str, ...], rotated_tools=()) -> dict[str, str]:
    """Parameters redundant by construction, and the user's, name -> reason.

    The last joint's zero ``Rz(q_n + theta_n)`` turns everything after axis n, which is only
    the tools: turning every tool point (and, with orientation rows, every tool rotation)
    about that axis gives the same measurements, however many points per pose are measured,
    so it is held at nominal and the tools are found in the flange frame of the nominal zero
    (it is observable only against a tool known beforehand, which identification does not
    assume)."""
    frozen = {}
    for name in ("j1.theta", "j1.d"):
        if name in model.names:
            frozen[name] = ("redundant with the device registration (the base frame is defined "
                            "by axis 1: its zero and height)")
    last = model.n_joints
    if model.joint_kinds[-1] == "revolute":
        what = "tool points and tool rotations" if rotated_tools else "tool points"
        frozen[f"j{last}.theta"] = (
            f"redundant with the tools: the last joint's zero turns them about axis {last}, "
            f"which their unknown {what} absorb (held at nominal; the tools are found in the "
            f"flange frame of the nominal zero)")
    for name in user_freeze:
        if name not in model.names:
            raise DataError(f"--freeze: no parameter named '{name}' (known: {', '.join(model.names)})")
        frozen[name] = "held at nominal on request"
    return frozen


def _describe(vector: np.ndarray, names: list[str]) -> str:
    order = np.argsort(-np.abs(vector))
    parts = [names[k] for k in order[:4] if abs(vector[k]) > 0.15 * abs(vector[order[0]])]
    return " + ".join(parts)


def _unit_scaled_svd(jac: np.ndarray, normal: np.ndarray | None = None):
    """(column norms (n,), singular values s (descending), V^T) of the Jacobian with its
    columns scaled to unit norm.

    With ``normal`` = J^T J at hand (the solver's), from its eigendecomposition when the
    scaled Jacobian's condition number is below ``NORMAL_EQUATIONS_CONDITION`` (J^T J squares
    it: the relative error of s and of the covariance stays below cond^2 * eps = 1e-6);
    otherwise, or without ``normal``, from a QR of the scaled Jacobian and the SVD of R."""
    if normal is not None:
        norms = np.sqrt(np.diag(normal))
        norms[norms == 0] = 1.0
        lam, vec = np.linalg.eigh(normal / np.outer(norms, norms))
        if lam[0] > lam[-1] / NORMAL_EQUATIONS_CONDITION**2:
            return norms, np.sqrt(lam[::-1]), vec[:, ::-1].T
    norms = np.sqrt(np.einsum("ij,ij->j", jac, jac))
    norms[norms == 0] = 1.0
    _, r_factor = qr(_unit_columns(jac, np.arange(jac.shape[1]), norms), mode="raw",
                     overwrite_a=True, check_finite=False)
    _, s, vt = np.linalg.svd(r_factor)
    return norms, s, vt


def _unit_columns(jac: np.ndarray, columns: np.ndarray, norms: np.ndarray) -> np.ndarray:
    """``jac[:, columns] / norms[columns]``, a new Fortran-ordered array (LAPACK's order:
    its QR then works in place)."""
    out = np.empty((len(jac), len(columns)), order="F")
    if len(columns) == jac.shape[1]:  # all of them, in order: no intermediate copy
        return np.divide(jac, norms, out=out)
    return np.divide(jac[:, columns], norms[columns], out=out)


def analyse_identifiability(problem: IdentificationProblem, x: np.ndarray,
                            jacobian: np.ndarray | None = None, normal: np.ndarray | None = None,
                            ) -> tuple[Identifiability, np.ndarray]:
    """SVD of the unit-column-scaled Jacobian at x (``jacobian``, and ``normal`` = J^T J,
    when the caller has them); returns the analysis and a boolean mask over the unknowns that
    are kept (inseparable ones dropped by pivoted QR; effects that the kept geometry nearly
    spans dropped by :func:`effect_separation`).

    With ``normal``, the pivoted Cholesky factorization of the scaled J^T J (the pivoted QR's
    R in exact arithmetic, n x n work) settles the usual case: when its smallest diagonal
    exceeds ``CERTAIN_RANK`` times its largest, the pivoted QR, whose threshold
    ``RANK_TOLERANCE`` is far lower, would keep every column too, and is skipped."""
    jac = problem.residuals_and_jacobian(x)[1] if jacobian is None else jacobian
    names = problem.names()
    n_geo = problem.n_unknowns - problem.n_effect_parameters
    if normal is None:
        norms = np.sqrt(np.einsum("ij,ij->j", jac, jac))
    else:
        norms = np.sqrt(np.diag(normal))
    frozen = {}
    keep = norms > 1e-12 * max(norms.max(), 1e-300)
    for k in np.flatnonzero(~keep[:n_geo]):
        frozen[names[k]] = "has no effect on the measured points with these poses"
    keep[n_geo:] = False  # effects join one by one below, after the geometry
    geo = np.flatnonzero(keep[:n_geo])
    scaled = r = None
    if normal is not None:
        scaled = normal[np.ix_(geo, geo)] / np.outer(norms[geo], norms[geo])
        factor, _, _, info = dpstrf(scaled)
        diag = np.abs(np.diag(factor))
        if info != 0 or diag.min() <= CERTAIN_RANK * diag.max():
            scaled = None  # not clearly regular: the pivoted QR decides
    if scaled is None:
        if normal is not None:  # the QR's own column norms (J^T J's agree to rounding)
            norms = np.sqrt(np.einsum("ij,ij->j", jac, jac))
        _, r, pivots = qr(_unit_columns(jac, geo, norms), mode="raw", pivoting=True,
                          overwrite_a=True, check_finite=False)
        diag = np.abs(np.diag(r))
        rank = int(np.sum(diag > RANK_TOLERANCE * diag[0]))
    else:
        rank = len(geo)
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
    if np.array_equal(np.flatnonzero(keep), geo) and r is None:  # clearly regular
        # s^2 from the scaled J^T J, to a relative error below eps / CERTAIN_RANK^2
        s, vt = np.sqrt(np.maximum(np.linalg.eigvalsh(scaled)[::-1], 0.0)), None
        if s[-1] < WEAK_TOLERANCE * s[0]:  # the weak combinations are wanted: vectors too
            lam, vec = np.linalg.eigh(scaled)
            s, vt = np.sqrt(np.maximum(lam[::-1], 0.0)), vec[:, ::-1].T
    elif np.array_equal(np.flatnonzero(keep), geo):  # the pivoted QR above is this one's
        s = np.linalg.svd(r, compute_uv=False)
        vt = None
        if s[-1] < WEAK_TOLERANCE * s[0]:  # the weak combinations are wanted: vectors too
            _, s, vt_r = np.linalg.svd(r)
            vt = np.empty_like(vt_r)
            vt[:, pivots] = vt_r
    else:
        _, s, vt = np.linalg.svd(np.linalg.qr(jac[:, keep] / norms[keep], mode="r"))
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


def _fit(problem: IdentificationProblem, x0: np.ndarray, options: IdentificationOptions,
         initial: tuple[np.ndarray, np.ndarray] | None = None):
    """(x, iterations, message, (residuals, Jacobian, J^T J) at x or None); ``initial``:
    the residuals and Jacobian at x0 when known.

    LM stops once the decrease of the cost still to come (Gauss-Newton's prediction) or that
    of the last step is below STEP_TOLERANCE_SIGMA^2 / dof of the cost: with
    sigma^2 = 2 cost / dof, a step shorter than STEP_TOLERANCE_SIGMA standard deviations of
    the estimate (Mahalanobis length), far below what the data resolve."""
    if options.solver == "lm":
        dof = 3 * len(problem.measured) + 3 * problem.n_oriented - problem.n_unknowns
        result = levenberg_marquardt(problem.residuals_and_jacobian, x0,
                                     max_iterations=options.max_iterations,
                                     ftol=STEP_TOLERANCE_SIGMA**2 / max(dof, 1),
                                     residuals=problem.residuals, initial=initial)
        return (result.x, result.iterations, result.message,
                (result.residuals, result.jacobian, result.normal))
    if options.solver == "trf":
        result = least_squares(problem.residuals, x0,
                               jac=lambda x: problem.residuals_and_jacobian(x)[1],
                               method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12)
        return result.x, int(result.nfev), result.message, None
    raise ValueError(f"solver must be 'lm' or 'trf', got {options.solver!r}")


def _row_errors(problem: IdentificationProblem, x: np.ndarray) -> np.ndarray:
    *_, predicted = problem.predict(x, jacobian=False)
    return np.linalg.norm(predicted - problem.measured, axis=1)


def _degrees(angle_rad: float | None) -> float | None:
    return None if angle_rad is None else float(np.degrees(angle_rad))


def _inlier_weight(problem: IdentificationProblem, x: np.ndarray) -> np.ndarray:
    """Row weights (m,) for the robust fit: 0 for a row whose position error, or whose
    orientation error, exceeds the 99.9 % quantile of its kind. Each kind's per-axis sigma
    is the smaller of a robust one (median) and RSS / (3 rows) scaled by M / (M - n), M all
    equations (the degrees of freedom shared out between the kinds)."""
    inliers = problem.row_weight > 0
    errors = _row_errors(problem, x)
    angles = problem.orientation_angles(x)
    with_angle = inliers & np.isfinite(angles)
    m_eq = 3 * inliers.sum() + 3 * with_angle.sum()
    inflate = m_eq / max(m_eq - problem.n_unknowns, 1)
    reject = np.zeros(len(errors), dtype=bool)
    for err, rows in ((errors, inliers), (angles, with_angle)):
        if not rows.any():
            continue
        sigma = np.sqrt(np.sum(err[rows] ** 2) / (3 * rows.sum()) * inflate)
        med_sigma = np.median(err[rows]) / 1.5382
        reject |= np.nan_to_num(err, nan=0.0) > OUTLIER_QUANTILE_SIGMA * min(sigma, med_sigma)
    return (~reject).astype(float)


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
    measured points, and orientations where the rows have them (see module docstring).
    ``meas.joints`` are controller axis values; the model works in URDF joints."""
    if not (options.position_sigma_mm > 0 and options.orientation_sigma_deg > 0):
        raise DataError(f"the position and orientation sigmas must be positive, got "
                        f"{options.position_sigma_mm} mm and {options.orientation_sigma_deg} deg")
    effects = _check_effects(robot, meas, options.effects)
    meas_ctrl = meas
    meas = dataclasses.replace(meas, joints=robot.joints_from_controller(meas.joints))
    _check_data(robot, meas)
    model = build_model(robot, options.convention)
    tool_names = sorted(set(meas.point_names))
    oriented = oriented_rows(meas)
    rotated_tools = sorted(set(meas.point_names[oriented]))
    frozen = structural_freeze(model, meas, tool_names, options.freeze, rotated_tools)
    candidate = np.array([k for k, p in enumerate(model.parameters) if p.name not in frozen], dtype=int)
    n_unknowns = (6 + len(candidate) + 3 * len(tool_names) + 3 * len(rotated_tools)
                  + sum(e.n_parameters for e in effects))
    n_equations = 3 * meas.n_rows + 3 * int(oriented.sum())
    if n_equations <= n_unknowns:
        per_row = 6 if oriented.all() else 3
        orientations = f" + {int(oriented.sum())} orientations x 3" if oriented.any() else ""
        raise DataError(
            f"{meas.source}: {n_equations} equations ({meas.n_rows} measured points x 3"
            f"{orientations}) for {n_unknowns} unknowns; measure at least "
            f"{-(-(n_unknowns + 1 - n_equations) // per_row)} more "
            f"points (poses in the same count, spread over the workspace)")

    nominal_flange = forward(model, model.nominal, meas.joints).flange
    point_index = _point_index(meas.point_names, tool_names)
    device_T_base, tools0 = register_device(nominal_flange, meas.points, point_index, len(tool_names))
    rotations0 = tool_rotation_start(nominal_flange, device_T_base, meas, rotated_tools)
    weight = options.orientation_weight
    inputs = None
    if effects:
        inputs = measurement_inputs(robot, meas_ctrl, dict(zip(tool_names, tools0)), effects)
    coupling = robot.urdf_from_controller

    def make_problem(rows_meas, rows_inputs, free_, effects_, reference):
        return IdentificationProblem(model, rows_meas, model.nominal, free_, tool_names,
                                     reference, effects_, rows_inputs, coupling, rotations0, weight)

    problem = make_problem(meas, inputs, candidate, effects, device_T_base)
    x0 = problem.pack(model.nominal, device_T_base, tools0,
                      [np.zeros(e.n_parameters) for e in effects])
    residual0, jac0 = problem.residuals_and_jacobian(x0)  # for the analysis and the fit
    at_x0 = (residual0, jac0, jac0.T @ jac0)
    del residual0, jac0
    ident, keep = analyse_identifiability(problem, x0, at_x0[1], at_x0[2])
    dropped = {e.label: ident.frozen.pop(e.label) for e in effects if e.label in ident.frozen}
    frozen.update(ident.frozen)
    names_all = problem.names()
    parameter_index = {name: k for k, name in enumerate(model.names)}
    free = np.array([parameter_index[n] for n, k in zip(names_all, keep)
                     if k and n in parameter_index], dtype=int)
    effects = tuple(e for e in effects if e.label not in dropped)
    problem = make_problem(meas, inputs, free, effects, device_T_base)
    # The same state (effects at zero) with fewer unknowns: x0 and the start's Jacobian with
    # the remaining columns.
    column = {name: k for k, name in enumerate(names_all)}
    columns = [column[n] for n in problem.names()]
    x0 = x0[columns]
    if columns != list(range(len(names_all))):
        at_x0 = (at_x0[0], at_x0[1][:, columns], at_x0[2][np.ix_(columns, columns)])

    x, iterations, message, evaluation = _fit(problem, x0, options, at_x0)
    outliers: list[int] = []
    if options.robust:
        for _ in range(5):
            new_weight = _inlier_weight(problem, x)
            if np.array_equal(new_weight, problem.row_weight):
                break
            problem.row_weight = new_weight
            x, iterations, message, evaluation = _fit(problem, x, options)
        outliers = [int(meas.rows[k]) if meas.rows is not None else k
                    for k in np.flatnonzero(problem.row_weight == 0)]

    if evaluation is None:
        evaluation = (*problem.residuals_and_jacobian(x), None)
    residual, jac, normal = evaluation
    used = problem.row_weight > 0
    m_eq = 3 * int(used.sum()) + 3 * int(used[problem.oriented_rows].sum())
    dof = m_eq - problem.n_unknowns
    sigma2 = float(residual @ residual) / max(dof, 1)
    norms, s, vt = _unit_scaled_svd(jac, normal)
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
    start = problem.rotation_start
    rotation_std = std_unknowns[start:start + 3 * len(rotated_tools)].reshape(-1, 3)
    rotations = problem.tool_rotations(x)
    fitted_effects = tuple(e.with_values(x[sl], std_unknowns[sl])
                           for e, sl in zip(effects, problem.effect_slices))
    m_rows = len(problem.measured)
    if np.all(problem.row_weight[used] == 1.0):  # the position rows of the residual at x
        errors = np.linalg.norm(residual[:3 * m_rows].reshape(m_rows, 3), axis=1)[used]
    else:
        errors = _row_errors(problem, x)[used]
    residual_rms = float(np.sqrt(np.mean(errors**2)))
    residual_max = float(errors.max())
    angles = problem.orientation_angles(x)[used]
    angles = angles[np.isfinite(angles)]
    orientation_rms = float(np.sqrt(np.mean(angles**2))) if angles.size else None
    orientation_max = float(angles.max()) if angles.size else None

    heldout_rms = heldout_max = heldout_errors = None
    heldout_orientation_rms = heldout_orientation_max = None
    n_poses = len(set(meas.pose_ids.tolist()))  # = meas.n_poses, without sorting strings
    k = min(options.folds, n_poses)
    if k >= 2:
        held, held_angles = [], []
        heldout_errors = np.full(meas.n_rows, np.nan)
        for test in pose_folds(meas.pose_ids, k):
            train = ~test & used
            if 3 * train.sum() + 3 * (train & oriented).sum() <= problem.n_unknowns:
                held = []
                break
            sub = make_problem(meas.subset(train), None if inputs is None else inputs.subset(train),
                               free, effects, pose)
            x_fold, *_ = _fit(sub, sub.pack(values, pose, tools, problem.effect_values(x),
                                              rotations), options)
            rows = test & used
            check = make_problem(meas.subset(rows), None if inputs is None else inputs.subset(rows),
                                 free, effects, pose)
            *_, pred = check.predict(x_fold, jacobian=False)
            held.append(np.linalg.norm(pred - meas.points[rows], axis=1))
            heldout_errors[rows] = held[-1]
            fold_angles = check.orientation_angles(x_fold)
            held_angles.append(fold_angles[np.isfinite(fold_angles)])
        if not held:
            heldout_errors = None
        else:
            held_all = np.concatenate(held)
            heldout_rms = float(np.sqrt(np.mean(held_all**2)))
            heldout_max = float(held_all.max())
            angles_all = np.concatenate(held_angles)
            if angles_all.size:
                heldout_orientation_rms = float(np.sqrt(np.mean(angles_all**2)))
                heldout_orientation_max = float(angles_all.max())

    validation = Validation(
        method=f"{k}-fold cross-validation by pose" if heldout_rms is not None else "none",
        poses=n_poses, residual_rms_mm=residual_rms * 1e3, residual_max_mm=residual_max * 1e3,
        heldout_rms_mm=None if heldout_rms is None else heldout_rms * 1e3,
        heldout_max_mm=None if heldout_max is None else heldout_max * 1e3,
        condition_number=ident.condition_number,
        orientation_rms_deg=_degrees(orientation_rms), orientation_max_deg=_degrees(orientation_max),
        heldout_orientation_rms_deg=_degrees(heldout_orientation_rms),
        heldout_orientation_max_deg=_degrees(heldout_orientation_max))
    tool_points = {}
    for t, name in enumerate(tool_names):
        quat = rot_std = None
        if name in rotated_tools:
            r = rotated_tools.index(name)
            quat, rot_std = quat_wxyz_from_matrix(rotations[r]), rotation_std[r]
        tool_points[name] = ToolPoint(xyz_m=tools[t], std_m=tool_std[t], quat_wxyz=quat,
                                      rot_std_rad=rot_std)
    calibration = Calibration(
        robot=robot, model=model, values=values, std=std, device_T_base=pose, frozen=frozen,
        tools=tool_points, effects=fitted_effects, validation=validation)
    return IdentificationResult(
        calibration=calibration, identifiability=ident, residual_rms=residual_rms,
        residual_max=residual_max, heldout_rms=heldout_rms, heldout_max=heldout_max,
        n_equations=m_eq, n_unknowns=problem.n_unknowns, n_poses=n_poses,
        iterations=iterations, message=message, outlier_rows=outliers,
        unknown_names=problem.names(), unknown_std=std_unknowns, dropped_effects=dropped,
        heldout_errors=heldout_errors, orientation_rms=orientation_rms,
        orientation_max=orientation_max, heldout_orientation_rms=heldout_orientation_rms,
        heldout_orientation_max=heldout_orientation_max,
        n_orientation_rows=int(used[problem.oriented_rows].sum()))


def problem_at(calibration: Calibration, meas: Measurements, inputs: EffectInputs | None,
               extra_effects=()) -> tuple[IdentificationProblem, np.ndarray]:
    """The identification problem at a calibration's solution, and its unknown vector:
    free = the parameters with a standard deviation, tools and effects as calibrated, plus
    ``extra_effects`` at zero (their Jacobian columns come last). ``meas.joints`` are
    controller axis values; ``inputs`` as from :func:`measurement_inputs`. Positions only:
    the problem has no orientation rows (its residuals are (3m,), as the diagnosis needs)."""
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
