"""The identification problem: residuals and analytic Jacobian over the unknown vector.

Residuals are predicted minus measured positions in the device frame, m; full-pose rows
(``Measurements.orientation``) add the rotation vector ``Log(R_meas^T R_pred)`` (rad) from
the measured to the predicted frame of the tool, ``R_pred = R_device_base R_flange R_tool``,
weighted by ``orientation_weight`` (m/rad). The unknowns are laid out by
:class:`olp_compensate.calibration.unknowns.UnknownLayout`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from ..kinematics.conventions import (matrix_from_quat_wxyz, rotation_from_rotvec,
                                      rotvec_from_rotation, skew)
from ..kinematics.buffers import reusable_array
from ..kinematics.model import KinematicModel, forward
from .calibration import Calibration
from .measurements import Measurements
from .unknowns import UnknownLayout

if TYPE_CHECKING:  # types only: the effects' module loads when effects are fitted
    from .effects import Effect, EffectInputs

_LEVI_CIVITA = np.zeros((3, 3, 3))
for _i, _j, _k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _LEVI_CIVITA[_i, _j, _k], _LEVI_CIVITA[_i, _k, _j] = 1.0, -1.0


def point_index(point_names: np.ndarray, tool_names: list[str]) -> np.ndarray:
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

    The unknown vector is laid out by ``layout`` (:class:`UnknownLayout`); the registration
    is ``device_T_base = (R0 Exp(phi), t0 + R0 rho)``, a tool rotation ``R_tool0 Exp(r)``.
    ``free``: indices (into the model's parameters) of the free geometric parameters.
    Joint effects deflect the controller axes (``inputs.q``) before
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
                 orientation_weight: float = 1.0,
                 row_scales: tuple[np.ndarray, np.ndarray] | None = None):
        self.model = model
        self.q = meas.joints
        self.measured = meas.points
        self.values = np.array(values, dtype=float)
        self.free = np.asarray(free, dtype=int)
        self.tool_names = list(tool_names)
        self.point_index = point_index(meas.point_names, self.tool_names)
        self.r0 = device_T_base0[:3, :3].copy()
        self.t0 = device_T_base0[:3, 3].copy()
        self.row_weight = np.ones(len(self.measured))
        """(m,) 1, or 0 for a row the robust fit rejected."""
        ones = np.ones(len(self.measured))
        self.position_scale, self.rotation_scale = (ones, ones) if row_scales is None else (
            np.asarray(row_scales[0], dtype=float), np.asarray(row_scales[1], dtype=float))
        """(m,) each row's weight from its own uncertainty (sigma_mm, sigma_deg columns):
        the reference sigma over the row's; ones without those columns."""
        self.effects: list[Effect] = list(effects)
        if self.effects and inputs is None:
            raise ValueError("effects need their inputs "
                             "(olp_compensate.calibration.effects.effect_inputs)")
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
            rows = oriented_rows(meas) & np.isin(meas.point_names, list(which))
        self.oriented_rows = np.flatnonzero(rows)
        self.rotation_index = np.array([which[n] for n in meas.point_names[rows]], dtype=int)
        self.measured_rotation = (matrix_from_quat_wxyz(meas.orientation[rows]) if rows.any()
                                  else np.zeros((0, 3, 3)))
        self.layout = UnknownLayout.build(
            geometry_names=[model.parameters[k].name for k in self.free],
            tool_names=self.tool_names, rotated_tools=self.rotated_tools,
            effect_names=[[f"{e.label}.{p}" for p in e.parameter_names] for e in self.effects])
        self.held = np.zeros(self.layout.size, dtype=bool)
        """(n,) True for a registration or tool unknown frozen by the identifiability
        analysis: held at its value in the start vector, not fitted (:meth:`held_view`)."""

    @property
    def n_unknowns(self) -> int:
        """The fitted unknowns (the layout's, less the held ones)."""
        return self.layout.size - int(self.held.sum())

    def held_view(self, x0: np.ndarray) -> "HeldView":
        """The problem over its fitted unknowns, the held ones at their values in x0."""
        return HeldView(self, x0)

    @property
    def n_oriented(self) -> int:
        """Number of orientation rows (3 equations each)."""
        return len(self.oriented_rows)

    def names(self) -> list[str]:
        """Every unknown's name, in the order of the unknown vector."""
        return self.layout.names()

    def unpack(self, x: np.ndarray):
        """(values (P,), device_T_base (4, 4), tools (T, 3)) for an unknown vector."""
        layout = self.layout
        values = self.values.copy()
        values[self.free] = x[layout.geometry]
        tools = x[layout.tool_points].reshape(-1, 3)
        pose = np.eye(4)
        pose[:3, :3] = self.r0 @ rotation_from_rotvec(x[layout.registration_rotation])
        pose[:3, 3] = self.t0 + self.r0 @ x[layout.registration_translation]
        return values, pose, tools

    def tool_rotations(self, x: np.ndarray) -> np.ndarray:
        """Rotations (T, 3, 3) in the flange frame of the tools in ``rotated_tools``."""
        r = x[self.layout.tool_rotations].reshape(-1, 3)
        return self.tool_r0 @ rotation_from_rotvec(r)

    def effect_values(self, x: np.ndarray) -> list[np.ndarray]:
        """The parameters of each effect, in the order of ``effects``."""
        return [x[s] for s in self.layout.effects]

    def pack(self, values: np.ndarray, device_T_base: np.ndarray, tools: np.ndarray,
             effect_values=None, tool_rotations: np.ndarray | None = None) -> np.ndarray:
        """Unknown vector for the given state, relative to the reference registration;
        ``effect_values`` default to the values the effects carry, ``tool_rotations``
        ((T, 3, 3) for ``rotated_tools``) to the reference rotations."""
        rho = self.r0.T @ (device_T_base[:3, 3] - self.t0)
        phi = rotvec_from_rotation(self.r0.T @ device_T_base[:3, :3])
        if effect_values is None:
            effect_values = [np.array(e.values) for e in self.effects]
        layout = self.layout
        x = np.zeros(layout.size)
        x[layout.registration_translation], x[layout.registration_rotation] = rho, phi
        x[layout.geometry] = values[self.free]
        x[layout.tool_points] = np.asarray(tools).ravel()
        if tool_rotations is not None:
            x[layout.tool_rotations] = rotvec_from_rotation(
                np.swapaxes(self.tool_r0, 1, 2) @ tool_rotations).ravel()
        for cols, value in zip(layout.effects, effect_values):
            x[cols] = np.asarray(value, float)
        return x

    def _actual_joints(self, x: np.ndarray) -> np.ndarray:
        joint = [(e, b, x[s]) for e, b, s in zip(self.effects, self._bases, self.layout.effects)
                 if e.acts_on_joint]
        if not joint:
            return self.q
        dq = np.zeros_like(self.q)
        for e, basis, theta in joint:
            dq[:, e.joint] += basis @ theta
        return self.q + (dq if self.coupling is None else dq @ self.coupling.T)

    def _scale(self, x: np.ndarray) -> np.ndarray | None:
        terms = [b @ x[s] for e, b, s in zip(self.effects, self._bases, self.layout.effects)
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
        residual = ((predicted - self.measured) * self.position_weight[:, None]).ravel()
        if self.n_oriented:
            residual = np.concatenate([residual, self.orientation_rows(x, pose, chain)[0]])
        return residual

    @property
    def position_weight(self) -> np.ndarray:
        """(m,) the weight of each row's position residuals: robust acceptance times the
        row's own uncertainty's."""
        return self.row_weight * self.position_scale

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
        weight = (self.orientation_weight * self.row_weight[rows]
                  * self.rotation_scale[rows])[:, None]
        residual = (errors * weight).ravel()
        if not jacobian:
            return residual, None
        k = len(rows)
        turn = self.tool_rotations(x)[self.rotation_index]
        jr_inv = _so3_right_jacobian_inverse(errors)
        to_error = jr_inv @ np.swapaxes(turn, 1, 2) @ np.swapaxes(chain.flange[rows, :3, :3], 1, 2)
        layout = self.layout
        jac = np.zeros((k, 3, self.layout.size))
        rotation = layout.registration_rotation
        jac[:, :, rotation] = to_error @ _so3_right_jacobian(x[rotation])
        jac[:, :, layout.geometry] = to_error @ chain.drot_dparam[rows][:, :, self.free]
        for t in range(len(self.rotated_tools)):
            sel = self.rotation_index == t
            cols = layout.tool_rotation(t)
            jac[sel, :, cols] = jr_inv[sel] @ _so3_right_jacobian(x[cols])
        coupling = np.eye(self.model.n_joints) if self.coupling is None else self.coupling
        for effect, basis, cols in zip(self.effects, self._bases, self.layout.effects):
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
        layout = self.layout
        # refilled at every evaluation of a fit: a released buffer is reused (page faults)
        jac = reusable_array("jacobian", (m, 3, self.layout.size), slots=3)
        jac.fill(0.0)
        jac[:, :, layout.registration_translation] = self.r0
        # -R [p]x J_r(phi): column l is a_l x (R p), a_l = R J_r(phi) e_l; as p @ (3, 9)
        turn = rotation @ _so3_right_jacobian(x[layout.registration_rotation])
        cross = np.einsum("ijk,jl->kil", _LEVI_CIVITA, turn)
        jac[:, :, layout.registration_rotation] = (
            chain.points @ (rotation.T @ cross.reshape(3, 9))).reshape(m, 3, 3)
        k = len(self.free)
        # R dp/dparam, on the (P, 3, m) layout forward computes (a view when free is a range)
        dpoint = chain.dpoint_dparam.transpose(2, 1, 0)
        contiguous = k > 0 and self.free[-1] - self.free[0] == k - 1
        free = slice(self.free[0], self.free[-1] + 1) if contiguous else self.free
        np.matmul(rotation, dpoint[free], out=jac[:, :, layout.geometry].transpose(2, 1, 0))
        if len(self.tool_names) == 1:
            np.matmul(rotation, chain.flange[:, :3, :3], out=jac[:, :, layout.tool_points])
        else:
            tool_block = np.matmul(rotation, chain.flange[:, :3, :3])
            for t in range(len(self.tool_names)):
                rows = self.point_index == t
                jac[rows, :, layout.tool_point(t)] = tool_block[rows]
        scale = self._scale(x)
        origin = None if scale is None else chain.flange[:, :3, 3] / scale[:, None]
        for effect, basis, cols in zip(self.effects, self._bases, self.layout.effects):
            jac[:, :, cols] = self.effect_columns(effect, basis, chain, pose, origin)
        w = self.position_weight[:, None]
        residual = ((predicted - self.measured) * w).ravel()
        if np.any(w != 1.0):
            jac *= w[:, :, None]
        jac = jac.reshape(3 * m, -1)
        if self.n_oriented:
            residual_o, jac_o = self.orientation_rows(x, pose, chain, jacobian=True)
            residual, jac = np.concatenate([residual, residual_o]), np.vstack([jac, jac_o])
        return residual, jac


class HeldView:
    """An :class:`IdentificationProblem` over its fitted unknowns only (those not in
    ``problem.held``), the held ones at their values in ``x0``: reduced vectors xr,
    residuals and Jacobian columns of the fitted unknowns. Without held unknowns every
    method passes the problem's own arrays through."""

    def __init__(self, problem: IdentificationProblem, x0: np.ndarray):
        self.problem, self.x0 = problem, np.asarray(x0, dtype=float)
        self.any = bool(problem.held.any())
        self.columns = np.flatnonzero(~problem.held)

    def full(self, xr: np.ndarray) -> np.ndarray:
        """The whole unknown vector for the fitted unknowns xr."""
        if not self.any:
            return xr
        x = self.x0.copy()
        x[self.columns] = xr
        return x

    def reduce(self, x: np.ndarray) -> np.ndarray:
        """The fitted unknowns of a whole vector."""
        return x[self.columns] if self.any else x

    def cut(self, evaluation: tuple | None) -> tuple | None:
        """(residuals, Jacobian[, J^T J]) of the whole vector cut to the fitted columns."""
        if evaluation is None or not self.any:
            return evaluation
        cols = self.columns
        cut = (evaluation[0], evaluation[1][:, cols])
        if len(evaluation) > 2 and evaluation[2] is not None:
            cut += (evaluation[2][np.ix_(cols, cols)],)
        return cut

    def residuals(self, xr: np.ndarray) -> np.ndarray:
        return self.problem.residuals(self.full(xr))

    def residuals_and_jacobian(self, xr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.cut(self.problem.residuals_and_jacobian(self.full(xr)))


def problem_at(calibration: Calibration, meas: Measurements, inputs: EffectInputs | None,
               extra_effects=()) -> tuple[IdentificationProblem, np.ndarray]:
    """The identification problem at a calibration's solution, and its unknown vector:
    free = the parameters with a standard deviation, tools and effects as calibrated, plus
    ``extra_effects`` at zero (their Jacobian columns come last). ``meas.joints`` are
    controller axis values; ``inputs`` as from :func:`.identify.measurement_inputs`.
    Positions only: the problem has no orientation rows (its residuals are (3m,), as the
    diagnosis needs)."""
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
