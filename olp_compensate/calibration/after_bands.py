"""The classic candidates scanned forward again once the cyclic bands are in (issue 28).

The effect scan (:mod:`.effect_scan`) runs before the bands. On an arm with a strong
cyclic error of one joint the residual is dominated by it, a weaker backlash of another
joint is not significant against it, and the band scan then lets a high-order band of
that other joint stand in for the backlash (a 6x-noise backlash of joint 3 beside a
12x-noise cyclic error of joint 2 was never named). So, with the bands in:

1. every classic candidate not named yet (the list of :func:`.effect_scan.candidate_effects`
   that the data can separate from the geometry) is added at zero to the current model;
2. at that model's linearization, with the kept bands refitted at the penalties they keep,
   on the bands' folds (time blocks with ``time_s``), each candidate in turn is fitted
   unpenalized beside them, and its held-out gain over the model without any candidate
   tested by the z-test of :meth:`.cyclic_scan.BandScan.gain_test`, significant below
   alpha / K (K the candidates tested), as in the forward scan;
3. the significant one of least held-out error is returned; the caller adds it, refits,
   scans the bands again and runs the backward elimination (:mod:`.backward_elimination`).
   As in the forward scan it is named only when separable (:mod:`.separability`) from the
   unpenalized columns (the geometry and the named effects: a penalized band's span holds
   a fair copy of a backlash step, and the band is tested again once the candidate is in)
   and significantly better than every significant candidate that is not; else it is a
   predictive term, not named (``AfterBandsRound.unnamed``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .cyclic_scan import BandOutcome, BandScan
from .effect_scan import EffectScan
from .effects import Effect
from .identifiability import effect_separation
from .separability import Refusal, separability_from_gram, separable


STAGE = "effect scan after the bands"


@dataclass(frozen=True)
class AfterBandsCandidate:
    """One candidate of a round after the bands: share of the held-out sum of squares it
    removes (``gain``), ``z``, ``p``, separability, RMS move (m) and significance."""

    effect: Effect
    gain: float
    z: float
    p_value: float
    separability: float
    moves_m: float
    significant: bool = False


@dataclass
class AfterBandsRound:
    """A round of the scan after the bands: its threshold, candidates and choice."""

    threshold: float
    candidates: list[AfterBandsCandidate] = field(default_factory=list)
    chosen: Effect | None = None
    unnamed: Refusal | None = None
    """Why the chosen candidate, kept in the model, is not named (None: named)."""

    @property
    def refused(self) -> list[Refusal]:
        """The significant candidates that are not separable (kept or not)."""
        return [Refusal(label=c.effect.label, kind=c.effect.kind, joint=c.effect.joint,
                        stage=STAGE, p_value=c.p_value, separability=c.separability,
                        moves_m=c.moves_m, gain=c.gain)
                for c in self.candidates
                if c.p_value < self.threshold and not separable(c.separability)]


def _with_candidates(scan: EffectScan, effects: list[Effect]) -> EffectScan:
    """The effect scan of the scan's model with ``effects`` appended at zero."""
    result = scan.result
    zeros = tuple(e.with_values(np.zeros(e.n_parameters)) for e in effects)
    calibration = dataclasses.replace(result.calibration,
                                      effects=tuple(result.calibration.effects) + zeros)
    return EffectScan(dataclasses.replace(result, calibration=calibration), scan.meas,
                      scan.inputs, scan.folds)


@dataclass(frozen=True)
class _BandsWithCandidates:
    """The band scan of the scan's model with ``effects`` appended at zero: ``own[i]``, the
    positions of effect i's columns among the kept unknowns; ``every``, all of them;
    ``kept``, the kept bands as (joint, ridge)."""

    band_scan: BandScan
    own: list[np.ndarray]
    every: np.ndarray
    kept: list[tuple[int, float]]


def _bands_with(scan: EffectScan, bands: BandOutcome, effects: list[Effect],
                robot) -> _BandsWithCandidates:
    wide = _with_candidates(scan, effects)
    positions = np.arange(len(wide.x))
    n_old = len(wide.problem.layout.effects) - len(effects)
    own = [np.flatnonzero(np.isin(wide.kept, positions[cols]))
           for cols in wide.problem.layout.effects[n_old:]]
    return _BandsWithCandidates(BandScan(wide, robot, scan.inputs.q, bands.scan.fold_rows),
                                own, np.concatenate(own),
                                [(b.joint, b.ridge) for b in bands.bands])


