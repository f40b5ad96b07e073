"""Compensation and the fitted-in-a-range parts of a calibration (issue 28): the rows
whose joints leave the joint ranges the named effects were fitted on are solved again on
the calibration's geometric fallback, the residual map (``olp-cal diagnose
--residual-map``) is applied to the rows inside its joint region, and each row gets a note
saying which parts applied (see :mod:`olp_compensate.calibration.validity`).

The one entry is :func:`apply_fitted_parts`, which :meth:`.pose.Compensator.fitted_parts`
calls: ``compensate_poses``, the service, the RoboDK post and both olp-fix paths go
through it. This module does not import :mod:`.pose` (the compensator is passed in, and
builds its own fallback with :meth:`~.pose.Compensator.fallback_compensator`), so pose.py
can import it without a cycle."""

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


@dataclass
class FittedParts:
    """Rows (m) after :func:`apply_fitted_parts`: ``q`` (m, n) URDF axes rad/m and
    ``flange`` (m, 4, 4) nominal flange poses, base frame, m (the rows that changed
    replaced); ``notes`` one string per row ('' where everything the calibration holds
    applied); ``fallback`` (m,) bool, the rows solved on the geometric fallback;
    ``position_error_m``, ``rotation_error_rad`` (m,) how closely the model that solved a
    row again reaches it (m, rad), NaN where the first solve's figures stand."""

    q: np.ndarray
    flange: np.ndarray
    notes: list
    fallback: np.ndarray
    position_error_m: np.ndarray
    rotation_error_rad: np.ndarray

    @classmethod
    def unchanged(cls, q: np.ndarray, flange: np.ndarray, notes: list | None = None):
        """The rows as solved: nothing solved again, ``notes`` default empty ones."""
        m = len(q)
        return cls(q=q, flange=flange, notes=[""] * m if notes is None else notes,
                   fallback=np.zeros(m, dtype=bool), position_error_m=np.full(m, np.nan),
                   rotation_error_rad=np.full(m, np.nan))

    def errors(self, position_m: np.ndarray, rotation_rad: np.ndarray):
        """(position m, rotation rad) (m,): the first solve's ``position_m``,
        ``rotation_rad`` with the rows solved again replaced."""
        again = ~np.isnan(self.position_error_m)
        return (np.where(again, self.position_error_m, position_m),
                np.where(again, self.rotation_error_rad, rotation_rad))


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
    2. the residual map, fitted on the extended model's residual, applied to the other
       rows inside its region (:func:`_map_pass`); not to the rows of step 1;
    3. the notes of the cyclic errors without a fallback (:func:`add_range_notes`).

    ``notes`` (m strings, appended to in place) default to empty ones."""
    parts = FittedParts.unchanged(q, flange, notes)
    if not has_range_parts(comp.calibration):
        return parts
    tried = _fallback(comp, desired, parts, ok)
    q_ctrl = comp.robot.controller_from_joints(parts.q)  # the cyclic errors' test: before the map
    for i in np.flatnonzero(parts.fallback):
        if comp.calibration.residual_map is not None:
            _append(parts.notes, i, "residual map not applied (it corrects the extended "
                                    "model, not the geometric one)")
    _map_pass(comp, desired, parts, ok & ~parts.fallback)
    add_range_notes(comp.calibration, q_ctrl, ok & ~tried, parts.notes)
    return parts


def _replace(parts: FittedParts, rows: np.ndarray, q2, flange2, solution) -> None:
    """Rows ``rows`` of ``parts`` (its arrays changed in place) solved again: joints
    ``q2``, flanges ``flange2`` and the solve's errors."""
    parts.q[rows], parts.flange[rows] = q2, flange2
    parts.position_error_m[rows] = solution.position_error_m
    parts.rotation_error_rad[rows] = solution.rotation_error_rad


