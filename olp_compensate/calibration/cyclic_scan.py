"""Cyclic angle error bands: each joint's angle error as harmonics 1..K of its angle
(:class:`.effects.CyclicError`), fitted with the geometry, ridge-regularized, tested as a
band with the held-out criterion of :mod:`.effect_scan`.

K per joint is what the joint's angles resolve (:func:`resolvable_order`): at least
``SAMPLES_PER_PERIOD`` distinct angles per period of the highest order over the span the
data cover, the highest order completing a period within that span, at most ``MAX_ORDER``,
and the band's 2K parameters at most ``PARAMETER_SHARE`` of the equations. The band
starts at the lowest order completing a period over the span (:func:`lowest_order`; lower
orders are smooth there: the geometry takes them, and fitted with it they reach any
amplitude, as on a real arm's 25-degree wrist span). A joint whose moment arm over the
measured points is short (:mod:`.moment_arms`) gets no band: its angle barely moves them,
and a band there only proxies other joints (seen on real data with the reflector at the
wrist centre).

The fit is linear at the current model's full-data solution (as the effect scan's): the
residual r (3m,) and the unit-scaled Jacobian of the current unknowns u (unpenalized)
with each band's columns c (rad, penalized by ``lambda |c|^2``; kept bands keep their
lambda). Everything is computed from per-fold Gram matrices, and the band's penalty from
the eigen-decomposition of its Schur complement, so the whole lambda grid costs one
decomposition per training set. Lambda is chosen by nested cross-validation: within each
outer training set (the other folds), by the inner folds; the outer held-out residuals so
obtained are what the band's test compares (:meth:`BandScan.gain_test`: the z-test of
:meth:`.effect_scan.EffectScan.gain_test`, with the leverage of the kept bands too).
The band of the final model takes the lambda that ordinary k-fold cross-validation over
all rows chooses.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from .band_solves import Factored, ProfiledBand, Recent, other_block
from .effect_scan import EffectScan, Heldout
from .problem import problem_at
from .identify import IdentificationResult
from .effects import CyclicError
from .separability import separability_from_gram
from .moment_arms import MIN_LEVER_M, moment_arms  # noqa: F401  (MIN_LEVER_M: re-exported)
from ..kinematics.robot import Robot

MAX_ORDER = 48
"""Highest order tried (cycles per turn)."""
SAMPLES_PER_PERIOD = 6
"""Distinct angles needed per period of the highest order, over the joint's span."""
PARAMETER_SHARE = 0.1
"""A band's parameters (2K) may be at most this share of the equations."""
MAX_MOVES = 2.0
"""A band that moves the measured points by more than this times the current held-out
RMS is not kept: it explains little of what it moves, so it cancels against the geometry
or other bands (on a real arm's path data, high orders of joints 1 and 4 moved the points
by 0.8 mm against each other to explain 0.04 mm)."""
RIDGE_GRID = np.logspace(-6, 3, 19)
"""Penalties tried, relative to the mean diagonal of the band's Gram matrix."""


def lowest_order(q: np.ndarray) -> int:
    """The lowest order completing a period over the span of the angles ``q`` (rad)."""
    span = float(np.ptp(q)) if len(q) else 0.0
    return max(1, int(np.ceil(2 * np.pi / span - 1e-9))) if span > 1e-6 else 1


def resolvable_order(q: np.ndarray, n_equations: int) -> int:
    """The highest harmonic order the angles ``q`` (rad) of one joint resolve (0: none)."""
    span = float(np.ptp(q)) if len(q) else 0.0
    if span <= 1e-6:
        return 0
    distinct = len(np.unique(np.round(q, 6)))
    order = min(int(2 * np.pi * distinct / (span * SAMPLES_PER_PERIOD)), MAX_ORDER,
                int(PARAMETER_SHARE * n_equations / 2))
    return order if order * span >= 2 * np.pi else 0


