"""Inverse kinematics: closed forms of the nominal robot, Newton refinement on any model.

Everything is batched over targets: poses ``(m, 4, 4)`` in metres, joint vectors ``(m, n)``
in radians, the user's joint convention (signs and zero positions of the controller).

- :class:`OPWParameters`, :func:`opw_forward`, :func:`opw_inverse`: 6R arms with an
  ortho-parallel base and a spherical wrist (ABB, KUKA, FANUC, Staubli, PUMA...), after
  M. Brandstoetter, A. Angerer, M. Hofbaur, "An analytical solution of the inverse kinematics
  problem of industrial serial manipulators with an ortho-parallel basis and a spherical
  wrist", Austrian Robotics Workshop 2014.
- :class:`URParameters`, :func:`ur_forward`, :func:`ur_inverse`: 6R arms with axes 2, 3, 4
  parallel (Universal Robots), after K. P. Hawkins, "Analytic inverse kinematics for the
  Universal Robots UR-5/UR-10 arms", Georgia Tech, 2013.
- :func:`fit_family`: which family a forward-kinematics callable belongs to, and its
  parameters, verified to 1e-9 m / 1e-9 rad.
- :func:`refine`: damped Newton on any model given as ``fk_jacobian``; :func:`solve`: closed
  form on the nominal family, then Newton on the (calibrated) model in the closed form's
  coordinates (two steps for most targets), :func:`refine`'s Newton from several starts
  for the rest.
- :class:`ReachBound`: a proof, from a 6R chain's geometry, that targets lie beyond its
  reach (near the stretched elbow): :func:`solve` does not retry those.

Branch numbering. The 8 solutions of both closed forms are ordered so that the index *is*
the configuration number: ``index = 4 * behind + 2 * elbow + wrist``, with the three bits of
:func:`configuration_bits`. For OPW arms this is ABB's ``cfx`` (see
:mod:`olp_compensate.compensation.confdata`). Unreachable branches are NaN. Failure of an iterative solve
is a value in :class:`IKSolution`, never an exception.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..kinematics.conventions import (invert_pose, pose_from_rotation_translation, rot_y, rot_z,
                          rotvec_from_rotation)
from ..errors import DataError, ModelError

__all__ = [
    "OPWParameters", "URParameters", "IKSolution", "REASONS",
    "opw_forward", "opw_inverse", "ur_forward", "ur_inverse",
    "closed_form_forward", "closed_form_inverse", "closed_form_branch", "configuration_bits", "branch_of",
    "select_branch", "nominal_joints_on_branch", "fit_family", "refine", "solve",
    "solve_with_nominal", "ReachBound",
]

REASONS = ("ok", "unreachable", "joint_limit", "singular", "branch_changed", "not_converged")
"""Every value :attr:`IKSolution.reason` can take."""

_TWO_PI = 2.0 * np.pi
_WRIST_EPS = 1e-12     # |sin(theta5)| below this: the wrist is treated as exactly singular
_DAMPING = 1e-10       # Tikhonov term of the Newton step, relative to mean(diag(J^T J))
_STALL_STEPS = 20      # Newton steps in a row without progress before a target is given up


# --------------------------------------------------------------------------- parameters

def _transform_field(value, name):
    if value is None:
        return None
    arr = np.asarray(value, dtype=float)
    if arr.shape != (4, 4) or not np.all(np.isfinite(arr)):
        raise ModelError(f"{name} must be a finite (4, 4) pose, got shape {arr.shape}")
    return tuple(tuple(float(v) for v in row) for row in arr)


def _check_common(self, lengths):
    for name in lengths:
        value = getattr(self, name)
        if not np.isfinite(value):
            raise ModelError(f"{name} must be a finite length in metres, got {value!r}")
        object.__setattr__(self, name, float(value))
    offsets = tuple(float(v) for v in self.offsets)
    signs = tuple(int(v) for v in self.signs)
    if len(offsets) != 6 or not np.all(np.isfinite(offsets)):
        raise ModelError(f"offsets must be 6 finite angles in radians, got {self.offsets!r}")
    if len(signs) != 6 or any(s not in (1, -1) for s in signs):
        raise ModelError(f"signs must be 6 values of +1 or -1, got {self.signs!r}")
    object.__setattr__(self, "offsets", offsets)
    object.__setattr__(self, "signs", signs)
    object.__setattr__(self, "base_T_root", _transform_field(self.base_T_root, "base_T_root"))
    object.__setattr__(self, "tip_T_flange", _transform_field(self.tip_T_flange, "tip_T_flange"))


class _Family:
    """Joint conventions shared by both families: ``theta = sign * q - offset``."""

    def model_angles(self, q):
        """Model angles ``theta (m, 6)`` (rad) from controller joints ``q (m, 6)``."""
        return np.asarray(self.signs) * q - np.asarray(self.offsets)

    def joint_angles(self, theta):
        """Controller joints ``q (m, 6)`` (rad) from model angles ``theta (m, 6)``."""
        return (theta + np.asarray(self.offsets)) * np.asarray(self.signs)

    def _base(self):
        return None if self.base_T_root is None else np.array(self.base_T_root)

    def _tip(self):
        return None if self.tip_T_flange is None else np.array(self.tip_T_flange)

    def _to_base(self, root_T_tip):
        base, tip = self._base(), self._tip()
        if base is not None:
            root_T_tip = base @ root_T_tip
        if tip is not None:
            root_T_tip = root_T_tip @ tip
        return root_T_tip

    def _to_root(self, base_T_flange):
        base, tip = self._base(), self._tip()
        if base is not None:
            base_T_flange = invert_pose(base) @ base_T_flange
        if tip is not None:
            base_T_flange = base_T_flange @ invert_pose(tip)
        return base_T_flange


@dataclass(frozen=True)
class OPWParameters(_Family):
    """Ortho-parallel arm with spherical wrist (Brandstoetter et al. 2014), lengths in m.

    Model angles ``theta = signs * q - offsets``; at ``theta = 0`` the arm stands straight up
    in the root frame: axis 1 = root z, axes 2 and 3 along y, the wrist centre at
    ``(a1 + a2, b, c1 + c2 + c3)``, the tip ``c4`` above it with the root orientation.
    ``base_T_root`` (root frame in the caller's base frame) and ``tip_T_flange`` (flange in
    the tip frame) are identity when None; they are given as (4, 4) poses and kept as
    nested tuples (``np.array(...)`` gives them back). Example, ABB IRB 2400 (ABB joint
    convention)::

        OPWParameters(a1=0.100, a2=-0.135, b=0.0, c1=0.615, c2=0.705, c3=0.755, c4=0.085,
                      offsets=(0, 0, -np.pi / 2, 0, 0, 0))
    """

    a1: float
    a2: float
    b: float
    c1: float
    c2: float
    c3: float
    c4: float
    offsets: tuple = (0.0,) * 6
    signs: tuple = (1,) * 6
    base_T_root: tuple | None = field(default=None, repr=False)
    tip_T_flange: tuple | None = field(default=None, repr=False)

    def __post_init__(self):
        _check_common(self, ("a1", "a2", "b", "c1", "c2", "c3", "c4"))
        if self.c2 <= 0 or np.hypot(self.a2, self.c3) <= 0:
            raise ModelError(f"c2 and hypot(a2, c3) must be positive lengths, got c2={self.c2}, "
                             f"a2={self.a2}, c3={self.c3}")


@dataclass(frozen=True)
class URParameters(_Family):
    """Arm with axes 2, 3, 4 parallel, as the standard DH table of Universal Robots (m).

    DH rows ``(theta_i, d_i, a_i, alpha_i)``: ``(t1, d1, 0, pi/2)``, ``(t2, 0, a2, 0)``,
    ``(t3, 0, a3, 0)``, ``(t4, d4, 0, pi/2)``, ``(t5, d5, 0, -pi/2)``, ``(t6, d6, 0, 0)`` with
    ``theta = signs * q - offsets``. UR5e: ``d1=0.1625, a2=-0.425, a3=-0.3922, d4=0.1333,
    d5=0.0997, d6=0.0996``. ``base_T_root`` and ``tip_T_flange`` as in :class:`OPWParameters`.
    """

    d1: float
    a2: float
    a3: float
    d4: float
    d5: float
    d6: float
    offsets: tuple = (0.0,) * 6
    signs: tuple = (1,) * 6
    base_T_root: tuple | None = field(default=None, repr=False)
    tip_T_flange: tuple | None = field(default=None, repr=False)

    def __post_init__(self):
        _check_common(self, ("d1", "a2", "a3", "d4", "d5", "d6"))
        if self.a2 == 0 or self.a3 == 0 or self.d6 == 0:
            raise ModelError(f"a2, a3 and d6 must be non-zero, got a2={self.a2}, a3={self.a3}, "
                             f"d6={self.d6}")


# --------------------------------------------------------------------------- input checks

def _as_poses(value, name):
    arr = np.asarray(value, dtype=float)
    if arr.shape == (4, 4):
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1:] != (4, 4):
        raise DataError(f"{name} must be poses of shape (m, 4, 4), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise DataError(f"{name} contains NaN or infinite values")
    return arr


def _as_joints(value, n, name, allow_nan=False):
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.ndim != 2 or (n is not None and arr.shape[1] != n):
        want = f"(m, {n})" if n is not None else "(m, n)"
        raise DataError(f"{name} must be joint values of shape {want} in rad, "
                        f"got shape {arr.shape}")
    if not allow_nan and not np.all(np.isfinite(arr)):
        raise DataError(f"{name} contains NaN or infinite values")
    return arr


def _as_limits(limits, n):
    if limits is None:
        return None
    arr = np.asarray(limits, dtype=float)
    if arr.shape != (n, 2):
        raise DataError(f"limits must be (lower, upper) per joint, shape ({n}, 2) in rad, "
                        f"got shape {arr.shape}")
    if np.any(arr[:, 0] > arr[:, 1]):
        raise DataError(f"limits have a lower bound above the upper bound: {arr.tolist()}")
    return arr


def _wrap(angle):
    """Angles wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - angle, _TWO_PI)


def _dh(theta, d, a, cos_alpha, sin_alpha):
    """Standard DH transforms ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``, shape ``(..., 4, 4)``."""
    c, s = np.cos(theta), np.sin(theta)
    out = np.zeros(np.shape(theta) + (4, 4))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2], out[..., 0, 3] = (
        c, -s * cos_alpha, s * sin_alpha, a * c)
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2], out[..., 1, 3] = (
        s, c * cos_alpha, -c * sin_alpha, a * s)
    out[..., 2, 1], out[..., 2, 2], out[..., 2, 3] = sin_alpha, cos_alpha, d
    out[..., 3, 3] = 1.0
    return out


# --------------------------------------------------------------------------- OPW family

def _opw_tip(params, theta):
    """Tip frames ``(m, 4, 4)`` in the root frame for model angles ``theta (m, 6)``."""
    t1, t2, t3, t4, t5, t6 = np.moveaxis(theta, -1, 0)
    psi3 = np.arctan2(params.a2, params.c3)
    k = np.hypot(params.a2, params.c3)
    cx1 = params.c2 * np.sin(t2) + k * np.sin(t2 + t3 + psi3) + params.a1
    cz1 = params.c2 * np.cos(t2) + k * np.cos(t2 + t3 + psi3)
    c1, s1 = np.cos(t1), np.sin(t1)
    centre = np.stack([cx1 * c1 - params.b * s1, cx1 * s1 + params.b * c1, cz1 + params.c1], -1)
    rotation = rot_z(t1) @ rot_y(t2 + t3) @ rot_z(t4) @ rot_y(t5) @ rot_z(t6)
    position = centre + params.c4 * rotation[..., :, 2]
    return pose_from_rotation_translation(rotation, position)


def opw_forward(params: OPWParameters, q) -> np.ndarray:
    """Flange poses ``base_T_flange (m, 4, 4)`` (m) for joints ``q (m, 6)`` (rad)."""
    q = _as_joints(q, 6, "q")
    return params._to_base(_opw_tip(params, params.model_angles(q)))


def _acos(x, clip):
    return np.arccos(np.clip(x, -1.0, 1.0) if clip else x)


