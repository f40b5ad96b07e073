"""The scan of :func:`olp_compensate.calibration.diagnose.diagnose`: candidate effects
cross-validated against the current model, linearized at its full-data solution, and the
test of their held-out gain (see the diagnose module's docstring, steps 3-5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from .effects import (Backlash, Effect, EffectInputs, GearHarmonic, JointCompliance,
                      JointScale, ThermalExpansion)
from .identifiability import effect_separation
from .identify import IdentificationResult
from .problem import problem_at
from .separability import Refusal, separability, separable
from .measurements import Measurements
from ..kinematics.robot import Robot


@dataclass(frozen=True)
class CandidateResult:
    """One candidate in one round: ``status`` 'tested', 'no effect' or 'inseparable' (with
    ``reason``); for tested ones the held-out sum of squares (m^2) of the extended model,
    the share of the current model's held-out sum of squares it removes (``gain``), the
    test statistic ``t`` (z) and its one-sided p-value."""

    effect: Effect
    status: str
    reason: str = ""
    heldout_sse: float = float("nan")
    gain: float = float("nan")
    t: float = float("nan")
    p_value: float = float("nan")
    significant: bool = False
    separability: float = float("nan")
    """Share of the fitted effect's motion distinct from the current model's columns
    (:mod:`.separability`); below ``MIN_SEPARABILITY`` it is not named."""
    moves_m: float = float("nan")
    """RMS per measured point of the fitted effect's motion, m (weighted units)."""




def _kept_columns(jac: np.ndarray) -> np.ndarray:
    norms = np.linalg.norm(jac, axis=0)
    return norms > 1e-12 * norms.max()


@dataclass(frozen=True)
class Heldout:
    """Held-out residuals (m, 3) of one linearized model and its in-sample noise estimate
    (per-axis variance, m^2)."""

    residuals: np.ndarray
    sigma2: float
    solution: np.ndarray | None = None
    """The full-data solution of the fit (unit-scaled columns), when computed."""

    @property
    def sse(self) -> float:
        return float(np.sum(self.residuals**2))


class EffectScan:
    """Linearized k-fold cross-validation of candidates at one model.

    State: the current model's residual r (3m,) and unit-scaled Jacobian J at its full-data
    solution, and per fold the SVD of the training rows of J (for the leverage term of the
    test's variance)."""

    def __init__(self, result: IdentificationResult, meas: Measurements, inputs: EffectInputs,
                 folds: list[np.ndarray]):
        problem, x = problem_at(result.calibration, meas, inputs)
        self.problem, self.x = problem, x
        self.residual, jac = problem.residuals_and_jacobian(x)
        kept = _kept_columns(jac)
        self.kept = np.flatnonzero(kept)
        """Positions in the unknown vector ``x`` of the columns of ``jac``."""
        self.jac = jac[:, kept]
        self.names = [n for n, k in zip(problem.names(), kept) if k]
        self.norms = np.linalg.norm(self.jac, axis=0)
        self.scaled = self.jac / self.norms
        self.meas, self.inputs, self.result, self.folds = meas, inputs, result, folds
        self.training = []
        for test in folds:
            eq = np.repeat(test, 3)
            _, s, vt = np.linalg.svd(self.scaled[~eq], full_matrices=False)
            ok = s > 1e-10 * s[0]
            self.training.append((eq, vt[ok], s[ok]))
        self.base = self.heldout(self.scaled)

    def heldout(self, jac: np.ndarray) -> Heldout:
        """Held-out residuals of r + jac dx refitted without each fold (jac scaled)."""
        out = np.empty(len(self.residual))
        for eq, _, _ in self.training:
            dx, *_ = np.linalg.lstsq(jac[~eq], -self.residual[~eq], rcond=1e-10)
            out[eq] = self.residual[eq] + jac[eq] @ dx
        dx, *_ = np.linalg.lstsq(jac, -self.residual, rcond=1e-10)
        rss = float(np.sum((self.residual + jac @ dx) ** 2))
        return Heldout(residuals=out.reshape(-1, 3),
                       sigma2=rss / max(len(self.residual) - jac.shape[1], 1), solution=dx)

    def separability(self, unit_block: np.ndarray, values: np.ndarray) -> tuple[float, float]:
        """(separability, RMS move per point) of the effect of unit-scaled columns
        ``unit_block`` at ``values`` beside the current model's columns."""
        if getattr(self, "_basis", None) is None:
            self._basis = np.linalg.qr(self.scaled)[0]
        motion = unit_block @ values
        moves = float(np.sqrt(3.0 * np.mean(motion**2)))
        return separability(self._basis, motion), moves

    def gain_test(self, reference: Heldout, candidate: Heldout) -> tuple[float, float, float]:
        """(gain, z, p): the held-out gain G = SSE(reference) - SSE(candidate), m^2, and the
        one-sided test of G > 0. Given the training folds, G = sum(2 e.D - |D|^2) over the
        held-out rows, D the change of prediction and e the reference's held-out residual,
        whose covariance is sigma^2 (I + H), H the test rows' leverage under the reference
        fit; so var(G) = 4 sigma^2 (|D|^2 + D'HD), with sigma^2 from the candidate's
        in-sample residual (a safe value under either hypothesis)."""
        delta = (reference.residuals - candidate.residuals).ravel()
        gain = reference.sse - candidate.sse
        leverage = 0.0
        for eq, vt, s in self.training:
            leverage += float(np.sum(((vt @ (self.scaled[eq].T @ delta[eq])) / s) ** 2))
        variance = 4.0 * candidate.sigma2 * (float(delta @ delta) + leverage)
        if variance <= 0:
            return gain, 0.0, 1.0
        z = gain / np.sqrt(variance)
        return float(gain), float(z), float(stats.norm.sf(z))

    def columns(self, effect: Effect) -> np.ndarray:
        """Jacobian columns (3m, p) of ``effect`` added at zero to the current model."""
        problem, x = problem_at(self.result.calibration, self.meas, self.inputs, [effect])
        _, jac = problem.residuals_and_jacobian(x)
        return jac[:, problem.layout.effects[-1]]

    def evaluate(self, effect: Effect) -> tuple[CandidateResult, Heldout | None]:
        """The candidate's result and its held-out residuals (None when not testable)."""
        block = self.columns(effect)
        reason = effect_separation(self.jac, block, self.names)
        if reason is not None:
            status = "no effect" if reason.startswith("has no effect") else "inseparable"
            return CandidateResult(effect=effect, status=status, reason=reason), None
        unit = block / np.linalg.norm(block, axis=0)
        held = self.heldout(np.hstack([self.scaled, unit]))
        gain, z, p = self.gain_test(self.base, held)
        share, moves = self.separability(unit, held.solution[-unit.shape[1]:])
        return CandidateResult(effect=effect, status="tested", heldout_sse=held.sse,
                               gain=gain / self.base.sse, t=z, p_value=p,
                               separability=share, moves_m=moves), held


