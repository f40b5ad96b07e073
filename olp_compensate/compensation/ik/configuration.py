"""Configurations: the three bits of a joint vector, and the branch and 2 pi turns a
requested ABB-style confdata (cf1, cf4, cf6, cfx) selects.

Joints ``(m, 6)`` rad (controller convention); confdata ``(m, 4)`` int; limits ``(6, 2)`` rad.
"""

from __future__ import annotations

import numpy as np

from ...errors import DataError
from .closed_form import closed_form_branch
from .families import OPWParameters, URParameters, check_family
from .inputs import TWO_PI, as_confdata, as_joints, as_limits, as_poses, wrap
from .ur import ur_frames


def configuration_margins(params, q):
    """Signed margins ``(m, 3)`` of the three configuration bits (>= 0 means bit 0)."""
    theta = params.model_angles(q)
    wrist = params.signs[4] * np.sin(theta[:, 4])
    if isinstance(params, OPWParameters):
        psi3 = np.arctan2(params.a2, params.c3)
        k = np.hypot(params.a2, params.c3)
        t2, t3 = theta[:, 1], theta[:, 2]
        front = params.c2 * np.sin(t2) + k * np.sin(t2 + t3 + psi3) + params.a1
        return np.stack([front, np.sin(t3 + psi3), wrist], 1)
    frames = ur_frames(params, theta)
    x1 = frames[0][:, :3, 0]
    p05 = frames[4][:, :3, 3]
    front = np.sign(params.a2) * np.einsum("ij,ij->i", p05, x1)
    return np.stack([front, np.sin(theta[:, 2]), wrist], 1)


def configuration_bits(params: OPWParameters | URParameters, q, tolerance: float = 0.0):
    """Configuration bits ``(m, 3)`` int of joints ``q (m, 6)``: (behind, elbow, wrist).

    OPW arms (ABB's cfx, see :mod:`olp_compensate.programs.object_model.confdata`): *behind* = wrist
    centre behind axis 1 (its x in the arm plane < 0), *elbow* = wrist centre behind the lower arm
    (``sin(theta3 + atan2(a2, c3)) < 0``), *wrist* = axis 5 negative
    (``sign5 * sin(theta5) < 0``). UR arms: *behind* = wrist point (frame 5 origin) on the
    side of axis 1 opposite to where the arm points at theta2 = 0; *elbow* =
    ``sin(theta3) < 0``; *wrist* as above. A bit whose margin is within ``tolerance``
    (m for *behind*, sine otherwise) is -1 (on a boundary).
    """
    check_family(params)
    return configuration_bits_unchecked(params, as_joints(q, 6, "q"), tolerance)


def configuration_bits_unchecked(params, q, tolerance):
    """:func:`configuration_bits` of joints ``q (m, 6)`` rad already checked."""
    margin = configuration_margins(params, q)
    bits = (margin < 0).astype(int)
    bits[~(np.abs(margin) >= tolerance) if tolerance > 0 else np.isnan(margin)] = -1
    return bits


def branch_of(params: OPWParameters | URParameters, q) -> np.ndarray:
    """Configuration number ``(m,)`` in 0..7 of joints ``q (m, 6)``; the closed forms'
    branch index: ``4 * behind + 2 * elbow + wrist`` of :func:`configuration_bits`."""
    bits = configuration_bits(params, q)
    return 4 * bits[:, 0] + 2 * bits[:, 1] + bits[:, 2]


QUADRANT_AXES = (0, 3, 5)


def shift_into(q, limits, lower, upper):
    """Shift ``q (m,)`` by multiples of 2 pi to be nearest the interval [lower, upper)
    (arrays ``(m,)``), staying inside ``limits`` (2,) if given (else as little outside as
    possible). Returns (value, distance to the interval)."""
    centre = 0.5 * (lower + upper)
    k0 = np.round((centre - q) / TWO_PI)
    candidates = q[:, None] + TWO_PI * (k0[:, None] + np.array([-1.0, 0.0, 1.0]))
    distance = np.maximum(np.maximum(lower[:, None] - candidates, 0.0),
                          candidates - upper[:, None])
    # inside the limits first, then nearest the interval, then nearest its centre
    score = distance + 1e-9 * np.abs(candidates - centre[:, None])
    if limits is not None:
        score += 1e6 * np.maximum(np.maximum(limits[0] - candidates, 0.0),
                                  candidates - limits[1])
    best = np.argmin(np.where(np.isnan(score), np.inf, score), axis=1)
    rows = np.arange(len(q))
    return candidates[rows, best], distance[rows, best]


def select_requested(solutions, confdata, limits, quadrant_tolerance):
    """Requested branches with 2 pi shifts; status 0 found, 1 no branch, 2 limits, 3 quadrant."""
    return select_on_branch(solutions[np.arange(len(solutions)), confdata[:, 3]], confdata, limits,
                     quadrant_tolerance)


