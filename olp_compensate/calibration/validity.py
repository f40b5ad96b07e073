"""Where the fitted-in-a-range parts of a calibration hold: the named effects (outside the
joint ranges they were fitted on the geometric fallback predicts, :mod:`.effect_ranges`),
the cyclic angle errors
(:class:`.effects.CyclicError`, valid in the axis span they were fitted on, zero outside)
and the residual map (:class:`.remainder.ResidualMap`, refused outside its joint region).
Prediction and compensation use them inside and say, per target, where they fell back."""

from __future__ import annotations

import numpy as np

from .calibration import Calibration
from .effect_ranges import fallback_notes
from .effects import CyclicError


def has_range_parts(cal: Calibration) -> bool:
    """Whether ``cal`` holds a part fitted in a range (effects with a geometric fallback,
    a cyclic error, a residual map): without one every row gets no note."""
    return (cal.geometric_fallback is not None or cal.residual_map is not None
            or any(isinstance(e, CyclicError) for e in cal.effects))


def range_notes(cal: Calibration, q_ctrl: np.ndarray, residual_map: bool = False) -> list[str]:
    """One note per row of controller axis values (m, n), '' when everything the
    calibration holds applies there."""
    q = np.atleast_2d(np.asarray(q_ctrl, float))
    notes = [[] for _ in range(len(q))]
    fallback = cal.outside_fitted(q)
    if np.any(fallback):
        for k, note in enumerate(fallback_notes(cal.effects, q, cal.robot)):
            if note:
                notes[k].append(note)
    for effect in cal.effects:
        if not isinstance(effect, CyclicError):
            continue
        if cal.geometric_fallback is not None and effect.fitted_range:
            continue  # said above, with the geometric model
        lo, hi = np.degrees(effect.q_range)
        for k in np.flatnonzero(~effect.inside(q)):
            notes[k].append(f"q{effect.joint + 1} outside [{lo:.1f}, {hi:.1f}] deg where its "
                            f"cyclic error was fitted: the rest of the model alone")
    if residual_map and cal.residual_map is not None:
        for k in np.flatnonzero(~cal.residual_map.inside(q)):
            notes[k].append("outside the joint region of the residual map: not applied")
    return ["; ".join(n) for n in notes]


def map_correction(cal: Calibration, q_ctrl: np.ndarray) -> np.ndarray:
    """(m, 3) what the residual map adds to a predicted point, device frame, m (zero
    without a map and outside its region)."""
    q = np.atleast_2d(np.asarray(q_ctrl, float))
    if cal.residual_map is None:
        return np.zeros((len(q), 3))
    return cal.residual_map.predict(q)
