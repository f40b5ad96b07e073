"""Backward elimination of the named effects once the cyclic bands are in (issue 28).

The effect scan (:mod:`.effect_scan`) runs before the cyclic bands (:mod:`.cyclic_scan`):
a backlash (a step in the sign of a gravity torque) or a gear harmonic of order 1-3 is
then tested against the geometry alone, and on an arm whose real error is a cyclic error
of tens of orders it proxies part of it (the replica of the issue's arm,
benchmarks/issue_arm.py, named a backlash and a harmonic k=1 of joint 2 it does not
have). Once the bands are in, every effect the forward scan kept is tested again:

1. at the band scan's linearization (the current model's full-data solution, the bands'
   columns at the penalties they keep, the bands' folds: time blocks with ``time_s``),
   each remaining effect is set to zero (the residual moved by its columns times its
   fitted values) and its columns left out in turn, and the held-out residuals of
   the model without it are compared with those of the model with it, by the z-test of
   :meth:`.cyclic_scan.BandScan.gain_test` (the forward scan's held-out criterion);
2. an effect whose gain is not significant at the threshold of the forward round that
   kept it (alpha / K, K the candidates of that round) is no longer needed; the least
   needed (largest p) is dropped and step 1 repeated on the rest;
3. when something was dropped, the geometry and the remaining effects are refitted
   (non-linear) and the bands scanned again at that model; the elimination repeats there
   until no effect is dropped.

Without a kept band there is nothing new to test against: the forward scan's choice
stands.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .cross_validation import time_blocked_folds
from .cyclic_scan import BandOutcome, BandScan, apply_bands
from .effect_scan import EffectScan
from .effects import Effect
from .identify import IdentificationResult, identify
from .after_bands import AfterBandsRound, confounded_bands, scan_after_bands
from .separability import Refusal
from .time_blocks import BlockedFigures, scan_bands_blocked


@dataclass(frozen=True)
class EliminationStep:
    """One named effect tested with the bands in: ``gain`` (share of the held-out sum of
    squares of the model without it that it removes), ``z`` and ``p`` of the test, the
    ``threshold`` it must beat (its forward round's alpha / K) and whether it was
    ``dropped``; ``round`` numbers the elimination rounds from 1."""

    effect: Effect
    round: int
    gain: float
    z: float
    p_value: float
    threshold: float
    dropped: bool


@dataclass
class BandStage:
    """What follows the effect scan: the model of the named effects that survive
    (``current``, its linearization ``scan``), the model with the bands (``extended``),
    the band scan, its time-blocked figures, and the elimination's steps."""

    current: IdentificationResult
    scan: EffectScan
    extended: IdentificationResult
    bands: BandOutcome | None = None
    blocked: BlockedFigures | None = None
    steps: list[EliminationStep] = field(default_factory=list)
    refused: list[Refusal] = field(default_factory=list)
    """Effects significant in the scan after the bands but not separable."""
    after_bands: list[AfterBandsRound] = field(default_factory=list)
    """The rounds of the classic candidates scanned again with the bands in."""
    added: list[tuple[Effect, float, Refusal | None]] = field(default_factory=list)
    """Effects kept by those rounds, in the order added: (effect, p-value, why it is not
    named or None)."""
    confounded: list[Refusal] = field(default_factory=list)
    """Kept bands the data cannot tell from a significant inseparable effect not in the
    model (:func:`.after_bands.confounded_bands`): kept, not named."""

    @property
    def dropped(self) -> list[Effect]:
        return [s.effect for s in self.steps if s.dropped]


def effect_columns(scan: EffectScan) -> list[np.ndarray]:
    """Per effect of the scan's model, its columns in ``scan.scaled``."""
    positions = np.arange(len(scan.x))
    return [np.flatnonzero(np.isin(scan.kept, positions[cols]))
            for cols in scan.problem.layout.effects]


def eliminate(bands: BandScan, kept: list[tuple[int, float]], effects: list[Effect],
              thresholds: list[float], first_round: int = 1) -> list[EliminationStep]:
    """The linear elimination (steps 1-2 of the module docstring) at the band scan
    ``bands`` with the kept bands ``kept`` ((joint, penalty)); ``effects``/``thresholds``:
    the scan model's effects in its layout's order and the threshold each must beat."""
    scan = bands.scan
    columns = effect_columns(scan)
    active = list(range(len(effects)))
    gone: list[int] = []
    steps: list[EliminationStep] = []
    number = first_round

    def without(removed: list[int]) -> tuple[BandScan, np.ndarray]:
        """The band scan of the model with the effects ``removed`` set to zero (the
        linearization's residual moved accordingly) and their columns left out."""
        step = np.zeros(bands.a.shape[1])
        drop = np.concatenate([columns[i] for i in removed] + [np.zeros(0, int)])
        step[drop] = -scan.x[scan.kept[drop]] * scan.norms[drop]
        return bands.shifted(step), drop

    while active:
        at_full, drop_all = without(gone)
        full, _ = at_full.current(kept, drop_all)
        tested = []
        for i in active:
            at_reduced, drop = without(gone + [i])
            reduced, _ = at_reduced.current(kept, drop)
            gain, z, p = bands.gain_test(reduced, full, kept, drop)
            tested.append((i, gain / max(reduced.sse, 1e-300), z, p))
        unneeded = [t for t in tested if not t[3] < thresholds[t[0]]]
        worst = max(unneeded, key=lambda t: t[3])[0] if unneeded else None
        steps += [EliminationStep(effect=effects[i], round=number, gain=float(g), z=float(z),
                                  p_value=float(p), threshold=thresholds[i],
                                  dropped=i == worst) for i, g, z, p in tested]
        if worst is None:
            break
        active.remove(worst)
        gone.append(worst)
        number += 1
    return steps


def _bands(scan: EffectScan, robot, meas, inputs, options, folds_k: int):
    """(band outcome, time-blocked figures) at the scan's model."""
    blocks = (time_blocked_folds(meas.time_s, meas.pose_ids, folds_k)
              if options.time_blocks else None)
    return scan_bands_blocked(scan, robot, inputs.q, options, blocks)


def band_stage(robot, meas, inputs, scan: EffectScan, effects: list[Effect],
               thresholds: list[float], options, base_options,
               candidates: list[Effect] = (), inseparable: list[Effect] = ()) -> BandStage:
    """The bands at the scan's model (the geometry and the named ``effects``, each with
    the threshold of the forward round that kept it), then the backward elimination of
    the effects the bands make unneeded (module docstring), then the ``candidates`` not
    kept scanned forward again with the bands in (:mod:`.after_bands`): one kept is
    added, the model refitted, the bands scanned and the elimination run again; last,
    a kept band the data cannot tell from one of the ``inseparable`` effects (significant,
    not separable, not in the model) is marked not to be named (``stage.confounded``;
    :func:`.after_bands.confounded_bands`; with pose folds only); ``options``:
    DiagnoseOptions, ``base_options``: the identification's."""
    current, folds = scan.result, scan.folds
    stage = BandStage(current=current, scan=scan, extended=current)
    if not options.cyclic:
        return stage
    folds_k = len(folds)
    bands, blocked = _bands(scan, robot, meas, inputs, options, folds_k)
    threshold_of = dict(zip([e.key for e in effects], thresholds))
    effects, tried = list(effects), set()
    while True:
        current, scan, bands, blocked, effects = _eliminate_all(
            stage, robot, meas, inputs, options, base_options, threshold_of,
            (current, scan, bands, blocked, effects))
        if not bands.bands or not candidates or len(effects) >= options.max_effects:
            break
        round_ = scan_after_bands(scan, bands, [c for c in candidates if c.key not in tried],
                                  robot, options.alpha, options.prefer_simpler_alpha)
        if round_ is None:
            break
        stage.after_bands.append(round_)
        stage.refused += round_.refused
        if round_.chosen is None:
            break
        tried.add(round_.chosen.key)
        refit = identify(robot, meas, dataclasses.replace(
            base_options, effects=tuple(effects) + (round_.chosen,)))
        if refit.dropped_effects:  # the non-linear fit disagrees: keep the model before
            round_.chosen, round_.unnamed = None, None
            break
        chosen = next(c for c in round_.candidates if c.effect.key == round_.chosen.key)
        stage.added.append((round_.chosen, chosen.p_value, round_.unnamed))
        threshold_of[round_.chosen.key] = round_.threshold
        effects.append(round_.chosen)
        current, scan = refit, EffectScan(refit, meas, inputs, folds)
        bands, blocked = _bands(scan, robot, meas, inputs, options, folds_k)
    if inseparable and blocked is None:  # bands standing in for an inseparable effect
        stage.confounded = confounded_bands(scan, bands, list(inseparable), robot,
                                            options.prefer_simpler_alpha)
    stage.current, stage.scan, stage.bands, stage.blocked = current, scan, bands, blocked
    stage.extended = apply_bands(current, scan, bands) if bands.bands else current
    return stage


def _eliminate_all(stage: BandStage, robot, meas, inputs, options, base_options,
                   threshold_of: dict, state: tuple) -> tuple:
    """Backward elimination rounds until nothing is dropped (steps recorded in
    ``stage``); ``state`` and the return: (current, scan, bands, blocked, effects)."""
    current, scan, bands, blocked, effects = state
    folds_k = len(scan.folds)
    while bands.bands and effects:
        kept = [(b.joint, b.ridge) for b in bands.bands]
        steps = eliminate(bands.scan, kept, list(effects), [threshold_of[e.key] for e in effects],
                          first_round=1 + max((s.round for s in stage.steps), default=0))
        stage.steps += steps
        dropped = {s.effect.key for s in steps if s.dropped}
        if not dropped:
            break
        remaining = [e for e in effects if e.key not in dropped]
        refit = identify(robot, meas, dataclasses.replace(base_options,
                                                          effects=tuple(remaining)))
        if refit.dropped_effects:  # the non-linear fit disagrees: keep the model before
            stage.steps = [dataclasses.replace(s, dropped=False) if s.effect.key in dropped
                           else s for s in stage.steps]
            break
        effects = remaining
        current, scan = refit, EffectScan(refit, meas, inputs, scan.folds)
        bands, blocked = _bands(scan, robot, meas, inputs, options, folds_k)
    return current, scan, bands, blocked, effects


def elimination_entry(steps: list[EliminationStep]) -> list[dict]:
    """The d.json key ``backward_elimination``: one entry per effect per round."""
    return [{"round": s.round, "effect": s.effect.label, "kind": s.effect.kind,
             "joint": None if s.effect.joint is None else s.effect.joint + 1,
             "heldout_gain": s.gain, "z": s.z, "p_value": s.p_value,
             "threshold": s.threshold, "dropped": s.dropped} for s in steps]


def elimination_lines(steps: list[EliminationStep]) -> list[str]:
    """The text summary's lines: what the bands made unneeded."""
    if not steps:
        return []
    dropped = [s for s in steps if s.dropped]
    if not dropped:
        return ["re-tested with the bands in: every named effect is still needed ("
                + ", ".join(f"{s.effect.label} p = {s.p_value:.1e}" for s in steps
                            if s.round == steps[-1].round) + ")"]
    return ["dropped after the bands: " + ", ".join(
        f"{s.effect.label} (held-out gain {100 * s.gain:.2f} %, p = {s.p_value:.1e} >= "
        f"{s.threshold:.1e})" for s in dropped)]
