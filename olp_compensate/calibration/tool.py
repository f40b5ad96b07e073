"""Tool-only recalibration: find the TCP in the flange frame from touched marks.

Two methods, both from flange poses ``base_T_flange`` (m, 4, 4) in metres computed by the
robot's forward kinematics from the joints read at each touch:

- **known marks**: the tool tip touched m >= 3 marks of known coordinates. In the base frame
  ``R_i t + o_i = mark_i`` is linear in the TCP ``t`` (flange frame) and always well
  determined (``A^T A = m I``). In a world frame the transform ``world_T_base`` (6 DOF) is
  solved too (Gauss-Newton, m >= 4 marks, which need both spread positions and tool
  orientations spread by rotations about two axes).
- **fixed point**: the tip touched one unknown fixed point from m >= 4 orientations:
  ``R_i t + o_i = P``, unknowns ``t`` (flange) and ``P`` (base), linear least squares.

Orientation: a touch gives one point per pose, which fixes the TCP position but says nothing
about how the tool frame is turned about that point, so ``quat_wxyz`` is None (keep the
orientation from the tool's drawing). Statistics follow scipy's least-squares habits:
``sigma^2 = RSS / (3m - n)`` and ``cov = sigma^2 (J^T J)^-1``.

Conditioning: the columns of the design matrix are scaled to unit norm and its singular
values are taken relative to the largest. A touch error ``e`` becomes a TCP error of about
``e * cond / sqrt(m)``; above :data:`COND_LIMIT` = 25 (tilts of less than about 8 degrees)
a typical 0.05-0.1 mm touch error turns into 0.5-1 mm at the tool, which a tool calibration
must not accept, so the poses are refused with :class:`PoorlyDeterminedTool` naming what to
add (tilts of 30 degrees give cond of about 7).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..errors import DataError
from ..kinematics.conventions import MM, rotation_angle_between, rotation_from_rotvec, skew
from .fit_check import MAX_RMS_M, judge_residual

COND_LIMIT = 25.0
"""Largest accepted condition number of the column-scaled design matrix (see module doc)."""
MIN_MARKS = {("known_marks", "base"): 3, ("known_marks", "world"): 4, ("fixed_point", None): 4}
"""Fewest touches per method (and frame) that leave redundancy to estimate the noise."""

SAME_MARK_M = 1e-4
"""Marks closer than this to each other in every coordinate are one mark, m."""

FlangePose = Callable[[np.ndarray], np.ndarray]
"""Forward kinematics: joints (m, n) rad -> base_T_flange (m, 4, 4), metres."""


class PoorlyDeterminedTool(DataError):
    """The poses are too alike to determine the tool; ``hint`` says what to add."""

    def __init__(self, message: str, hint: str, condition_number: float):
        self.hint = hint
        self.condition_number = condition_number
        super().__init__(f"{message} {hint}")


@dataclass(frozen=True)
class ToolRequest:
    """What a tool recalibration needs; the wizard builds the same object.

    ``joints``: (m, n) rad, one row per touch. ``marks``: (m, 3) metres in ``frame``
    ('base' or 'world') for ``method='known_marks'``, None for ``'fixed_point'``.
    ``mark_names``: (m,) labels for reports (default M1, M2, ...).
    """

    name: str
    method: str
    joints: np.ndarray
    marks: np.ndarray | None = None
    frame: str = "base"
    mark_names: tuple[str, ...] | None = None

    def labels(self) -> tuple[str, ...]:
        return self.mark_names or tuple(f"M{k + 1}" for k in range(len(self.joints)))


@dataclass(frozen=True)
class ToolCalibration:
    """A recalibrated tool.

    ``xyz_m``, ``xyz_std_m``: TCP in the flange frame and its standard deviation (3,), m.
    ``quat_wxyz``: tool orientation in the flange frame, None when the method cannot see it.
    ``residuals_m``: (m,) distance between model and mark per touch; ``residual_vectors_m``
    (m, 3) the same as vectors (mark frame). ``point_m``: the fixed point (base frame) for
    the fixed-point method. ``world_T_base``: solved for marks in a world frame.
    ``sigma_m``: estimated touch noise per coordinate. ``condition_number``: of the
    column-scaled design matrix.
    """

    name: str
    xyz_m: np.ndarray
    xyz_std_m: np.ndarray
    quat_wxyz: np.ndarray | None
    residuals_m: np.ndarray
    point_m: np.ndarray | None
    condition_number: float
    method: str
    residual_vectors_m: np.ndarray = field(repr=False, default=None)
    mark_names: tuple[str, ...] = ()
    sigma_m: float = float("nan")
    world_T_base: np.ndarray | None = None
    xyz_cov_m2: np.ndarray | None = field(repr=False, default=None)

    @property
    def rms_m(self) -> float:
        """Root mean square of the per-mark residual distances, m."""
        return float(np.sqrt(np.mean(self.residuals_m ** 2)))


# -- validation and conditioning ---------------------------------------------------------------

def _check_poses(base_T_flange, m_min: int, what: str) -> np.ndarray:
    poses = np.asarray(base_T_flange, dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise DataError(f"base_T_flange: expected shape (m, 4, 4), got {poses.shape}")
    if not np.all(np.isfinite(poses)):
        raise DataError("base_T_flange: contains NaN or infinite values")
    if len(poses) < m_min:
        raise DataError(f"{what} needs at least {m_min} touches, got {len(poses)}")
    return poses


def _scaled_svd(jac: np.ndarray):
    """Singular values (relative to the largest) and right vectors of the column-scaled J."""
    norms = np.linalg.norm(jac, axis=0)
    norms[norms == 0] = 1.0
    _, s, vt = np.linalg.svd(jac / norms, full_matrices=False)
    rel = s / s[0]
    cond = float(np.inf if rel[-1] <= 0 else 1.0 / rel[-1])
    return rel, vt / norms, cond


def _describe(u: np.ndarray, frame: str) -> str:
    """A direction in words, sign-agnostic: 'the base z axis (vertical)', or
    'the base direction (a, b, c)'."""
    u = u * np.sign(u[np.argmax(np.abs(u))])
    k = int(np.argmax(u))
    if u[k] > 0.95:
        vertical = " (vertical)" if frame == "base" and k == 2 else ""
        return f"the {frame} {'xyz'[k]} axis{vertical}"
    return f"the {frame} direction ({u[0]:.2f}, {u[1]:.2f}, {u[2]:.2f})"


def _max_tilt_deg(rotations: np.ndarray) -> float:
    angles = rotation_angle_between(rotations[:, None], rotations[None, :])
    return float(np.degrees(np.max(angles)))


def _refuse(rel, vt, cond, rotations, method: str, t_slice: slice, axis_of) -> None:
    """Raise PoorlyDeterminedTool when the scaled design is worse than COND_LIMIT."""
    if cond <= COND_LIMIT:
        return
    weak = int(np.sum(rel < 1.0 / COND_LIMIT))
    spread = _max_tilt_deg(rotations)
    message = (f"cannot determine the tool from these {len(rotations)} poses "
               f"({method}; condition number {cond:.3g} > {COND_LIMIT:g}; the tool "
               f"orientations differ by at most {spread:.1f} degrees).")
    if weak >= 2:
        hint = ("The poses are too alike: rotate the tool by at least 30 degrees about two "
                "different axes between touches (for example tilt it forward for one touch "
                "and sideways for another).")
    else:
        v = vt[-1]
        t_dir = v[t_slice] / (np.linalg.norm(v[t_slice]) or 1.0)
        axis = axis_of(v, t_dir)
        if np.linalg.norm(v[t_slice]) < 0.3 * np.linalg.norm(v) or axis is None:
            hint = ("The marks lie nearly on a line: add marks away from that line, spread "
                    "over a plane.")
        else:
            perpendicular = ("a horizontal axis" if abs(axis[2]) > 0.9 else
                             f"an axis perpendicular to {_describe(axis, 'base')}")
            hint = (f"All poses turn the tool about nearly one axis, {_describe(axis, 'base')}, "
                    f"so the TCP component along {_describe(t_dir, 'flange')} is undetermined: "
                    f"add a touch with the tool rotated by at least 30 degrees about "
                    f"{perpendicular}.")
    raise PoorlyDeterminedTool(message, hint, cond)


def _result(name, method, t, cov, residuals, labels, sigma, cond, point=None, world=None):
    labels = tuple(labels) if labels is not None else tuple(f"M{k + 1}"
                                                            for k in range(len(residuals)))
    return ToolCalibration(
        name=name, xyz_m=t, xyz_std_m=np.sqrt(np.clip(np.diag(cov), 0, None)), quat_wxyz=None,
        residuals_m=np.linalg.norm(residuals, axis=1), point_m=point, condition_number=cond,
        method=method, residual_vectors_m=residuals, mark_names=labels, sigma_m=sigma,
        world_T_base=world, xyz_cov_m2=cov)


# -- the two methods ---------------------------------------------------------------------------

def tool_from_fixed_point(base_T_flange, name: str = "tool", mark_names=None) -> ToolCalibration:
    """TCP from m >= 4 touches of one unknown fixed point: ``R_i t + o_i = P``.

    ``base_T_flange``: (m, 4, 4) metres. Returns the TCP (flange frame) and ``point_m`` (P,
    base frame). Raises :class:`PoorlyDeterminedTool` when the orientations are too alike.
    """
    poses = _check_poses(base_T_flange, MIN_MARKS[("fixed_point", None)],
                         "the fixed-point method")
    m = len(poses)
    rot, org = poses[:, :3, :3], poses[:, :3, 3]
    a = np.concatenate([rot, -np.broadcast_to(np.eye(3), (m, 3, 3))], axis=2).reshape(3 * m, 6)
    b = -org.reshape(3 * m)
    rel, vt, cond = _scaled_svd(a)
    _refuse(rel, vt, cond, rot, "fixed point", slice(0, 3),
            lambda v, t_dir: v[3:] / (np.linalg.norm(v[3:]) or 1.0))
    x, *_ = np.linalg.lstsq(a, b, rcond=None)
    residuals = (a @ x - b).reshape(m, 3)
    sigma2 = float(np.sum(residuals ** 2)) / (3 * m - 6)
    cov = sigma2 * np.linalg.inv(a.T @ a)[:3, :3]
    return _result(name, "fixed_point", x[:3], cov, residuals, mark_names, math.sqrt(sigma2),
                   cond, point=x[3:])


def tool_from_known_marks(base_T_flange, marks_m, frame: str = "base", name: str = "tool",
                          mark_names=None, iterations: int = 30) -> ToolCalibration:
    """TCP from touches of marks with known coordinates ``marks_m`` (m, 3), metres.

    ``frame='base'``: marks in the robot base frame; linear, m >= 3. ``frame='world'``:
    marks in another frame; ``world_T_base`` is solved as well (Gauss-Newton from a Kabsch
    start, at most ``iterations`` steps), m >= 4.
    """
    if frame not in ("base", "world"):
        raise DataError(f"frame: expected 'base' or 'world', got {frame!r}")
    poses = _check_poses(base_T_flange, MIN_MARKS[("known_marks", frame)],
                         f"the known-marks method in the {frame} frame")
    marks = np.asarray(marks_m, dtype=float)
    if marks.shape != (len(poses), 3):
        raise DataError(f"marks: expected shape ({len(poses)}, 3) to match the poses, got "
                        f"{marks.shape}")
    if not np.all(np.isfinite(marks)):
        raise DataError("marks: contain NaN or infinite values")
    if np.all(np.ptp(marks, axis=0) < SAME_MARK_M):
        where = ", ".join(f"{v / MM:.6g}" for v in marks[0])
        raise DataError(f"marks: every mark has the same coordinates ({where}) mm; give each "
                        f"mark its own coordinates, or leave them empty on every row for the "
                        f"fixed-point method (one point touched from several orientations)")
    m = len(poses)
    rot, org = poses[:, :3, :3], poses[:, :3, 3]
    if frame == "base":
        a = rot.reshape(3 * m, 3)
        b = (marks - org).reshape(3 * m)
        rel, vt, cond = _scaled_svd(a)
        t, *_ = np.linalg.lstsq(a, b, rcond=None)
        residuals = (a @ t - b).reshape(m, 3)
        sigma2 = float(np.sum(residuals ** 2)) / (3 * m - 3)
        cov = sigma2 * np.linalg.inv(a.T @ a)
        return _result(name, "known_marks", t, cov, residuals, mark_names, math.sqrt(sigma2),
                       cond)
    return _known_marks_world(rot, org, marks, name, mark_names, iterations)


def _kabsch(src: np.ndarray, dst: np.ndarray):
    """Rotation and translation with ``R src + p ~ dst`` (rows are points)."""
    cs, cd = src.mean(0), dst.mean(0)
    u, _, vt = np.linalg.svd((src - cs).T @ (dst - cd))
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, cd - r @ cs


def _known_marks_world(rot, org, marks, name, mark_names, iterations):
    m = len(rot)
    # Start: alternate registration and linear TCP a few times (robust for tools < ~1 m).
    t = np.zeros(3)
    for _ in range(5):
        rw, pw = _kabsch(org + rot @ t, marks)
        t, *_ = np.linalg.lstsq((rw @ rot).reshape(3 * m, 3),
                                (marks - pw - org @ rw.T).reshape(3 * m), rcond=None)
    centre = marks.mean(axis=0)  # rotate about the marks' centroid: decouples R and p

    def linearize(rw, pw, t):
        arm = (org + rot @ t) @ rw.T + pw - centre
        jac = np.concatenate([-skew(arm), np.broadcast_to(np.eye(3), (m, 3, 3)), rw @ rot],
                             axis=2).reshape(3 * m, 9)
        return arm + centre - marks, jac

    for _ in range(iterations):
        residuals, jac = linearize(rw, pw, t)
        step, *_ = np.linalg.lstsq(jac, -residuals.reshape(3 * m), rcond=None)
        turn = rotation_from_rotvec(step[:3])
        rw, pw = turn @ rw, turn @ (pw - centre) + centre + step[3:6]
        t = t + step[6:]
        if np.linalg.norm(step) < 1e-12:
            break
    residuals, jac = linearize(rw, pw, t)
    rel, vt, cond = _scaled_svd(jac)

    def axis_of(v, t_dir):
        return None if np.linalg.norm(v[6:]) < 0.3 * np.linalg.norm(v) else \
            rot[0] @ t_dir
    _refuse(rel, vt, cond, rot, "known marks in a world frame", slice(6, 9), axis_of)
    sigma2 = float(np.sum(residuals ** 2)) / (3 * m - 9)
    cov = sigma2 * np.linalg.inv(jac.T @ jac)[6:, 6:]
    world = np.eye(4)
    world[:3, :3], world[:3, 3] = rw, pw
    return _result(name, "known_marks", t, cov, residuals, mark_names, math.sqrt(sigma2), cond,
                   world=world)


def calibrate_tool(request: ToolRequest, flange_pose: FlangePose) -> ToolCalibration:
    """The library call: joints -> flange poses -> the request's method.

    ``flange_pose(q)`` maps joints (m, n) rad to ``base_T_flange`` (m, 4, 4) in metres.
    """
    joints = np.asarray(request.joints, dtype=float)
    if joints.ndim != 2 or not np.all(np.isfinite(joints)):
        raise DataError(f"joints: expected a finite (m, n) array in rad, got shape {joints.shape}")
    if request.mark_names is not None and len(request.mark_names) != len(joints):
        raise DataError(f"mark_names: {len(request.mark_names)} names for {len(joints)} touches")
    poses = np.asarray(flange_pose(joints), dtype=float)
    if poses.shape != (len(joints), 4, 4):
        raise DataError(f"flange_pose returned shape {poses.shape}, expected ({len(joints)}, 4, 4)")
    if request.method == "fixed_point":
        return tool_from_fixed_point(poses, request.name, request.labels())
    if request.method == "known_marks":
        if request.marks is None:
            raise DataError("the known-marks method needs the marks' coordinates")
        return tool_from_known_marks(poses, request.marks, request.frame, request.name,
                                     request.labels())
    raise DataError(f"method: expected 'known_marks' or 'fixed_point', got {request.method!r}")


def check_tool_fit(result: ToolCalibration, max_rms_m: float = MAX_RMS_M) -> None:
    """:class:`DataError` when a fitted tool is not fit to save: a non-finite TCP or
    residual, or an RMS residual above ``max_rms_m`` (naming the worst touch): the rule of
    :mod:`olp_compensate.calibration.fit_check`, shared with base and identify."""
    numbers = np.concatenate([np.ravel(result.xyz_m), np.ravel(result.residuals_m)])
    if not np.all(np.isfinite(numbers)):
        raise DataError(f"tool {result.name}: the fit gave non-finite numbers; check the "
                        f"marks' coordinates and joints")
    verdict = judge_residual(f"tool {result.name}: the touches do not fit one tool point",
                             result.residuals_m, result.mark_names, max_rms_m)
    if verdict.rejected:
        raise DataError(f"{verdict.message} Nothing written")


# -- report -----------------------------------------------------------------------------------

def tool_report(result: ToolCalibration, flag_above_m: float | None = None) -> list[str]:
    """The result as printed lines (mm): TCP and its std, conditioning, residual per touch
    (flagged above ``flag_above_m``, m), the fixed point or ``world_T_base`` when solved."""
    from ..kinematics.conventions import rotvec_from_rotation

    def fmt(values_m):
        return "(" + ", ".join(f"{v / MM:.3f}" for v in values_m) + ")"

    lines = [f"Tool {result.name} ({result.method.replace('_', ' ')}, "
             f"{len(result.residuals_m)} touches), TCP in the flange frame:"]
    for axis, value, std in zip("xyz", result.xyz_m, result.xyz_std_m):
        lines.append(f"  {axis} = {value / MM:10.3f} mm  +/- {std / MM:.3f} mm")
    lines.append(f"  condition number {result.condition_number:.2f} (refused above "
                 f"{COND_LIMIT:g}), estimated touch noise {result.sigma_m / MM:.3f} mm")
    lines.append("  residual per touch:")
    for label, r in zip(result.mark_names, result.residuals_m):
        flag = ("   <-- larger than expected"
                if flag_above_m is not None and r > flag_above_m else "")
        lines.append(f"    {label:>6} {r / MM:8.3f} mm{flag}")
    lines.append(f"  RMS residual {result.rms_m / MM:.3f} mm")
    if result.point_m is not None:
        lines.append(f"  fixed point in the base frame: {fmt(result.point_m)} mm")
    if result.world_T_base is not None:
        rotvec = np.degrees(rotvec_from_rotation(result.world_T_base[:3, :3]))
        lines.append(f"  world_T_base: translation {fmt(result.world_T_base[:3, 3])} mm, "
                     f"rotation vector ({', '.join(f'{v:.4f}' for v in rotvec)}) deg")
    if result.quat_wxyz is None:
        lines.append("  Orientation: touching points cannot measure it; keep the tool's "
                     "orientation from its drawing.")
    return lines


# -- RAPID ------------------------------------------------------------------------------------

def _num(value: float, decimals: int) -> str:
    text = f"{round(float(value), decimals) + 0.0:.{decimals}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


def rapid_tooldata(result: ToolCalibration, mass_kg: float, cog_mm=(0.0, 0.0, 0.0),
                   robhold: bool = True, quat_wxyz=None, aom_wxyz=(1.0, 0.0, 0.0, 0.0),
                   inertia_kgm2=(0.0, 0.0, 0.0)) -> str:
    """The RAPID ``tooldata`` literal of a calibrated tool.

    ``[robhold,[[x,y,z],[q1,q2,q3,q4]],[mass,[cx,cy,cz],[a1,a2,a3,a4],ix,iy,iz]]`` with the
    TCP in mm (0.001 mm resolution) in the flange frame, the orientation from the result, else
    ``quat_wxyz``, else the flange's. RAPID refuses a tool mass <= 0 kg, so does this.
    """
    if not (mass_kg > 0 and math.isfinite(mass_kg)):
        raise DataError(f"mass_kg: RAPID needs a tool mass > 0 kg, got {mass_kg}")
    quat = result.quat_wxyz if result.quat_wxyz is not None else quat_wxyz
    quat = np.array([1.0, 0.0, 0.0, 0.0] if quat is None else quat, dtype=float)
    quat = quat / np.linalg.norm(quat)
    aom = np.asarray(aom_wxyz, dtype=float) / np.linalg.norm(aom_wxyz)
    xyz = ",".join(_num(v / MM, 3) for v in result.xyz_m)
    q = ",".join(_num(v, 9) for v in quat)
    cog = ",".join(_num(v, 3) for v in cog_mm)
    a = ",".join(_num(v, 9) for v in aom)
    inertia = ",".join(_num(v, 6) for v in inertia_kgm2)
    return (f"[{'TRUE' if robhold else 'FALSE'},[[{xyz}],[{q}]],"
            f"[{_num(mass_kg, 3)},[{cog}],[{a}],{inertia}]]")
