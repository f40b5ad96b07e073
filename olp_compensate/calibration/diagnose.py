"""Diagnosis: what the geometric model gets wrong, which effect explains it, and the gain.

1. Fit the geometric model (:func:`olp_compensate.calibration.identify.identify`) with k-fold
   cross-validation by pose.
2. Noise floor: the spread of repeated measurements of one pose (rows sharing ``pose`` and
   ``point``) when there are any, else ``DiagnoseOptions.noise_m``, else the residual of
   the final model (an upper bound).
3. Scan (:mod:`.effect_scan`): every candidate of :func:`.effect_scan.candidate_effects` that
   the data can test (its term is not zero and not a combination of the geometry, see
   :func:`.identifiability.effect_separation`) is added to the current model and both models
   are cross-validated on the same folds. The fits are Gauss-Newton steps from the current
   full-data solution (the problem is linear to far below the noise there), so
   the whole scan costs a few least-squares solves per candidate.
4. Test: G = held-out sum of squared errors of the current model minus that of the model
   with the candidate (the held-out gain). Given the training folds, G is a sum of
   ``2 e.D - |D|^2`` over the held-out rows (D the change of the prediction, e the current
   model's held-out residual, whose covariance is sigma^2 (I + H), H the leverage of the
   test rows), so ``z = G / (2 sigma sqrt(|D|^2 + D'HD))`` with sigma from the candidate's
   in-sample residual. A candidate is significant when the one-sided p = P(N(0,1) > z) is
   below alpha / K, K the number of candidates tested in the round (Bonferroni). Without the
   effect G has a negative mean (the larger model fits noise), so the test is conservative:
   the chance that a round keeps a spurious effect is at most about ``alpha`` (default 1 %).
   On effect-free virtual robots z has mean -1 and sd 1.2, and none of 300 diagnoses named
   an effect (benchmarks/diagnose.py measures it again).
5. Choice: among significant candidates the lowest held-out error wins, except that a
   candidate with fewer parameters is preferred when the winner is not significantly better
   than it (the same z-test, 5 %); candidates the data cannot tell from the chosen one are
   reported as alternatives. The chosen effect is added, the model refitted (non-linear,
   geometry and effects together) and the scan repeated until no candidate is significant.
6. The cyclic bands (:mod:`.cyclic_scan`), then every effect kept above tested again with
   them in and dropped when no longer needed (:mod:`.backward_elimination`), then the
   classic candidates scanned again with the bands in (:mod:`.after_bands`).
7. Naming (:mod:`.separability`): every term the tests keep stays in the extended model;
   it is named only when separable from the geometry and distinguishable from every
   significant candidate that is not. The others are "predictive terms, not named"
   (their held-out gain is kept, their names and sizes withheld).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .effects import Effect, EffectInputs, JointCompliance, ThermalExpansion
from ..errors import DataError
from .after_bands import AfterBandsRound, after_bands_entry
from .backward_elimination import EliminationStep, band_stage, elimination_entry
from .cross_validation import pose_folds
from .cyclic_scan import BandOutcome
from .diagnose_entries import candidate_entry, effect_entry
from .diagnose_text import account_of, summary
from .diagnose_account import band_refusal, band_rounds, refusals_with_bands
from .remainder import Predictability, predictability
from .separability import Refusal, predictive_entries, refusal_entries, separable
from .time_blocks import BlockedFigures, blocked_entry
from .effect_scan import (CandidateResult, EffectScan, candidate_effects, choose_candidate,
                          drift_warning, naming_refusal)
from .identify import (IdentificationOptions, IdentificationResult, identify,
                       measurement_inputs)
from .problem import problem_at
from .measurements import Measurements
from ..kinematics.robot import Robot

TEST_DESCRIPTION = (
    "one-sided z-test of the held-out gain (current model's held-out sum of squares minus "
    "the extended model's, k-fold by pose), variance 4 sigma^2 (|D|^2 + D'HD) from the "
    "noise and the change D of the held-out predictions; significant when p < alpha / K "
    "(Bonferroni over the K candidates of a round)")

NOISE_SOURCE = ("what no model of the joints predicts (the held-out error of the flexible model "
                "of the remainder; measure some poses twice for a direct figure)")


@dataclass(frozen=True)
class DiagnoseOptions:
    """Choices of a diagnosis. ``noise_m``: per-axis measurement noise, m, when known;
    ``alpha``: false-alarm rate per round (family-wise); ``folds``: cross-validation folds;
    ``max_effects``: stop after this many; ``kinds``: effect kinds to try (all by default);
    ``prefer_simpler_alpha``: level of the test that lets a larger candidate beat a smaller."""

    noise_m: float | None = None
    alpha: float = 0.01
    folds: int = 5
    max_effects: int = 4
    kinds: tuple[str, ...] | None = None
    prefer_simpler_alpha: float = 0.05
    convention: str = "auto"
    cyclic: bool = True
    """Scan the cyclic angle error bands (:mod:`.cyclic_scan`) after the named terms."""
    account: bool = True
    """Estimate what remains predictable (:mod:`.remainder`); without it the noise floor
    falls back to the residual of the final model (the diagnosis before issue 28)."""
    time_blocks: bool = True
    """With a time_s column, choose the cyclic bands on blocks of time (:mod:`.time_blocks`)."""


@dataclass(frozen=True)
class NoiseFloor:
    """Per-axis measurement noise ``sigma_m`` (m) and where it came from."""

    sigma_m: float
    source: str


@dataclass(frozen=True)
class Round:
    """One scan: the per-candidate results, the significance threshold alpha / K, the
    chosen effect (None: nothing helps) and alternatives the data cannot tell from it."""

    threshold: float
    candidates: list[CandidateResult]
    chosen: Effect | None
    alternatives: list[str] = field(default_factory=list)
    heldout_sse: float = float("nan")
    refused: list[Refusal] = field(default_factory=list)
    """Candidates significant by the test but not separable from the geometry."""
    unnamed: Refusal | None = None
    """Why the chosen candidate, kept in the model, is not named (None: named)."""


@dataclass(frozen=True)
class KeptEffect:
    """A named effect with its fitted values (``effect.values``, ``effect.std``), the p-value
    of the round that kept it, how far it moves the measured points (RMS and max over the
    rows, m) and the alternatives the data could not rule out."""

    effect: Effect
    p_value: float
    point_rms_m: float
    point_max_m: float
    alternatives: list[str] = field(default_factory=list)
    displacement: np.ndarray | None = None
    """(m, 3) how the effect moves each measured point, device frame, m."""
    unnamed: Refusal | None = None
    """Set for a predictive term kept in the model but not named: why, and its gain."""


@dataclass(frozen=True)
class Diagnosis:
    """Outcome of :func:`diagnose`; lengths in metres, device frame.

    ``geometric``/``extended``: the identifications before and after (the same when no
    effect was found); ``residual_before``/``residual_after``: (m, 3) measured minus
    predicted; ``predicted_change``: (m, 3) extended minus geometric prediction (the error
    the extended model predicts the geometric one makes); ``dpoint_dq``: (m, 3, n) how each
    measured point moves per radian of each controller axis; ``flange_device``: (m, 3) the
    flange position (base frame origin, device axes), for thermal expansion; ``inputs``:
    the effect inputs at the measured rows (controller axes, gravity torques...).
    """

    robot: Robot
    measurements: Measurements
    geometric: IdentificationResult
    extended: IdentificationResult
    effects: list[KeptEffect]
    rounds: list[Round]
    noise: NoiseFloor
    untestable: dict[str, str]
    drift: str | None
    residual_before: np.ndarray
    residual_after: np.ndarray
    predicted_change: np.ndarray
    dpoint_dq: np.ndarray
    flange_device: np.ndarray
    inputs: EffectInputs
    alpha: float
    candidates_tried: int
    test: str = TEST_DESCRIPTION
    bands: BandOutcome | None = None
    """The cyclic band scan (None when not run)."""
    remainder: Predictability | None = None
    """How much of the extended model's held-out residual a flexible model predicts."""
    blocked: BlockedFigures | None = None
    """Held-out figures by blocks of time (rows with time_s; :mod:`.time_blocks`)."""
    elimination: list[EliminationStep] = field(default_factory=list)
    """The named effects re-tested once the bands were in (:mod:`.backward_elimination`)."""
    refused: list[Refusal] = field(default_factory=list)
    """Effects significant by the test but not named: not separable from the geometry
    (:mod:`.separability`), first refusal of each effect at each stage."""
    after_bands: list[AfterBandsRound] = field(default_factory=list)
    """The classic candidates scanned again once the bands were in (:mod:`.after_bands`)."""
    predictive: list[KeptEffect] = field(default_factory=list)
    """Terms kept in the extended model but not named (``unnamed`` says why)."""

    @property
    def found(self) -> bool:
        """Named effects found (the predictive terms not named do not count)."""
        return bool(self.effects)

    @property
    def extends(self) -> bool:
        """The extended model differs from the geometric one (named or unnamed terms)."""
        return bool(self.effects or self.predictive)


