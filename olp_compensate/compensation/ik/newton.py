"""Damped Newton on any model given as ``fk_jacobian``: :func:`refine` (the whole batch at
once, :func:`damped_newton`, or a pool of rows, :func:`pooled_newton`).

Joints ``(m, n)`` rad, targets ``(m, 4, 4)`` m in the base frame; the model returns flange
poses and the geometric Jacobian (flange-origin velocity, then angular velocity, base frame).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ...errors import DataError, ModelError
from .inputs import as_joints, as_limits, as_poses
from .normal_equations import DAMPING, gauss_newton_steps, near_singular
from .residuals import error_norms, pose_error
from .solution import IKSolution


_STALL_STEPS = 20      # Newton steps in a row without progress before a target is given up


def _evaluate(fk_jacobian, q, target, n):
    """The model's Jacobian ``(k, 6, n)`` (a copy) and pose errors ``(k, 6)`` at ``q (k, n)``."""
    poses, jac = model_poses_and_jacobian(fk_jacobian, q, n)
    # the Jacobian is kept across calls: a copy, in case the model reuses its buffers
    return np.array(jac, dtype=float), pose_error(target, poses)


def model_poses_and_jacobian(fk_jacobian, q, n):
    """The model's poses ``(k, 4, 4)`` and Jacobian ``(k, 6, n)`` at ``q (k, n)``, checked."""
    poses, jac = fk_jacobian(q)
    poses, jac = np.asarray(poses, dtype=float), np.asarray(jac, dtype=float)
    if poses.shape != (len(q), 4, 4) or jac.shape != (len(q), 6, n):
        raise ModelError(f"fk_jacobian must return poses ({len(q)}, 4, 4) and a Jacobian "
                         f"({len(q)}, 6, {n}); got {poses.shape} and {jac.shape}")
    return poses, jac


def damped_newton(fk_jacobian, q0, target, position_tol, rotation_tol, max_iterations, max_step,
            accept=None, groups=None):
    """The iteration of :func:`refine` on rows of finite ``q0``. Only unfinished rows are
    evaluated; each row leaves the batch when it converges, stalls or runs out of steps.
    Multi-start: ``accept(rows, q, jac) -> (k,) bool`` judges rows as they converge; once
    one row of a group (``groups (m,)`` int >= 0) is accepted, the others of the group
    leave too. Returns q, jac, err, iterations, converged, stalled."""
    m, n = q0.shape
    q = q0.copy()
    jac = np.full((m, 6, n), np.nan)
    err = np.full((m, 6), np.nan)
    iterations = np.zeros(m, int)
    converged = np.zeros(m, bool)
    stalled = np.zeros(m, bool)
    act = np.flatnonzero(np.all(np.isfinite(q0), axis=1))
    if len(act) == 0:
        return q, jac, err, iterations, converged, stalled
    q_a, target_a = q[act], target[act]
    J, e = _evaluate(fk_jacobian, q_a, target_a, n)
    cost = np.einsum("ij,ij->i", e, e)
    fraction = np.ones(len(act))         # backtracking: share of the Newton step tried
    stale = np.zeros(len(act), int)      # steps in a row without real progress
    stuck = np.zeros(len(act), bool)
    resolved = None if accept is None else np.zeros(int(np.max(groups, initial=0)) + 1, bool)
    for iteration in range(max_iterations + 1):
        position, rotation = error_norms(e)
        done = (position <= position_tol) & (rotation <= rotation_tol)
        leave = done | stuck if iteration < max_iterations else np.ones(len(act), bool)
        if accept is not None:
            finished = np.flatnonzero(done)
            if len(finished):
                good = finished[accept(act[finished], q_a[finished], J[finished])]
                resolved[groups[act[good]]] = True
            leave |= resolved[groups[act]]
        if np.any(leave):
            rows = act[leave]
            q[rows], jac[rows], err[rows] = q_a[leave], J[leave], e[leave]
            iterations[rows] = iteration
            converged[rows] = done[leave]
            stalled[rows] = stuck[leave] & ~done[leave]
            keep = ~leave
            if not np.any(keep):
                break
            act, q_a, target_a, J, e = act[keep], q_a[keep], target_a[keep], J[keep], e[keep]
            cost, fraction, stale = cost[keep], fraction[keep], stale[keep]
        q_a, J, e, cost, fraction, stale, stuck = newton_step(
            fk_jacobian, target_a, max_step, q_a, J, e, cost, fraction, stale)
    return q, jac, err, iterations, converged, stalled


