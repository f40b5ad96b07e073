"""Base recalibration: re-fit only where the robot stands, from a few marks of known position.

Motta 2006, sections 6 and 10: "every time a robot moves from a portion of the workspace to
another, the base has to be recalibrated"; in section 10 the base frame was moved "to coincide
with the world coordinate system at the measurement target plate" in each region. The arm's
geometry and the tool stay as calibrated; only ``device_T_base`` (here: the new frame, world
or device, from the robot base) is fitted.

The tool point of a known tool touches m >= 3 marks whose coordinates ``mark_i`` are known in
the new frame. Its base-frame position ``b_i`` follows from the calibrated model at the joints
read at each touch. The fit minimizes ``sum |R b_i + p - mark_i|^2``:

- 6 DoF: the closed-form Kabsch/Horn solution (:func:`olp_compensate.calibration.registration.kabsch`);
- 4 DoF (``keep_tilt``): the tilt of the input ``device_T_base`` is kept (its rotation is
  written ``Rz(psi) Ry(beta) Rx(alpha)`` about the new frame's fixed axes and ``Ry Rx`` is
  kept), the rotation about the new frame's z axis and the translation are fitted (a planar
  Kabsch on the tilted points, closed form).

Statistics follow scipy's least-squares habits (``sigma^2 = RSS / (3m - dof)``,
``cov = sigma^2 (J^T J)^-1``), with the rotation taken about the marks' centroid so rotation
and translation decouple. Conditioning: as :mod:`olp_compensate.calibration.tool` does, the
column-scaled Jacobian's condition number above :data:`COND_LIMIT` refuses the marks
(:class:`PoorlyDeterminedBase`) with advice: marks nearly on a line leave the rotation about
that line free.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError
from ..kinematics.conventions import MM, rot_z, rotvec_from_rotation, skew
from .calibration import Calibration
from .registration import kabsch

COND_LIMIT = 25.0
"""Largest accepted condition number of the column-scaled Jacobian (as for tools)."""
MIN_MARKS = 3
"""Fewest marks: three points not on a line fix a rigid frame; a fourth checks it."""
LINE_RATIO = 0.05
"""Marks whose second principal spread is below this fraction of the first lie 'on a line'."""


class PoorlyDeterminedBase(DataError):
    """The marks are too few or too close to a line to fix the base; ``hint`` says what to add."""

    def __init__(self, message: str, hint: str, condition_number: float):
        self.hint = hint
        self.condition_number = condition_number
        super().__init__(f"{message} {hint}")


@dataclass(frozen=True)
class BaseRecalibration:
    """A recalibrated base frame.

    ``calibration``: the input calibration with the new ``device_T_base`` (4, 4), m: the
    robot base in the frame of the marks. ``residuals_m`` (m,): distance between the
    predicted tool point and each mark; ``residual_vectors_m`` (m, 3) the same as vectors
    (mark frame). ``rotation_std_rad`` (3,): standard deviation of a small rotation about
    the mark frame's x, y, z axes (0 for the axes kept by ``keep_tilt``);
    ``origin_std_m`` (3,): of the base origin in the mark frame; ``centroid_std_m`` (3,):
    of a point at the marks' centroid. ``sigma_m``: estimated touch noise per coordinate;
    ``dof``: 6, or 4 with the tilt kept; ``condition_number`` of the column-scaled Jacobian.
    ``change_m`` and ``change_rad``: how far the base origin moved and the frame turned
    relative to the input calibration's ``device_T_base``.
    """

    calibration: Calibration
    tool: str
    residuals_m: np.ndarray
    residual_vectors_m: np.ndarray = field(repr=False)
    mark_names: tuple[str, ...]
    rotation_std_rad: np.ndarray
    origin_std_m: np.ndarray
    centroid_std_m: np.ndarray
    sigma_m: float
    dof: int
    condition_number: float
    change_m: float
    change_rad: float

    @property
    def device_T_base(self) -> np.ndarray:
        return self.calibration.device_T_base

    @property
    def rms_m(self) -> float:
        """Root mean square of the per-mark residual distances, m."""
        return float(np.sqrt(np.mean(self.residuals_m ** 2)))


def _tool_name(calibration: Calibration, tool: str | None) -> str:
    if tool is not None:
        if tool not in calibration.tools:
            known = ", ".join(sorted(calibration.tools)) or "none"
            raise DataError(f"tool: the calibration has no tool named {tool!r} (known: {known})")
        return tool
    if len(calibration.tools) != 1:
        known = ", ".join(sorted(calibration.tools)) or "none"
        raise DataError(f"tool: name the tool that touched the marks (the calibration has "
                        f"{len(calibration.tools)} tools: {known})")
    return next(iter(calibration.tools))


def _check_inputs(joints, points_m, mark_names, n_joints: int):
    joints = np.atleast_2d(np.asarray(joints, dtype=float))
    points = np.atleast_2d(np.asarray(points_m, dtype=float))
    if joints.ndim != 2 or joints.shape[1] != n_joints:
        raise DataError(f"joints: expected shape (m, {n_joints}), got {joints.shape}")
    if points.shape != (len(joints), 3):
        raise DataError(f"points_m: expected shape ({len(joints)}, 3) to match the joints, "
                        f"got {points.shape}")
    if not (np.all(np.isfinite(joints)) and np.all(np.isfinite(points))):
        raise DataError("joints and points_m must be finite")
    if len(joints) < MIN_MARKS:
        raise PoorlyDeterminedBase(
            f"cannot fix the base from {len(joints)} mark(s).",
            f"Touch at least {MIN_MARKS} marks not on one line (4 or more, spread over the "
            f"region where the robot works, also check the fit).", math.inf)
    names = (tuple(mark_names) if mark_names is not None
             else tuple(f"M{k + 1}" for k in range(len(joints))))
    if len(names) != len(joints):
        raise DataError(f"mark_names: {len(names)} names for {len(joints)} marks")
    return joints, points, names


def tilt_of(rotation: np.ndarray) -> np.ndarray:
    """The tilt ``Ry(beta) Rx(alpha)`` of ``rotation = Rz(psi) Ry(beta) Rx(alpha)`` (3, 3):
    what is left after removing the turn about the outer frame's z axis."""
    r = np.asarray(rotation, dtype=float)
    psi = math.atan2(r[1, 0], r[0, 0])
    return rot_z(-psi) @ r