def _opw_branch(params, root_T_tip, branch, clip):
    """Model angles ``(k, 6)`` of one branch per row (``branch (k,)`` in 0..7) for tip poses
    in the root frame; NaN where unreachable. ``clip``: out-of-reach targets get the
    stretched arm instead of NaN."""
    behind, elbow, negative = branch >= 4, (branch // 2) % 2 == 1, branch % 2 == 1
    M = np.ascontiguousarray(root_T_tip[:, :3, :].transpose(1, 2, 0))    # (3, 4, k)
    R = M[:, :3]                                                        # R[i, j]: (k,)
    cx, cy, cz = M[:, 3] - params.c4 * R[:, 2]
    a1, a2, b, c1, c2, c3 = params.a1, params.a2, params.b, params.c1, params.c2, params.c3
    kappa_2 = a2 * a2 + c3 * c3
    psi3 = np.arctan2(a2, c3)
    with np.errstate(invalid="ignore", divide="ignore"):
        radial2 = cx * cx + cy * cy - b * b
        nx1 = np.sqrt(np.maximum(radial2, 0.0) if clip else radial2) - a1
        tmp1, tmp2 = np.arctan2(cy, cx), np.arctan2(b, nx1 + a1)
        theta1 = np.where(behind, tmp1 + tmp2 - np.pi, tmp1 - tmp2)
        # wrist centre in the arm plane, relative to axis 2 (behind: the arm turned round)
        forward = np.where(behind, nx1 + 2 * a1, nx1)
        dz = cz - c1
        s_2 = forward * forward + dz * dz
        phi = np.where(behind, -1.0, 1.0) * np.arctan2(forward, dz)
        g2 = _acos((s_2 + c2 * c2 - kappa_2) / (2 * np.sqrt(s_2) * c2), clip)
        g3 = _acos((s_2 - c2 * c2 - kappa_2) / (2 * c2 * np.sqrt(kappa_2)), clip)
    side = np.where(elbow, -1.0, 1.0)          # +1: wrist centre in front of the lower arm
    theta2 = phi - side * g2
    theta3 = side * g3 - psi3
    # rows of r = (Rz(theta1) Ry(theta2 + theta3))^T rotation, entry by entry
    s1, c1_ = np.sin(theta1), np.cos(theta1)
    t23 = theta2 + theta3
    s23, c23 = np.sin(t23), np.cos(t23)
    along = c1_ * R[0] + s1 * R[1]                                      # (3, k)
    across = c1_ * R[1] - s1 * R[0]
    r2 = s23 * along + c23 * R[2]
    theta4, theta5, theta6 = _spherical_wrist(
        c23 * along - s23 * R[2], across, r2, -params.offsets[3], params.signs[4], negative)
    theta = np.stack([theta1, theta2, theta3, theta4, theta5, theta6], 1)
    theta[np.any(np.isnan(theta), axis=1)] = np.nan
    return theta


def _spherical_wrist(r0, r1, r2, free4, sign5, negative):
    """Wrist angles (theta4, theta5, theta6), each ``(k,)``, of ``r = Rz(t4) Ry(t5) Rz(t6)``
    given by its rows ``r0, r1, r2 (3, k)`` (entry j of all k rows in ``r0[j]``): with
    ``sign5 * sin(t5) >= 0`` (positive wrist), or the flipped wrist where ``negative``. At a
    singular wrist t4 = ``free4``."""
    horizontal = np.hypot(r0[2], r1[2])
    t5 = np.arctan2(horizontal, r2[2])
    t4 = np.arctan2(r1[2], r0[2])
    t6 = np.arctan2(r2[1], -r2[0])
    singular = horizontal < _WRIST_EPS
    if np.any(singular):
        upright = r2[2] > 0
        t6_up = np.arctan2(r1[0], r0[0]) - free4
        t6_down = free4 - np.arctan2(-r1[0], -r0[0])
        t4 = np.where(singular, free4, t4)
        t6 = np.where(singular, np.where(upright, t6_up, t6_down), t6)
    flip = negative if sign5 > 0 else ~negative
    return (np.where(flip, t4 + np.pi, t4), np.where(flip, -t5, t5),
            np.where(flip, t6 + np.pi, t6))


def _all_branches(solve_branch, params, base_T_flange, clip):
    """``(m, 8, 6)`` controller joints, branch k in column k, wrapped to (-pi, pi]."""
    T = params._to_root(base_T_flange)
    m = len(T)
    theta = solve_branch(params, np.repeat(T, 8, axis=0), np.tile(np.arange(8), m), clip)
    return _wrap(params.joint_angles(theta)).reshape(m, 8, 6)


def _one_branch(params, base_T_flange, branch, clip):
    """``(m, 6)`` controller joints on ``branch (m,)``, wrapped to (-pi, pi]."""
    solve_branch = _opw_branch if isinstance(params, OPWParameters) else _ur_branch
    theta = solve_branch(params, params._to_root(base_T_flange), branch, clip)
    return _wrap(params.joint_angles(theta))


def closed_form_branch(params: OPWParameters | URParameters, base_T_flange, branch) -> np.ndarray:
    """The solution ``(m, 6)`` rad on ``branch (m,)`` (= ABB cfx) for flange poses
    ``(m, 4, 4)``, NaN where that branch cannot reach: one eighth of
    :func:`closed_form_inverse`'s work."""
    _check_family(params)
    T = _as_poses(base_T_flange, "base_T_flange")
    return _one_branch(params, T, np.broadcast_to(np.asarray(branch, dtype=int), (len(T),)),
                       clip=False)


def opw_inverse(params: OPWParameters, base_T_flange) -> np.ndarray:
    """All 8 joint solutions ``(m, 8, 6)`` (rad, in (-pi, pi]) for flange poses ``(m, 4, 4)``.

    Branch ``k`` has configuration number ``k`` (ABB cfx, see :func:`configuration_bits`);
    unreachable branches are NaN. At a singular wrist, axis 4 is set to 0.
    """
    return _all_branches(_opw_branch, params, _as_poses(base_T_flange, "base_T_flange"), False)


# --------------------------------------------------------------------------- UR family

_UR_ALPHA = ((0.0, 1.0), (1.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.0, -1.0), (1.0, 0.0))


def _ur_link(params, i, theta):
    d = (params.d1, 0.0, 0.0, params.d4, params.d5, params.d6)[i]
    a = (0.0, params.a2, params.a3, 0.0, 0.0, 0.0)[i]
    return _dh(theta, d, a, *_UR_ALPHA[i])


def _ur_frames(params, theta):
    """DH frames 1..6 in the root frame, shape ``(6, m, 4, 4)``."""
    frames = []
    T = None
    for i in range(6):
        link = _ur_link(params, i, theta[..., i])
        T = link if T is None else T @ link
        frames.append(T)
    return np.stack(frames)


def ur_forward(params: URParameters, q) -> np.ndarray:
    """Flange poses ``base_T_flange (m, 4, 4)`` (m) for joints ``q (m, 6)`` (rad)."""
    q = _as_joints(q, 6, "q")
    return params._to_base(_ur_frames(params, params.model_angles(q))[-1])


def _ur_branch(params, root_T_tip, branch, clip):
    """Model angles ``(k, 6)`` of one branch per row, as :func:`_opw_branch` (Hawkins)."""
    behind, elbow, negative = branch >= 4, (branch // 2) % 2 == 1, branch % 2 == 1
    T = root_T_tip
    x_axis, y_axis, z_axis, p06 = T[:, :3, 0], T[:, :3, 1], T[:, :3, 2], T[:, :3, 3]
    p05 = p06 - params.d6 * z_axis
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.hypot(p05[:, 0], p05[:, 1])
        phi = _acos(params.d4 / r, clip)
        # "+phi" puts the wrist point at p05 . x1 <= 0: in front when a2 < 0
        plus = behind if params.a2 >= 0 else ~behind
        t1 = np.arctan2(p05[:, 1], p05[:, 0]) + np.where(plus, phi, -phi) + np.pi / 2
        s1, c1 = np.sin(t1), np.cos(t1)
        t5 = _acos((p06[:, 0] * s1 - p06[:, 1] * c1 - params.d4) / params.d6, clip)
        t5 = params.signs[4] * np.where(negative, -t5, t5)
        s5 = np.sin(t5)
        singular = np.abs(s5) < _WRIST_EPS
        safe = np.where(singular, 1.0, s5)
        t6 = np.where(singular, -params.offsets[5],
                      np.arctan2((-y_axis[:, 0] * s1 + y_axis[:, 1] * c1) / safe,
                                 (x_axis[:, 0] * s1 - x_axis[:, 1] * c1) / safe))
        T14 = (invert_pose(_ur_link(params, 0, t1)) @ T
               @ invert_pose(_ur_link(params, 4, t5) @ _ur_link(params, 5, t6)))
        px, py = T14[:, 0, 3], T14[:, 1, 3]
        g3 = _acos((px * px + py * py - params.a2 ** 2 - params.a3 ** 2)
                   / (2 * params.a2 * params.a3), clip)
    t3 = np.where(elbow, -g3, g3)
    t2 = np.arctan2(py, px) - np.arctan2(params.a3 * np.sin(t3),
                                         params.a2 + params.a3 * np.cos(t3))
    t4 = np.arctan2(T14[:, 1, 0], T14[:, 0, 0]) - t2 - t3
    theta = np.stack([t1, t2, t3, t4, t5, t6], 1)
    theta[np.any(np.isnan(theta), axis=1)] = np.nan
    return theta


def ur_inverse(params: URParameters, base_T_flange) -> np.ndarray:
    """All 8 joint solutions ``(m, 8, 6)`` (rad, in (-pi, pi]) for flange poses ``(m, 4, 4)``.

    Branch ``k`` has configuration number ``k`` (:func:`configuration_bits`); unreachable
    branches are NaN. At a singular wrist (sin(theta5) = 0), axis 6 is set to 0.
    """
    return _all_branches(_ur_branch, params, _as_poses(base_T_flange, "base_T_flange"), False)


# --------------------------------------------------------------------------- both families

def _check_family(params):
    if not isinstance(params, (OPWParameters, URParameters)):
        raise ModelError(f"expected OPWParameters or URParameters, got {type(params).__name__}")


def closed_form_forward(params: OPWParameters | URParameters, q) -> np.ndarray:
    """:func:`opw_forward` or :func:`ur_forward`, whichever family ``params`` is."""
    _check_family(params)
    return (opw_forward if isinstance(params, OPWParameters) else ur_forward)(params, q)


def closed_form_inverse(params: OPWParameters | URParameters, base_T_flange,
                        clip: bool = False) -> np.ndarray:
    """:func:`opw_inverse` or :func:`ur_inverse`, whichever family ``params`` is.

    ``clip``: poses out of reach get the joints of the stretched arm towards them instead
    of NaN (a start for a closest-approach search)."""
    _check_family(params)
    if clip:
        return _closed_form(params, _as_poses(base_T_flange, "base_T_flange"), clip=True)
    return (opw_inverse if isinstance(params, OPWParameters) else ur_inverse)(params,
                                                                            base_T_flange)


def _margins(params, q):
    """Signed margins ``(m, 3)`` of the three configuration bits (>= 0 means bit 0)."""
    theta = params.model_angles(q)
    wrist = params.signs[4] * np.sin(theta[:, 4])
    if isinstance(params, OPWParameters):
        psi3 = np.arctan2(params.a2, params.c3)
        k = np.hypot(params.a2, params.c3)
        t2, t3 = theta[:, 1], theta[:, 2]
        front = params.c2 * np.sin(t2) + k * np.sin(t2 + t3 + psi3) + params.a1
        return np.stack([front, np.sin(t3 + psi3), wrist], 1)
    frames = _ur_frames(params, theta)
    x1 = frames[0][:, :3, 0]
    p05 = frames[4][:, :3, 3]
    front = np.sign(params.a2) * np.einsum("ij,ij->i", p05, x1)
    return np.stack([front, np.sin(theta[:, 2]), wrist], 1)


def configuration_bits(params: OPWParameters | URParameters, q, tolerance: float = 0.0):
    """Configuration bits ``(m, 3)`` int of joints ``q (m, 6)``: (behind, elbow, wrist).

    OPW arms (ABB's cfx, see :mod:`olp_compensate.compensation.confdata`): *behind* = wrist centre behind
    axis 1 (its x in the arm plane < 0), *elbow* = wrist centre behind the lower arm
    (``sin(theta3 + atan2(a2, c3)) < 0``), *wrist* = axis 5 negative
    (``sign5 * sin(theta5) < 0``). UR arms: *behind* = wrist point (frame 5 origin) on the
    side of axis 1 opposite to where the arm points at theta2 = 0; *elbow* =
    ``sin(theta3) < 0``; *wrist* as above. A bit whose margin is within ``tolerance``
    (m for *behind*, sine otherwise) is -1 (on a boundary).
    """
    _check_family(params)
    return _bits(params, _as_joints(q, 6, "q"), tolerance)


def _bits(params, q, tolerance):
    margin = _margins(params, q)
    bits = (margin < 0).astype(int)
    bits[~(np.abs(margin) >= tolerance) if tolerance > 0 else np.isnan(margin)] = -1
    return bits


def branch_of(params: OPWParameters | URParameters, q) -> np.ndarray:
    """Configuration number ``(m,)`` in 0..7 of joints ``q (m, 6)``; the closed forms'
    branch index: ``4 * behind + 2 * elbow + wrist`` of :func:`configuration_bits`."""
    bits = configuration_bits(params, q)
    return 4 * bits[:, 0] + 2 * bits[:, 1] + bits[:, 2]


# --------------------------------------------------------------------------- branch choice

_QUADRANT_AXES = (0, 3, 5)


def _shift_into(q, limits, lower, upper):
    """Shift ``q (m,)`` by multiples of 2 pi to be nearest the interval [lower, upper)
    (arrays ``(m,)``), staying inside ``limits`` (2,) if given (else as little outside as
    possible). Returns (value, distance to the interval)."""
    centre = 0.5 * (lower + upper)
    k0 = np.round((centre - q) / _TWO_PI)
    candidates = q[:, None] + _TWO_PI * (k0[:, None] + np.array([-1.0, 0.0, 1.0]))
    distance = np.maximum(np.maximum(lower[:, None] - candidates, 0.0),
                          candidates - upper[:, None])
    # inside the limits first, then nearest the interval, then nearest its centre
    score = distance + 1e-9 * np.abs(candidates - centre[:, None])
    if limits is not None:
        score += 1e6 * np.maximum(np.maximum(limits[0] - candidates, 0.0),
                                  candidates - limits[1])
    best = np.argmin(np.where(np.isnan(score), np.inf, score), axis=1)
    rows = np.arange(len(q))
    return candidates[rows, best], distance[rows, best]


def _select(solutions, confdata, limits, quadrant_tolerance):
    """Requested branches with 2 pi shifts; status 0 found, 1 no branch, 2 limits, 3 quadrant."""
    return _select_q(solutions[np.arange(len(solutions)), confdata[:, 3]], confdata, limits,
                     quadrant_tolerance)


def _select_q(q, confdata, limits, quadrant_tolerance):
    """:func:`_select` of joints ``q (m, 6)`` already on the requested branch: each axis as
    :func:`_shift_into` does it, all at once (axes first, so that rows are contiguous).
    Rows whose turn nearest the centre is inside the quadrant and the limits (by more than
    a tie of the scores could tell) keep it, found (status 0), without comparing turns."""
    axes = list(_QUADRANT_AXES) + ([1, 2, 4] if limits is not None else [])
    value = q[:, axes].T                                                 # (axes, m)
    lower = np.empty_like(value)
    lower[:3] = confdata[:, :3].T * (np.pi / 2)
    upper = lower + np.pi / 2
    if limits is not None:
        lower[3:], upper[3:] = limits[[1, 2, 4], 0, None], limits[[1, 2, 4], 1, None]
        lim = limits[axes]
    centre = 0.5 * (lower + upper)
    turns = np.round((centre - value) / _TWO_PI)
    best = value + _TWO_PI * turns
    inside = (best >= lower) & (best <= upper) & (np.abs(best - centre) < np.pi - 1e-6)
    if limits is not None:
        inside &= (best >= lim[:, 0, None]) & (best <= lim[:, 1, None])
    q = q.copy()
    q[:, axes] = best.T
    status = np.zeros(len(q), int)
    rest = np.flatnonzero(~np.all(inside, axis=0))
    if len(rest) == 0:
        return q, status
    value, lower, upper, centre, turns = (a[:, rest] for a in (value, lower, upper, centre,
                                                               turns))
    best = best_distance = best_score = None
    for shift in (-1.0, 0.0, 1.0):
        candidate = value + _TWO_PI * (turns + shift)
        distance = np.maximum(np.maximum(lower - candidate, 0.0), candidate - upper)
        # inside the limits first, then nearest the interval, then nearest its centre
        score = distance + 1e-9 * np.abs(candidate - centre)
        if limits is not None:
            score += 1e6 * np.maximum(np.maximum(lim[:, 0, None] - candidate, 0.0),
                                      candidate - lim[:, 1, None])
        if best is None:
            best, best_distance, best_score = candidate, distance, score
        else:
            better = score < best_score
            best = np.where(better, candidate, best)
            best_distance = np.where(better, distance, best_distance)
            best_score = np.where(better, score, best_score)
    part = q[rest]
    part[:, axes] = best.T
    q[rest] = part
    exists = np.all(np.isfinite(part), axis=1)
    quadrant_ok = ~np.any(best_distance[:3] > quadrant_tolerance, axis=0)
    within = np.ones(len(rest), bool)
    if limits is not None:
        within = np.all((part >= limits[:, 0]) & (part <= limits[:, 1]), axis=1)
    status[rest] = np.where(~exists, 1, np.where(~within, 2, np.where(~quadrant_ok, 3, 0)))
    return q, status


def _as_confdata(confdata, m):
    arr = np.asarray(confdata)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.shape != (m, 4) or not np.all(np.equal(np.mod(arr, 1), 0)):
        raise DataError(f"confdata must be integers (cf1, cf4, cf6, cfx) of shape ({m}, 4), "
                        f"got shape {arr.shape}")
    arr = arr.astype(int)
    if np.any((arr[:, 3] < 0) | (arr[:, 3] > 7)):
        raise DataError(f"cfx must be in 0..7, got {sorted(set(arr[:, 3].tolist()))}")
    return arr


def select_branch(solutions, confdata, limits=None, quadrant_tolerance: float = np.pi / 4):
    """The solution matching ABB-style ``confdata (m, 4)`` = (cf1, cf4, cf6, cfx).

    ``solutions (m, 8, 6)`` from :func:`opw_inverse` / :func:`ur_inverse` (branch index =
    cfx). Axes 1, 4, 6 are shifted by multiples of 2 pi into the quadrants
    ``[cf * 90 deg, (cf + 1) * 90 deg)``, or as near as ``limits (6, 2)`` (rad) allow; the
    other axes by 2 pi only to enter the limits. Returns ``q (m, 6)`` rad and
    ``found (m,)`` bool: False where the branch is unreachable, outside the limits, or an
    axis lies more than ``quadrant_tolerance`` (rad) from its requested quadrant.
    """
    solutions = np.asarray(solutions, dtype=float)
    if solutions.ndim != 3 or solutions.shape[1:] != (8, 6):
        raise DataError(f"solutions must have shape (m, 8, 6), got {solutions.shape}")
    confdata = _as_confdata(confdata, len(solutions))
    q, status = _select(solutions, confdata, _as_limits(limits, 6), quadrant_tolerance)
    return q, status == 0


def nominal_joints_on_branch(family_params: OPWParameters | URParameters, base_T_flange,
                             confdata, limits=None,
                             quadrant_tolerance: float = np.pi / 4) -> np.ndarray:
    """Joints ``(m, 6)`` rad the nominal controller takes for ``base_T_flange (m, 4, 4)``
    on ABB-style ``confdata (m, 4)``: the closed form of that branch, shifted as
    :func:`select_branch` does; NaN where the branch cannot reach. Only branch cfx is
    solved (not all eight)."""
    _check_family(family_params)
    T = _as_poses(base_T_flange, "base_T_flange")
    confdata = _as_confdata(confdata, len(T))
    q = closed_form_branch(family_params, T, confdata[:, 3])
    return _select_q(q, confdata, _as_limits(limits, 6), quadrant_tolerance)[0]


# --------------------------------------------------------------------------- family fit

_FIT_ANGLE = 0.7          # rad, the finite rotation used to read each joint axis
_STRUCTURE_TOL = 1e-7     # m or rad: how far from the family's geometry a fit may start
_FOLD_TOL = 1e-9          # flange frame folded into c4 / d6 and the axis-6 offset below this
_VERIFY_TOL = 1e-9        # m and rad: acceptance of a fitted family


def _read_axes(flange_pose, n):
    """Joint axes at q = 0 in the base frame: directions (n, 3), points (n, 3), and M (4, 4)."""
    q = np.zeros((n + 1, n))
    q[1:] = np.eye(n) * _FIT_ANGLE
    poses = _as_poses(flange_pose(q), "flange_pose(q)")
    if len(poses) != n + 1:
        raise ModelError(f"flange_pose returned {len(poses)} poses for {n + 1} joint vectors")
    M = poses[0]
    G = poses[1:] @ invert_pose(M)
    w = rotvec_from_rotation(G[:, :3, :3])
    if np.any(np.abs(np.linalg.norm(w, axis=1) - _FIT_ANGLE) > _STRUCTURE_TOL):
        return None                                              # not a unit-gain revolute
    directions = w / _FIT_ANGLE
    points = np.empty((n, 3))
    for i in range(n):
        A = np.eye(3) - G[i, :3, :3]
        points[i] = np.linalg.lstsq(A, G[i, :3, 3], rcond=1e-9)[0]
        if np.linalg.norm(A @ points[i] - G[i, :3, 3]) > _STRUCTURE_TOL:
            return None                                          # a screw, not a rotation
    return directions, points, M


def _closest_point(points, directions):
    """Point nearest to all lines (least squares) and the largest distance to them."""
    P = np.eye(3) - directions[:, :, None] * directions[:, None, :]
    A, rhs = P.sum(0), np.einsum("kij,kj->i", P, points)
    if np.linalg.svd(A, compute_uv=False)[-1] < 1e-6:
        return None, np.inf
    x = np.linalg.solve(A, rhs)
    dist = np.linalg.norm(np.einsum("kij,kj->ki", P, x - points), axis=1)
    return x, dist.max()


def _root_frame(direction1, point1):
    """Root frame: z along axis 1, origin on it nearest the base origin, x from base x."""
    z = direction1
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z], 1)
    return pose_from_rotation_translation(R, point1)


