"""URScript rules: no configuration is written; the solution nearest the joints the
controller starts from is taken.

Conventions and their sources (URScript manual, e-Series Script Directory):

- ``p[x, y, z, rx, ry, rz]``: m, and a rotation vector (axis times angle, rad).
- ``movej`` with a pose and ``get_inverse_kin(x)`` without ``qnear`` take "the solution
  closest to the current joint positions"; with ``qnear``, the one closest to ``qnear``;
  ``movel``/``movep``/``movec`` move the TCP in Cartesian space from where the arm is, so
  they end on the solution reached continuously from the current joints, the nearest one
  away from singularities. All UR10e joints turn +-360 deg: each solution is taken with
  the whole turns nearest the reference joints.
- The reference joints of a target (see :mod:`..programs.urscript`): its ``qnear``, else
  the joint target moved to before it, else the previous pose target's solved joints
  (program order), else, for the first motion, the first joint list of the script; with
  none of these the branch nearest zero is assumed and the report says so. Where two
  solutions are nearly as near the reference (less than 0.1 rad apart in distance) the
  report says the controller may take either.
"""

from __future__ import annotations

import math

import numpy as np

from ...compensation.dialect_rules import ArmGeometry, DialectRules
from ...kinematics.conventions import rotation_from_rotvec, rotvec_from_rotation
from ..pose_dialects import PoseConvention, PoseTarget

AMBIGUOUS_RAD = 0.1


def _rotvec_near(rotation: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The rotation vector of ``rotation`` nearest ``reference`` (v, or v +- 2 pi v/|v|)."""
    v = rotvec_from_rotation(rotation)
    angle = float(np.linalg.norm(v))
    if angle < 1e-12:
        return v
    axis = v / angle
    candidates = [v, v - 2 * math.pi * axis, v + 2 * math.pi * axis]
    return min(candidates, key=lambda c: float(np.sum((c - reference) ** 2)))


def urscript_written(target: PoseTarget) -> tuple[float, ...]:
    """The deciding joints (rad) the script writes for the target, or ()."""
    return tuple(n.value for n in target.config)


def _shifted(q: np.ndarray, reference: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """``q`` with each axis moved by whole turns nearest ``reference``, inside its range."""
    out = q.copy()
    for i in range(len(q)):
        best = None
        for k in (-2, -1, 0, 1, 2):
            value = q[i] + 2 * math.pi * k
            if ranges[i, 0] - 1e-9 <= value <= ranges[i, 1] + 1e-9:
                if best is None or abs(value - reference[i]) < abs(best - reference[i]):
                    best = value
        if best is not None:
            out[i] = best
    return out


def urscript_choose(geometry: ArmGeometry, target: PoseTarget, branches: np.ndarray, previous):
    written = urscript_written(target)
    note = ""
    if written:
        reference = np.array(written[:len(branches[0])])
    elif previous is not None:
        reference = np.asarray(previous, dtype=float)
    else:
        reference = np.zeros(branches.shape[1])
        note = ("no joints before the first motion (no qnear, no joint target): the "
                "solution nearest zero is assumed, the controller takes the one nearest the "
                "joints it starts from")
    ranges = geometry.robot.controller_ranges
    candidates = [_shifted(q, reference, ranges) for q in branches if np.all(np.isfinite(q))]
    if not candidates:
        return None, "the nominal arm does not reach the target", note
    distances = [float(np.linalg.norm(q - reference)) for q in candidates]
    order = np.argsort(distances)
    best = candidates[order[0]]
    others = [distances[k] for k in order[1:]
              if np.linalg.norm(candidates[k] - best) > 1e-6]
    if others and others[0] - distances[order[0]] < AMBIGUOUS_RAD:
        ambiguous = (f"ambiguous: two solutions nearly as near the reference joints "
                     f"({distances[order[0]]:.3f} and {others[0]:.3f} rad away), the "
                     f"controller may take either")
        note = "; ".join(x for x in (note, ambiguous) if x)
    return best, None, note


def _words(values: tuple) -> str:
    if not values:
        return ""
    return "near [" + ", ".join(f"{math.degrees(v):.1f}" for v in values) + "] deg"


URSCRIPT = DialectRules(
    name="urscript",
    convention=PoseConvention(
        position_scale=1.0,
        rotation=lambda rv: rotation_from_rotvec(np.asarray(rv, dtype=float)),
        angles=lambda rotation, ref: _rotvec_near(rotation, np.asarray(ref, dtype=float)),
        position_decimals=6, angle_decimals=6),
    choose=urscript_choose,
    config=lambda geometry, q, target: urscript_written(target),
    written=urscript_written,
    config_edits=lambda target, values: [],
    config_words=_words,
    is_identity=lambda key: False,
    joints_are_config=True)
