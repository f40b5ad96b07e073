"""What the non-geometric effects read per row: the controller axes, the gravity load
torque about them (and its derivatives), the temperature and the approach directions; and
the operating conditions they come from (:class:`Conditions`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics.robot import Robot
from .gravity import gravity_model


@dataclass(frozen=True)
class Conditions:
    """Operating conditions beyond the joints, per row (all optional).

    ``payload_kg`` (m,) carried at ``payload_point_m`` (m, 3), flange frame, m (default the
    flange origin); ``temperature_c`` (m,), deg C; ``directions`` (m, n) approach direction
    per controller axis, +1 / -1, 0 when unknown.
    """

    payload_kg: np.ndarray | None = None
    payload_point_m: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    directions: np.ndarray | None = None


@dataclass(frozen=True)
class EffectInputs:
    """What the effects read, per row: ``q`` (m, n) controller axes, rad/m; ``torque``
    (m, n) gravity load torque about the controller axes, N.m, and ``dtorque_dq`` (m, n, n)
    (each None when not computed); ``temperature_c`` (m,) or None; ``directions`` (m, n) or
    None."""

    q: np.ndarray
    torque: np.ndarray | None = None
    dtorque_dq: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    directions: np.ndarray | None = None

    @property
    def n_rows(self) -> int:
        return len(self.q)

    def subset(self, mask) -> "EffectInputs":
        """The rows selected by a boolean mask or index array."""
        def pick(a):
            return None if a is None else a[mask]
        return EffectInputs(q=self.q[mask], torque=pick(self.torque),
                            dtorque_dq=pick(self.dtorque_dq),
                            temperature_c=pick(self.temperature_c),
                            directions=pick(self.directions))


def effect_inputs(robot: Robot, q_ctrl: np.ndarray, conditions: Conditions | None = None,
                  torque: bool = True, derivatives: bool = False) -> EffectInputs:
    """Evaluate the inputs of the effects for controller axis values ``q_ctrl`` (m, n)."""
    q_ctrl = np.atleast_2d(np.asarray(q_ctrl, dtype=float))
    conditions = conditions or Conditions()
    tau = dtau = None
    if torque:
        tau, dtau = gravity_model(robot).load_torque(q_ctrl, conditions.payload_kg,
                                                     conditions.payload_point_m, derivatives)
    return EffectInputs(q=q_ctrl, torque=tau, dtorque_dq=dtau,
                        temperature_c=conditions.temperature_c, directions=conditions.directions)