@dataclass(frozen=True)
class BandResult:
    """One band in one round: its joint (0-based), ``gain`` (share of the current
    held-out sum of squares it removes), ``z`` and ``p`` of the test, the penalty chosen
    on all rows, and whether it is significant (p below alpha / K)."""

    effect: CyclicError
    gain: float
    z: float
    p_value: float
    ridge: float
    significant: bool = False
    moves: float = 0.0
    """RMS of how far the fitted band moves the measured points over the current model's
    held-out RMS (above ``MAX_MOVES``: it cancels against other terms, not kept)."""
    moves_m: float = float("nan")
    """RMS of how far the fitted band moves the measured points, m (weighted units)."""
    separability: float = float("nan")
    """Share of the band's motion distinct from the unpenalized unknowns (the geometry and
    the named effects; the kept bands are penalized and tested again by the elimination)
    (:mod:`.separability`; below ``MIN_SEPARABILITY``: kept when significant, not named)."""
    base_rms_m: float = float("nan")
    """Held-out RMS (3-D per row, m, weighted) of the model the band was tested against."""


@dataclass
class BandOutcome:
    """What the band scan found: the kept bands (fitted values, strongest first in
    ``rounds``), what the current unknowns must take up with them (``rhs``; the step
    itself is chosen by :func:`apply_bands`), the held-out residuals of the final model,
    and the rounds."""

    bands: list[CyclicError] = field(default_factory=list)
    p_values: list[float] = field(default_factory=list)
    heldout: Heldout | None = None
    rhs: np.ndarray | None = None
    """What the other unknowns must take up once the bands are in (3m,), m."""
    short_lever: list[int] = field(default_factory=list)
    """Joints (0-based) whose axis passes too near the measured points for a band."""
    rounds: list[list[BandResult]] = field(default_factory=list)
    thresholds: list[float] = field(default_factory=list)
    scan: "BandScan | None" = field(default=None, repr=False, compare=False)
    """The band scan itself (its folds: time blocks when given), for the backward
    elimination of :mod:`.backward_elimination`."""