def newton_step(fk_jacobian, target, max_step, q, J, e, cost, fraction, stale):
    """One step of :func:`damped_newton` on every row (each row's arithmetic its own, the
    same whatever the other rows): the Gauss-Newton step scaled to at most ``max_step``
    rad and by the backtracking share ``fraction (k,)``, taken where it lowers the squared
    error ``cost (k,)``. Returns the rows' new q, J, e, cost, fraction, ``stale`` (steps in
    a row without lowering the error by a millionth) and ``stuck`` (k,) bool (stalled:
    :data:`_STALL_STEPS` such steps, or a share below 1e-9)."""
    n = q.shape[1]
    step = gauss_newton_steps(J, e, DAMPING)
    biggest = np.max(np.abs(step), axis=1)
    step *= (np.minimum(1.0, max_step / np.maximum(biggest, 1e-300)) * fraction)[:, None]
    trial = q + step
    J_t, e_t = _evaluate(fk_jacobian, trial, target, n)
    cost_t = np.einsum("ij,ij->i", e_t, e_t)
    better = cost_t < cost
    if np.all(better):
        q, J, e = trial, J_t, e_t
    else:
        q = np.where(better[:, None], trial, q)
        J = np.where(better[:, None, None], J_t, J)
        e = np.where(better[:, None], e_t, e)
    fraction = np.where(better, np.minimum(1.0, 2.0 * fraction), 0.25 * fraction)
    # stalled: _STALL_STEPS steps in a row without lowering the error by a millionth
    stale = np.where(cost_t < (1.0 - 1e-6) * cost, 0, stale + 1)
    cost = np.where(better, cost_t, cost)
    stuck = (stale >= _STALL_STEPS) | (fraction < 1e-9)
    return q, J, e, cost, fraction, stale, stuck


def refine(fk_jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], q0, target,
           limits=None, position_tol: float = 1e-9, rotation_tol: float = 1e-9,
           max_iterations: int = 50, *, singular_tol: float = 1e-7, max_step: float = 0.5,
           configuration: Callable[[np.ndarray], np.ndarray] | None = None,
           pool: int | None = None, drop=None, park=None) -> IKSolution:
    """Damped Newton from ``q0 (m, n)`` rad to ``target (m, 4, 4)`` m.

    ``fk_jacobian(q (k, n)) -> (base_T_flange (k, 4, 4), jacobian (k, 6, n))``, the
    geometric Jacobian in the base frame (rows: flange-origin linear velocity, then angular
    velocity). All targets iterate together; converged ones leave the batch (the model is
    evaluated only on unfinished rows). The Gauss-Newton
    step (with a 1e-10 relative Tikhonov term) is scaled so no joint moves more than
    ``max_step`` rad and is taken only if it lowers the squared error, else a quarter of it
    is tried next (backtracking; the share doubles again after a success). A target whose
    squared error has not dropped by a millionth in 20 steps in a row is 'unreachable'
    (stuck at the workspace boundary or a singularity). Converged when the position error is at most
    ``position_tol`` (m) and the rotation error at most ``rotation_tol`` (rad). Rows of
    ``q0`` with NaN are 'unreachable'. ``limits (n, 2)`` rad are checked at the end, not
    enforced. ``configuration(q (k, n)) -> (k,) or (k, b) int`` (-1 = undetermined), if
    given, labels the configuration: a label of the result that differs from that of
    ``q0`` gives 'branch_changed'. ``pool``: at most this many rows iterate at once, a
    finished row's place taken by the next (:func:`pooled_newton`; the same
    results, far fewer passes over the batch when rows take very different numbers of
    steps); ``drop`` its rows to give up early ('unreachable'), ``park`` rows to set aside
    as they join ('not_converged', left at ``q0``). See :class:`IKSolution` for the
    reasons.
    """
    q0 = as_joints(q0, None, "q0", allow_nan=True)
    m, n = q0.shape
    target = as_poses(target, "target")
    if len(target) != m:
        raise DataError(f"target has {len(target)} poses but q0 has {m} rows")
    limits = as_limits(limits, n)
    for name, value in (("position_tol", position_tol), ("rotation_tol", rotation_tol)):
        if not value > 0:
            raise DataError(f"{name} must be positive, got {value!r}")
    if int(max_iterations) < 0:
        raise DataError(f"max_iterations must be >= 0, got {max_iterations!r}")

    if pool is None:
        q, jac, err, iterations, converged, stalled = damped_newton(
            fk_jacobian, q0, target, position_tol, rotation_tol, int(max_iterations),
            max_step)
        jac = jac[converged]
    else:
        q, jac, err, iterations, converged, stalled = pooled_newton(
            fk_jacobian, q0, target, position_tol, rotation_tol, int(max_iterations),
            max_step, pool, drop, park)
    reason = np.full(m, "not_converged", dtype="<U14")
    reason[~np.all(np.isfinite(q0), axis=1) | stalled] = "unreachable"
    reason[converged] = "ok"

    done = np.flatnonzero(converged)
    if len(done):
        reason[done[near_singular(jac, singular_tol)]] = "singular"
        if limits is not None:
            outside = np.any((q[done] < limits[:, 0]) | (q[done] > limits[:, 1]), axis=1)
            reason[done[outside]] = "joint_limit"
        if configuration is not None:
            before = np.asarray(configuration(q0[done])).reshape(len(done), -1)
            after = np.asarray(configuration(q[done])).reshape(len(done), -1)
            changed = np.any((before >= 0) & (after >= 0) & (before != after), axis=1)
            reason[done[changed]] = "branch_changed"
    success = np.isin(reason, ("ok", "singular"))
    position, rotation = error_norms(err)
    return IKSolution(q=q, success=success, reason=reason, iterations=iterations,
                      position_error_m=position, rotation_error_rad=rotation)