def _tidy_length(value):
    """Round fitted lengths to 1e-12 m: fit noise of ~1e-16 m would only clutter a repr."""
    return float(np.round(value, 12)) + 0.0


def _tidy_angles(angles):
    """Wrap to (-pi, pi] and snap to multiples of pi/2 within 1e-12 rad."""
    angles = _wrap(np.asarray(angles, dtype=float))
    snapped = np.round(angles / (np.pi / 2)) * (np.pi / 2)
    return tuple(float(v) + 0.0 for v in np.where(np.abs(angles - snapped) < 1e-12,
                                                   _wrap(snapped), angles))


def _is_identity(T):
    return np.allclose(T, np.eye(4), rtol=0.0, atol=1e-14)


def _fold_tip(tip_T_flange):
    """(along-z offset, rotation about z) if the flange lies on the tip z axis, else None."""
    R, t = tip_T_flange[:3, :3], tip_T_flange[:3, 3]
    if abs(R[2, 2] - 1.0) < _FOLD_TOL and np.hypot(t[0], t[1]) < _FOLD_TOL:
        return t[2], np.arctan2(R[1, 0], R[0, 0])
    return None


def _fit_opw(directions, points, M):
    """OPW parameters from joint axes at q = 0 (base frame) and the flange pose M, or None.

    Frame choices: root z along axis 1 (sign1 = +1); arm x towards the front (a1 > 0);
    sign4 so that c3 > 0; sign5 so that |offset4| <= pi/2; sign6 so that the flange z is
    the tip z when it lies along axis 6 (then folded into c4 and offset6)."""
    root = _root_frame(directions[0], points[0])
    root_inv = invert_pose(root)
    w = directions @ root_inv[:3, :3].T
    p = points @ root_inv[:3, :3].T + root_inv[:3, 3]
    flange = root_inv @ M
    centre, spread = _closest_point(p[3:], w[3:])
    if centre is None or spread > _STRUCTURE_TOL:
        return None                                              # no spherical wrist
    if (abs(w[0] @ w[1]) > _STRUCTURE_TOL or np.linalg.norm(np.cross(w[1], w[2])) > _STRUCTURE_TOL
            or abs(w[2] @ w[3]) > _STRUCTURE_TOL):
        return None
    z = np.array([0.0, 0.0, 1.0])
    # arm frame: y along axis 2, x towards the front (a1 > 0, else the wrist centre at q = 0)
    choice = None
    for sign2 in (1, -1):
        y_arm = sign2 * w[1]
        x_arm = np.cross(y_arm, z)
        a1 = p[1] @ x_arm
        key = (a1 > _STRUCTURE_TOL, abs(a1) <= _STRUCTURE_TOL and centre @ x_arm > _STRUCTURE_TOL)
        if choice is None or key > choice[0]:
            choice = (key, sign2, x_arm, y_arm, a1)
    _, sign2, x_arm, y_arm, a1 = choice
    theta1 = np.arctan2(x_arm[1], x_arm[0])
    c1 = p[1] @ z
    sign3 = 1 if w[2] @ y_arm > 0 else -1
    x3, z3 = p[2] @ x_arm, p[2] @ z
    c2 = np.hypot(x3 - a1, z3 - c1)
    theta2 = np.arctan2(x3 - a1, z3 - c1)
    b = centre @ y_arm
    dx, dz = centre @ x_arm - x3, centre @ z - z3
    best = None
    for sign4 in (1, -1):
        d4 = sign4 * w[3]
        t23 = np.arctan2(d4 @ x_arm, d4 @ z)
        a2 = dx * np.cos(t23) - dz * np.sin(t23)
        c3 = dx * np.sin(t23) + dz * np.cos(t23)
        if best is None or c3 > best[3]:
            best = (sign4, t23, a2, c3)
    sign4, t23, a2, c3 = best
    arm = np.stack([x_arm, y_arm, z], 1)
    R0c = arm @ rot_y(t23)
    best = None
    for sign5 in (1, -1):
        v = R0c.T @ (sign5 * w[4])
        t4 = np.arctan2(-v[0], v[1])
        if best is None or abs(t4) < abs(best[1]):
            best = (sign5, t4)
    sign5, t4 = best
    R04 = R0c @ rot_z(t4)
    flange_z = flange[:3, 2]
    if abs(abs(flange_z @ w[5]) - 1.0) < _FOLD_TOL:
        candidates = (1 if flange_z @ w[5] > 0 else -1,)
    else:
        candidates = (1, -1)
    best = None
    for sign6 in candidates:
        u = R04.T @ (sign6 * w[5])
        t5 = np.arctan2(u[0], u[2])
        if best is None or abs(t5) < abs(best[1]):
            best = (sign6, t5)
    sign6, t5 = best
    tip0 = pose_from_rotation_translation(R04 @ rot_y(t5), centre)
    tip_T_flange = invert_pose(tip0) @ flange
    folded = _fold_tip(tip_T_flange)
    if folded is not None:
        c4, t6 = folded
        tip_T_flange = None
    else:
        c4, t6 = 0.0, 0.0
    theta0 = np.array([theta1, theta2, t23 - theta2, t4, t5, t6])
    a1, a2, b, c1, c2, c3, c4 = map(_tidy_length, (a1, a2, b, c1, c2, c3, c4))
    return OPWParameters(
        a1=a1, a2=a2, b=b, c1=c1, c2=c2, c3=c3, c4=c4, offsets=_tidy_angles(-theta0),
        signs=(1, sign2, sign3, sign4, sign5, sign6),
        base_T_root=None if _is_identity(root) else root, tip_T_flange=tip_T_flange)


def _line_intersection(p_a, d_a, p_b, d_b):
    """Parameter along line a of its closest point to line b, and the lines' distance."""
    n = np.cross(d_a, d_b)
    if np.linalg.norm(n) < 1e-6:
        return None, np.inf
    n /= np.linalg.norm(n)
    distance = abs((p_b - p_a) @ n)
    # solve p_a + s d_a = p_b + t d_b in least squares
    A = np.stack([d_a, -d_b], 1)
    s, _ = np.linalg.lstsq(A, p_b - p_a, rcond=1e-12)[0]
    return s, distance