def scan_after_bands(scan: EffectScan, bands: BandOutcome, candidates: list[Effect],
                     robot, alpha: float, prefer_simpler_alpha: float = 0.05
                     ) -> AfterBandsRound | None:
    """One round of the module docstring at the scan's model with the kept ``bands``;
    None when no candidate can be tested. As in the forward scan, the chosen candidate is
    not named when it is not separable, or when the data cannot tell it from a
    significant inseparable one (not significantly better than it at
    ``prefer_simpler_alpha``)."""
    named = {e.key for e in scan.problem.effects}
    testable = [c for c in candidates if c.key not in named
                and effect_separation(scan.jac, scan.columns(c), scan.names) is None]
    if not testable or not bands.bands:
        return None
    setup = _bands_with(scan, bands, testable, robot)
    band_scan, own, every, kept = setup.band_scan, setup.own, setup.every, setup.kept
    n_bands = sum(len(band_scan.columns[j]) for j, _ in kept)
    reference, _ = band_scan.current(kept, every)
    gram = band_scan._training(frozenset())[0]
    out = AfterBandsRound(threshold=alpha / len(testable))
    held_of = {}
    for effect, cols in zip(testable, own):
        drop = np.setdiff1d(every, cols)
        held, x = band_scan.current(kept, drop)
        gain, z, p = band_scan.gain_test(reference, held, kept, every)
        layout, _, _ = band_scan._layout(kept, None, drop)
        at = np.flatnonzero(np.isin(layout, cols))
        unpenalized = np.setdiff1d(layout[:len(layout) - n_bands], layout[at])
        share, _ = separability_from_gram(gram, unpenalized, layout[at], x[at])
        motion = band_scan.a[:, layout[at]] @ x[at]
        candidate = AfterBandsCandidate(
            effect=effect, gain=gain / max(reference.sse, 1e-300), z=z, p_value=p,
            separability=share, moves_m=float(np.sqrt(3.0 * np.mean(motion**2))))
        out.candidates.append(dataclasses.replace(candidate, significant=bool(p < out.threshold)))
        held_of[effect.key] = (held, drop)
    significant = [c for c in out.candidates if c.significant]
    if not significant:
        return out
    chosen = min(significant, key=lambda c: held_of[c.effect.key][0].sse)
    out.chosen = chosen.effect
    held, _ = held_of[chosen.effect.key]
    n = max(len(reference.residuals), 1)
    fields = dict(label=chosen.effect.label, kind=chosen.effect.kind, joint=chosen.effect.joint,
                  stage=STAGE, p_value=chosen.p_value, separability=chosen.separability,
                  moves_m=chosen.moves_m, gain=chosen.gain,
                  gain_m=float(np.sqrt(reference.sse / n) - np.sqrt(held.sse / n)))
    confounded = [r for r in significant if r is not chosen and not separable(r.separability)
                  and band_scan.gain_test(held_of[r.effect.key][0], held, kept,
                                          held_of[r.effect.key][1])[2] >= prefer_simpler_alpha]
    if not separable(chosen.separability):
        out.unnamed = Refusal(**fields)
    elif confounded:
        out.unnamed = Refusal(**fields, confounded_with=confounded[0].effect.label)
    return out


def confounded_bands(scan: EffectScan, bands: BandOutcome, inseparable: list[Effect], robot,
                     prefer_simpler_alpha: float = 0.05) -> list[Refusal]:
    """The kept bands the data cannot tell from a significant inseparable effect that is
    not in the model (``inseparable``): the model with the band is not significantly
    better (``prefer_simpler_alpha``) than the same model with that effect, unpenalized,
    in its place (on a joint-by-joint sweep the geometry absorbs a compliance of joint 3,
    and bands of joints 2 and 3 can take its gain). Such a band stays in the model, not
    named; the refusal's ``confounded_with`` names the effect."""
    named = {e.key for e in scan.problem.effects}
    effects = [e for e in inseparable if e.key not in named]
    if not effects or not bands.bands:
        return []
    setup = _bands_with(scan, bands, effects, robot)
    band_scan, own, every, kept = setup.band_scan, setup.own, setup.every, setup.kept
    with_bands, _ = band_scan.current(kept, every)
    out = []
    for band, p_band in zip(bands.bands, bands.p_values):
        rest = [k for k in kept if k[0] != band.joint]
        for effect, cols in zip(effects, own):
            drop = np.setdiff1d(every, cols)
            instead, _ = band_scan.current(rest, drop)
            p = band_scan.gain_test(instead, with_bands, rest, drop)[2]
            if p >= prefer_simpler_alpha:
                out.append(Refusal(label=band.label, kind=band.kind, joint=band.joint,
                                   stage="cyclic bands", p_value=p_band,
                                   separability=float("nan"), moves_m=float("nan"),
                                   confounded_with=effect.label))
                break
    return out


def after_bands_entry(rounds: list[AfterBandsRound]) -> list[dict]:
    """The d.json key ``effect_scan_after_bands``: one entry per round."""
    return [{"threshold": r.threshold, "chosen": None if r.chosen is None else r.chosen.label,
             "chosen_named": r.chosen is not None and r.unnamed is None,
             "candidates": [{"effect": c.effect.label, "kind": c.effect.kind,
                             "joint": None if c.effect.joint is None else c.effect.joint + 1,
                             "heldout_gain": c.gain, "z": c.z, "p_value": c.p_value,
                             "separability": c.separability, "significant": c.significant}
                            for c in r.candidates]} for r in rounds]


def after_bands_lines(rounds: list[AfterBandsRound]) -> list[str]:
    """The text summary's lines: one per round after the bands."""
    lines = []
    for number, r in enumerate(rounds, 1):
        best = sorted(r.candidates, key=lambda c: c.p_value)[:3]
        tested = ", ".join(f"{c.effect.label} ({100 * c.gain:.1f} %, p = {c.p_value:.1e})"
                           for c in best)
        verdict = ("no further term is significant" if r.chosen is None
                   else f"kept {r.chosen.label}" if r.unnamed is None
                   else "kept a predictive term, not named (below)")
        lines.append(f"effect scan after the bands, round {number} (threshold "
                     f"{r.threshold:.1e}; best: {tested}): {verdict}")
    return lines