def _fit_6dof(base_points: np.ndarray, marks: np.ndarray) -> np.ndarray:
    return kabsch(base_points, marks)


def _fit_4dof(base_points: np.ndarray, marks: np.ndarray, tilt: np.ndarray) -> np.ndarray:
    """Rz(theta) tilt b + p closest to the marks: planar Kabsch in x, y; z by the mean."""
    tilted = base_points @ tilt.T
    a = tilted - tilted.mean(axis=0)
    b = marks - marks.mean(axis=0)
    cross = np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    dot = np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])
    theta = math.atan2(cross, dot)
    pose = np.eye(4)
    pose[:3, :3] = rot_z(theta) @ tilt
    pose[:3, 3] = marks.mean(axis=0) - pose[:3, :3] @ base_points.mean(axis=0)
    return pose


def _jacobian(pose: np.ndarray, base_points: np.ndarray, centre: np.ndarray, dof: int):
    """(3m, dof) derivative of the predicted marks with respect to a small rotation about
    ``centre`` (x, y, z or z only) and a translation, mark frame."""
    arm = base_points @ pose[:3, :3].T + pose[:3, 3] - centre
    m = len(arm)
    rotation = -skew(arm)                                    # (m, 3, 3): d/d omega
    if dof == 4:
        rotation = rotation[:, :, 2:]
    jac = np.concatenate([rotation, np.broadcast_to(np.eye(3), (m, 3, 3))], axis=2)
    return jac.reshape(3 * m, dof)


def _condition(jac: np.ndarray) -> float:
    norms = np.linalg.norm(jac, axis=0)
    norms[norms == 0] = 1.0
    s = np.linalg.svd(jac / norms, compute_uv=False)
    return float(np.inf if s[-1] <= 1e-15 * s[0] else s[0] / s[-1])


def _refuse(marks: np.ndarray, cond: float, dof: int) -> None:
    """Raise :class:`PoorlyDeterminedBase` when the marks cannot fix the frame."""
    spread = np.linalg.svd(marks - marks.mean(axis=0), compute_uv=False)
    on_line = spread[0] <= 0 or spread[1] < LINE_RATIO * spread[0]
    if on_line and dof == 6:
        raise PoorlyDeterminedBase(
            f"cannot fix the base from these {len(marks)} marks: they lie nearly on a line "
            f"(spread {spread[0] / MM:.1f} mm along it, {spread[1] / MM:.1f} mm across; "
            f"condition number {cond:.3g}), so the rotation about that line is free.",
            "Add marks away from that line, spread over a plane (ideally around the region "
            "where the robot works), or keep the tilt (keep_tilt) if the base is level.", cond)
    if spread[0] <= 0:
        raise PoorlyDeterminedBase(
            f"cannot fix the base from these {len(marks)} marks: they are one point.",
            "Touch marks spread over the region where the robot works.", cond)
    if cond > COND_LIMIT:
        raise PoorlyDeterminedBase(
            f"cannot fix the base from these {len(marks)} marks: condition number "
            f"{cond:.3g} > {COND_LIMIT:g} (spread {spread[0] / MM:.1f}, {spread[1] / MM:.1f}, "
            f"{spread[2] / MM:.1f} mm along their principal directions).",
            "Spread the marks more evenly: add marks across the narrow direction.", cond)