class BandScan:
    """The cyclic bands of every joint the data resolve, at one model (an EffectScan)."""

    def __init__(self, scan: EffectScan, robot: Robot, q_ctrl: np.ndarray, folds=None):
        self.scan = scan
        n_eq = len(scan.residual)
        blocks, self.templates, self.columns = [], {}, {}
        self.short_lever: list[int] = []
        start = scan.scaled.shape[1]
        self.arms = moment_arms(scan.problem, scan.x, robot)
        for j, joint in enumerate(robot.joints):
            if joint.kind != "revolute":
                continue
            order = resolvable_order(q_ctrl[:, j], n_eq)
            if order == 0:
                continue
            template = CyclicError(joint=j, max_order=order, min_order=lowest_order(q_ctrl[:, j]),
                                   q_range=(float(q_ctrl[:, j].min()), float(q_ctrl[:, j].max())))
            block = scan.columns(template)
            if not np.any(block) or not self.arms.allows(j):
                self.short_lever.append(j)
                continue
            self.templates[j] = template
            self.columns[j] = np.arange(start, start + block.shape[1])
            start += block.shape[1]
            blocks.append(block)
        self.n_u = scan.scaled.shape[1]
        a = np.hstack([scan.scaled] + blocks)
        self.a = a
        r = self.residual = scan.residual
        self.fold_rows = list(scan.folds if folds is None else folds)
        """The folds' row masks (the scan's, or the time blocks given)."""
        self.fold_eq = [np.repeat(test, 3) for test in self.fold_rows]
        self.grams = [a[eq].T @ a[eq] for eq in self.fold_eq]
        self.rhs = [a[eq].T @ r[eq] for eq in self.fold_eq]
        self.rr = [float(r[eq] @ r[eq]) for eq in self.fold_eq]
        total = sum(self.grams)
        self.scale = {j: float(np.mean(np.diag(total)[cols])) for j, cols in self.columns.items()}
        self._cache: dict = {}
        self._sums: dict = {}
        self._current: dict = {}
        self._factors = Recent()
        """Factored matrices by (training set, columns, penalties): they depend on the Gram
        matrices only, so :meth:`shifted` copies share them (as ``_fold_grams``, the
        folds' Gram matrices on the columns of the last layouts)."""
        self._fold_grams = Recent(2 * len(self.grams))

    @property
    def joints(self) -> list[int]:
        return list(self.columns)

    def shifted(self, step: np.ndarray) -> "BandScan":
        """This scan with the linearization's residual r moved to ``r + a @ step`` (a the
        columns, current unknowns scaled, then bands): the model with those unknowns
        changed by ``step``, e.g. a named effect set to zero. Shares the Gram matrices."""
        out = copy.copy(self)
        out.residual = self.residual + self.a @ step
        out.rhs = [rhs + gram @ step for rhs, gram in zip(self.rhs, self.grams)]
        out.rr = [rr + 2.0 * float(step @ rhs) + float(step @ gram @ step)
                  for rr, rhs, gram in zip(self.rr, self.rhs, self.grams)]
        out._cache, out._sums, out._current = {}, {}, {}
        return out

    def _layout(self, kept: list[tuple[int, float]], joint: int | None, drop=()):
        """(columns, penalty of the non-candidate columns, number of them); ``drop``:
        columns of the current unknowns left out (a named effect's, when it is
        eliminated)."""
        own = np.setdiff1d(np.arange(self.n_u), np.asarray(drop, dtype=int))
        cols = [own] + [self.columns[j] for j, _ in kept]
        penalty = [np.zeros(len(own))] + [np.full(len(self.columns[j]), lam) for j, lam in kept]
        n_u = sum(len(c) for c in cols)
        if joint is not None:
            cols.append(self.columns[joint])
        return np.concatenate(cols), np.concatenate(penalty), n_u

    def _training(self, excluded: frozenset) -> tuple[np.ndarray, np.ndarray]:
        """Gram matrix and right-hand side of the folds not in ``excluded`` (cached: every
        candidate shares the training sets)."""
        if excluded not in self._sums:
            train = [f for f in range(len(self.grams)) if f not in excluded]
            self._sums[excluded] = (sum(self.grams[f] for f in train),
                                    sum(self.rhs[f] for f in train))
        return self._sums[excluded]

    def _schur(self, key, excluded: frozenset, cols, penalty, n_u) -> ProfiledBand:
        cache_key = (key, excluded)
        if cache_key not in self._cache:
            gram, rhs = self._training(excluded)
            gram = gram[np.ix_(cols, cols)]
            block = ("other", excluded, cols[:n_u].tobytes(), penalty.tobytes())
            factor = self._factors.get_or_make(
                block, lambda: other_block(gram[:n_u, :n_u], penalty))
            self._cache[cache_key] = ProfiledBand(gram, rhs[cols], n_u, factor)
        return self._cache[cache_key]

    def _factored(self, excluded: frozenset, cols: np.ndarray, penalty: np.ndarray
                  ) -> Factored:
        """The training Gram matrix of the folds not in ``excluded`` on ``cols`` plus
        ``diag(penalty)``, factored (cached)."""
        return self._factors.get_or_make(
            (excluded, cols.tobytes(), penalty.tobytes()),
            lambda: Factored(self._training(excluded)[0][np.ix_(cols, cols)] + np.diag(penalty)))

    def _sse(self, fold: int, cols, x: np.ndarray) -> float:
        return self._sses(fold, cols, x[:, None])[0]

    def _sses(self, fold: int, cols, xs: np.ndarray) -> np.ndarray:
        """Held-out sums of squares on ``fold`` of the solutions in the columns of xs."""
        g = self._fold_grams.get_or_make((fold, cols.tobytes()),
                                         lambda: self.grams[fold][np.ix_(cols, cols)])
        return (self.rr[fold] + 2.0 * self.rhs[fold][cols] @ xs
                + np.einsum("ij,ij->j", xs, g @ xs))

    def _heldout(self, fits: list[np.ndarray], cols, sigma2: float) -> Heldout:
        """Held-out residuals (m, 3) of the per-fold solutions ``fits`` in ``cols``: each
        fold's rows moved by its own fit (one product of ``a`` with every fit)."""
        xs = np.zeros((self.a.shape[1], len(fits)))
        for f, x in enumerate(fits):
            xs[cols, f] = x
        moved = self.a @ xs
        out = self.residual.copy()
        for f, eq in enumerate(self.fold_eq):
            out[eq] += moved[eq, f]
        return Heldout(residuals=out.reshape(-1, 3), sigma2=sigma2)

    def _best_lambda(self, key, outer: frozenset, layout, joint: int) -> float:
        """The grid's penalty of least held-out error over the folds not in ``outer``."""
        cols, penalty, n_u = layout
        grid = RIDGE_GRID * self.scale[joint]
        if len(self.grams) - len(outer) < 2:  # no inner folds left (2-fold diagnosis)
            return float(grid[len(grid) // 2])
        sse = np.zeros(len(grid))
        for inner in range(len(self.grams)):
            if inner in outer:
                continue
            schur = self._schur(key, outer | {inner}, cols, penalty, n_u)
            sse += self._sses(inner, cols, np.column_stack([schur.solution(lam)
                                                            for lam in grid]))
        return float(grid[int(np.argmin(sse))])

    def evaluate(self, joint: int, kept: list[tuple[int, float]]
                 ) -> tuple[Heldout, float, float, float]:
        """Nested-CV held-out residuals of the current model plus band ``joint``, the
        penalty ordinary CV chooses on all rows, the band's RMS move of the measured
        points at that penalty (weighted units, as the residuals) and its separability
        from the other columns (:func:`.separability.separability_from_gram`)."""
        layout = self._layout(kept, joint)
        cols, penalty, n_u = layout
        key = (tuple(kept), joint)
        k = len(self.grams)
        fits = []
        for f in range(k):
            lam = self._best_lambda(key, frozenset({f}), layout, joint)
            fits.append(self._schur(key, frozenset({f}), cols, penalty, n_u).solution(lam))
        lam_all = self._best_lambda(key, frozenset(), layout, joint)
        full = self._schur(key, frozenset(), cols, penalty, n_u)
        x = full.solution(lam_all)
        n_eq = len(self.scan.residual)
        rss = sum(self._sse(f, cols, x) for f in range(k))
        sigma2 = rss / max(n_eq - n_u - full.dof(lam_all), 1.0)
        n_band = len(self.columns[joint])
        move = self.a[:, self.columns[joint]] @ x[-n_band:]
        own = n_u - sum(len(self.columns[j]) for j, _ in kept)  # unpenalized columns
        share, _ = separability_from_gram(self._training(frozenset())[0], cols[:own],
                                          cols[n_u:], x[n_u:])
        return (self._heldout(fits, cols, sigma2), lam_all,
                float(np.sqrt(3 * np.mean(move**2))), share)

    def gain_test(self, reference: Heldout, candidate: Heldout,
                  kept: list[tuple[int, float]], drop=()) -> tuple[float, float, float]:
        """(gain, z, p) as :meth:`.effect_scan.EffectScan.gain_test`, with the leverage of
        the test rows under the current model's own fit (the geometry and the kept bands
        at their penalties: ``A_t (G_T + P)^-1 A_t'``), which the held-out residuals of a
        model with bands carry; ``drop``: the reference's left-out columns (see
        :meth:`current`)."""
        cols, penalty, _ = self._layout(kept, None, drop)
        delta = (reference.residuals - candidate.residuals).ravel()
        gain = reference.sse - candidate.sse
        per_fold = np.zeros((len(delta), len(self.fold_eq)))
        for f, eq in enumerate(self.fold_eq):
            per_fold[eq, f] = delta[eq]
        v_all = (self.a.T @ per_fold)[cols]  # A_t' delta_t of every fold t
        leverage = 0.0
        for f in range(len(self.fold_eq)):
            v = v_all[:, f]
            leverage += float(v @ self._factored(frozenset({f}), cols, penalty).solve(v))
        variance = 4.0 * candidate.sigma2 * (float(delta @ delta) + leverage)
        if variance <= 0:
            return gain, 0.0, 1.0
        z = gain / np.sqrt(variance)
        return float(gain), float(z), float(stats.norm.sf(z))

    def current(self, kept: list[tuple[int, float]], drop=()) -> tuple[Heldout, np.ndarray]:
        """Held-out residuals of the current model with the kept bands at their penalties,
        and its full-data solution (the columns of ``_layout(kept, None, drop)``);
        ``drop``: columns of the current unknowns (``scan.scaled``) left out."""
        key = (tuple(kept), np.unique(np.asarray(drop, dtype=int)).tobytes())
        if key not in self._current:
            cols, penalty, n_u = self._layout(kept, None, drop)
            fits = [-self._factored(frozenset({f}), cols, penalty).solve(
                self._training(frozenset({f}))[1][cols]) for f in range(len(self.grams))]
            x = -self._factored(frozenset(), cols, penalty).solve(
                self._training(frozenset())[1][cols])
            self._current[key] = self._fitted(cols, n_u, fits, x)
        return self._current[key]

    def _fitted(self, cols: np.ndarray, n_u: int, fits: list[np.ndarray], x: np.ndarray
               ) -> tuple[Heldout, np.ndarray]:
        """(held-out residuals, x) of the per-fold solutions ``fits`` and the full-data
        solution ``x`` in ``cols`` (the first ``n_u`` of them fitted: the noise estimate's
        degrees of freedom), as :meth:`current` returns them."""
        rss = sum(self._sse(f, cols, x) for f in range(len(self.grams)))
        dof = len(self.scan.residual) - n_u
        return self._heldout(fits, cols, rss / max(dof, 1)), x


def scan_bands(scan: EffectScan, robot: Robot, q_ctrl: np.ndarray, alpha: float,
               folds=None) -> BandOutcome:
    """Add the significant bands one at a time, the one of least held-out error first,
    until no other band lowers the held-out error significantly (alpha / K, K the bands
    tested in the round); see the module docstring. ``folds``: row masks in place of the
    scan's (time blocks, :mod:`.time_blocks`)."""
    bands = BandScan(scan, robot, q_ctrl, folds)
    outcome = BandOutcome(short_lever=list(bands.short_lever), scan=bands)
    kept: list[tuple[int, float]] = []
    base, _ = bands.current(kept)
    held_of: dict[int, Heldout] = {}
    while len(kept) < len(bands.joints):
        results = []
        base_rms = np.sqrt(base.sse / len(base.residuals))  # 3-D RMS per row, weighted
        for j in bands.joints:
            if j in dict(kept):
                continue
            held, lam, move, share = bands.evaluate(j, kept)
            gain, z, p = bands.gain_test(base, held, kept)
            held_of[j] = held
            results.append(BandResult(effect=bands.templates[j], gain=gain / base.sse, z=z,
                                      p_value=p, ridge=lam, moves=float(move / base_rms),
                                      moves_m=float(move), separability=share,
                                      base_rms_m=float(base_rms)))
        if not results:
            break
        threshold = alpha / len(results)
        results = [dataclasses.replace(r, significant=bool(r.p_value < threshold
                                                           and r.moves <= MAX_MOVES))
                   for r in results]
        outcome.rounds.append(results)
        outcome.thresholds.append(threshold)
        significant = [r for r in results if r.significant]
        if not significant:
            break
        best = min(significant, key=lambda r: held_of[r.effect.joint].sse)
        kept.append((best.effect.joint, best.ridge))
        outcome.p_values.append(best.p_value)
        outcome.heldout = held_of[best.effect.joint]
        # the next bands are tested against the kept ones at the penalty they keep
        base, _ = bands.current(kept)
    if not kept:
        return outcome
    _, x = bands.current(kept)
    # the other unknowns again, given the bands, by the minimum-norm least squares: a
    # direction the data cannot see (a reflector on axis 6 makes some) must not move, or
    # the non-linear model leaves the linearization (118 mm off on a real arm's data)
    cols = np.concatenate([bands.columns[j] for j, _ in kept])
    outcome.rhs = -(scan.residual + bands.a[:, cols] @ x[bands.n_u:])
    outcome.bands = band_effects(bands, kept, x)
    return outcome


def band_effects(bands: BandScan, kept: list[tuple[int, float]], x: np.ndarray
                 ) -> list[CyclicError]:
    """The kept bands with their values in the solution ``x`` of ``bands.current(kept)``
    (band columns in rad, after the ``bands.n_u`` current unknowns)."""
    out, at = [], bands.n_u
    for j, lam in kept:
        n, template = len(bands.columns[j]), bands.templates[j]
        out.append(CyclicError(joint=j, values=tuple(x[at:at + n]),
                               max_order=template.max_order, min_order=template.min_order,
                               q_range=template.q_range, ridge=lam))
        at += n
    return out


STEP_RCONDS = (1e-9, 1e-6, 1e-4, 1e-3, 1e-2, 1e-1)
"""Truncations tried for the step of the other unknowns (relative singular values)."""


def _moved(scan: EffectScan, cal, du: np.ndarray, bands: list[CyclicError]):
    """(values, device_T_base, tools, effects) of the scan's model moved by ``du`` (the
    scan's kept unknowns) with the bands appended."""
    x = scan.x.copy()
    x[scan.kept] += du
    problem = scan.problem
    values, pose, tools = problem.unpack(x)
    effects = tuple(e.with_values(v, e.std) for e, v in
                    zip(problem.effects, problem.effect_values(x))) + tuple(bands)
    points = {name: dataclasses.replace(cal.tools[name], xyz_m=tools[k])
              for k, name in enumerate(problem.tool_names)}
    return values, pose, points, effects


def apply_bands(result: IdentificationResult, scan: EffectScan,
                outcome: BandOutcome) -> IdentificationResult:
    """``result`` with the band scan's full-data solution: the bands appended to the
    effects, the current unknowns moved by the linear step that takes up ``outcome.rhs``
    (minimum norm, truncated until the non-linear model agrees with the linear one: steps
    along directions the data barely see left a real arm's model 0.6 m off), and the
    held-out figures of the band scan's final cross-validation."""
    cal, best = result.calibration, None
    for rcond in STEP_RCONDS:
        step = np.linalg.lstsq(scan.scaled, outcome.rhs, rcond=rcond)[0]
        linear = float(np.sqrt(np.mean((outcome.rhs - scan.scaled @ step) ** 2)))
        moved = _moved(scan, cal, step / scan.norms, outcome.bands)
        problem, x = problem_at(dataclasses.replace(
            cal, values=moved[0], device_T_base=moved[1], tools=moved[2], effects=moved[3]),
            scan.meas, scan.inputs)
        actual = float(np.sqrt(np.mean(problem.residuals(x) ** 2)))
        if best is None or actual < best[0]:
            best = (actual, moved)
        if actual <= 1.05 * linear + 1e-9:
            break
    values, pose, points, effects = best[1]
    errors = np.linalg.norm(outcome.heldout.residuals, axis=1)
    rms, worst = float(np.sqrt(np.mean(errors**2))), float(errors.max())
    validation = cal.validation
    if validation is not None:
        validation = dataclasses.replace(
            validation, heldout_rms_mm=rms * 1e3, heldout_max_mm=worst * 1e3,
            method=f"{len(scan.folds)}-fold cross-validation by pose (linearized, "
                   f"cyclic bands' penalty by nested cross-validation)")
    calibration = dataclasses.replace(cal, values=values, device_T_base=pose, tools=points,
                                      effects=effects, validation=validation)
    return dataclasses.replace(result, calibration=calibration, heldout_rms=rms,
                               heldout_max=worst, heldout_errors=errors)


SOURCES = {1: "eccentricity of the output bearing or of the encoder disc",
           2: "ellipticity of a strain-wave (harmonic drive) gear or of the encoder"}


def dominant_orders(effect: CyclicError, count: int = 2) -> list[int]:
    """The ``count`` orders of largest fitted amplitude, strongest first."""
    return [int(effect.orders[k]) for k in np.argsort(-effect.amplitudes())[:count]]


def order_resolution(effect: CyclicError) -> float:
    """How far apart (cycles per turn) two orders must be to be told apart over the span
    the band was fitted on: 360 deg / span (over a half turn, orders k and k + 1 differ by
    half a cycle: the fit can share one's amplitude with the other)."""
    span = effect.q_range[1] - effect.q_range[0]
    return float(2 * np.pi / span) if span > 0 else float("inf")


def band_text(effect: CyclicError) -> str:
    """'joint j: cyclic angle error, dominant orders k1, k2 (periods), amplitude' with the
    orders' likely sources as hypotheses and the order resolution of the span."""
    orders = dominant_orders(effect)
    amplitude = effect.amplitudes()
    periods = ", ".join(f"{k} ({360 / k:.1f} deg)" for k in orders)
    sources = "; ".join(SOURCES.get(k, f"order {k}: a gear stage turning {k} times per "
                                       f"turn of the joint, or the encoder's {k}-per-turn "
                                       f"error") for k in orders)
    lo, hi = np.degrees(effect.q_range)
    return (f"joint {effect.joint + 1}: cyclic angle error, dominant orders {periods}, "
            f"amplitude {np.degrees(amplitude[orders[0] - effect.min_order]) * 1e3:.3g} mdeg "
            f"(orders {effect.min_order}-{effect.max_order}: "
            f"{np.degrees(effect.headline()[0]) * 1e3:.3g} "
            f"mdeg); orders closer than {order_resolution(effect):.1f} are not resolved over "
            f"the span; valid for q{effect.joint + 1} in [{lo:.1f}, {hi:.1f}] deg; "
            f"likely sources (hypotheses): {sources}")