def _fit_ur(directions, points, M):
    """UR (DH) parameters from joint axes at q = 0 (base frame) and the flange pose M, or
    None. Signs of a2, a3 and of axes 5, 6 are chosen for the smallest zero offsets."""
    root = _root_frame(directions[0], points[0])
    root_inv = invert_pose(root)
    w = directions @ root_inv[:3, :3].T
    p = points @ root_inv[:3, :3].T + root_inv[:3, 3]
    flange = root_inv @ M
    z = np.array([0.0, 0.0, 1.0])
    if abs(w[0] @ w[1]) > _STRUCTURE_TOL:
        return None
    if any(np.linalg.norm(np.cross(w[1], w[i])) > _STRUCTURE_TOL for i in (2, 3)):
        return None
    z1 = w[1]                                     # sign2 = +1 by choice of theta1
    theta1 = np.arctan2(z1[0], -z1[1])
    x1 = np.array([np.cos(theta1), np.sin(theta1), 0.0])
    y1 = np.cross(z1, x1)
    d1 = p[1] @ z
    origin1 = d1 * z
    if abs((p[1] - origin1) @ x1) > _STRUCTURE_TOL:
        return None                                              # axis 2 misses axis 1

    def planar(point):
        rel = point - origin1
        return np.array([rel @ x1, rel @ y1])

    def length_and_angle(vec, previous):
        best = None
        for sign in (-1.0, 1.0):
            length = sign * np.linalg.norm(vec)
            angle = _wrap(np.arctan2(vec[1] / length, vec[0] / length) - previous)
            if best is None or abs(angle) < abs(best[1]) - 1e-12:
                best = (length, angle)
        return best

    P3, P4 = planar(p[2]), planar(p[3])
    a2, theta2 = length_and_angle(P3, 0.0)
    a3, theta3 = length_and_angle(P4 - P3, theta2)
    sign3 = 1 if w[2] @ z1 > 0 else -1
    sign4 = 1 if w[3] @ z1 > 0 else -1
    t23 = theta2 + theta3
    x3 = np.cos(t23) * x1 + np.sin(t23) * y1
    y3 = np.cross(z1, x3)
    origin3 = origin1 + a2 * (np.cos(theta2) * x1 + np.sin(theta2) * y1) + a3 * x3
    d4, gap = _line_intersection(origin3, z1, p[4], w[4])
    if d4 is None or gap > _STRUCTURE_TOL:
        return None
    origin4 = origin3 + d4 * z1
    best = None
    for sign5 in (1, -1):
        z4 = sign5 * w[4]
        t4 = np.arctan2(z4 @ x3, -(z4 @ y3))
        if best is None or abs(t4) < abs(best[1]):
            best = (sign5, t4, z4)
    sign5, theta4, z4 = best
    x4 = np.cos(theta4) * x3 + np.sin(theta4) * y3
    y4 = np.cross(z4, x4)
    d5, gap = _line_intersection(origin4, z4, p[5], w[5])
    if d5 is None or gap > _STRUCTURE_TOL:
        return None
    origin5 = origin4 + d5 * z4
    flange_z = flange[:3, 2]
    if abs(abs(flange_z @ w[5]) - 1.0) < _FOLD_TOL:
        candidates = (1 if flange_z @ w[5] > 0 else -1,)
    else:
        candidates = (1, -1)
    best = None
    for sign6 in candidates:
        z5 = sign6 * w[5]
        t5 = np.arctan2(-(z5 @ x4), z5 @ y4)
        if best is None or abs(t5) < abs(best[1]):
            best = (sign6, t5, z5)
    sign6, theta5, z5 = best
    x5 = np.cos(theta5) * x4 + np.sin(theta5) * y4
    R5 = np.stack([x5, np.cross(z5, x5), z5], 1)
    reach = (flange[:3, 3] - origin5) @ z5
    d6 = reach if abs(reach) > 1e-3 else 0.1                 # d6 must not vanish
    tip0 = pose_from_rotation_translation(R5, origin5 + d6 * z5)
    tip_T_flange = invert_pose(tip0) @ flange
    folded = _fold_tip(tip_T_flange)
    if folded is not None:
        d6, theta6 = d6 + folded[0], folded[1]
        tip_T_flange = None
    else:
        theta6 = 0.0
    theta0 = np.array([theta1, theta2, theta3, theta4, theta5, theta6])
    d1, a2, a3, d4, d5, d6 = map(_tidy_length, (d1, a2, a3, d4, d5, d6))
    return URParameters(
        d1=d1, a2=a2, a3=a3, d4=d4, d5=d5, d6=d6, offsets=_tidy_angles(-theta0),
        signs=(1, 1, sign3, sign4, sign5, sign6),
        base_T_root=None if _is_identity(root) else root, tip_T_flange=tip_T_flange)


def _pose_error(target, poses):
    """Errors ``(m, 6)``: position (m) and rotation vector (rad), both in the base frame,
    taking ``poses`` to ``target``."""
    err = np.empty((len(poses), 6))
    np.subtract(target[:, :3, 3], poses[:, :3, 3], out=err[:, :3])
    # R = Rt Rp^T = sum_k t_k p_k^T over the columns k: sin(angle) * axis = (R - R^T)^v / 2
    # = sum_k p_k x t_k / 2 and cos(angle) = (trace(R) - 1) / 2 = (sum Rt * Rp - 1) / 2.
    # Exact, and cheaper than via a quaternion, up to 90 deg (beyond: the quaternion).
    t = np.ascontiguousarray(np.moveaxis(target[:, :3, :3], 0, -1))      # (3, 3, m)
    p = np.ascontiguousarray(np.moveaxis(poses[:, :3, :3], 0, -1))
    dr = np.empty((3, len(poses)))
    np.sum(p[1] * t[2] - p[2] * t[1], axis=0, out=dr[0])
    np.sum(p[2] * t[0] - p[0] * t[2], axis=0, out=dr[1])
    np.sum(p[0] * t[1] - p[1] * t[0], axis=0, out=dr[2])
    dr *= 0.5
    cos = 0.5 * (np.sum(t * p, axis=(0, 1)) - 1.0)
    sin = np.sqrt(np.sum(dr * dr, axis=0))
    tiny = sin < 1e-12
    dr *= np.where(tiny, 1.0, np.arctan2(sin, cos) / np.where(tiny, 1.0, sin))
    err[:, 3:] = dr.T
    wide = np.flatnonzero(cos < 0.0)
    if len(wide):
        err[wide, 3:] = rotvec_from_rotation(
            target[wide, :3, :3] @ np.swapaxes(poses[wide, :3, :3], -1, -2))
    return err


def fit_family(flange_pose: Callable[[np.ndarray], np.ndarray], n_joints: int = 6,
               seed: int = 0) -> OPWParameters | URParameters | None:
    """Closed-form family and parameters of a robot given only its forward kinematics.

    ``flange_pose(q (m, n_joints) rad) -> base_T_flange (m, 4, 4)`` (m). The joint axes are
    read at q = 0 from finite rotations of each joint, the OPW or UR geometry is fitted to
    them, and the fit is accepted only if the family's forward kinematics matches
    ``flange_pose`` at 50 random configurations (uniform in [-pi, pi], ``seed``) within
    1e-9 m and 1e-9 rad. Returns None for any other robot.
    """
    if n_joints != 6:
        return None
    axes = _read_axes(flange_pose, n_joints)
    if axes is None:
        return None
    q = np.random.default_rng(seed).uniform(-np.pi, np.pi, (50, 6))
    expected = _as_poses(flange_pose(q), "flange_pose(q)")
    for fit, forward in ((_fit_opw, opw_forward), (_fit_ur, ur_forward)):
        try:
            params = fit(*axes)
        except (ModelError, np.linalg.LinAlgError):
            params = None
        if params is None:
            continue
        err = _pose_error(expected, forward(params, q))
        if (np.max(np.linalg.norm(err[:, :3], axis=1)) <= _VERIFY_TOL
                and np.max(np.linalg.norm(err[:, 3:], axis=1)) <= _VERIFY_TOL):
            return params
    return None


# --------------------------------------------------------------------------- refinement

@dataclass
class IKSolution:
    """Result of :func:`refine` / :func:`solve` for m targets.

    q : (m, n) rad, the last iterate (valid only where ``success``).
    success : (m,) bool, True where the target is reached within tolerance, inside the
        joint limits, on the requested configuration.
    reason : (m,) str from :data:`REASONS`. 'ok'; 'singular' (reached, success True, but the
        Jacobian's smallest singular value is below ``singular_tol`` times its largest, so
        some joints, e.g. axes 4 and 6 at axis 5 = 0, are not unique); 'unreachable' (no
        solution on the requested branch, or the iteration stalled short of the target);
        'joint_limit'; 'branch_changed' (reached, but on another configuration than
        requested); 'not_converged' (iteration limit).
    iterations : (m,) int, Newton steps tried.
    position_error_m, rotation_error_rad : (m,) final errors (norms, base frame).
    """

    q: np.ndarray
    success: np.ndarray
    reason: np.ndarray
    iterations: np.ndarray
    position_error_m: np.ndarray
    rotation_error_rad: np.ndarray


def _evaluate(fk_jacobian, q, target, n):
    poses, jac = _model(fk_jacobian, q, n)
    # the Jacobian is kept across calls: a copy, in case the model reuses its buffers
    return np.array(jac, dtype=float), _pose_error(target, poses)


def _model(fk_jacobian, q, n):
    """The model's poses ``(k, 4, 4)`` and Jacobian ``(k, 6, n)`` at ``q (k, n)``, checked."""
    poses, jac = fk_jacobian(q)
    poses, jac = np.asarray(poses, dtype=float), np.asarray(jac, dtype=float)
    if poses.shape != (len(q), 4, 4) or jac.shape != (len(q), 6, n):
        raise ModelError(f"fk_jacobian must return poses ({len(q)}, 4, 4) and a Jacobian "
                         f"({len(q)}, 6, {n}); got {poses.shape} and {jac.shape}")
    return poses, jac


def _joint_major(jac):
    """``jac (k, r, n)`` as a contiguous ``(n, r, k)`` array: the columns, batch last (no
    copy if it is one already, as a Jacobian built that way and handed out transposed)."""
    return np.ascontiguousarray(np.transpose(jac, (2, 1, 0)))


def _norms(err):
    """Position and rotation error norms ``(m,)`` of errors ``(m, 6)``."""
    return (np.sqrt(np.einsum("ij,ij->i", err[:, :3], err[:, :3])),
            np.sqrt(np.einsum("ij,ij->i", err[:, 3:], err[:, 3:])))


def _normal_matrices(jc, rhs=None):
    """``J^T J`` of Jacobians ``jc (n, r, k)`` (columns, batch last) as ``(n, n [+ 1], k)``
    (so that the elimination below works on contiguous rows), with ``J^T rhs`` appended as
    column n for ``rhs (k, r)``. The upper triangle is computed, the lower copied."""
    n, _, k = jc.shape
    A = np.empty((n, n + (rhs is not None), k))
    for i in range(n):
        np.einsum("ak,jak->jk", jc[i], jc[i:], out=A[i, i:n])
        A[i + 1:, i] = A[i, i + 1:n]
    if rhs is not None:
        A[:, n] = np.einsum("iak,ak->ik", jc, np.ascontiguousarray(rhs.T))
    return A


def _eliminate(A, n):
    """Gaussian elimination without pivoting, in place, of ``A (n, n + c, k)`` whose
    leading ``(n, n)`` blocks are symmetric positive (semi)definite (where it is stable)."""
    for c in range(n - 1):
        factor = A[c + 1:, c] / A[c, c]
        A[c + 1:, c + 1:] -= factor[:, None] * A[c, None, c + 1:]


def _gauss_newton_steps(jac, err, damping):
    """Steps ``(k, n)`` solving ``(J^T J + mu I) dq = J^T err``, ``mu = damping *
    trace(J^T J) / n``, for a batch ``jac (k, 6, n)``; see :func:`_gauss_newton_steps_t`."""
    return _gauss_newton_steps_t(_joint_major(jac), err, damping)


def _gauss_newton_steps_t(jc, err, damping):
    """:func:`_gauss_newton_steps` of Jacobians ``jc (n, 6, k)``, columns and batch last.
    Batched by hand: LAPACK's solve pays a call per 6 x 6 system. Rows without a finite
    solution get a zero step."""
    n = jc.shape[0]
    A = _normal_matrices(jc, err)
    diagonal = np.arange(n)
    A[diagonal, diagonal] += damping * np.einsum("iik->k", A[:, :n]) / n
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        _eliminate(A, n)
        step = np.empty((n, A.shape[2]))
        for c in range(n - 1, -1, -1):
            step[c] = (A[c, n] - np.einsum("ik,ik->k", A[c, c + 1:n], step[c + 1:])) / A[c, c]
    step = step.T
    step[~np.all(np.isfinite(step), axis=1)] = 0.0
    return step


def _singular(jac, tolerance):
    """Rows ``(k,)`` of ``jac (k, 6, n)`` whose smallest singular value is below
    ``tolerance`` times the largest; see :func:`_singular_t`."""
    return _singular_t(_joint_major(jac), tolerance)


def _singular_t(jc, tolerance):
    """:func:`_singular` of Jacobians ``jc (n, 6, k)``, columns and batch last. For square
    ones, |det J| / |J|_F^6 <= s_min / s_max clears most rows without an SVD (det(J)^2 =
    det(J^T J), the product of the pivots of its elimination)."""
    k = jc.shape[2]
    candidates = np.ones(k, bool)
    if jc.shape[0] == 6 and k:
        A = _normal_matrices(jc)
        frobenius_2 = np.einsum("iik->k", A)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            _eliminate(A, 6)
            det_2 = np.prod(A[np.arange(6), np.arange(6)], axis=0)
            candidates = ~(det_2 >= tolerance ** 2 * frobenius_2 ** 6)
    singular = np.zeros(k, bool)
    if np.any(candidates):
        sv = np.linalg.svd(np.transpose(jc[..., candidates], (2, 1, 0)), compute_uv=False)
        singular[candidates] = sv[:, -1] < tolerance * sv[:, 0]
    return singular