def candidate_effects(robot: Robot, has_temperature: bool) -> list[Effect]:
    """Every term the diagnosis tries: compliance, backlash, harmonics of order 1-3 and
    scale on each revolute axis, and thermal expansion when temperatures were measured
    (the cyclic error bands are scanned apart, :mod:`.cyclic_scan`)."""
    out: list[Effect] = []
    for j, joint in enumerate(robot.joints):
        if joint.kind != "revolute":
            continue
        out += [JointCompliance(joint=j), Backlash(joint=j), JointScale(joint=j)]
        out += [GearHarmonic(joint=j, order=k) for k in (1, 2, 3)]
    if has_temperature:
        out.append(ThermalExpansion())
    return out


def choose_candidate(scan: EffectScan, tested: list[tuple[CandidateResult, Heldout]],
                     threshold: float, prefer_simpler_alpha: float):
    """(chosen candidate or None, labels of the alternatives); see the module docstring."""
    significant = [item for item in tested if item[0].p_value < threshold]
    if not significant:
        return None, []
    best = min(significant, key=lambda item: item[1].sse)

    def not_better(item, than) -> bool:
        """``item`` is not significantly better than ``than`` on held-out data."""
        return scan.gain_test(than[1], item[1])[2] >= prefer_simpler_alpha

    simpler = [item for item in significant
               if item[0].effect.n_parameters < best[0].effect.n_parameters
               and not_better(best, item)]
    chosen = (min(simpler, key=lambda it: (it[0].effect.n_parameters, it[1].sse))
              if simpler else best)
    alternatives = [c.effect.label for c, held in significant
                    if c is not chosen[0] and not_better(chosen, (c, held))]
    return chosen[0], alternatives


def heldout_rms_drop(reference: Heldout, candidate: Heldout) -> float:
    """How much the held-out RMS (3-D per row, m, weighted as the fit) falls from
    ``reference`` to ``candidate``."""
    n = max(len(reference.residuals), 1)
    return float(np.sqrt(reference.sse / n) - np.sqrt(candidate.sse / n))


def naming_refusal(scan: EffectScan, tested: list, chosen: CandidateResult, threshold: float,
                   prefer_simpler_alpha: float, stage: str) -> Refusal | None:
    """Why the ``chosen`` candidate, kept in the model, is not named (None: it is named).
    Not named when it is not separable (:mod:`.separability`), or when the data cannot
    tell it from a significant candidate that is not (it is not significantly better than
    it, :meth:`EffectScan.gain_test` at ``prefer_simpler_alpha``: it may be that one's
    proxy). The refusal carries its held-out gain (share and RMS drop, m)."""
    held = next(h for r, h in tested if r is chosen)
    fields = dict(label=chosen.effect.label, kind=chosen.effect.kind, joint=chosen.effect.joint,
                  stage=stage, p_value=chosen.p_value, separability=chosen.separability,
                  moves_m=chosen.moves_m, gain=chosen.gain,
                  gain_m=heldout_rms_drop(scan.base, held))
    if not separable(chosen.separability):
        return Refusal(**fields)
    confounded = [r for r, h in tested if r is not chosen and r.p_value < threshold
                  and not separable(r.separability)
                  and scan.gain_test(h, held)[2] >= prefer_simpler_alpha]
    if confounded:
        return Refusal(**fields, confounded_with=confounded[0].effect.label)
    return None


def drift_warning(scan: EffectScan, alpha: float) -> str | None:
    """A warning when the residuals drift with ``time_s`` (the device or the base moved, or
    the arm warmed up), tested like a candidate; None when they do not (or no time)."""
    time = scan.meas.time_s
    if time is None or np.ptp(time) == 0:
        return None
    block = np.zeros((scan.meas.n_rows, 3, 3))
    for axis in range(3):
        block[:, axis, axis] = time - time.mean()
    block = block.reshape(-1, 3)
    held = scan.heldout(np.hstack([scan.scaled, block / np.linalg.norm(block, axis=0)]))
    _, _, p = scan.gain_test(scan.base, held)
    if p >= alpha:
        return None
    temperature = scan.meas.temperature_c
    advice = ("add a temperature_c column" if temperature is None else
              "the temperature_c column does not explain it" if np.ptp(temperature) > 0 else
              "the temperature_c column is constant")
    return (f"the remaining residuals drift with time_s (p = {p:.1e}): the device or the "
            f"robot base moved, or the arm warmed up; {advice}")