def recalibrate_base(calibration: Calibration, joints, points_m, tool: str | None = None,
                     keep_tilt: bool = False, mark_names=None) -> BaseRecalibration:
    """Re-fit only the base frame of ``calibration`` from touched marks.

    ``joints``: (m, n) controller axes, rad (m for prismatic), one row per touch;
    ``points_m``: (m, 3) the marks' coordinates in the new (world or device) frame, m;
    ``tool``: the calibrated tool that touched them (default: the calibration's only tool);
    ``keep_tilt``: keep the input ``device_T_base``'s tilt, fit 4 DoF (rotation about the
    new frame's z axis and the translation). Raises :class:`PoorlyDeterminedBase` when the
    marks are too few or too close to a line, :class:`DataError` for bad input.
    """
    name = _tool_name(calibration, tool)
    joints, marks, names = _check_inputs(joints, points_m, mark_names,
                                         calibration.robot.n_joints)
    flange = calibration.flange_poses(joints)
    local = calibration.tools[name].xyz_m
    base_points = flange[:, :3, 3] + flange[:, :3, :3] @ local
    dof = 4 if keep_tilt else 6
    if keep_tilt:
        pose = _fit_4dof(base_points, marks, tilt_of(calibration.device_T_base[:3, :3]))
    else:
        pose = _fit_6dof(base_points, marks)
    centre = marks.mean(axis=0)
    jac = _jacobian(pose, base_points, centre, dof)
    cond = _condition(jac)
    _refuse(marks, cond, dof)
    residuals = base_points @ pose[:3, :3].T + pose[:3, 3] - marks
    redundancy = 3 * len(marks) - dof
    sigma2 = float(np.sum(residuals ** 2)) / redundancy
    cov = sigma2 * np.linalg.inv(jac.T @ jac)
    n_rot = dof - 3
    rotation_std = np.zeros(3)
    rotation_std[3 - n_rot:] = np.sqrt(np.clip(np.diag(cov)[:n_rot], 0, None))
    lever = np.concatenate([-skew(pose[:3, 3] - centre)[:, 3 - n_rot:], np.eye(3)], axis=1)
    origin_cov = lever @ cov @ lever.T
    old = calibration.device_T_base
    turn = pose[:3, :3] @ old[:3, :3].T
    return BaseRecalibration(
        calibration=dataclasses.replace(calibration, device_T_base=pose), tool=name,
        residuals_m=np.linalg.norm(residuals, axis=1), residual_vectors_m=residuals,
        mark_names=names, rotation_std_rad=rotation_std,
        origin_std_m=np.sqrt(np.clip(np.diag(origin_cov), 0, None)),
        centroid_std_m=np.sqrt(np.clip(np.diag(cov)[n_rot:], 0, None)),
        sigma_m=math.sqrt(sigma2), dof=dof, condition_number=cond,
        change_m=float(np.linalg.norm(pose[:3, 3] - old[:3, 3])),
        change_rad=float(np.linalg.norm(rotvec_from_rotation(turn))))


def base_report(result: BaseRecalibration, flag_above_m: float | None = None) -> list[str]:
    """The result as printed lines (mm, degrees)."""
    pose = result.device_T_base
    rotvec = np.degrees(rotvec_from_rotation(pose[:3, :3]))
    what = "6 DoF" if result.dof == 6 else "4 DoF: tilt kept, rotation about z and translation"
    lines = [f"base frame refitted from {len(result.residuals_m)} marks of tool "
             f"{result.tool} ({what}):",
             "  base origin in the marks' frame: (" + ", ".join(
                 f"{v / MM:.3f}" for v in pose[:3, 3]) + ") mm  +/- (" + ", ".join(
                 f"{v / MM:.3f}" for v in result.origin_std_m) + ") mm",
             "  rotation vector: (" + ", ".join(f"{v:.4f}" for v in rotvec) + ") deg  "
             "+/- (" + ", ".join(f"{np.degrees(v):.4f}" for v in result.rotation_std_rad)
             + ") deg about x, y, z",
             "  at the marks' centroid: +/- (" + ", ".join(
                 f"{v / MM:.3f}" for v in result.centroid_std_m) + ") mm",
             f"  moved {result.change_m / MM:.3f} mm and turned "
             f"{np.degrees(result.change_rad):.4f} deg from the input calibration's frame",
             f"  condition number {result.condition_number:.2f} (refused above "
             f"{COND_LIMIT:g}), estimated touch noise {result.sigma_m / MM:.3f} mm",
             "  residual per mark:"]
    for label, r in zip(result.mark_names, result.residuals_m):
        flag = ("   <-- larger than expected"
                if flag_above_m is not None and r > flag_above_m else "")
        lines.append(f"    {label:>8} {r / MM:8.3f} mm{flag}")
    lines.append(f"  RMS residual {result.rms_m / MM:.3f} mm")
    return lines