# -- a pool of rows ---------------------------------------------------------------------
#
# Each pass of :func:`damped_newton` over a batch costs about 0.6 ms whatever its
# size, plus about 1.2 us a row (the IRB 2400's calibrated chain, measured on the search's
# starts). A search whose starts mostly converge in two or three steps while a few stall for
# 25 or run out their 60 keeps iterating a nearly empty batch: on the benchmark's
# all-failing module, 2,400 passes for 690,000 row-steps. Here a row that finishes leaves
# and the next waiting row joins (each row's steps are its own: it ends where
# :func:`damped_newton` ends it, up to the rounding of numpy's batched products, which
# differs with a batch's size by some 1e-14 rad): the passes are about the row-steps over
# the pool size.


class _Pool:
    """The rows iterating: global indices ``act (k,)`` and their state (see
    :func:`newton_step`), ``steps (k,)`` taken so far."""

    def __init__(self, n: int):
        self.act = np.zeros(0, int)
        self.q, self.target = np.zeros((0, n)), np.zeros((0, 4, 4))
        self.J, self.e = np.zeros((0, 6, n)), np.zeros((0, 6))
        self.cost, self.fraction = np.zeros(0), np.zeros(0)
        self.stale, self.steps = np.zeros(0, int), np.zeros(0, int)
        self.stuck = np.zeros(0, bool)

    _FIELDS = ("act", "q", "target", "J", "e", "cost", "fraction", "stale", "steps", "stuck")

    def keep(self, rows: np.ndarray) -> None:
        for name in self._FIELDS:
            setattr(self, name, getattr(self, name)[rows])

    def join(self, fk_jacobian, rows: np.ndarray, q0: np.ndarray, target: np.ndarray) -> None:
        """Rows ``rows`` join from ``q0 (k, n)`` toward ``target (k, 4, 4)``."""
        n = q0.shape[1]
        J, e = _evaluate(fk_jacobian, q0, target, n)
        k = len(rows)
        new = dict(act=rows, q=q0, target=target, J=J, e=e,
                   cost=np.einsum("ij,ij->i", e, e), fraction=np.ones(k),
                   stale=np.zeros(k, int), steps=np.zeros(k, int), stuck=np.zeros(k, bool))
        for name in self._FIELDS:
            setattr(self, name, np.concatenate([getattr(self, name), new[name]]))