def _newton(fk_jacobian, q0, target, position_tol, rotation_tol, max_iterations, max_step,
            accept=None, groups=None):
    """The iteration of :func:`refine` on rows of finite ``q0``. Only unfinished rows are
    evaluated; each row leaves the batch when it converges, stalls or runs out of steps.
    Multi-start: ``accept(rows, q, jac) -> (k,) bool`` judges rows as they converge; once
    one row of a group (``groups (m,)`` int >= 0) is accepted, the others of the group
    leave too. Returns q, jac, err, iterations, converged, stalled."""
    m, n = q0.shape
    q = q0.copy()
    jac = np.full((m, 6, n), np.nan)
    err = np.full((m, 6), np.nan)
    iterations = np.zeros(m, int)
    converged = np.zeros(m, bool)
    stalled = np.zeros(m, bool)
    act = np.flatnonzero(np.all(np.isfinite(q0), axis=1))
    if len(act) == 0:
        return q, jac, err, iterations, converged, stalled
    q_a, target_a = q[act], target[act]
    J, e = _evaluate(fk_jacobian, q_a, target_a, n)
    cost = np.einsum("ij,ij->i", e, e)
    fraction = np.ones(len(act))         # backtracking: share of the Newton step tried
    stale = np.zeros(len(act), int)      # steps in a row without real progress
    stuck = np.zeros(len(act), bool)
    resolved = None if accept is None else np.zeros(int(np.max(groups, initial=0)) + 1, bool)
    for iteration in range(max_iterations + 1):
        position, rotation = _norms(e)
        done = (position <= position_tol) & (rotation <= rotation_tol)
        leave = done | stuck if iteration < max_iterations else np.ones(len(act), bool)
        if accept is not None:
            finished = np.flatnonzero(done)
            if len(finished):
                good = finished[accept(act[finished], q_a[finished], J[finished])]
                resolved[groups[act[good]]] = True
            leave |= resolved[groups[act]]
        if np.any(leave):
            rows = act[leave]
            q[rows], jac[rows], err[rows] = q_a[leave], J[leave], e[leave]
            iterations[rows] = iteration
            converged[rows] = done[leave]
            stalled[rows] = stuck[leave] & ~done[leave]
            keep = ~leave
            if not np.any(keep):
                break
            act, q_a, target_a, J, e = act[keep], q_a[keep], target_a[keep], J[keep], e[keep]
            cost, fraction, stale = cost[keep], fraction[keep], stale[keep]
        step = _gauss_newton_steps(J, e, _DAMPING)
        biggest = np.max(np.abs(step), axis=1)
        step *= (np.minimum(1.0, max_step / np.maximum(biggest, 1e-300)) * fraction)[:, None]
        trial = q_a + step
        J_t, e_t = _evaluate(fk_jacobian, trial, target_a, n)
        cost_t = np.einsum("ij,ij->i", e_t, e_t)
        better = cost_t < cost
        if np.all(better):
            q_a, J, e = trial, J_t, e_t
        else:
            q_a = np.where(better[:, None], trial, q_a)
            J = np.where(better[:, None, None], J_t, J)
            e = np.where(better[:, None], e_t, e)
        fraction = np.where(better, np.minimum(1.0, 2.0 * fraction), 0.25 * fraction)
        # stalled: _STALL_STEPS steps in a row without lowering the error by a millionth
        stale = np.where(cost_t < (1.0 - 1e-6) * cost, 0, stale + 1)
        cost = np.where(better, cost_t, cost)
        stuck = (stale >= _STALL_STEPS) | (fraction < 1e-9)
    return q, jac, err, iterations, converged, stalled


def refine(fk_jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], q0, target,
           limits=None, position_tol: float = 1e-9, rotation_tol: float = 1e-9,
           max_iterations: int = 50, *, singular_tol: float = 1e-7, max_step: float = 0.5,
           configuration: Callable[[np.ndarray], np.ndarray] | None = None) -> IKSolution:
    """Damped Newton from ``q0 (m, n)`` rad to ``target (m, 4, 4)`` m.

    ``fk_jacobian(q (k, n)) -> (base_T_flange (k, 4, 4), jacobian (k, 6, n))``, the
    geometric Jacobian in the base frame (rows: flange-origin linear velocity, then angular
    velocity). All targets iterate together; converged ones leave the batch (the model is
    evaluated only on unfinished rows). The Gauss-Newton
    step (with a 1e-10 relative Tikhonov term) is scaled so no joint moves more than
    ``max_step`` rad and is taken only if it lowers the squared error, else a quarter of it
    is tried next (backtracking; the share doubles again after a success). A target whose
    squared error has not dropped by a millionth in 20 steps in a row is 'unreachable'
    (stuck at the workspace boundary or a singularity). Converged when the position error is at most
    ``position_tol`` (m) and the rotation error at most ``rotation_tol`` (rad). Rows of
    ``q0`` with NaN are 'unreachable'. ``limits (n, 2)`` rad are checked at the end, not
    enforced. ``configuration(q (k, n)) -> (k,) or (k, b) int`` (-1 = undetermined), if
    given, labels the configuration: a label of the result that differs from that of
    ``q0`` gives 'branch_changed'. See :class:`IKSolution` for the reasons.
    """
    q0 = _as_joints(q0, None, "q0", allow_nan=True)
    m, n = q0.shape
    target = _as_poses(target, "target")
    if len(target) != m:
        raise DataError(f"target has {len(target)} poses but q0 has {m} rows")
    limits = _as_limits(limits, n)
    for name, value in (("position_tol", position_tol), ("rotation_tol", rotation_tol)):
        if not value > 0:
            raise DataError(f"{name} must be positive, got {value!r}")
    if int(max_iterations) < 0:
        raise DataError(f"max_iterations must be >= 0, got {max_iterations!r}")

    q, jac, err, iterations, converged, stalled = _newton(
        fk_jacobian, q0, target, position_tol, rotation_tol, int(max_iterations), max_step)
    reason = np.full(m, "not_converged", dtype="<U14")
    reason[~np.all(np.isfinite(q0), axis=1) | stalled] = "unreachable"
    reason[converged] = "ok"

    done = np.flatnonzero(converged)
    if len(done):
        reason[done[_singular(jac[done], singular_tol)]] = "singular"
        if limits is not None:
            outside = np.any((q[done] < limits[:, 0]) | (q[done] > limits[:, 1]), axis=1)
            reason[done[outside]] = "joint_limit"
        if configuration is not None:
            before = np.asarray(configuration(q0[done])).reshape(len(done), -1)
            after = np.asarray(configuration(q[done])).reshape(len(done), -1)
            changed = np.any((before >= 0) & (after >= 0) & (before != after), axis=1)
            reason[done[changed]] = "branch_changed"
    success = np.isin(reason, ("ok", "singular"))
    position, rotation = _norms(err)
    return IKSolution(q=q, success=success, reason=reason, iterations=iterations,
                      position_error_m=position, rotation_error_rad=rotation)


def _closed_form(params, T, clip):
    solve_branch = _opw_branch if isinstance(params, OPWParameters) else _ur_branch
    return _all_branches(solve_branch, params, T, clip)


def _default_confdata(solutions, limits):
    """Where no configuration is asked for: the reachable branch with the smallest |q|."""
    q = solutions.copy()
    if limits is not None:
        outside = np.any((q < limits[:, 0]) | (q > limits[:, 1]), axis=2)
        q[outside] = np.nan
    norm = np.where(np.all(np.isfinite(q), 2), np.sum(q * q, 2), np.inf)
    cfx = np.argmin(norm, axis=1)
    chosen = solutions[np.arange(len(q)), cfx]
    quadrant = np.floor(np.nan_to_num(chosen[:, list(_QUADRANT_AXES)]) / (np.pi / 2))
    return np.concatenate([quadrant.astype(int), cfx[:, None]], 1)


_CLOSED_FORM_STEPS = 8    # steps of _closed_form_newton before the multi-start Newton
_WILD = 1.0               # _closed_form_newton: fixed-point step where |twist - e| > this |e|
_BLOCK = 2048             # targets per batch of _closed_form_newton
_FIRST_STEPS = 2          # its steps in blocks, before the rows that need more go on together
_MULTI_START_STEPS = 12   # Newton steps of the multi-start retry
_JOINT_STEP = 1e-6        # m and rad: errors below this are stepped in the joints
_FIXED_POINT_STEPS = 20
_FIXED_POINT_TOL = 1e-6    # rad: the closed-form iteration hands over to Newton below this


def _opw_jacobian(params, theta):
    """Geometric Jacobian ``(m, 6, 6)`` (root frame, at the flange origin, per model angle)
    and flange positions ``(m, 3)`` of the OPW arm."""
    arm = _opw_axes(params, theta)
    z = np.zeros_like(arm.y_arm)
    z[2] = 1.0
    axes = np.stack([z, arm.y_arm, arm.y_arm, arm.col2, arm.y4, arm.z6])   # (6, 3, m)
    points = np.stack([np.zeros_like(z), arm.axis2, arm.axis3, arm.centre, arm.centre,
                       arm.centre])
    return _screw_jacobian(axes, arm.flange - points), arm.flange.T


@dataclass(frozen=True)
class _OPWAxes:
    """Joint axes of an OPW arm at m configurations, root frame, each ``(3, m)``: axis 1 is
    the root z through the origin; ``y_arm`` the direction of axes 2 and 3, through the
    points ``axis2`` and ``axis3``; ``col2``, ``y4``, ``z6`` the directions of axes 4, 5
    and 6, through the wrist ``centre``; ``flange`` the flange origin, m."""

    y_arm: np.ndarray
    axis2: np.ndarray
    axis3: np.ndarray
    col2: np.ndarray
    y4: np.ndarray
    z6: np.ndarray
    centre: np.ndarray
    flange: np.ndarray


def _opw_axes(params, theta):
    """:class:`_OPWAxes` of the OPW arm at model angles ``theta (m, 6)``."""
    t1, t2, t3, t4, t5, t6 = theta.T
    c1, s1 = np.cos(t1), np.sin(t1)
    zero = np.zeros_like(t1)
    x_arm = np.stack([c1, s1, zero])                                  # (3, m)
    y_arm = np.stack([-s1, c1, zero])
    psi3 = np.arctan2(params.a2, params.c3)
    k = np.hypot(params.a2, params.c3)
    s2, c2 = np.sin(t2), np.cos(t2)
    t23 = t2 + t3
    s23, c23 = np.sin(t23), np.cos(t23)
    sk = s23 * np.cos(psi3) + c23 * np.sin(psi3)                      # sin(t23 + psi3)
    ck = c23 * np.cos(psi3) - s23 * np.sin(psi3)
    axis2 = params.a1 * x_arm
    axis2[2] += params.c1
    axis3 = axis2 + params.c2 * s2 * x_arm
    axis3[2] += params.c2 * c2
    centre = (params.c2 * s2 + k * sk + params.a1) * x_arm + params.b * y_arm
    centre[2] += params.c2 * c2 + k * ck + params.c1
    col0 = c23 * x_arm                                                # R0c = Rz(t1) Ry(t23)
    col0[2] -= s23
    col2 = s23 * x_arm
    col2[2] += c23
    s4, c4, s5, c5 = np.sin(t4), np.cos(t4), np.sin(t5), np.cos(t5)
    x4 = c4 * col0 + s4 * y_arm                                       # R04 = R0c Rz(t4)
    y4 = c4 * y_arm - s4 * col0
    z6 = s5 * x4 + c5 * col2                                          # R05 z = R06 z
    flange = centre + params.c4 * z6
    tip = params._tip()
    if tip is not None:
        s6, c6 = np.sin(t6), np.cos(t6)
        x5 = c5 * x4 - s5 * col2
        x6, y6 = c6 * x5 + s6 * y4, c6 * y4 - s6 * x5
        flange = flange + x6 * tip[0, 3] + y6 * tip[1, 3] + z6 * tip[2, 3]
    return _OPWAxes(y_arm, axis2, axis3, col2, y4, z6, centre, flange)


def _screw_jacobian(axes, r):
    """``(m, 6, n)`` Jacobian with columns ``(w x r, w)`` for axes and lever arms ``(n, 3, m)``."""
    jac = np.empty((axes.shape[2], 6, axes.shape[0]))
    jac[:, 0] = (axes[:, 1] * r[:, 2] - axes[:, 2] * r[:, 1]).T
    jac[:, 1] = (axes[:, 2] * r[:, 0] - axes[:, 0] * r[:, 2]).T
    jac[:, 2] = (axes[:, 0] * r[:, 1] - axes[:, 1] * r[:, 0]).T
    jac[:, 3:] = axes.transpose(2, 1, 0)
    return jac


def _ur_jacobian(params, theta):
    """As :func:`_opw_jacobian`, for the UR arm (from its DH frames)."""
    frames = _ur_frames(params, theta)
    tip, last = params._tip(), frames[-1]
    flange = last[:, :3, 3] if tip is None else last[:, :3, :3] @ tip[:3, 3] + last[:, :3, 3]
    axes = np.concatenate([np.broadcast_to([0.0, 0.0, 1.0], (1, len(theta), 3)),
                           frames[:5, :, :3, 2]])                     # (6, m, 3)
    points = np.concatenate([np.zeros((1, len(theta), 3)), frames[:5, :, :3, 3]])
    return (_screw_jacobian(np.swapaxes(axes, 1, 2), np.swapaxes(flange - points, 1, 2)),
            flange)


def _nominal_jacobian(params, q):
    """Geometric Jacobian ``(m, 6, 6)`` of the nominal family in the base frame, at the
    flange origin, per controller joint (as ``fk_jacobian`` returns it)."""
    theta = params.model_angles(q)
    jac, _ = (_opw_jacobian if isinstance(params, OPWParameters) else _ur_jacobian)(params,
                                                                                  theta)
    jac *= np.asarray(params.signs, dtype=float)
    base = params._base()
    if base is not None:
        jac[:, :3] = base[:3, :3] @ jac[:, :3]
        jac[:, 3:] = base[:3, :3] @ jac[:, 3:]
    return jac


def _nominal_twist(params, q, dq):
    """``J_nominal(q) dq`` ``(m, 6)``: the flange twist (base frame) of joint steps
    ``dq (m, 6)`` at ``q (m, 6)`` rad, without forming the Jacobian (OPW arms): with the
    wrist's angular velocity w_w = sum of its axes times their steps,
    ``v = dq1 z x f + dq23 y_arm x (...) + w_w x (f - centre)``."""
    if not isinstance(params, OPWParameters):
        return np.einsum("kij,kj->ki", _nominal_jacobian(params, q), dq)
    arm = _opw_axes(params, params.model_angles(q))
    w0, w1, w2, w3, w4, w5 = (dq * np.asarray(params.signs, dtype=float)).T
    f = arm.flange
    wrist = w3 * arm.col2 + w4 * arm.y4 + w5 * arm.z6
    lever = w1 * (f - arm.axis2) + w2 * (f - arm.axis3)              # about y_arm
    r = f - arm.centre
    y = arm.y_arm
    twist = np.empty((6, len(q)))
    twist[0] = -w0 * f[1] + y[1] * lever[2] - y[2] * lever[1] + wrist[1] * r[2] - wrist[2] * r[1]
    twist[1] = w0 * f[0] + y[2] * lever[0] - y[0] * lever[2] + wrist[2] * r[0] - wrist[0] * r[2]
    twist[2] = y[0] * lever[1] - y[1] * lever[0] + wrist[0] * r[1] - wrist[1] * r[0]
    twist[3:] = (w1 + w2) * y + wrist
    twist[5] += w0
    twist = twist.T
    base = params._base()
    if base is not None:
        twist[:, :3] = twist[:, :3] @ base[:3, :3].T
        twist[:, 3:] = twist[:, 3:] @ base[:3, :3].T
    return twist