def noise_floor(meas: Measurements, noise_m: float | None, residual_sigma: float,
                residual_source: str = "residual of the final model (an upper bound: measure "
                                       "some poses twice for a real one)") -> NoiseFloor:
    """Per-axis noise: repeated poses first, then ``noise_m``, then ``residual_sigma``
    (what no model of the joints predicts, see :mod:`.remainder`)."""
    groups: dict[tuple, list[int]] = {}
    for k, key in enumerate(zip(meas.pose_ids, meas.point_names)):
        groups.setdefault(key, []).append(k)
    repeated = [rows for rows in groups.values() if len(rows) > 1]
    dof = 3 * sum(len(rows) - 1 for rows in repeated)
    if dof >= 9:
        sse = sum(float(np.sum((meas.points[rows] - meas.points[rows].mean(axis=0)) ** 2))
                  for rows in repeated)
        return NoiseFloor(sigma_m=float(np.sqrt(sse / dof)),
                          source=f"repeated poses ({len(repeated)} repeated, {dof} degrees "
                                 f"of freedom)")
    if noise_m is not None:
        return NoiseFloor(sigma_m=float(noise_m), source="stated (--noise-mm)")
    return NoiseFloor(sigma_m=float(residual_sigma), source=residual_source)


def _checked_folds(meas: Measurements, options: DiagnoseOptions) -> int:
    """The number of folds; DataError for options out of their domain."""
    if not 0 < options.alpha < 1:
        raise DataError(f"alpha must lie in (0, 1), got {options.alpha}")
    if options.noise_m is not None and not options.noise_m > 0:
        raise DataError(f"DiagnoseOptions.noise_m must be positive, got {options.noise_m} m")
    folds_k = min(options.folds, meas.n_poses)
    if folds_k < 2:
        raise DataError(f"{meas.source}: the diagnosis needs at least 2 poses and 2 folds")
    asked = options.kinds or ()
    if "thermal_expansion" in asked and meas.temperature_c is None:
        raise DataError(f"{meas.source}: thermal_expansion needs the 'temperature_c' column, "
                        f"which the measurements do not have")
    return folds_k


