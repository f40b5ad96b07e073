"""Where the named effects were fitted, and the geometric model outside (issue 28).

A named effect is a map of the joints fitted on the rows measured; outside the joint
ranges of those rows it extrapolates, and so does the geometry fitted *with* it: the two
share parts of the error (a cyclic band's mean over a part of a turn is a joint offset, a
gear harmonic of order 1 is one too), so removing the effect alone leaves a geometry tuned
to be used with it, which is not the geometric model (on the ASTL LINE session, joint 2's
top fifth held out: 0.181 mm with the effects against 0.174 mm geometric, the cyclic band
already zero there). A target where any effect is outside its fitted range is therefore
predicted and compensated *entirely* by the geometric model identified on the same rows
(stored beside the extended one in calib.json as ``"geometric_fallback"``): there it equals
the geometric model, so it cannot be worse.

Each effect records the span of every controller axis over the rows it was fitted on
(``Effect.fitted_range``), not only of the axes its own term reads: the geometry was
fitted with all of them over that box, so a target outside the box in any axis (joint 2's
top fifth, with a cyclic error of joint 3 only) is already an extrapolation of the pair;
the geometric model there is the reference the extension must not lose to. Files without
ranges or without the geometric model are used as before (the effects everywhere, a
cyclic error zero outside its own ``q_range``).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from ..kinematics.robot import Robot

if TYPE_CHECKING:  # a type only
    from .effects import Effect


def with_fitted_ranges(effects, q_ctrl: np.ndarray) -> tuple[Effect, ...]:
    """``effects`` with ``fitted_range`` set from the rows' controller axes (m, n)."""
    q = np.atleast_2d(np.asarray(q_ctrl, float))
    low, high = q.min(axis=0), q.max(axis=0)
    span = tuple((j, float(low[j]), float(high[j])) for j in range(q.shape[1]))
    return tuple(dataclasses.replace(e, fitted_range=span) for e in effects)


def outside_axes(effect: Effect, q_ctrl: np.ndarray) -> np.ndarray:
    """(m, n) True where a row's axis lies outside the effect's fitted span of it."""
    q = np.atleast_2d(np.asarray(q_ctrl, float))
    out = np.zeros(q.shape, dtype=bool)
    for j, low, high in effect.fitted_range:
        out[:, j] = (q[:, j] < low) | (q[:, j] > high)
    return out


def outside_fitted(effects, q_ctrl: np.ndarray) -> np.ndarray:
    """(m,) True where some effect is outside the span it was fitted on."""
    q = np.atleast_2d(np.asarray(q_ctrl, float))
    out = np.zeros(len(q), dtype=bool)
    for e in effects:
        out |= outside_axes(e, q).any(axis=1)
    return out


def fallback_notes(effects, q_ctrl: np.ndarray, robot: Robot) -> list[str]:
    """One note per row (m, n controller axes): the axes outside the span the effects
    were fitted on, and that the geometric model is used there; '' inside."""
    q = np.atleast_2d(np.asarray(q_ctrl, float))
    low = np.full(q.shape[1], -np.inf)
    high = np.full(q.shape[1], np.inf)
    outside = np.zeros(q.shape, dtype=bool)
    for e in effects:
        outside |= outside_axes(e, q)
        for j, lo, hi in e.fitted_range:
            low[j], high[j] = max(low[j], lo), min(high[j], hi)
    notes = []
    for k in range(len(q)):
        parts = []
        for j in np.flatnonzero(outside[k]):
            value, lo, hi = _axis_values(robot, j, q[k, j], low[j], high[j])
            unit = "deg" if robot.joints[j].kind == "revolute" else "mm"
            parts.append(f"q{j + 1} = {value:.1f} {unit} outside [{lo:.1f}, {hi:.1f}]")
        notes.append(f"{', '.join(parts)} where the named effects were fitted: geometric "
                     f"model used" if parts else "")
    return notes


def _axis_values(robot: Robot, j: int, *values: float) -> list[float]:
    """``values`` of controller axis j in deg (revolute) or mm (prismatic)."""
    scale = 180.0 / np.pi if robot.joints[j].kind == "revolute" else 1e3
    return [v * scale for v in values]


def with_geometric_fallback(extended, geometric, q_ctrl: np.ndarray):
    """The extended :class:`.calibration.Calibration` with its effects' fitted ranges
    (from the rows' controller axes (m, n)) and ``geometric`` (fitted on the same rows,
    without effects) as the model outside them; ``extended`` itself without effects."""
    if not extended.effects:
        return extended
    plain = dataclasses.replace(geometric, effects=(), residual_map=None, regions=(),
                                geometric_fallback=None)
    return dataclasses.replace(extended, effects=with_fitted_ranges(extended.effects, q_ctrl),
                               geometric_fallback=plain)