def _rotation_from_rotvec(rotvec):
    """Rotation matrices ``(m, 3, 3)`` from rotation vectors ``(m, 3)`` (Rodrigues)."""
    angle = np.sqrt(np.einsum("ij,ij->i", rotvec, rotvec))
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0 - angle ** 2 / 6.0, np.sin(angle) / safe)
    b = np.where(small, 0.5 - angle ** 2 / 24.0, (1.0 - np.cos(angle)) / safe ** 2)
    x, y, z = rotvec.T
    R = np.empty((len(rotvec), 3, 3))
    xx, yy, zz, xy, xz, yz = x * x, y * y, z * z, x * y, x * z, y * z
    R[:, 0, 0], R[:, 1, 1], R[:, 2, 2] = 1 - b * (yy + zz), 1 - b * (xx + zz), 1 - b * (xx + yy)
    R[:, 0, 1], R[:, 1, 0] = b * xy - a * z, b * xy + a * z
    R[:, 0, 2], R[:, 2, 0] = b * xz + a * y, b * xz - a * y
    R[:, 1, 2], R[:, 2, 1] = b * yz - a * x, b * yz + a * x
    return R


def _closed_form_newton(params, fk_jacobian, T, cfx, q0, position_tol, rotation_tol,
                        max_steps, singular_tol, X0=None):
    """Newton on the model in the coordinates of the nominal closed form.

    The joints are ``q = IK_nominal(X)`` on branch ``cfx`` of a corrected target X (at first
    the target T). The model's error ``e`` at q asks for joint steps ``dq = J_model^-1 e``;
    they become a step of X along ``J_nominal dq``, and q is solved again in closed form.
    Near the shoulder and wrist singularities the joints are far from linear in the pose,
    while X is nearly linear in it (model and nominal differ by millimetres): this converges
    in two steps where Newton in q needs many, and it stays on the nominal branch. Without
    ``J_nominal`` (taking ``J_nominal = J_model``) it is the fixed point of
    :func:`_closed_form_on_model`. ``X0``: the corrected targets to continue from (with
    ``q0`` their solutions). Returns q, singular (converged rows whose Jacobian is singular,
    see :func:`_singular`), err (at q), steps, converged and X (of the rows not converged),
    per row; rows of ``q0`` with NaN are skipped. Errors below ``_JOINT_STEP`` are stepped
    in the joints (Newton there is as good, and saves the closed form)."""
    m, n = q0.shape
    q, X = q0.copy(), (T if X0 is None else X0).copy()
    forward = opw_forward if isinstance(params, OPWParameters) else ur_forward
    stale = np.zeros(m, bool)                 # X is not the one of q (a step in the joints)
    singular = np.zeros(m, bool)
    err = np.full((m, 6), np.nan)
    steps = np.zeros(m, int)
    converged = np.zeros(m, bool)
    act = np.flatnonzero(np.all(np.isfinite(q0), axis=1))
    q_a, X_a, T_a, cfx_a = q[act], X[act], T[act], cfx[act]
    for step in range(max_steps + 1):
        if len(act) == 0:
            break
        poses, jac = _model(fk_jacobian, q_a, n)
        e = _pose_error(T_a, poses)
        jt = _joint_major(jac)                      # used before the model is called again
        position, rotation = _norms(e)
        done = (position <= position_tol) & (rotation <= rotation_tol)
        leave = done | (step == max_steps)
        if np.any(leave):
            rows = act[leave]
            q[rows], err[rows], steps[rows] = q_a[leave], e[leave], step
            X[rows], converged[rows] = X_a[leave], done[leave]
            finished = np.flatnonzero(done)
            if len(finished):
                singular[act[finished]] = _singular_t(jt[..., finished], singular_tol)
            keep = ~leave
            act, q_a, X_a, T_a, cfx_a = act[keep], q_a[keep], X_a[keep], T_a[keep], cfx_a[keep]
            if len(act) == 0:
                break
            jt, e = jt[..., keep], e[keep]
        dq = _gauss_newton_steps_t(jt, e, _DAMPING)
        # a step this close to the solution is as good in the joints: no closed form
        # (the corrected target X of such a row is brought up to date if it needs one)
        near = np.einsum("ij,ij->i", e, e) <= _JOINT_STEP ** 2
        q_a[near] += dq[near]
        stale[act[near]] = True
        far = np.flatnonzero(~near)
        if len(far) == 0:
            continue
        behind = far[stale[act[far]]]
        if len(behind):
            X_a[behind] = forward(params, q_a[behind])
            stale[act[behind]] = False
        q_f, X_f, e_f = q_a[far], X_a[far], e[far]
        twist = _nominal_twist(params, q_f, dq[far])
        # J_nominal J_model^-1 is the identity but for millimetres over the distance to a
        # singularity; where it is far from it, the fixed-point step (twist = e) is safer
        wild = (np.einsum("ij,ij->i", twist - e_f, twist - e_f)
                > _WILD ** 2 * np.einsum("ij,ij->i", e_f, e_f))
        twist[wild] = e_f[wild]
        X_new = X_f.copy()
        X_new[:, :3, 3] += twist[:, :3]
        X_new[:, :3, :3] = _rotation_from_rotvec(twist[:, 3:]) @ X_f[:, :3, :3]
        new = _one_branch(params, X_new, cfx_a[far], clip=True)
        new += _TWO_PI * np.round((q_f - new) / _TWO_PI)
        ok = np.all(np.isfinite(new), axis=1)
        q_a[far] = np.where(ok[:, None], new, q_f)
        X_a[far] = np.where(ok[:, None, None], X_new, X_f)
    stale &= ~converged                       # the others' X are not used again
    if np.any(stale):
        X[stale] = forward(params, q[stale])
    return q, singular, err, steps, converged, X


def _closed_form_on_model(params, fk_jacobian, T, cfx, q):
    """Closed-form iteration onto the model: ``q <- IK_nominal(T inv(E(q)))`` on branch cfx,
    with ``E(q) = inv(FK_nominal(q)) FK_model(q)`` the model's flange error. Keeps the
    requested branch exactly and is robust where Newton is not (near the shoulder and wrist
    singularities, whose closed form is exact); each step is one model evaluation.
    Returns q and the number of steps per row."""
    q = q.copy()
    steps = np.zeros(len(q), int)
    rows = np.flatnonzero(np.all(np.isfinite(q), axis=1))
    forward = opw_forward if isinstance(params, OPWParameters) else ur_forward
    for _ in range(_FIXED_POINT_STEPS):
        if len(rows) == 0:
            break
        model_pose = np.asarray(fk_jacobian(q[rows])[0], dtype=float)
        error = invert_pose(forward(params, q[rows])) @ model_pose
        corrected = T[rows] @ invert_pose(error)
        new = _one_branch(params, corrected, cfx[rows], clip=True)
        new += _TWO_PI * np.round((q[rows] - new) / _TWO_PI)
        ok = np.all(np.isfinite(new), axis=1)
        moved = np.max(np.abs(new - q[rows]), axis=1)
        q[rows[ok]] = new[ok]
        steps[rows] += 1
        rows = rows[ok & (moved > _FIXED_POINT_TOL)]
    return q, steps


def _wrist_in_quadrant(params, q, cf4, fraction):
    """Axis 4 moved to ``(cf4 + fraction) * 90 deg``, axis 6 so that theta4 + theta6 stays."""
    theta = params.model_angles(q)
    theta4 = params.signs[3] * (cf4 + fraction) * (np.pi / 2) - params.offsets[3]
    theta[:, 5] += theta[:, 3] - theta4
    theta[:, 3] = theta4
    return params.joint_angles(theta)


def _flip_wrist(params, q):
    theta = params.model_angles(q)
    theta[:, 3] += np.pi
    theta[:, 4] *= -1.0
    theta[:, 5] += np.pi
    return _wrap(params.joint_angles(theta))


# --------------------------------------------------------------------------- reach certificate

_REACH_SPAN = 0.6         # rad: widest elbow interval (about the stretched elbow) examined
_REACH_CELLS = 8          # first subdivision of that interval
_REACH_ROUNDS = 14        # halvings of a cell before a target is left to the iteration
_REACH_MARGIN = 1e-12     # m^2: rounding allowance of the final comparison
_REACH_CONDITION = 1e-6   # an inverse cosine within this of +-1 is not trusted


def _circle_square(c0, c1, c2, point):
    """Bounds of ``|c0 + c1 cos t + c2 sin t - point|^2`` (a point on a circle, up to
    rounding): ``(A, B, phase, E)`` with the square ``A + B cos(t - phase) + e(t)``,
    ``|e(t)| <= E``, B >= 0."""
    d0 = c0 - point
    a = d0 @ d0 + 0.5 * (c1 @ c1 + c2 @ c2)
    bc, bs = 2.0 * (d0 @ c1), 2.0 * (d0 @ c2)
    error = np.hypot(0.5 * (c1 @ c1 - c2 @ c2), c1 @ c2) + 1e-15 * a
    return a, np.hypot(bc, bs), np.arctan2(bs, bc), error


def _circle(f):
    """Centre and the two half-axes ``(c0, c1, c2)`` of ``f(t) = c0 + c1 cos t + c2 sin t``
    (a point turned about an axis), from f at 0, pi/2 and pi."""
    at0, at90, at180 = f(0.0), f(0.5 * np.pi), f(np.pi)
    c0 = 0.5 * (at0 + at180)
    return c0, 0.5 * (at0 - at180), at90 - c0


def _closest_on_axes(point_a, axis_a, point_b, axis_b):
    """Parameters (s, t) of the closest points ``point_a + s axis_a`` and ``point_b + t
    axis_b`` of two unit axes, or None where they are (nearly) parallel."""
    ab = axis_a @ axis_b
    if 1.0 - ab * ab < 1e-6:
        return None
    w = point_b - point_a
    s, t = np.linalg.solve(np.array([[1.0, -ab], [ab, -1.0]]), np.array([w @ axis_a, w @ axis_b]))
    return s, t


@dataclass(frozen=True)
class _ReachTargets:
    """Per-target values :meth:`ReachBound.unreachable` uses, m: W6 in frame 1 (k, 3), its
    distance to axis 1 and to the circle of S (k,), axis 6 in frame 1 (k, 3), and the
    wrist bit asked for (k,)."""

    local: np.ndarray
    radial: np.ndarray
    distance: np.ndarray
    axis6: np.ndarray
    wrist: np.ndarray