def _inseparable(rounds: list[Round]) -> list[Effect]:
    """The candidates the forward scan refused as not separable (significant ones)."""
    labels = {r.label for round_ in rounds for r in round_.refused if not r.confounded_with}
    out = {c.effect.key: c.effect for round_ in rounds for c in round_.candidates
           if c.effect.label in labels}
    return list(out.values())


def _scan_round(scan: EffectScan, candidates: list[Effect], skip: set, alpha: float,
                prefer_simpler_alpha: float, stage: str = "effect scan"
                ) -> tuple[Round, CandidateResult | None, dict]:
    """One round: every candidate not in ``skip`` (keys) tested at the scan's model;
    (the round, the chosen candidate or None, label -> reason of the untestable ones).
    Significant: p below alpha / K and separable from the geometry (:mod:`.separability`;
    the refused ones are listed in the round)."""
    results, tested, untestable = [], [], {}
    for candidate in candidates:
        if candidate.key in skip:
            continue
        result, held = scan.evaluate(candidate)
        results.append(result)
        if held is not None:
            tested.append((result, held))
        else:
            untestable[candidate.label] = result.reason
    threshold = alpha / max(len(tested), 1)
    marked = {id(r): dataclasses.replace(r, significant=bool(r.p_value < threshold))
              for r, _ in tested}
    refused = [Refusal(label=r.effect.label, kind=r.effect.kind, joint=r.effect.joint,
                       stage=stage, p_value=r.p_value, separability=r.separability,
                       moves_m=r.moves_m, gain=r.gain)
               for r, _ in tested if r.p_value < threshold and not separable(r.separability)]
    results = [marked.get(id(r), r) for r in results]
    tested = [(marked[id(r)], held) for r, held in tested]
    chosen, alternatives = choose_candidate(scan, tested, threshold, prefer_simpler_alpha)
    unnamed = None if chosen is None else naming_refusal(
        scan, tested, chosen, threshold, prefer_simpler_alpha, stage)
    round_ = Round(threshold=threshold, candidates=results,
                   chosen=None if chosen is None else chosen.effect,
                   alternatives=alternatives, heldout_sse=scan.base.sse, refused=refused,
                   unnamed=unnamed)
    return round_, chosen, untestable


