"""Controller configuration conventions: which of the 8 IK branches a program asks for.

ABB ``confdata`` = ``[cf1, cf4, cf6, cfx]`` (ABB, *Technical reference manual - RAPID
Instructions, Functions and Data types*, data type ``confdata``; the same text as ABB's
*RAPID Reference Manual - Basic Characteristics* and RobotStudio's online
``RapidIFDTechRefManual``, page "confdata"):

- cf1, cf4, cf6: quadrant numbers of axes 1, 4 and 6. "Quadrant 0 is the first quarter
  revolution, 0-90 deg, in a positive direction from the zero position; quadrant 1 is the
  next, 90-180 deg, etc. Quadrant -1 is the revolution 0 deg - (-90 deg)": ``floor(q / 90
  deg)``, so [-90, 0) deg is -1.
- cfx (for robots with 8 solutions per pose, i.e. OPW arms), 0..7::

      cfx  wrist centre vs axis 1   wrist centre vs lower arm   axis 5
      0    in front of              in front of                 positive
      1    in front of              in front of                 negative
      2    in front of              behind                      positive
      3    in front of              behind                      negative
      4    behind                   in front of                 positive
      5    behind                   in front of                 negative
      6    behind                   behind                      positive
      7    behind                   behind                      negative

  Made precise here (:func:`olp_compensate.compensation.ik.configuration_bits`): "in front of axis 1"
  means the wrist centre's coordinate along the arm's forward direction (axis 1 turned by
  q1) is >= 0; "in front of the lower arm" means the wrist centre lies on the forward side
  of the line through axes 2 and 3 (for the ABB home pose both hold, cfx = 0); "axis 5
  positive" means ``sign5 * sin(theta5) >= 0`` (q5 in [0, 180] deg when axis 5 has no zero
  offset). The closed forms of :mod:`olp_compensate.compensation.ik` return branch k = cfx k.
  UR arms have no ABB cfx; the same function gives the analogous bits (shoulder, elbow,
  wrist) of :func:`olp_compensate.compensation.ik.configuration_bits`.

The configuration written (the rule of every dialect): the configuration data written
with a compensated target is the configuration of the joints written, the joints the
controller will take for it, never the one the program had when the joints left it:

- ABB cf1, cf4, cf6: the quadrants of the written joints' axes 1, 4 and 6
  (:func:`written_confdata`), with two cases where the written number stays, both where
  the controller takes the same joints whichever is written: an axis within
  :data:`BORDER_RAD` of a quadrant border (what the written numbers resolve; either
  quadrant holds for it), and an axis the program's own confdata already disagreed with
  at its nominal joints and that compensation left in the same quadrant (the program's
  choice is not rewritten: with the nominal calibration no byte changes). cfx is the one
  asked for (the solver keeps the configuration asked for, and so does the rule of
  :mod:`.config_rule`);
- KUKA S and T, FANUC's letters and turn numbers, VAL3's shoulder/elbow/wrist: those of
  the written joints (:mod:`~olp_compensate.compensation.dialect_rules`,
  :mod:`..fanuc.rules`, :mod:`..val3.rules`; KRL's T bit of an axis within 1e-5 rad of 0
  keeps the written bit, as here);
- V+ and URScript write no configuration with a target.

V+ (Adept, Staubli CS7) and similar PUMA-style flags (RIGHTY/LEFTY, ABOVE/BELOW,
FLIP/NOFLIP); FLIP means joint 5 negative (Servotronix softMC wiki, ``robot.WRISTCMD`` for
the PUMA model: "FLIP - value of joint 5 is negative"). RIGHTY: the arm plane is offset to
the right of the line from axis 1 to the wrist centre, seen from above, as a human right
arm (for an arm without shoulder offset, b = 0, RIGHTY is taken as "wrist centre in front
of axis 1", an assumption of this module). ABOVE: the elbow is above the line from the
shoulder (axis 2) to the wrist centre.
"""

from __future__ import annotations

import numpy as np

from ...compensation.ik import OPWParameters, URParameters, branch_of, select_branch
from ...compensation.ik.configuration import configuration_margins
from ...compensation.ik.families import check_family
from ...compensation.ik.inputs import as_joints
from ...errors import DataError, ModelError

__all__ = ["abb_confdata", "select_branch", "vplus_configuration", "vplus_branch",
           "written_confdata", "BORDER_RAD"]

