"""The IK of a calibrated arm on the configuration a program asks for: :func:`solve`.

The nominal closed form on the requested branch, Newton onto the model in its coordinates,
then, for the few targets that fail, the reach proof, Newton from several starts and the
closed-form fixed point. Targets ``(m, 4, 4)`` m, joints ``(m, 6)`` rad, base frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .closed_form import closed_form_solutions, one_branch
from .closed_form_newton import closed_form_newton, closed_form_on_model
from .configuration import (configuration_bits_unchecked, default_confdata, flip_wrist,
                            select_on_branch, select_requested, wrist_in_quadrant)
from .families import OPWParameters, URParameters, check_family
from .inputs import as_confdata, as_limits, as_poses
from .newton import damped_newton, refine
from .normal_equations import near_singular
from .reach import ReachBound
from .residuals import error_norms
from .solution import IKSolution

CLOSED_FORM_STEPS = 8     # steps of closed_form_newton before the multi-start Newton
BLOCK = 2048              # targets per batch of closed_form_newton
_FIRST_STEPS = 2          # its steps in blocks, before the rows that need more go on together
_MULTI_START_STEPS = 12   # Newton steps of the multi-start retry
MULTI_START_BLOCK = 2048
"""Failed targets whose multi-start (4.) iterates together: its fifteen starts a target
bound the memory; the fewer targets the later stages keep iterate all together (each row's
arithmetic is its own, so the blocks change no digit)."""
_RESULT_FIELDS = ("q", "success", "reason", "position_error_m", "rotation_error_rad")
_STATE_FIELDS = ("q", "success", "reason", "iterations", "position_error_m",
                 "rotation_error_rad")   # of an IKSolution, in its order


@dataclass(frozen=True)
class SolveOptions:
    """Tolerances and budgets of :func:`solve` (see there): m, rad, Newton steps."""

    position_tol: float = 1e-9
    rotation_tol: float = 1e-9
    max_iterations: int = 100
    quadrant_tolerance: float = np.pi / 4
    boundary_tolerance: float = 1e-9
    singular_tol: float = 1e-7
    retries: bool = True
    ruled: bool = False


def solve(family_params: OPWParameters | URParameters,
          fk_jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], target,
          confdata=None, limits=None, *, position_tol: float = 1e-9,
          rotation_tol: float = 1e-9, max_iterations: int = 100,
          quadrant_tolerance: float = np.pi / 4, boundary_tolerance: float = 1e-9,
          singular_tol: float = 1e-7, reach: ReachBound | None = None,
          retries: bool = True, ruled: bool = False) -> IKSolution:
    """Joints reaching ``target (m, 4, 4)`` (m) on the model ``fk_jacobian``, per branch.

    1. The nominal closed form of ``family_params`` on the branch ``confdata (m, 4)`` =
       (cf1, cf4, cf6, cfx) (see :func:`select_branch`; None: the reachable branch nearest
       q = 0, and any configuration is accepted). Targets slightly outside the nominal
       workspace start from the stretched arm; no start at all is 'unreachable'.
    2. Newton onto the model (``fk_jacobian``, e.g. the calibrated robot) in the
       coordinates of the closed form: the model's error corrects the target given to the
       nominal closed form on the same branch (exactly, via the nominal and model
       Jacobians), to ``position_tol`` (m) / ``rotation_tol`` (rad); usually two steps.
    3. The result is shifted by multiples of 2 pi as :func:`select_branch` does and
       checked: outside ``limits (6, 2)`` rad is 'joint_limit'; configuration bits
       (:func:`configuration_bits` of the nominal family, bits within
       ``boundary_tolerance`` of their boundary ignored) other than requested, or axis 1, 4
       or 6 more than ``quadrant_tolerance`` rad from its quadrant, is 'branch_changed'.
    4. Failed targets (near singularities, where the model can have several solutions per
       nominal configuration) are retried by :func:`refine`'s Newton from several starts at
       once, the first accepted by the checks of 3 winning: the nominal start, the flipped
       wrist (OPW), axis 4 placed in its quadrant (theta4 + theta6 kept), the nominal
       solutions of the neighbouring branches.
    5. Still failed targets: the closed-form fixed point onto the model (the nominal
       inverse of the target corrected by the model's flange error, until joints move less
       than 1e-6 rad), :func:`refine`, and the starts of 4 one after the other. The reasons
       of targets that fail in the end are those of this last step.
    ``max_iterations`` bounds the Newton steps of each of these stages. ``reach``: the
    model's :class:`ReachBound` (its chain on the joints ``fk_jacobian`` takes); targets
    still failed after 2. that it proves out of reach (on the requested wrist
    configuration) are 'unreachable' at once, without 4. and 5. ``retries`` False stops
    after 3. (a caller that gathers the failed targets of many batches retries them in one:
    4. and 5. cost per Newton step, whatever the number of targets). ``ruled`` True: the
    caller decides the failed targets by the configuration rule
    (:func:`~olp_compensate.compensation.config_rule.decide`, which searches them again
    and sets their joints): the targets ``reach`` proves out of reach after the first two
    steps of 2. stop there instead of taking its remaining steps (same statuses; their
    joints and errors are the rule's).
    """
    options = SolveOptions(position_tol=position_tol, rotation_tol=rotation_tol,
                           max_iterations=max_iterations, quadrant_tolerance=quadrant_tolerance,
                           boundary_tolerance=boundary_tolerance, singular_tol=singular_tol,
                           retries=retries, ruled=ruled)
    return _BranchSolver(family_params, fk_jacobian, target, confdata, limits, options,
                         reach).solve()[0]


def solve_with_nominal(family_params: OPWParameters | URParameters,
                       fk_jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                       target, confdata=None, limits=None, *, keep: list | None = None,
                       resume: SolverState | None = None, **options
                       ) -> tuple[IKSolution, np.ndarray]:
    """:func:`solve` (same arguments), and the joints ``(m, 6)`` rad of the nominal closed
    form on the requested branch it starts from (as :func:`nominal_joints_on_branch`
    gives them), at no extra cost: what the nominal controller does with ``target``.

    ``keep`` (a list): the solver's :class:`SolverState` of every target is appended to it
    (with ``retries`` False: what a later call with ``resume`` goes on from). ``resume``:
    the state such a call kept for these ``target`` (the same poses, its ``confdata``):
    the closed form and the reach screen are not made again, the retries go on from it."""
    reach = options.pop("reach", None)
    solver = _BranchSolver(family_params, fk_jacobian, target, confdata, limits,
                           SolveOptions(**options), reach, resume)
    out = solver.solve()
    if keep is not None:
        keep.append(solver.state())
    return out


@dataclass
class SolverState:
    """What :func:`solve_with_nominal` has done for m targets: the configuration solved on
    ``confdata (m, 4)``, the nominal closed form's joints ``start (m, 6)`` rad,
    ``stretched (m,)``, ``status (m,)`` (1: no start, or proven out of reach) and the
    :class:`IKSolution` ``result`` so far (see :class:`_BranchSolver`)."""

    confdata: np.ndarray
    start: np.ndarray
    stretched: np.ndarray
    status: np.ndarray
    result: IKSolution

    def rows(self, rows) -> SolverState:
        """The state of targets ``rows`` (an index array or a boolean mask), copied."""
        r = self.result
        return SolverState(self.confdata[rows], self.start[rows], self.stretched[rows],
                           self.status[rows], IKSolution(
                               *(getattr(r, name)[rows] for name in _STATE_FIELDS)))

    @staticmethod
    def concatenate(states: list[SolverState]) -> SolverState:
        """One state of ``states`` one after the other."""
        return SolverState(*(np.concatenate([getattr(s, name) for s in states]) for name in (
            "confdata", "start", "stretched", "status")), IKSolution(*(np.concatenate(
                [getattr(s.result, name) for s in states]) for name in _STATE_FIELDS)))


def _empty_solution(m: int) -> IKSolution:
    """m targets not solved yet: NaN joints and errors, 'unreachable', no steps."""
    return IKSolution(q=np.full((m, 6), np.nan), success=np.zeros(m, bool),
                      reason=np.full(m, "unreachable", dtype="<U14"),
                      iterations=np.zeros(m, int), position_error_m=np.full(m, np.nan),
                      rotation_error_rad=np.full(m, np.nan))


class _FirstAccepted:
    """``accept`` of :func:`damped_newton` for a multi-start: a converged start counts when
    the solver's verdict on it is 'ok'; :attr:`accepted` remembers which starts did."""

    def __init__(self, solver: _BranchSolver, owner: np.ndarray):
        self.solver, self.owner = solver, owner
        self.accepted = np.zeros(len(owner), bool)

    def __call__(self, candidates, q, jac):
        _, reason = self.solver.verdict(q, self.owner[candidates])
        self.accepted[candidates] = reason == "ok"
        return reason == "ok"


class _BranchSolver:
    """The state the stages of :func:`solve` share, for m targets ``T (m, 4, 4)`` m.

    ``confdata (m, 4)`` the configuration asked for (or the default one when none is, then
    ``check_configuration`` is False); ``start (m, 6)`` rad the nominal closed form's
    joints on it, ``stretched (m,)`` where that start is the stretched arm's, ``status
    (m,)`` of :func:`select_on_branch` (1: no start, or proven out of reach); ``result``
    the :class:`IKSolution` the stages fill in. Each stage works on the rows given or on
    the rows still failed; :meth:`solve` runs them in order.
    """

    def __init__(self, params, fk_jacobian, target, confdata, limits, options: SolveOptions,
                 reach: ReachBound | None, resume: SolverState | None = None):
        check_family(params)
        self.params, self.fk_jacobian, self.options, self.reach = (params, fk_jacobian,
                                                                   options, reach)
        self.T = as_poses(target, "target")
        m = len(self.T)
        self.limits = as_limits(limits, 6)
        self.max_iterations = int(options.max_iterations)
        self.check_configuration = confdata is not None
        self.solutions = None                     # all nominal branches (m, 8, 6), if needed
        if confdata is None:
            self.solutions = closed_form_solutions(params, self.T, clip=False)
            self.confdata = default_confdata(self.solutions, self.limits)
        else:
            self.confdata = as_confdata(confdata, m)
        self.start = np.full((m, 6), np.nan)      # the nominal closed form's joints
        self.stretched = np.zeros(m, bool)        # start is the stretched arm's
        self.status = np.ones(m, int)             # of select_on_branch: 1 = no start at all
        self.result = _empty_solution(m)
        self.resumed = resume is not None
        if resume is not None:              # the first stages done: their state, copied
            state = resume.rows(np.arange(m))
            self.confdata, self.start, self.stretched, self.status, self.result = (
                as_confdata(state.confdata, m), state.start, state.stretched, state.status,
                state.result)
            self.check_configuration, self.solutions = True, None

    def state(self) -> SolverState:
        """The state of every target, copied (see :class:`SolverState`)."""
        return SolverState(self.confdata, self.start, self.stretched, self.status,
                           self.result).rows(np.arange(len(self.T)))

    # -- checks ---------------------------------------------------------------------------

    def requested(self, rows):
        """The configuration bits (k, 3) asked for on ``rows``."""
        cfx = self.confdata[rows, 3]
        return np.stack([cfx // 4, (cfx // 2) % 2, cfx % 2], 1)

    def branches(self, rows):
        """All nominal closed-form solutions ``(k, 8, 6)`` rad of ``rows``."""
        if self.solutions is not None:
            return self.solutions[rows]
        return closed_form_solutions(self.params, self.T[rows], clip=False)

    def verdict(self, q, rows):
        """Reached joints ``q (k, 6)`` of ``rows`` shifted to the requested turns, and 'ok',
        'branch_changed' or 'joint_limit' per row: the checks refine was not asked to make."""
        o = self.options
        q, check = select_on_branch(q, self.confdata[rows], self.limits, o.quadrant_tolerance)
        got = configuration_bits_unchecked(self.params, q, o.boundary_tolerance)
        wrong = (np.any((got >= 0) & (got != self.requested(rows)), axis=1)
                 & self.check_configuration)
        reason = np.full(len(rows), "ok", dtype="<U14")
        reason[~wrong & (check == 2)] = "joint_limit"
        reason[((check == 3) & self.check_configuration) | wrong] = "branch_changed"
        return q, reason

    def check(self, result: IKSolution, rows) -> IKSolution:
        """``result`` of ``rows`` with the :meth:`verdict` applied to its reached rows."""
        # == twice, not np.isin: its np.unique imports numpy.ma (7-20 ms a run)
        reached = np.flatnonzero((result.reason == "ok") | (result.reason == "singular"))
        q, reason = self.verdict(result.q[reached], rows[reached])
        result.q[reached] = q
        result.reason[reached] = np.where(reason == "ok", result.reason[reached], reason)
        result.success = (result.reason == "ok") | (result.reason == "singular")
        return result

    def store(self, rows, q, singular, err, converged, iterations, only_success=False):
        """Checks a stage's end ``q (k, 6)``, ``err (k, 6)`` on ``rows`` and writes it into
        :attr:`result` (only its successes when ``only_success``); adds the steps."""
        reason = np.where(converged, "ok", "not_converged").astype("<U14")
        reason[converged & singular] = "singular"
        position, rotation = error_norms(err)
        part = self.check(IKSolution(q=q, success=converged, reason=reason,
                                     iterations=iterations, position_error_m=position,
                                     rotation_error_rad=rotation), rows)
        keep = part.success if only_success else np.ones(len(rows), bool)
        for name in _RESULT_FIELDS:
            getattr(self.result, name)[rows[keep]] = getattr(part, name)[keep]
        self.result.iterations[rows] += iterations

    def failed_rows(self):
        """Rows not solved yet that have a start and are not proven out of reach."""
        return np.flatnonzero(~self.result.success & (self.status != 1))

    # -- stages ---------------------------------------------------------------------------

    def nominal_start(self, block):
        """1. The nominal closed form on the requested branch for the rows ``block`` (the
        stretched arm where it has none): sets :attr:`start`, :attr:`status`,
        :attr:`stretched`; returns the rows that have a start."""
        confdata, T = self.confdata[block], self.T[block]
        if self.solutions is not None:
            first = self.solutions[block, confdata[:, 3]]
        else:
            first = one_branch(self.params, T, confdata[:, 3], clip=False)
        first, found = select_on_branch(first, confdata, self.limits, np.inf)
        missing = np.flatnonzero(found == 1)
        self.stretched[block[missing]] = True
        if len(missing):
            clipped = one_branch(self.params, T[missing], confdata[missing, 3], clip=True)
            first[missing], found[missing] = select_on_branch(clipped, confdata[missing],
                                                              self.limits, np.inf)
        first[found == 1] = np.nan
        self.start[block], self.status[block] = first, found
        return block[found != 1]

    def closed_form_stage(self):
        """1. and 2.: the start and two Newton steps in the closed form's coordinates in
        blocks of :data:`BLOCK` rows (arrays of a few thousand rows stay in the processor's
        cache), then the few rows that need more steps, together."""
        o, m = self.options, len(self.T)
        unfinished = []                           # (rows, q, X) of rows to go on with
        for block in np.array_split(np.arange(m), -(-m // BLOCK)) if m else ():
            rows = self.nominal_start(block)
            if len(rows) == 0:
                continue
            q, singular, err, steps, converged, X = closed_form_newton(
                self.params, self.fk_jacobian, self.T[rows], self.confdata[rows, 3],
                self.start[rows], o.position_tol, o.rotation_tol,
                min(_FIRST_STEPS, self.max_iterations), o.singular_tol)
            self.store(rows, q, singular, err, converged, steps)
            unfinished.append((rows[~converged], q[~converged], X[~converged]))
        rows = (np.concatenate([part[0] for part in unfinished]) if unfinished
                else np.zeros(0, int))
        if len(rows) and self.max_iterations > _FIRST_STEPS:
            q_end, X_end = (np.concatenate([part[i] for part in unfinished]) for i in (1, 2))
            if o.ruled:               # the rule searches the rows proven out of reach anyway
                go_on = ~self.beyond_reach(rows)
                self.status[rows[~go_on]] = 1
                rows, q_end, X_end = rows[go_on], q_end[go_on], X_end[go_on]
        if len(rows) and self.max_iterations > _FIRST_STEPS:
            q, singular, err, steps, converged, _ = closed_form_newton(
                self.params, self.fk_jacobian, self.T[rows], self.confdata[rows, 3], q_end,
                o.position_tol, o.rotation_tol,
                min(CLOSED_FORM_STEPS, self.max_iterations) - _FIRST_STEPS, o.singular_tol,
                X_end)
            self.result.iterations[rows] -= 1     # the first evaluation is the last one's again
            self.store(rows, q, singular, err, converged, steps)

    def beyond_reach(self, rows):
        """(k,) bool: which of ``rows`` :attr:`reach` proves out of reach (on the requested
        wrist configuration); none without a bound."""
        if self.reach is None or len(rows) == 0:
            return np.zeros(len(rows), bool)
        wrist = self.requested(rows)[:, 2] if self.check_configuration else None
        return np.asarray(self.reach.unreachable(self.T[rows], wrist, self.params,
                                                 self.options.boundary_tolerance), bool)

    def screen_reach(self):
        """3. The failures :attr:`reach` proves out of reach (on the requested wrist
        configuration) get status 1, as no start at all: 'unreachable', nothing to retry."""
        rows = self.failed_rows()
        self.status[rows[self.beyond_reach(rows)]] = 1

    def restarts(self, rows, first_starts, base, last_starts=None):
        """The starts ``[(k, 6), ...]`` rad of a multi-start on ``rows``: ``first_starts``
        (if any), the flipped wrist (OPW), axis 4 (and axis 1) placed in its quadrant with
        theta4 + theta6 kept, from ``base``, the nominal neighbouring branches, and
        ``last_starts`` (if any)."""
        params, confdata = self.params, self.confdata
        starts = [] if first_starts is None else [first_starts]
        if isinstance(params, OPWParameters):
            starts.append(flip_wrist(params, base))
        starts += [wrist_in_quadrant(params, base, confdata[rows, 1], f)
                   for f in (0.5, 0.25, 0.75)]
        # near the shoulder singularity axis 1 is as free as axes 4 and 6 near the wrist's
        for f in (0.5, 0.25, 0.75):
            turned = wrist_in_quadrant(params, base, confdata[rows, 1], f)
            turned[:, 0] = (confdata[rows, 0] + f) * (np.pi / 2)
            starts.append(turned)
        nearby = self.branches(rows)
        for flip in (4, 2, 1, 6, 5, 3, 7):
            starts.append(select_requested(nearby, np.concatenate(
                [confdata[rows, :3], confdata[rows, 3:] ^ flip], 1), self.limits, np.inf)[0])
        return starts if last_starts is None else [*starts, last_starts]

    def multi_start(self, rows, first_starts, base, steps, last_starts=None):
        """4. Newton from the :meth:`restarts` of ``rows`` at once, at most ``steps`` each;
        the first start accepted by the checks wins (its results are stored; of starts
        accepted at the same step, the first in the list)."""
        o = self.options
        starts = self.restarts(rows, first_starts, base, last_starts)
        k = len(rows)
        owner = np.tile(rows, len(starts))
        accept = _FirstAccepted(self, owner)
        q, jac, err, iterations, converged, _ = damped_newton(
            self.fk_jacobian, np.concatenate(starts), self.T[owner], o.position_tol,
            o.rotation_tol, steps, 0.5, accept=accept,
            groups=np.tile(np.arange(k), len(starts)))
        won = accept.accepted.reshape(len(starts), k)
        chosen = (np.argmax(won, axis=0) * k + np.arange(k))[np.any(won, axis=0)]
        singular = np.zeros(len(chosen), bool)
        done = np.flatnonzero(converged[chosen])
        singular[done] = near_singular(jac[chosen[done]], o.singular_tol)
        self.store(owner[chosen], q[chosen], singular, err[chosen], converged[chosen],
                   np.zeros(len(chosen), int), only_success=True)
        self.result.iterations[rows] += np.max(iterations.reshape(len(starts), k), axis=0)

    def run(self, q_start, rows, first=False):
        """:func:`refine` of ``rows`` from ``q_start (k, 6)``, after the closed-form fixed
        point onto the model when ``first``; checked (:meth:`check`)."""
        o = self.options
        steps = np.zeros(len(rows), int)
        if first:
            q_start, steps = closed_form_on_model(self.params, self.fk_jacobian, self.T[rows],
                                                  self.confdata[rows, 3], q_start)
        result = refine(self.fk_jacobian, q_start, self.T[rows], None, o.position_tol,
                        o.rotation_tol, self.max_iterations, singular_tol=o.singular_tol)
        result.iterations += steps
        return self.check(result, rows)

    def fixed_point_retry(self):
        """5. Still failed rows: the closed-form fixed point and refine (:meth:`run`), then
        the restarts of 4 from its result with the full iteration budget, and the nominal
        start of 4 again, last, with that budget (near two singularities at once Newton can
        need more than 4.'s steps from it, while the fixed point goes to another solution
        of the configuration, which the quadrant check rejects)."""
        rows = self.failed_rows()
        if len(rows) == 0:
            return
        again = self.run(self.start[rows], rows, first=True)
        for name in _RESULT_FIELDS:
            getattr(self.result, name)[rows] = getattr(again, name)
        self.result.iterations[rows] += again.iterations
        rows = rows[~again.success]
        if len(rows):
            self.multi_start(rows, None, self.result.q[rows], self.max_iterations,
                             last_starts=self.start[rows])

    def solve(self):
        """All stages in order: the :class:`IKSolution`, and the nominal closed form's
        joints ``(m, 6)`` rad on the requested branch (NaN where it cannot reach)."""
        if not self.resumed:
            self.closed_form_stage()
            self.screen_reach()
        rows = self.failed_rows()
        if len(rows) and self.options.retries:
            for a in range(0, len(rows), MULTI_START_BLOCK):   # fifteen starts a row
                block = rows[a:a + MULTI_START_BLOCK]
                self.multi_start(block, self.start[block], self.result.q[block],
                                 min(_MULTI_START_STEPS, self.max_iterations))
            self.fixed_point_retry()
        self.result.reason[self.status == 1] = "unreachable"
        self.result.success[self.status == 1] = False
        start = self.start.copy()
        start[self.stretched] = np.nan            # the nominal closed form has no solution
        return self.result, start