def _fallback(comp, desired, parts: FittedParts, ok) -> np.ndarray:
    """Step 1 of :func:`apply_fitted_parts` on ``parts`` (changed in place); (m,) the rows
    outside the fitted ranges (those solved on the fallback: ``parts.fallback``)."""
    cal = comp.calibration
    tried = np.zeros(len(parts.q), dtype=bool)
    if cal.geometric_fallback is None or not np.any(ok):
        return tried
    robot = comp.robot
    rows = np.flatnonzero(ok)
    q_ext = robot.controller_from_joints(parts.q[rows])
    outside = cal.outside_fitted(q_ext)
    rows, q_ext = rows[outside], q_ext[outside]
    if not len(rows):
        return tried
    tried[rows] = True
    geometric = comp.fallback_compensator()
    q2, flange2, solution, _ = geometric.compensate_flanges(desired[rows], None,
                                                           comp.confdata(parts.q[rows]))
    good = solution.success
    parts.q, parts.flange = parts.q.copy(), parts.flange.copy()
    _replace(parts, rows[good], q2[good], flange2[good], _rows_of(solution, good))
    parts.fallback[rows[good]] = True
    # the note names the reported joints where they are outside, else (a target on the
    # edge: the geometric solution just inside) the extended model's, and says so
    q_now = robot.controller_from_joints(parts.q[rows])
    edge = good & ~cal.outside_fitted(q_now)
    shown = np.where(edge[:, None], q_ext, q_now)
    for i, note, used, on_edge in zip(rows, fallback_notes(cal.effects, shown, robot),
                                      good, edge):
        if not used:
            _append(parts.notes, i, note.replace("geometric model used", NO_GEOMETRIC))
        else:
            _append(parts.notes, i, _edge_note(note) if on_edge else note)
    return tried


def _edge_note(note: str) -> str:
    """The note of a target on the edge of the fitted ranges (``note``: the extended
    solution's, from :func:`~..calibration.effect_ranges.fallback_notes`)."""
    axes = note.split(" where the named effects were fitted")[0]
    return (f"{EDGE}: the extended model's solution has {axes}, the geometric model's "
            f"lies inside; geometric model used")


def _map_pass(comp, desired, parts: FittedParts, ok) -> None:
    """Solve again the rows of ``ok`` inside the map's region, the desired flange moved
    by minus the map's residual at the first solution (base frame; the map was fitted at
    the calibration's measured point, its shift stands for the tool's); ``parts`` changed
    in place where the second solve succeeds inside the region, a note on each row."""
    rmap = comp.calibration.residual_map
    if rmap is None or not np.any(ok):
        return
    robot, notes = comp.robot, parts.notes
    rows = np.flatnonzero(ok)
    inside = rmap.inside(robot.controller_from_joints(parts.q[rows]))
    for i in rows[~inside]:
        _append(notes, i, "outside the joint region of the residual map: not applied")
    rows = rows[inside]
    if not len(rows):
        return
    rotation = comp.calibration.device_T_base[:3, :3]
    shift = rmap.predict(robot.controller_from_joints(parts.q[rows])) @ rotation  # R^T e
    shifted = desired[rows].copy()
    shifted[:, :3, 3] -= shift
    q2, flange2, solution, _ = comp.compensate_flanges(shifted, None,
                                                       comp.confdata(parts.q[rows]))
    good = solution.success & rmap.inside(robot.controller_from_joints(
        np.where(solution.success[:, None], q2, parts.q[rows])))
    parts.q, parts.flange = parts.q.copy(), parts.flange.copy()
    _replace(parts, rows[good], q2[good], flange2[good], _rows_of(solution, good))
    for i, used in zip(rows, good):
        _append(notes, i, APPLIED if used else "residual map not applied (its solution "
                                               "left the region or failed)")


def _rows_of(solution, rows: np.ndarray):
    """The errors of ``solution``'s ``rows`` (a small record with the two arrays)."""
    return _Errors(solution.position_error_m[rows], solution.rotation_error_rad[rows])


@dataclass(frozen=True)
class _Errors:
    position_error_m: np.ndarray
    rotation_error_rad: np.ndarray


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
