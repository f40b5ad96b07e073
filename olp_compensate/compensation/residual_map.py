"""Compensation and the fitted-in-a-range parts of a calibration (issue 28): the rows
whose joints leave the joint ranges the named effects were fitted on are solved again on
the calibration's geometric fallback, the residual map (``olp-cal diagnose
--residual-map``) is applied to the rows inside its joint region, and each row gets a note
saying which parts applied (see :mod:`olp_compensate.calibration.validity`).

The one entry is :func:`apply_fitted_parts`, which :meth:`.pose.Compensator.fitted_parts`
calls: ``compensate_poses``, the service, the RoboDK post and both olp-fix paths go
through it. This module does not import :mod:`.pose` (the compensator is passed in, and
builds its own fallback with :meth:`~.pose.Compensator.fallback_compensator`), so pose.py
can import it without a cycle. ``residual_map_pass``, ``range_fallback_pass`` and
``add_range_notes`` are kept for older callers."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..calibration.calibration import Calibration
from ..calibration.effect_ranges import fallback_notes
from ..calibration.validity import has_range_parts, range_notes

APPLIED = "residual map applied"
NO_GEOMETRIC = "the geometric model reaches no solution here: the extended model's kept"
EDGE = "on the edge of the joint ranges the named effects were fitted on"
"""A target whose extended solution leaves the ranges and whose geometric one does not:
no answer is consistent with both models there; the geometric one is written (predict,
at its joints, uses the extended model)."""


@dataclass(frozen=True)
class FittedParts:
    """Rows (m) after :func:`apply_fitted_parts`: ``q`` (m, n) URDF axes rad/m and
    ``flange`` (m, 4, 4) nominal flange poses, base frame, m (the rows that changed
    replaced); ``notes`` one string per row ('' where everything the calibration holds
    applied); ``fallback`` (m,) bool, the rows solved on the geometric fallback."""

    q: np.ndarray
    flange: np.ndarray
    notes: list
    fallback: np.ndarray


def _append(notes: list, i: int, text: str) -> None:
    notes[i] = f"{notes[i]}; {text}" if notes[i] else text


def apply_fitted_parts(comp, desired: np.ndarray, q: np.ndarray, flange: np.ndarray,
                       ok: np.ndarray, notes: list | None = None) -> FittedParts:
    """The rule every compensation applies after solving ``desired`` (m, 4, 4) flange
    poses, base frame, m, with ``comp`` (a :class:`~.pose.Compensator`) into ``q`` (m, n)
    URDF axes and ``flange`` (m, 4, 4), ``ok`` (m,) the rows compensated:

    1. the rows whose joints leave an effect's fitted range (``Calibration.outside_fitted``,
       the test predict uses) are solved again on the geometric fallback, same
       configuration, with the note of the axes outside (the extended model's answer kept,
       and said so, where the geometric model reaches none);
    2. the residual map's pass on the rows inside its region (:func:`residual_map_pass`);
    3. the notes of the cyclic errors without a fallback (:func:`add_range_notes`).

    ``notes`` (m strings, appended to in place) default to empty ones."""
    notes = [""] * len(q) if notes is None else notes
    if not has_range_parts(comp.calibration):
        return FittedParts(q=q, flange=flange, notes=notes,
                           fallback=np.zeros(len(q), dtype=bool))
    q, flange, tried, fallback = _fallback(comp, desired, q, flange, ok, notes)
    q_ctrl = comp.robot.controller_from_joints(q)   # the cyclic errors' test: before the map
    q, flange = _map_pass(comp, desired, q, flange, ok, notes)
    add_range_notes(comp.calibration, q_ctrl, ok & ~tried, notes)
    return FittedParts(q=q, flange=flange, notes=notes, fallback=fallback)


def _fallback(comp, desired, q, flange, ok, notes, axes: bool = True):
    """Step 1 of :func:`apply_fitted_parts`: (q, flange, rows outside the fitted ranges,
    rows solved on the fallback);
    without ``axes`` only the rows the geometric model does not reach get a note (as
    before :func:`add_range_notes` was folded in)."""
    cal = comp.calibration
    tried, fallback = np.zeros(len(q), dtype=bool), np.zeros(len(q), dtype=bool)
    if cal.geometric_fallback is None or not np.any(ok):
        return q, flange, tried, fallback
    robot = comp.robot
    rows = np.flatnonzero(ok)
    q_ext = robot.controller_from_joints(q[rows])
    outside = cal.outside_fitted(q_ext)
    rows, q_ext = rows[outside], q_ext[outside]
    if not len(rows):
        return q, flange, tried, fallback
    tried[rows] = True
    geometric = comp.fallback_compensator()
    q2, flange2, solution, _ = geometric.compensate_flanges(desired[rows], None,
                                                           comp.confdata(q[rows]))
    good = solution.success
    q, flange = q.copy(), flange.copy()
    q[rows[good]], flange[rows[good]] = q2[good], flange2[good]
    fallback[rows[good]] = True
    # the note names the reported joints where they are outside, else (a target on the
    # edge: the geometric solution just inside) the extended model's, and says so
    q_now = robot.controller_from_joints(q[rows])
    edge = good & ~cal.outside_fitted(q_now)
    shown = np.where(edge[:, None], q_ext, q_now)
    for i, note, used, on_edge in zip(rows, fallback_notes(cal.effects, shown, robot),
                                      good, edge):
        if not used:
            _append(notes, i, note.replace("geometric model used", NO_GEOMETRIC)
                    if axes else NO_GEOMETRIC)
        elif on_edge and axes:
            _append(notes, i, _edge_note(note))
        elif axes:
            _append(notes, i, note)
    return q, flange, tried, fallback


def _edge_note(note: str) -> str:
    """The note of a target on the edge of the fitted ranges (``note``: the extended
    solution's, from :func:`~..calibration.effect_ranges.fallback_notes`)."""
    axes = note.split(" where the named effects were fitted")[0]
    return (f"{EDGE}: the extended model's solution has {axes}, the geometric model's "
            f"lies inside; geometric model used")


def residual_map_pass(comp, desired: np.ndarray, q: np.ndarray, flange: np.ndarray,
                      ok: np.ndarray, notes: list):
    """(q, flange) after steps 1 and 2 of :func:`apply_fitted_parts` (kept for older
    callers: the notes of step 3 are :func:`add_range_notes`'s)."""
    q, flange, _, _ = _fallback(comp, desired, q, flange, ok, notes, axes=False)
    return _map_pass(comp, desired, q, flange, ok, notes)


def _map_pass(comp, desired, q, flange, ok, notes):
    """Solve again the compensated rows inside the map's region, the desired flange moved
    by minus the map's residual at the first solution (base frame; the map was fitted at
    the calibration's measured point, its shift stands for the tool's); (q, flange) with
    those rows replaced where the second solve succeeds inside the region."""
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


def range_fallback_pass(comp, desired: np.ndarray, q: np.ndarray, flange: np.ndarray,
                        ok: np.ndarray, notes: list):
    """(q, flange) after step 1 of :func:`apply_fitted_parts` (kept for older callers)."""
    q, flange, _, _ = _fallback(comp, desired, q, flange, ok, notes, axes=False)
    return q, flange


def add_range_notes(calibration: Calibration, q_ctrl: np.ndarray, ok: np.ndarray,
                    notes: list) -> None:
    """A note on each row of ``ok`` outside a cyclic error's fitted range, or (rows not
    passed through :func:`apply_fitted_parts`) an effect's."""
    if not np.any(ok):
        return
    rows = np.flatnonzero(ok)
    for i, note in zip(rows, range_notes(calibration, q_ctrl[rows])):
        if note:
            _append(notes, i, note)
