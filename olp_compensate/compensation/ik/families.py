"""The two closed-form families: their parameters and joint conventions.

:class:`OPWParameters` (ortho-parallel base, spherical wrist) and :class:`URParameters`
(axes 2, 3, 4 parallel) hold lengths in m and the controller's joint convention
``theta = signs * q - offsets`` (rad). Their forward and inverse kinematics are in
:mod:`.opw` and :mod:`.ur`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...errors import ModelError
from ...kinematics.conventions import invert_pose
from .inputs import wrap


WRIST_EPS = 1e-12     # |sin(theta5)| below this: the wrist is treated as exactly singular


def _transform_field(value, name):
    """A (4, 4) pose as nested tuples (None stays None); ModelError if malformed."""
    if value is None:
        return None
    arr = np.asarray(value, dtype=float)
    if arr.shape != (4, 4) or not np.all(np.isfinite(arr)):
        raise ModelError(f"{name} must be a finite (4, 4) pose, got shape {arr.shape}")
    return tuple(tuple(float(v) for v in row) for row in arr)


def _check_common(self, lengths):
    """Checks and normalizes the lengths (m), offsets (rad), signs and frames of a family."""
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


def clipped_acos(x, clip):
    """arccos of ``x``; with ``clip``, of ``x`` clipped to [-1, 1] (no NaN out of reach)."""
    return np.arccos(np.clip(x, -1.0, 1.0) if clip else x)


def all_branches(solve_branch, params, base_T_flange, clip):
    """``(m, 8, 6)`` controller joints, branch k in column k, wrapped to (-pi, pi]."""
    T = params._to_root(base_T_flange)
    m = len(T)
    theta = solve_branch(params, np.repeat(T, 8, axis=0), np.tile(np.arange(8), m), clip)
    return wrap(params.joint_angles(theta)).reshape(m, 8, 6)


def check_family(params):
    """ModelError unless ``params`` is one of the two closed-form families."""
    if not isinstance(params, (OPWParameters, URParameters)):
        raise ModelError(f"expected OPWParameters or URParameters, got {type(params).__name__}")
