"""Moment arms of the joints over the measured points: which joints' angle errors show
as position errors at all (issue 28).

The moment arm of revolute axis j at a row is ``|d p / d q_j|`` (m per rad), the distance
from the axis to the measured point, read from the model's own Jacobian at the data
(geometry only: no row weights). A cyclic band of a joint whose arm is short is not
identifiable as position error: to move the points as much as the main joints' errors it
needs an angle error ``L_max / L_j`` times theirs, and along a path its columns are nearly
collinear with theirs, so it proxies their error (the ASTL CURVE reflector sits 30-34 mm
from axes 4 and 5 and 0.6 m from axes 1-3). A band is tested only when
``L_j >= MIN_LEVER_M``. The estimate this replaces read the arm from the weighted
Jacobian and moved with the rows' weights: it put CURVE's wrist arms above 50 mm with the
tracker's unfloored sigmas and below with floored ones.

Not in the rule: the noise and the band's size. In the linearized fit a band's
significance does not depend on its lever (a shorter arm scales its amplitude and that
amplitude's uncertainty alike; the held-out test already weighs the noise and the band's
2K parameters), and a share of the largest arm (10 % tried) would drop joint 6 on virtual
robots whose tool sits 50-100 mm off its axis, where a cyclic error at 4x the noise is
named right.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics.robot import Robot

MIN_LEVER_M = 0.03
"""Shortest RMS moment arm (m) of a joint that gets a band, whatever the others'. 30 mm:
at 50 mm, benchmarks/cyclic.py missed a joint-6 error whose tool sits 39 mm off the axis
(18/20); at 30 mm it names it, and the four ASTL sessions name exactly the same effects
(with time blocks, CURVE's 30-34 mm wrist arms no longer proxy the main joints)."""


@dataclass(frozen=True)
class MomentArms:
    """``rms_m`` (n,): RMS over the rows of each controller axis's moment arm, m/rad
    (prismatic axes: 1); ``threshold_m``: the shortest arm that gets a band."""

    rms_m: np.ndarray
    threshold_m: float

    def allows(self, joint: int) -> bool:
        return bool(self.rms_m[joint] >= self.threshold_m)


def moment_arms(problem, x: np.ndarray, robot: Robot) -> MomentArms:
    """The moment arms of ``robot``'s controller axes over the rows of an identification
    ``problem`` at its solution ``x`` (:mod:`.problem`)."""
    *_, chain, _ = problem.predict(x, jacobian=True)
    d = chain.dpoint_dq  # (m, 3, n) base frame, URDF joints
    if robot.urdf_from_controller is not None:
        d = d @ robot.urdf_from_controller
    rms = np.sqrt(np.mean(np.sum(d ** 2, axis=1), axis=0))
    return MomentArms(rms_m=rms, threshold_m=MIN_LEVER_M)
