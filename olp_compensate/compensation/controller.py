"""The controller's model and the load: the two other models of compensation.

Three models take part (see the design notes): the **real arm** (the calibration), the
**controller's model** (what the robot controller computes with: the data sheet by default,
the maker's factory calibration on every UR, an absolute-accuracy option's model) and the
**load** the arm carries. A :class:`~.pose.Compensator` given a controller model reads each
target through it (the joints the pendant would take) and writes, for the joints the real
arm needs, the pose the controller's model turns into exactly those joints. Given a
:class:`Load`, it solves the real arm with its load-dependent effects (joint compliance)
under that load.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..calibration.calibration import Calibration
from ..calibration.effects import Conditions
from ..errors import DataError
from ..kinematics.fixed_chain import FixedChain
from .ik import refine

CONTROLLER_TOLERANCE = 1e-10
"""m and rad: how closely the controller's joints reproduce a target."""


@dataclass(frozen=True)
class Load:
    """A payload: ``kg`` at ``cog_m`` (3,), its centre of gravity in the flange frame, m;
    ``source`` says where it came from (tooldata name, ``set_payload``, the command line)."""

    kg: float
    cog_m: np.ndarray
    source: str = ""

    def __post_init__(self):
        cog = np.asarray(self.cog_m, dtype=float).reshape(-1)
        if not (np.isfinite(self.kg) and self.kg >= 0):
            raise DataError(f"payload: expected a mass >= 0 kg, got {self.kg}")
        if cog.shape != (3,) or not np.all(np.isfinite(cog)):
            raise DataError(f"payload: expected a centre of gravity of 3 finite numbers, got "
                            f"{cog.tolist()}")
        object.__setattr__(self, "kg", float(self.kg))
        object.__setattr__(self, "cog_m", cog)

    def conditions(self, m: int) -> Conditions:
        """The effects' conditions for m rows under this load."""
        return Conditions(payload_kg=np.full(m, self.kg),
                          payload_point_m=np.broadcast_to(self.cog_m, (m, 3)).copy())

    def words(self) -> str:
        """'load 60 kg at [0, 0, 250] mm (tooldata gun)'."""
        cog = ", ".join(f"{v * 1e3:g}" for v in self.cog_m)
        return f"load {self.kg:g} kg at [{cog}] mm" + (f" ({self.source})" if self.source else "")


def controller_model_chain(controller: Calibration, calibration: Calibration) -> FixedChain:
    """The chain of the controller's model, checked to be of the calibration's robot."""
    # imported when used: the fit's module brings scipy.linalg (0.24 s, 25 MB), which
    # olp-fix without --controller never needs
    from ..calibration.controller_fit import controller_chain

    if controller.robot.fingerprint != calibration.robot.fingerprint:
        raise DataError(f"controller model: a calibration of {controller.robot.name}, but the "
                        f"arm is a {calibration.robot.name}; the controller's model must be of "
                        f"the same robot model")
    return controller_chain(controller)


def refine_on_controller(chain: FixedChain, q_urdf: np.ndarray,
                         base_T_flange: np.ndarray) -> np.ndarray:
    """The joints (m, n) near ``q_urdf`` (m, n) at which ``chain`` reaches ``base_T_flange``
    (m, 4, 4); NaN where ``q_urdf`` is NaN or Newton does not converge."""
    q = np.array(q_urdf, dtype=float, copy=True)
    if q.ndim != 2 or not len(q):
        return q
    rows = np.flatnonzero(np.all(np.isfinite(q), axis=1))
    if not len(rows):
        return q
    solution = refine(chain.flange_and_jacobian, q[rows], np.asarray(base_T_flange)[rows],
                      None, CONTROLLER_TOLERANCE, CONTROLLER_TOLERANCE, 30)
    q[rows] = np.where(solution.success[:, None], solution.q, np.nan)
    return q