def pooled_newton(fk_jacobian, q0, target, position_tol, rotation_tol, max_iterations,
                  max_step, pool: int, drop=None, park=None):
    """:func:`damped_newton` (no multi-start) of the rows of finite ``q0 (m, n)``
    toward ``target (m, 4, 4)`` with at most ``pool`` rows iterating at once: when half of
    them have finished, the next rows in order join. ``drop(steps, rows, cost, err) ->
    (k,) bool`` as rows join (its answer unused) and after each step, on the rows
    iterating (``steps (k,)`` each one's steps so far): those it names leave as stalled.
    ``park(rows, q, jac, err) -> (k,) bool`` on the rows joining that have not converged
    at their start: those it names leave at once, not converged nor stalled, ``q`` their
    start. Returns q, jac, err, iterations, converged, stalled as :func:`damped_newton`,
    but ``jac`` only of the converged rows, in order ``(c, 6, n)`` (the others' are not
    kept: a search's 18,000 starts would hold 5 MB)."""
    m, n = q0.shape
    q = q0.copy()
    kept_rows, kept_jac = [], []          # the converged rows' Jacobians, as they leave
    err = np.full((m, 6), np.nan)
    iterations = np.zeros(m, int)
    converged = np.zeros(m, bool)
    stalled = np.zeros(m, bool)
    waiting = np.flatnonzero(np.all(np.isfinite(q0), axis=1))
    pool = max(int(pool), 1)
    p = _Pool(n)
    while len(waiting) or len(p.act):
        while len(waiting) and len(p.act) <= pool // 2:     # (rows set aside leave at once)
            rows, waiting = waiting[:pool - len(p.act)], waiting[pool - len(p.act):]
            p.join(fk_jacobian, rows, q0[rows], target[rows])
            if drop is not None:                  # their errors at the start (none stops)
                new = slice(len(p.act) - len(rows), None)
                drop(p.steps[new], p.act[new], p.cost[new], p.e[new])
            if park is not None:
                _park(p, park, len(rows), err, position_tol, rotation_tol)
        position, rotation = error_norms(p.e)
        done = (position <= position_tol) & (rotation <= rotation_tol)
        leave = done | p.stuck | (p.steps >= max_iterations)
        if np.any(leave):
            rows = p.act[leave]
            q[rows], err[rows] = p.q[leave], p.e[leave]
            kept_rows.append(p.act[done])
            kept_jac.append(p.J[done])
            iterations[rows] = p.steps[leave]
            converged[rows] = done[leave]
            stalled[rows] = p.stuck[leave] & ~done[leave]
            p.keep(np.flatnonzero(~leave))
            if not len(p.act):
                continue
        p.q, p.J, p.e, p.cost, p.fraction, p.stale, p.stuck = newton_step(
            fk_jacobian, p.target, max_step, p.q, p.J, p.e, p.cost, p.fraction, p.stale)
        p.steps = p.steps + 1
        if drop is not None:
            p.stuck = p.stuck | drop(p.steps, p.act, p.cost, p.e)
    rows = np.concatenate(kept_rows) if kept_rows else np.zeros(0, int)
    jac = (np.concatenate(kept_jac) if kept_jac else np.zeros((0, 6, n)))[np.argsort(rows)]
    return q, jac, err, iterations, converged, stalled


def _park(p: _Pool, park, joined: int, err: np.ndarray, position_tol: float,
          rotation_tol: float) -> None:
    """The ``park`` of :func:`pooled_newton` on the last ``joined`` rows of the pool ``p``:
    those it names leave it (their errors written to ``err``; their q stays the start)."""
    new = np.arange(len(p.act) - joined, len(p.act))
    position, rotation = error_norms(p.e[new])
    going = ~((position <= position_tol) & (rotation <= rotation_tol))
    going[going] = park(p.act[new[going]], p.q[new[going]], p.J[new[going]], p.e[new[going]])
    if np.any(going):
        err[p.act[new[going]]] = p.e[new[going]]
        stay = np.ones(len(p.act), bool)
        stay[new[going]] = False
        p.keep(np.flatnonzero(stay))