BORDER_RAD = 1e-5
"""An axis this close (rad, 0.0006 deg) to a quadrant border is on either side of it."""


def written_confdata(written: np.ndarray, q_ctrl: np.ndarray, nominal_ctrl: np.ndarray
                     ) -> np.ndarray:
    """The confdata ``(k, 4)`` int to write with compensated joints ``q_ctrl (k, n)``
    (controller axes, rad) for targets written with ``written (k, 4)``, whose nominal
    controller joints were ``nominal_ctrl (k, n)`` (NaN where none): cf1, cf4, cf6 the
    quadrants of ``q_ctrl``'s axes 1, 4, 6, except the written one where the axis lies
    within :data:`BORDER_RAD` of that quadrant, or where the written one already differed
    from the nominal joints' quadrant and compensation did not change the quadrant; cfx
    as written (see the module's notes)."""
    quarter = np.pi / 2
    axes = q_ctrl[:, [0, 3, 5]]
    quadrant = np.floor(axes / quarter).astype(int)
    lower = written[:, :3] * quarter
    near_written = (axes >= lower - BORDER_RAD) & (axes <= lower + quarter + BORDER_RAD)
    with np.errstate(invalid="ignore"):
        before = np.floor(nominal_ctrl[:, [0, 3, 5]] / quarter)
        near_before = np.floor((nominal_ctrl[:, [0, 3, 5]] - BORDER_RAD) / quarter)
        after_before = np.floor((nominal_ctrl[:, [0, 3, 5]] + BORDER_RAD) / quarter)
    program_choice = ((before != written[:, :3]) & (near_before != written[:, :3])
                      & (after_before != written[:, :3]) & (before == quadrant))
    out = written.copy()
    out[:, :3] = np.where(near_written | program_choice, written[:, :3], quadrant)
    return out


def abb_confdata(params: OPWParameters | URParameters, q) -> np.ndarray:
    """ABB confdata ``(m, 4)`` int = (cf1, cf4, cf6, cfx) of joints ``q (m, 6)`` rad."""
    check_family(params)
    q = as_joints(q, 6, "q")
    quadrants = np.floor(q[:, [0, 3, 5]] / (np.pi / 2)).astype(int)
    return np.concatenate([quadrants, branch_of(params, q)[:, None]], 1)


def vplus_configuration(params: OPWParameters, q) -> np.ndarray:
    """V+ flags ``(m, 3)`` bool = (RIGHTY, ABOVE, FLIP) of joints ``q (m, 6)`` rad (OPW)."""
    if not isinstance(params, OPWParameters):
        raise ModelError(f"V+ configurations are defined here for OPW (PUMA-like) arms, "
                         f"got {type(params).__name__}")
    q = as_joints(q, 6, "q", allow_nan=True)
    front, lower_arm, wrist = configuration_margins(params, q).T
    righty = front >= 0 if params.b == 0 else front * params.b < 0
    # elbow above the shoulder-wrist line: "front of lower arm" seen from the side the
    # wrist centre is on
    above = lower_arm * (front - params.a1) > 0
    return np.stack([righty, above, wrist < 0], 1)


def vplus_branch(params: OPWParameters, solutions, righty, above, flip):
    """The solution with the given V+ flags, each (m,) bool or a scalar.

    ``solutions (m, 8, 6)`` from :func:`olp_compensate.compensation.ik.opw_inverse`. Returns ``q (m, 6)``
    rad (NaN where none) and ``found (m,)`` bool.
    """
    solutions = np.asarray(solutions, dtype=float)
    if solutions.ndim != 3 or solutions.shape[1:] != (8, 6):
        raise DataError(f"solutions must have shape (m, 8, 6), got {solutions.shape}")
    m = len(solutions)
    wanted = np.stack([np.broadcast_to(np.asarray(v, dtype=bool), (m,))
                       for v in (righty, above, flip)], 1)
    flags = vplus_configuration(params, solutions.reshape(-1, 6)).reshape(m, 8, 3)
    match = np.all(flags == wanted[:, None, :], axis=2)
    match &= np.all(np.isfinite(solutions), axis=2)
    found = np.any(match, axis=1)
    q = np.full((m, 6), np.nan)
    q[found] = solutions[found, np.argmax(match[found], axis=1)]
    return q, found