def _kept_effects(after, x_after: np.ndarray, extended: IdentificationResult,
                  kept: list[tuple]) -> list[KeptEffect]:
    """Each kept effect with how far it alone moves the measured points: the extended
    problem ``after`` at ``x_after`` with only that effect switched on, minus with none."""
    x_plain = x_after.copy()  # the extended model with its effects switched off
    for cols in after.layout.effects:
        x_plain[cols] = 0.0
    plain = after.predict(x_plain, jacobian=False)[-1]
    out = []
    for cols, fitted, (_, p_value, alternatives, unnamed) in zip(
            after.layout.effects, extended.calibration.effects, kept):
        x_one = x_plain.copy()
        x_one[cols] = x_after[cols]
        displacement = after.predict(x_one, jacobian=False)[-1] - plain
        moved = np.linalg.norm(displacement, axis=1)
        out.append(KeptEffect(effect=fitted, p_value=p_value,
                              point_rms_m=float(np.sqrt(np.mean(moved**2))),
                              point_max_m=float(moved.max()), alternatives=alternatives,
                              displacement=displacement, unnamed=unnamed))
    return out


def _candidates(robot: Robot, meas: Measurements, options: DiagnoseOptions) -> list[Effect]:
    """The classic candidates of the options' kinds (thermal expansion referred to the
    mean measured temperature)."""
    candidates = [c for c in candidate_effects(robot, meas.temperature_c is not None)
                  if options.kinds is None or c.kind in options.kinds]
    return [dataclasses.replace(c, reference_temperature_c=float(np.mean(meas.temperature_c)))
            if isinstance(c, ThermalExpansion) else c for c in candidates]


def _final_terms(kept: list[tuple], stage) -> list[tuple]:
    """The terms of the extended model, (effect, p-value, alternatives, why not named or
    None): the forward scan's ``kept`` less those the bands made unneeded, those the scan
    after the bands added, then the kept bands (:class:`.backward_elimination.BandStage`)."""
    gone = {e.key for e in stage.dropped}
    kept = [k for k in kept + [(e, p, [], u) for e, p, u in stage.added] if k[0].key not in gone]
    bands = stage.bands
    if bands is not None:
        confounded = {r.joint: r.confounded_with for r in stage.confounded}
        kept += [(b, p, [], band_refusal(bands, b, confounded.get(b.joint, "")))
                 for b, p in zip(bands.bands, bands.p_values)]
    return kept


def diagnose(robot: Robot, meas: Measurements,
             options: DiagnoseOptions = DiagnoseOptions()) -> Diagnosis:
    """Diagnose the measurements of ``robot`` (see the module docstring)."""
    folds_k = _checked_folds(meas, options)
    base_options = IdentificationOptions(convention=options.convention, folds=folds_k)
    geometric = identify(robot, meas, base_options)
    tools = {n: t.xyz_m for n, t in geometric.calibration.tools.items()}
    inputs = measurement_inputs(robot, meas, tools, [JointCompliance(joint=0)])
    folds = pose_folds(meas.pose_ids, folds_k)
    candidates = _candidates(robot, meas, options)

    current = geometric
    kept: list[tuple] = []  # (effect, p-value, alternatives, why not named or None)
    rounds: list[Round] = []
    untestable: dict[str, str] = {}
    scan = EffectScan(current, meas, inputs, folds)
    while len(kept) < options.max_effects:
        round_, chosen, not_testable = _scan_round(
            scan, candidates, {k[0].key for k in kept}, options.alpha,
            options.prefer_simpler_alpha)
        if not rounds:
            untestable = not_testable
        rounds.append(round_)
        if chosen is None:
            break
        effects = tuple(k[0] for k in kept) + (chosen.effect,)
        refit = identify(robot, meas, dataclasses.replace(base_options, effects=effects))
        if refit.dropped_effects:  # the non-linear fit disagrees with the scan: stop here
            rounds[-1] = dataclasses.replace(rounds[-1], chosen=None)
            break
        kept.append((chosen.effect, chosen.p_value, round_.alternatives, round_.unnamed))
        current = refit
        scan = EffectScan(current, meas, inputs, folds)

    # the bands (with time_s chosen on blocks of time), then the named effects they make
    # unneeded dropped (:mod:`.backward_elimination`)
    stage = band_stage(robot, meas, inputs, scan, [k[0] for k in kept],
                       [r.threshold for r in rounds[:len(kept)]], options, base_options,
                       candidates, _inseparable(rounds))
    kept = _final_terms(kept, stage)
    scan, extended, bands, blocked = stage.scan, stage.extended, stage.bands, stage.blocked
    drift = drift_warning(scan, options.alpha)
    target = bands.heldout if bands is not None and bands.bands else scan.base
    before, x_before = problem_at(geometric.calibration, meas, inputs)
    after, x_after = problem_at(extended.calibration, meas, inputs)
    predicted_before = before.predict(x_before, jacobian=False)[-1]
    *_, chain, predicted_after = after.predict(x_after, jacobian=True)
    rotation = extended.calibration.device_T_base[:3, :3]
    coupling = (np.eye(robot.n_joints) if robot.urdf_from_controller is None
                else robot.urdf_from_controller)
    dpoint_dq = np.einsum("ij,mjk,kl->mil", rotation, chain.dpoint_dq, coupling)
    residual_after = after.measured - predicted_after
    remainder, source = None, NOISE_SOURCE
    if options.account:
        remainder = predictability(inputs.q, tuple(j.kind for j in robot.joints),
                                   -target.residuals, folds, meas.temperature_c, meas.time_s,
                                   map_target=residual_after)
        residual_sigma = remainder.rms_after / np.sqrt(3)
    else:
        dof = max(extended.n_equations - extended.n_unknowns, 1)
        residual_sigma = float(np.sqrt(np.sum(residual_after**2) / dof))
        source = "residual of the final model (an upper bound: measure some poses twice)"
    flange = np.einsum("ij,mj->mi", rotation, chain.flange[:, :3, 3])
    terms = _kept_effects(after, x_after, extended, kept)
    return Diagnosis(robot=robot, measurements=meas, geometric=geometric, extended=extended,
                     effects=[t for t in terms if t.unnamed is None], rounds=rounds,
                     predictive=[t for t in terms if t.unnamed is not None],
                     noise=noise_floor(meas, options.noise_m, residual_sigma, source),
                     untestable=untestable, drift=drift,
                     residual_before=before.measured - predicted_before,
                     residual_after=residual_after,
                     predicted_change=predicted_after - predicted_before,
                     dpoint_dq=dpoint_dq, flange_device=flange, inputs=inputs,
                     alpha=options.alpha, candidates_tried=len(candidates), bands=bands,
                     remainder=remainder, blocked=blocked, elimination=stage.steps,
                     after_bands=stage.after_bands,
                     refused=[r for r in refusals_with_bands(
                         [r for round_ in rounds for r in round_.refused] + stage.refused, bands)
                         if r.label not in {k[0].label for k in kept}])