def select_on_branch(q, confdata, limits, quadrant_tolerance):
    """:func:`select_requested` of joints ``q (m, 6)`` already on the requested branch: each axis as
    :func:`shift_into` does it, all at once (axes first, so that rows are contiguous).
    Rows whose turn nearest the centre is inside the quadrant and the limits (by more than
    a tie of the scores could tell) keep it, found (status 0), without comparing turns."""
    axes = list(QUADRANT_AXES) + ([1, 2, 4] if limits is not None else [])
    value = q[:, axes].T                                                 # (axes, m)
    lower = np.empty_like(value)
    lower[:3] = confdata[:, :3].T * (np.pi / 2)
    upper = lower + np.pi / 2
    if limits is not None:
        lower[3:], upper[3:] = limits[[1, 2, 4], 0, None], limits[[1, 2, 4], 1, None]
        lim = limits[axes]
    centre = 0.5 * (lower + upper)
    turns = np.round((centre - value) / TWO_PI)
    best = value + TWO_PI * turns
    inside = (best >= lower) & (best <= upper) & (np.abs(best - centre) < np.pi - 1e-6)
    if limits is not None:
        inside &= (best >= lim[:, 0, None]) & (best <= lim[:, 1, None])
    q = q.copy()
    q[:, axes] = best.T
    status = np.zeros(len(q), int)
    rest = np.flatnonzero(~np.all(inside, axis=0))
    if len(rest) == 0:
        return q, status
    value, lower, upper, centre, turns = (a[:, rest] for a in (value, lower, upper, centre,
                                                               turns))
    best = best_distance = best_score = None
    for shift in (-1.0, 0.0, 1.0):
        candidate = value + TWO_PI * (turns + shift)
        distance = np.maximum(np.maximum(lower - candidate, 0.0), candidate - upper)
        # inside the limits first, then nearest the interval, then nearest its centre
        score = distance + 1e-9 * np.abs(candidate - centre)
        if limits is not None:
            score += 1e6 * np.maximum(np.maximum(lim[:, 0, None] - candidate, 0.0),
                                      candidate - lim[:, 1, None])
        if best is None:
            best, best_distance, best_score = candidate, distance, score
        else:
            better = score < best_score
            best = np.where(better, candidate, best)
            best_distance = np.where(better, distance, best_distance)
            best_score = np.where(better, score, best_score)
    part = q[rest]
    part[:, axes] = best.T
    q[rest] = part
    exists = np.all(np.isfinite(part), axis=1)
    quadrant_ok = ~np.any(best_distance[:3] > quadrant_tolerance, axis=0)
    within = np.ones(len(rest), bool)
    if limits is not None:
        within = np.all((part >= limits[:, 0]) & (part <= limits[:, 1]), axis=1)
    status[rest] = np.where(~exists, 1, np.where(~within, 2, np.where(~quadrant_ok, 3, 0)))
    return q, status


def select_branch(solutions, confdata, limits=None, quadrant_tolerance: float = np.pi / 4):
    """The solution matching ABB-style ``confdata (m, 4)`` = (cf1, cf4, cf6, cfx).

    ``solutions (m, 8, 6)`` from :func:`opw_inverse` / :func:`ur_inverse` (branch index =
    cfx). Axes 1, 4, 6 are shifted by multiples of 2 pi into the quadrants
    ``[cf * 90 deg, (cf + 1) * 90 deg)``, or as near as ``limits (6, 2)`` (rad) allow; the
    other axes by 2 pi only to enter the limits. Returns ``q (m, 6)`` rad and
    ``found (m,)`` bool: False where the branch is unreachable, outside the limits, or an
    axis lies more than ``quadrant_tolerance`` (rad) from its requested quadrant.
    """
    solutions = np.asarray(solutions, dtype=float)
    if solutions.ndim != 3 or solutions.shape[1:] != (8, 6):
        raise DataError(f"solutions must have shape (m, 8, 6), got {solutions.shape}")
    confdata = as_confdata(confdata, len(solutions))
    q, status = select_requested(solutions, confdata, as_limits(limits, 6), quadrant_tolerance)
    return q, status == 0


def nominal_joints_on_branch(family_params: OPWParameters | URParameters, base_T_flange,
                             confdata, limits=None,
                             quadrant_tolerance: float = np.pi / 4) -> np.ndarray:
    """Joints ``(m, 6)`` rad the nominal controller takes for ``base_T_flange (m, 4, 4)``
    on ABB-style ``confdata (m, 4)``: the closed form of that branch, shifted as
    :func:`select_branch` does; NaN where the branch cannot reach. Only branch cfx is
    solved (not all eight)."""
    check_family(family_params)
    T = as_poses(base_T_flange, "base_T_flange")
    confdata = as_confdata(confdata, len(T))
    q = closed_form_branch(family_params, T, confdata[:, 3])
    return select_on_branch(q, confdata, as_limits(limits, 6), quadrant_tolerance)[0]


def default_confdata(solutions, limits):
    """Where no configuration is asked for: the reachable branch with the smallest |q|."""
    q = solutions.copy()
    if limits is not None:
        outside = np.any((q < limits[:, 0]) | (q > limits[:, 1]), axis=2)
        q[outside] = np.nan
    norm = np.where(np.all(np.isfinite(q), 2), np.sum(q * q, 2), np.inf)
    cfx = np.argmin(norm, axis=1)
    chosen = solutions[np.arange(len(q)), cfx]
    quadrant = np.floor(np.nan_to_num(chosen[:, list(QUADRANT_AXES)]) / (np.pi / 2))
    return np.concatenate([quadrant.astype(int), cfx[:, None]], 1)


def wrist_in_quadrant(params, q, cf4, fraction):
    """Axis 4 moved to ``(cf4 + fraction) * 90 deg``, axis 6 so that theta4 + theta6 stays."""
    theta = params.model_angles(q)
    theta4 = params.signs[3] * (cf4 + fraction) * (np.pi / 2) - params.offsets[3]
    theta[:, 5] += theta[:, 3] - theta4
    theta[:, 3] = theta4
    return params.joint_angles(theta)


def flip_wrist(params, q):
    """The other wrist solution ``(m, 6)`` rad of the same flange pose (theta4 + pi, -theta5,
    theta6 + pi)."""
    theta = params.model_angles(q)
    theta[:, 3] += np.pi
    theta[:, 4] *= -1.0
    theta[:, 5] += np.pi
    return wrap(params.joint_angles(theta))