def _turn(v, angle):
    """Vectors ``v (k, 3)`` turned about z by ``angle (k,)`` rad."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.empty_like(v)
    out[:, 0] = c * v[:, 0] - s * v[:, 1]
    out[:, 1] = s * v[:, 0] + c * v[:, 1]
    out[:, 2] = v[:, 2]
    return out


class ReachBound:
    """A sound test that targets lie beyond the reach of a 6R arm near its stretched elbow.

    The arm is given by its joint frames at zero (``frames (6, 4, 4)``, base frame, z on
    each joint axis, as just before the joint's own motion) and the flange at zero
    (``flange (4, 4)``), m: frame k + 1 is ``frame_k Rz(q_k) K_k`` with ``K_k`` constant
    (the structure of the calibrated model). Axes 2 and 3 need not be parallel, nor need
    axes 4, 5 and 6 meet: only exact invariants are used. With S a point on axis 2, P4 on
    axis 4 and W6 on axis 6 (near the wrist centre), and R4 the rotation of frame 4,

    - ``|P4 - S|^2 = f3(q3)`` and ``a3(q3) = R4^T (P4 - S)`` depend on the elbow angle
      alone, ``w(q4, q5) = R4^T (W6 - P4)`` on the wrist angles alone, so that
      ``|W6 - S(q1)|^2 = f3 + 2 a3 . w + |w|^2`` exactly;
    - W6 is a point of the flange: the target places it, and ``|W6 - S(q1)|`` is at least
      its distance to the circle S turns on about axis 1;
    - every joint of a solution follows from its elbow angle and the target: axis 1 from
      ``(P4 - S) . u2 = n3(q3)`` (P4 in the plane of axis 2, up to a q3-dependent offset),
      axis 2 from the direction of P4, the wrist from the rotation ``R4^T R_target``; P4 is
      within :attr:`wrist_offset` of W6. The wrist offset w is evaluated on this arm over
      a subdivision of the possible elbow angles, with bounds for all a cell and the
      wrist offset can change (each shoulder and wrist solution separately).

    A target is declared unreachable only when every cell's bound of ``|W6 - S|^2`` lies
    below the squared distance; the requested wrist configuration (sign of sin(theta5), see
    :func:`configuration_bits`) may exclude the other wrist solution. What the bounds
    cannot settle (wrist or shoulder near singular, elbow far from stretched, a reachable
    target) is left to the iteration: the test never rejects a reachable target.
    ``branches``: the chain's joints are the ones the configuration is read on (False when
    joint effects stand between them: the wrist configuration asked for is then not used).
    """

    def __init__(self, frames, flange, branches: bool = True):
        frames = np.asarray(frames, dtype=float)
        flange = np.asarray(flange, dtype=float)
        if frames.shape != (6, 4, 4) or flange.shape != (4, 4):
            raise ModelError(f"ReachBound needs 6 joint frames (6, 4, 4) and a flange (4, 4), "
                             f"got {frames.shape} and {flange.shape}")
        self.branches = bool(branches)
        links = [invert_pose(frames[k]) @ frames[k + 1] for k in range(5)]
        links.append(invert_pose(frames[5]) @ flange)
        self.first = frames[0]
        self.links = np.array(links)                          # K_1 .. K_6
        origin, axis = frames[:, :3, 3], frames[:, :3, 2]
        on45 = _closest_on_axes(origin[3], axis[3], origin[4], axis[4])
        if on45 is None:
            raise ModelError("ReachBound: axes 4 and 5 are parallel")
        z4 = on45[0]                                          # P4 = (0, 0, z4) in frame 4
        p5 = origin[4] + on45[1] * axis[4]
        z6 = (p5 - origin[5]) @ axis[5]                       # W6 = (0, 0, z6) in frame 6
        p4 = origin[3] + z4 * axis[3]
        p3 = origin[2] + ((p4 - origin[2]) @ axis[2]) * axis[2]
        z_s = (p3 - origin[1]) @ axis[1]                      # S = (0, 0, z_s) in frame 2
        self.z4, self.z_s = z4, z_s
        flange_inv = invert_pose(flange)
        self.w6_flange = flange_inv[:3, :3] @ (origin[5] + z6 * axis[5]) + flange_inv[:3, 3]
        self.axis6_flange = flange_inv[:3, :3] @ axis[5]
        K1, K2, K3, K4, K5 = self.links[:5]
        self.rotations = self.links[:5, :3, :3]
        self.offsets = self.links[:5, :3, 3]
        # the circle of S about axis 1, frame 1
        self.s0 = K1[:3, :3] @ np.array([0.0, 0.0, z_s]) + K1[:3, 3]
        self.u2 = K1[:3, 2]
        self.radius_s, self.height_s = np.hypot(self.s0[0], self.s0[1]), self.s0[2]
        # the elbow: P4 in frame 2 turned by q2 is Rz(q2) m(q3), m = K2 Rz(q3) p4_in3
        self.p4_in3 = K3[:3, :3] @ np.array([0.0, 0.0, z4]) + K3[:3, 3]
        s_point = np.array([0.0, 0.0, z_s])
        self.f3 = _circle_square(*_circle(lambda t: self._m(np.array([t]))[0]), s_point)
        if not self.f3[1] > 0:
            raise ModelError("ReachBound: the elbow does not change the reach")
        self.sin23 = np.linalg.norm(np.cross([0.0, 0.0, 1.0], K2[:3, 2]))
        self.r_s3 = np.linalg.norm(np.cross(s_point - K2[:3, 3], K2[:3, 2]))   # S to axis 3
        self.r_43 = np.hypot(self.p4_in3[0], self.p4_in3[1])                 # P4 to axis 3
        # the wrist: axis 6 in frame 4 is Rz(q4) h(q5), h = K4 Rz(q5) g; h_z = p . Rz(q5) g
        p, g = K4[2, :3], K5[:3, 2]
        self.g = g
        self.g_xy = np.hypot(g[0], g[1])
        cc, ss = p[0] * g[0] + p[1] * g[1], p[1] * g[0] - p[0] * g[1]
        self.a5, self.rho5, self.phase5 = p[2] * g[2], np.hypot(cc, ss), np.arctan2(ss, cc)
        if not self.rho5 > 0:
            raise ModelError("ReachBound: axis 5 does not turn axis 6 about axis 4")
        # W6 in frame 4 is Rz(q4) (K4 Rz(q5) w6_in5), w6_in5 = W6 in frame 5
        self.w6_in5 = K5[:3, :3] @ np.array([0.0, 0.0, z6]) + K5[:3, 3]
        c0, c1, c2 = _circle(lambda t: self._w5(np.array([t]))[0])
        a, b, _, e = _circle_square(c0, c1, c2, np.array([0.0, 0.0, z4]))
        self.wrist_offset = np.sqrt(a + b + e) + 1e-12        # largest |W6 - P4|, m
        self.r_w4 = (np.hypot(c0[0], c0[1])                   # largest distance W6 to axis 4
                     + np.sqrt(c1[0] ** 2 + c1[1] ** 2 + c2[0] ** 2 + c2[1] ** 2))
        self.r_w5 = np.hypot(self.w6_in5[0], self.w6_in5[1])  # W6 to axis 5

    def _m(self, t):
        """P4 in frame 2 at q2 = 0, ``(k, 3)``, for elbow angles ``t (k,)``."""
        turned = _turn(np.broadcast_to(self.p4_in3, (len(t), 3)), t)
        return turned @ self.rotations[1].T + self.offsets[1]

    def _w5(self, q5):
        """W6 in frame 4 at q4 = 0, ``(k, 3)``, for wrist angles ``q5 (k,)``."""
        turned = _turn(np.broadcast_to(self.w6_in5, (len(q5), 3)), q5)
        return turned @ self.rotations[3].T + self.offsets[3]

    def unreachable(self, target, wrist=None, params=None, tolerance: float = 1e-9):
        """``(k,) bool``: True where no joints put the flange on ``target (k, 4, 4)`` (m),
        a proof; False where it is not settled. ``wrist (k,)``: the wrist bit asked for
        (0 or 1, -1 any; None: any), read with the conventions of ``params`` (the nominal
        family) with ``tolerance`` as in :func:`configuration_bits`."""
        T = _as_poses(target, "target")
        k = len(T)
        out = np.zeros(k, bool)
        if k == 0:
            return out
        first_r = self.first[:3, :3]
        w6 = T[:, :3, :3] @ self.w6_flange + T[:, :3, 3]
        local = (w6 - self.first[:3, 3]) @ first_r                        # frame 1
        radial = np.hypot(local[:, 0], local[:, 1])
        distance = np.hypot(radial - self.radius_s, local[:, 2] - self.height_s)
        a3, b3, phase3, e3 = self.f3
        delta = self.wrist_offset
        shortest = distance - delta                       # |P4 - S| of any solution
        kappa = (shortest * np.abs(shortest) - a3 - e3) / b3
        out[kappa > 1.0] = True
        rows = np.flatnonzero((kappa <= 1.0) & (kappa > np.cos(_REACH_SPAN)) & (shortest > 0))
        if len(rows) == 0:
            return out
        if wrist is None or params is None or not self.branches:
            wrist, params = np.full(k, -1), None
        wrist = np.broadcast_to(np.asarray(wrist, dtype=int), (k,))
        axis6 = (T[:, :3, :3] @ self.axis6_flange) @ first_r
        data = _ReachTargets(local, radial, distance, axis6, wrist)
        half = np.arccos(kappa[rows])
        # each shoulder root whose S stays far enough from W6 whatever the elbow: settled
        reach_max = np.sqrt(a3 + b3 + e3) + delta
        keep_root = []
        for s1 in (1.0, -1.0):
            _, _, floor, bad = self._shoulder(data, rows, np.full(len(rows), s1),
                                              np.full(len(rows), phase3), half)
            keep_root.append(bad | ~(reach_max ** 2 < floor ** 2 - _REACH_MARGIN))
        # cells of (row, shoulder root, wrist root, elbow interval [lo, hi])
        row, s1, s5, lo, hi = [], [], [], [], []
        edges = np.linspace(-1.0, 1.0, _REACH_CELLS + 1)
        for i, root in enumerate((1.0, -1.0)):
            for wrist_root in (1.0, -1.0):
                r = np.flatnonzero(keep_root[i])
                row.append(np.repeat(rows[r], _REACH_CELLS))
                s1.append(np.full(len(r) * _REACH_CELLS, root))
                s5.append(np.full(len(r) * _REACH_CELLS, wrist_root))
                lo.append((phase3 + half[r, None] * edges[:-1]).ravel())
                hi.append((phase3 + half[r, None] * edges[1:]).ravel())
        row, s1, s5, lo, hi = map(np.concatenate, (row, s1, s5, lo, hi))
        open_ = np.zeros(k, bool)                         # not to be settled: left to Newton
        for round_ in range(_REACH_ROUNDS + 1):
            settled, stuck = self._cells(data, params, tolerance, row, s1, s5, lo, hi)
            open_[row[stuck]] = True
            split = ~settled & ~open_[row]
            if not np.any(split):
                break
            if round_ == _REACH_ROUNDS:
                open_[row[split]] = True
                break
            mid = 0.5 * (lo[split] + hi[split])
            row, s1, s5 = (np.repeat(a[split], 2) for a in (row, s1, s5))
            lo = np.stack([lo[split], mid], 1).ravel()
            hi = np.stack([mid, hi[split]], 1).ravel()
        out[rows] = ~open_[rows]
        return out

    def _shoulder(self, data, r, s1, t, half):
        """Axis 1 of the solutions on shoulder root ``s1`` with elbow angles within ``half``
        of ``t`` (all ``(n,)``, rad): the centre's q1, a bound of |q1 - centre|, a lower
        bound of ``|W6 - S(q1)|`` (m), and where the bound does not apply."""
        m_z = self._m(t)[:, 2]
        u2 = self.u2
        x, y = data.local[r, 0], data.local[r, 1]
        alpha, beta = u2[0] * x + u2[1] * y, u2[0] * y - u2[1] * x
        big = np.hypot(alpha, beta)
        with np.errstate(divide="ignore", invalid="ignore"):
            x1 = (m_z - self.z_s + self.s0 @ u2 - u2[2] * data.local[r, 2]) / big
            dx1 = (self.wrist_offset + self.r_43 * self.sin23 * half) / big
            reach1 = np.abs(x1) + dx1
            bad = ~(reach1 < 1.0 - _REACH_CONDITION)
            dq1 = dx1 / np.sqrt(1.0 - np.minimum(reach1, 1.0 - _REACH_CONDITION) ** 2)
        q1 = np.arctan2(beta, alpha) + s1 * np.arccos(np.clip(x1, -1.0, 1.0))
        # |W6 - S(q1)| = |Rz(-q1) W6 - s0| in frame 1; S moves radius_s per rad of q1
        to_s = np.linalg.norm(_turn(data.local[r], -q1) - self.s0, axis=1)
        floor = np.maximum(data.distance[r], to_s - self.radius_s * dq1)
        return q1, dq1, floor, bad

    def _cells(self, data, params, tolerance, row, s1, s5, lo, hi):
        """Settle cells of elbow angles [lo, hi] (rad): ``(settled, stuck)``, each
        ``(n,) bool``. Settled: no solution on this shoulder root (``s1`` = +-1) and wrist
        root (``s5``) has its elbow angle in the cell. Stuck: not even a cell of no width
        at its centre would be settled (bounds that do not apply, or a reachable target)."""
        a3, b3, phase3, e3 = self.f3
        delta = self.wrist_offset
        n = len(row)
        settled = np.zeros(n, bool)
        stuck = np.zeros(n, bool)
        # the largest f3 in the cell; a first test without the wrist's direction
        before, after = lo - phase3, hi - phase3
        top = np.where((before <= 0) & (after >= 0), 1.0,
                       np.maximum(np.cos(before), np.cos(after)))
        f3_max = a3 + e3 + b3 * top
        coarse = f3_max + 2.0 * np.sqrt(np.maximum(f3_max, 0.0)) * delta + delta * delta
        settled |= coarse < data.distance[row] ** 2 - _REACH_MARGIN
        live = np.flatnonzero(~settled)
        if len(live) == 0:
            return settled, stuck
        r, t, half = row[live], 0.5 * (lo[live] + hi[live]), 0.5 * (hi[live] - lo[live])
        K1, K2, K3, K4 = self.rotations[:4]
        q1, _, _, _ = self._shoulder(data, r, s1[live], t, half)
        m = self._m(t)
        tw = (_turn(data.local[r], -q1) - self.offsets[0]) @ K1         # W6 in frame 2
        tw_xy, m_xy = np.hypot(tw[:, 0], tw[:, 1]), np.hypot(m[:, 0], m[:, 1])
        q2 = np.arctan2(tw[:, 1], tw[:, 0]) - np.arctan2(m[:, 1], m[:, 0])
        # axis 6 in frame 4: R4^T a, R4 = first Rz(q1) K1 Rz(q2) K2 Rz(q3) K3
        e = _turn(_turn(_turn(data.axis6[r], -q1) @ K1, -q2) @ K2, -t) @ K3
        x5 = (e[:, 2] - self.a5) / self.rho5
        q5 = self.phase5 + s5[live] * np.arccos(np.clip(x5, -1.0, 1.0))
        e_xy = np.hypot(e[:, 0], e[:, 1])
        h = _turn(np.broadcast_to(self.g, (len(live), 3)), q5) @ K4.T
        q4 = np.arctan2(e[:, 1], e[:, 0]) - np.arctan2(h[:, 1], h[:, 0])
        w = _turn(self._w5(q5), q4)
        w[:, 2] -= self.z4                                                  # W6 - P4, frame 4
        arm = _turn((m - np.array([0.0, 0.0, self.z_s])) @ K2, -t) @ K3     # P4 - S, frame 4
        centre = 2.0 * np.einsum("ij,ij->i", arm, w) + np.einsum("ij,ij->i", w, w)
        arm_norm, w_norm = np.linalg.norm(arm, axis=1), np.linalg.norm(w, axis=1)
        f3_mid = a3 + e3 + b3 * np.cos(t - phase3)
        results = []
        for width, f3_top in ((half, f3_max[live]), (np.zeros_like(half), f3_mid)):
            # how far a solution with its elbow in the cell is from the centre's joints
            _, dq1, floor, bad = self._shoulder(data, r, s1[live], t, width)
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                ratio_a = (delta + data.radial[r] * dq1) / tw_xy
                ratio_b = self.r_43 * width / m_xy
                dq2 = np.arcsin(np.minimum(ratio_a, 1.0)) + np.arcsin(np.minimum(ratio_b, 1.0))
                turn = dq1 + dq2 + width                   # the angle R4 may differ by
                reach5 = np.abs(x5) + turn / self.rho5
                dq5 = (turn / self.rho5) / np.sqrt(
                    1.0 - np.minimum(reach5, 1.0 - _REACH_CONDITION) ** 2)
                ratio_c, ratio_d = turn / e_xy, self.g_xy * dq5 / e_xy
                dq4 = np.arcsin(np.minimum(ratio_c, 1.0)) + np.arcsin(np.minimum(ratio_d, 1.0))
                bad |= ~((ratio_a < 1.0) & (ratio_b < 1.0) & (reach5 < 1.0 - _REACH_CONDITION)
                         & (ratio_c < 1.0) & (ratio_d < 1.0))
                dw = self.r_w4 * dq4 + self.r_w5 * dq5          # |w - w(centre)|
                bound = (f3_top + centre + 2.0 * self.r_s3 * width * delta
                         + 2.0 * arm_norm * dw + dw * (2.0 * w_norm + dw))
                below = bound < floor * floor - _REACH_MARGIN
            if params is not None:           # the other wrist configuration than asked for
                wanted = data.wrist[r]
                margin = params.signs[4] * np.sin(params.signs[4] * q5 - params.offsets[4])
                below |= (((wanted == 0) & (margin + dq5 < -tolerance))
                          | ((wanted == 1) & (margin - dq5 >= tolerance)))
            results.append(below & ~bad)
        settled[live] = results[0]
        stuck[live] = ~results[1]
        return settled, stuck


def solve(family_params: OPWParameters | URParameters,
          fk_jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], target,
          confdata=None, limits=None, *, position_tol: float = 1e-9,
          rotation_tol: float = 1e-9, max_iterations: int = 100,
          quadrant_tolerance: float = np.pi / 4, boundary_tolerance: float = 1e-9,
          singular_tol: float = 1e-7, reach: ReachBound | None = None) -> IKSolution:
    """Joints reaching ``target (m, 4, 4)`` (m) on the model ``fk_jacobian``, per branch.

    1. The nominal closed form of ``family_params`` on the branch ``confdata (m, 4)`` =
       (cf1, cf4, cf6, cfx) (see :func:`select_branch`; None: the reachable branch nearest
       q = 0, and any configuration is accepted). Targets slightly outside the nominal
       workspace start from the stretched arm; no start at all is 'unreachable'.
    2. Newton onto the model (``fk_jacobian``, e.g. the calibrated robot) in the
       coordinates of the closed form: the model's error corrects the target given to the
       nominal closed form on the same branch (exactly, via the nominal and model
       Jacobians), to ``position_tol`` (m) / ``rotation_tol`` (rad); usually two steps.
    3. The result is shifted by multiples of 2 pi as :func:`select_branch` does and
       checked: outside ``limits (6, 2)`` rad is 'joint_limit'; configuration bits
       (:func:`configuration_bits` of the nominal family, bits within
       ``boundary_tolerance`` of their boundary ignored) other than requested, or axis 1, 4
       or 6 more than ``quadrant_tolerance`` rad from its quadrant, is 'branch_changed'.
    4. Failed targets (near singularities, where the model can have several solutions per
       nominal configuration) are retried by :func:`refine`'s Newton from several starts at
       once, the first accepted by the checks of 3 winning: the nominal start, the flipped
       wrist (OPW), axis 4 placed in its quadrant (theta4 + theta6 kept), the nominal
       solutions of the neighbouring branches.
    5. Still failed targets: the closed-form fixed point onto the model (the nominal
       inverse of the target corrected by the model's flange error, until joints move less
       than 1e-6 rad), :func:`refine`, and the starts of 4 one after the other. The reasons
       of targets that fail in the end are those of this last step.
    ``max_iterations`` bounds the Newton steps of each of these stages. ``reach``: the
    model's :class:`ReachBound` (its chain on the joints ``fk_jacobian`` takes); targets
    still failed after 2. that it proves out of reach (on the requested wrist
    configuration) are 'unreachable' at once, without 4. and 5.
    """
    return _solve(family_params, fk_jacobian, target, confdata, limits,
                  position_tol=position_tol, rotation_tol=rotation_tol,
                  max_iterations=max_iterations, quadrant_tolerance=quadrant_tolerance,
                  boundary_tolerance=boundary_tolerance, singular_tol=singular_tol,
                  reach=reach)[0]


def solve_with_nominal(family_params: OPWParameters | URParameters,
                       fk_jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                       target, confdata=None, limits=None, **options
                       ) -> tuple[IKSolution, np.ndarray]:
    """:func:`solve` (same arguments), and the joints ``(m, 6)`` rad of the nominal closed
    form on the requested branch it starts from (as :func:`nominal_joints_on_branch`
    gives them), at no extra cost: what the nominal controller does with ``target``."""
    return _solve(family_params, fk_jacobian, target, confdata, limits, **options)


def _solve(family_params, fk_jacobian, target, confdata=None, limits=None, *,
           position_tol=1e-9, rotation_tol=1e-9, max_iterations=100,
           quadrant_tolerance=np.pi / 4, boundary_tolerance=1e-9, singular_tol=1e-7,
           reach=None):
    """:func:`solve` (same arguments), and the nominal closed form's joints ``(m, 6)`` on
    the requested branch (shifted as :func:`select_branch` does; NaN where that branch
    cannot reach)."""
    _check_family(family_params)
    T = _as_poses(target, "target")
    m = len(T)
    limits = _as_limits(limits, 6)
    max_iterations = int(max_iterations)
    check_configuration = confdata is not None
    solutions = None                              # all nominal branches (m, 8, 6), if needed
    if confdata is None:
        solutions = _closed_form(family_params, T, clip=False)
        confdata = _default_confdata(solutions, limits)
    else:
        confdata = _as_confdata(confdata, m)
    start = np.full((m, 6), np.nan)               # the nominal closed form's joints
    stretched = np.zeros(m, bool)                 # start is the stretched arm's
    status = np.ones(m, int)                      # of _select: 1 = no start at all

    def requested(rows):
        """The configuration bits (k, 3) asked for on ``rows``."""
        cfx = confdata[rows, 3]
        return np.stack([cfx // 4, (cfx // 2) % 2, cfx % 2], 1)

    def branches(rows):
        if solutions is not None:
            return solutions[rows]
        return _closed_form(family_params, T[rows], clip=False)

    def verdict(q, rows):
        """Reached joints shifted to the requested turns, and 'ok', 'branch_changed' or
        'joint_limit': the checks refine was not asked to make."""
        q, check = _select_q(q, confdata[rows], limits, quadrant_tolerance)
        got = _bits(family_params, q, boundary_tolerance)
        wrong = np.any((got >= 0) & (got != requested(rows)), axis=1) & check_configuration
        reason = np.full(len(rows), "ok", dtype="<U14")
        reason[~wrong & (check == 2)] = "joint_limit"
        reason[((check == 3) & check_configuration) | wrong] = "branch_changed"
        return q, reason

    def check(result, rows):
        reached = np.flatnonzero(np.isin(result.reason, ("ok", "singular")))
        q, reason = verdict(result.q[reached], rows[reached])
        result.q[reached] = q
        result.reason[reached] = np.where(reason == "ok", result.reason[reached], reason)
        result.success = np.isin(result.reason, ("ok", "singular"))
        return result

    def run(q_start, rows, first=False):
        steps = np.zeros(len(rows), int)
        if first:
            q_start, steps = _closed_form_on_model(family_params, fk_jacobian, T[rows],
                                                   confdata[rows, 3], q_start)
        result = refine(fk_jacobian, q_start, T[rows], None, position_tol, rotation_tol,
                        max_iterations, singular_tol=singular_tol)
        result.iterations += steps
        return check(result, rows)

    def store(result, rows, q, singular, err, converged, iterations, only_success=False):
        reason = np.where(converged, "ok", "not_converged").astype("<U14")
        reason[converged & singular] = "singular"
        position, rotation = _norms(err)
        part = check(IKSolution(q=q, success=converged, reason=reason, iterations=iterations,
                                position_error_m=position, rotation_error_rad=rotation), rows)
        keep = part.success if only_success else np.ones(len(rows), bool)
        for name in ("q", "success", "reason", "position_error_m", "rotation_error_rad"):
            getattr(result, name)[rows[keep]] = getattr(part, name)[keep]
        result.iterations[rows] += iterations

    result = IKSolution(q=np.full((m, 6), np.nan), success=np.zeros(m, bool),
                        reason=np.full(m, "unreachable", dtype="<U14"),
                        iterations=np.zeros(m, int), position_error_m=np.full(m, np.nan),
                        rotation_error_rad=np.full(m, np.nan))
    # 2. Newton in the closed form's coordinates, all targets with a start
    # (in blocks: arrays of a few thousand rows stay in the processor's cache)
    # 1. and two steps of 2. in blocks (arrays of a few thousand rows stay in the processor's
    # cache), then the few rows that need more, together.
    unfinished = []                               # (rows, q, X) of rows to go on with
    for block in np.array_split(np.arange(m), -(-m // _BLOCK)) if m else ():
        if solutions is not None:
            first = solutions[block, confdata[block, 3]]
        else:
            first = _one_branch(family_params, T[block], confdata[block, 3], clip=False)
        first, found = _select_q(first, confdata[block], limits, np.inf)
        missing = np.flatnonzero(found == 1)
        stretched[block[missing]] = True
        if len(missing):
            clipped = _one_branch(family_params, T[block[missing]], confdata[block[missing], 3],
                                  clip=True)
            first[missing], found[missing] = _select_q(clipped, confdata[block[missing]], limits,
                                                       np.inf)
        first[found == 1] = np.nan
        start[block], status[block] = first, found
        rows = block[found != 1]
        if len(rows) == 0:
            continue
        q, singular, err, steps, converged, X = _closed_form_newton(
            family_params, fk_jacobian, T[rows], confdata[rows, 3], start[rows],
            position_tol, rotation_tol, min(_FIRST_STEPS, max_iterations), singular_tol)
        store(result, rows, q, singular, err, converged, steps)
        unfinished.append((rows[~converged], q[~converged], X[~converged]))
    rows = np.concatenate([part[0] for part in unfinished]) if unfinished else np.zeros(0, int)
    if len(rows) and max_iterations > _FIRST_STEPS:
        q_end, X_end = (np.concatenate([part[i] for part in unfinished]) for i in (1, 2))
        q, singular, err, steps, converged, _ = _closed_form_newton(
            family_params, fk_jacobian, T[rows], confdata[rows, 3], q_end, position_tol,
            rotation_tol, min(_CLOSED_FORM_STEPS, max_iterations) - _FIRST_STEPS,
            singular_tol, X_end)
        result.iterations[rows] -= 1            # the first evaluation is the last one's again
        store(result, rows, q, singular, err, converged, steps)

    def multi_start(rows, first_starts, base, steps):
        """Newton from several starts per row at once; the first start accepted by the
        checks wins (its results are stored). ``base``: the joints the wrist restarts
        are derived from."""
        starts = [] if first_starts is None else [first_starts]
        if isinstance(family_params, OPWParameters):
            starts.append(_flip_wrist(family_params, base))
        starts += [_wrist_in_quadrant(family_params, base, confdata[rows, 1], f)
                   for f in (0.5, 0.25, 0.75)]
        # near the shoulder singularity axis 1 is as free as axes 4 and 6 near the wrist's
        for f in (0.5, 0.25, 0.75):
            turned = _wrist_in_quadrant(family_params, base, confdata[rows, 1], f)
            turned[:, 0] = (confdata[rows, 0] + f) * (np.pi / 2)
            starts.append(turned)
        nearby = branches(rows)
        for flip in (4, 2, 1, 6, 5, 3, 7):
            starts.append(_select(nearby, np.concatenate(
                [confdata[rows, :3], confdata[rows, 3:] ^ flip], 1), limits, np.inf)[0])
        k = len(rows)
        owner = np.tile(rows, len(starts))
        accepted = np.zeros(len(owner), bool)

        def accept(candidates, q, jac):
            _, reason = verdict(q, owner[candidates])
            accepted[candidates] = reason == "ok"
            return reason == "ok"

        q, jac, err, iterations, converged, _ = _newton(
            fk_jacobian, np.concatenate(starts), T[owner], position_tol, rotation_tol, steps,
            0.5, accept=accept, groups=np.tile(np.arange(k), len(starts)))
        won = accepted.reshape(len(starts), k)
        chosen = (np.argmax(won, axis=0) * k + np.arange(k))[np.any(won, axis=0)]
        singular = np.zeros(len(chosen), bool)
        done = np.flatnonzero(converged[chosen])
        singular[done] = _singular(jac[chosen[done]], singular_tol)
        store(result, owner[chosen], q[chosen], singular, err[chosen], converged[chosen],
              np.zeros(len(chosen), int), only_success=True)
        result.iterations[rows] += np.max(iterations.reshape(len(starts), k), axis=0)

    # 3. the failures the model's reach excludes: nothing to retry
    if reach is not None:
        rows = np.flatnonzero(~result.success & (status != 1))
        if len(rows):
            wrist = requested(rows)[:, 2] if check_configuration else None
            beyond = rows[reach.unreachable(T[rows], wrist, family_params, boundary_tolerance)]
            status[beyond] = 1                        # as no start at all: 'unreachable'

    # 4. the failures: Newton from several starts at once
    rows = np.flatnonzero(~result.success & (status != 1))
    if len(rows):
        multi_start(rows, start[rows], result.q[rows], min(_MULTI_START_STEPS, max_iterations))

    # 5. still failed: the closed-form fixed point and refine, then the restarts of 4 from
    # its result with the full iteration budget
    rows = np.flatnonzero(~result.success & (status != 1))
    if len(rows):
        again = run(start[rows], rows, first=True)
        for name in ("q", "success", "reason", "position_error_m", "rotation_error_rad"):
            getattr(result, name)[rows] = getattr(again, name)
        result.iterations[rows] += again.iterations
        rows = rows[~again.success]
        if len(rows):
            multi_start(rows, None, result.q[rows], max_iterations)
    result.reason[status == 1] = "unreachable"
    result.success[status == 1] = False
    start[stretched] = np.nan                     # the nominal closed form has no solution
    return result, start