def _mm(value_m: float | None) -> float | None:
    return None if value_m is None else value_m * 1e3


def diagnosis_to_dict(d: Diagnosis) -> dict:
    """The ``--json`` document. Effects: ``value`` is the effect's size in ``unit`` (c,
    w, s, alpha; for a gear harmonic the amplitude sqrt(a^2 + b^2) in rad, with ``order``,
    ``phase_rad`` (dq = A sin(k q + phase)) and the raw ``parameters`` a, b); ``joint`` is
    the 1-based controller axis, null for thermal expansion. Lengths in mm."""
    sigma3 = d.noise.sigma_m * np.sqrt(3)
    return {
        "format": "olp-compensate diagnosis", "version": 1,
        "robot": d.robot.name, "measurements": d.measurements.source,
        "poses": d.measurements.n_poses, "rows": d.measurements.n_rows,
        "noise_mm": d.noise.sigma_m * 1e3, "noise_source": d.noise.source,
        "noise_3d_rms_mm": sigma3 * 1e3,
        "effects": [effect_entry(k) for k in d.effects],
        "found": d.found,
        "heldout_rms_mm": {"geometric": _mm(d.geometric.heldout_rms),
                           "extended": _mm(d.extended.heldout_rms),
                           "predictable": _mm(None if d.remainder is None
                                              else d.remainder.rms_after)},
        "account": account_of(d),
        "cyclic_bands": band_rounds(d.bands),
        "cyclic_short_lever_joints": [j + 1 for j in (d.bands.short_lever if d.bands else [])],
        **blocked_entry(d.blocked),
        "heldout_max_mm": {"geometric": _mm(d.geometric.heldout_max),
                           "extended": _mm(d.extended.heldout_max)},
        "heldout_method": d.extended.calibration.validation.method,
        "test": {"description": d.test, "alpha": d.alpha,
                 "rounds": [{"threshold": r.threshold,
                             "chosen": None if r.chosen is None else r.chosen.label,
                             "chosen_named": r.chosen is not None and r.unnamed is None,
                             "alternatives": r.alternatives,
                             "candidates": [candidate_entry(c) for c in r.candidates]}
                            for r in d.rounds]},
        "backward_elimination": elimination_entry(d.elimination),
        "not_named": refusal_entries(d.refused),
        "predictive_not_named": predictive_entries([t.unnamed for t in d.predictive]),
        "effect_scan_after_bands": after_bands_entry(d.after_bands),
        "untestable": d.untestable,
        "drift": d.drift,
        "conclusion": summary(d).splitlines()[-1],
    }
