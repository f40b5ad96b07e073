"""olp-fix and the fitted-in-a-range parts of a calibration: the residual map
(``olp-cal diagnose --residual-map``) applied to the targets inside its joint region, and
a note on each target outside a cyclic error's fitted range or the map's region (see
:mod:`olp_compensate.calibration.validity`)."""

from __future__ import annotations

import numpy as np

from ..calibration.calibration import Calibration
from ..calibration.validity import range_notes
from .pose import Compensator

APPLIED = "residual map applied"


def _append(notes: list, i: int, text: str) -> None:
    notes[i] = f"{notes[i]}; {text}" if notes[i] else text


def residual_map_pass(comp: Compensator, desired: np.ndarray, q: np.ndarray,
                      flange: np.ndarray, ok: np.ndarray, notes: list):
    """Solve again the compensated rows inside the map's region, the desired flange moved
    by minus the map's residual at the first solution (base frame; the map was fitted at
    the calibration's measured point, its shift stands for the tool's); (q, flange) with
    those rows replaced where the second solve succeeds inside the region. ``notes`` (one
    per row) get what was done. First the rows outside the effects' fitted ranges are
    solved again on the geometric model (:func:`range_fallback_pass`)."""
    q, flange = range_fallback_pass(comp, desired, q, flange, ok, notes)
    rmap = comp.calibration.residual_map
    if rmap is None or not np.any(ok):
        return q, flange
    robot = comp.robot
    rows = np.flatnonzero(ok)
    inside = rmap.inside(robot.controller_from_joints(q[rows]))
    for i in rows[~inside]:
        _append(notes, i, "outside the joint region of the residual map: not applied")
    rows = rows[inside]
    if not len(rows):
        return q, flange
    rotation = comp.calibration.device_T_base[:3, :3]
    shift = rmap.predict(robot.controller_from_joints(q[rows])) @ rotation  # R^T e per row
    shifted = desired[rows].copy()
    shifted[:, :3, 3] -= shift
    q2, flange2, solution, _ = comp.compensate_flanges(shifted, None, comp.confdata(q[rows]))
    good = solution.success & rmap.inside(robot.controller_from_joints(
        np.where(solution.success[:, None], q2, q[rows])))
    q, flange = q.copy(), flange.copy()
    q[rows[good]], flange[rows[good]] = q2[good], flange2[good]
    for i, used in zip(rows, good):
        _append(notes, i, APPLIED if used else "residual map not applied (its solution "
                                               "left the region or failed)")
    return q, flange


def range_fallback_pass(comp: Compensator, desired: np.ndarray, q: np.ndarray,
                        flange: np.ndarray, ok: np.ndarray, notes: list):
    """Solve the compensated rows whose joints leave a named effect's fitted range again
    on the calibration's geometric fallback (:mod:`..calibration.effect_ranges`), on the
    same configuration; (q, flange) with those rows replaced where it succeeds (the note
    itself comes from :func:`add_range_notes`)."""
    cal = comp.calibration
    if cal.geometric_fallback is None or not np.any(ok):
        return q, flange
    rows = np.flatnonzero(ok)
    rows = rows[cal.outside_fitted(comp.robot.controller_from_joints(q[rows]))]
    if not len(rows):
        return q, flange
    geometric = Compensator(cal.geometric_fallback, comp.controller, comp.load)
    q2, flange2, solution, _ = geometric.compensate_flanges(desired[rows], None,
                                                           comp.confdata(q[rows]))
    good = solution.success
    q, flange = q.copy(), flange.copy()
    q[rows[good]], flange[rows[good]] = q2[good], flange2[good]
    for i in rows[~good]:
        _append(notes, i, "the geometric model reaches no solution here: the extended "
                          "model's kept")
    return q, flange


def add_range_notes(calibration: Calibration, q_ctrl: np.ndarray, ok: np.ndarray,
                    notes: list) -> None:
    """A note on each compensated row outside a cyclic error's fitted range."""
    if not np.any(ok):
        return
    rows = np.flatnonzero(ok)
    for i, note in zip(rows, range_notes(calibration, q_ctrl[rows])):
        if note:
            _append(notes, i, note)
