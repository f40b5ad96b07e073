"""The honest account of what remains after a diagnosis (issue 28, item 2): how much of
the geometric model's held-out error the named effects explain, how much more a flexible
model of the joints predicts without naming it (:mod:`.remainder`), and the noise floor.

RMS figures add in quadrature: with B the geometric model's held-out RMS, E the extended
model's and P what remains after the flexible model of E's held-out residual, the named
effects explain ``A = sqrt(B^2 - E^2)``, the unnamed predictable part is
``C = sqrt(E^2 - P^2)`` and the rest, P, is the noise floor (3-D RMS)."""

from __future__ import annotations

import numpy as np

from .cyclic_scan import MAX_MOVES, MIN_LEVER_M, BandOutcome, dominant_orders, order_resolution
from .effects import CyclicError
from .remainder import Predictability
from .separability import MIN_SEPARABILITY, Refusal, separable


def _quadrature(big: float, small: float) -> float:
    return float(np.sqrt(max(big**2 - small**2, 0.0)))


def account(geometric_m: float, extended_m: float, remainder: Predictability | None,
            noise_sigma_m: float, noise_source: str, predictive_terms: int = 0) -> dict:
    """The JSON account, mm (3-D RMS except ``noise_per_axis_mm``); the extended model
    holds the named effects and ``predictive_terms`` terms kept but not named (what
    ``explained_by_named_effects_mm`` counts with them)."""
    predictable = extended_m if remainder is None else remainder.rms_after
    return {"geometric_heldout_mm": geometric_m * 1e3,
            "explained_by_named_effects_mm": _quadrature(geometric_m, extended_m) * 1e3,
            "extended_heldout_mm": extended_m * 1e3,
            "predictive_terms_in_extended": predictive_terms,
            "predictable_not_named_mm": _quadrature(extended_m, predictable) * 1e3,
            "predictable_from_joints": [] if remainder is None
            else [j + 1 for j in remainder.joints],
            "remaining_mm": predictable * 1e3,
            "noise_per_axis_mm": noise_sigma_m * 1e3, "noise_source": noise_source,
            "predictable_by": None if remainder is None else remainder.model,
            "method": "RMS figures in quadrature; the predictable part by the better of a "
                      "random-Fourier-feature ridge model and a k-nearest-neighbour model of "
                      "the extended model's held-out residual against the joints (and "
                      "temperature and time where given), nested cross-validation"}


def account_lines(doc: dict) -> list[str]:
    """The account in words (the text summary's last lines before the conclusion)."""
    joints = doc["predictable_from_joints"]
    where = (f" from joint{'s' if len(joints) > 1 else ''} "
             + " and ".join(str(j) for j in joints)) if joints else ""
    n = doc.get("predictive_terms_in_extended", 0)
    terms = (f" and {n} predictive term{'s' if n > 1 else ''} not named" if n else "")
    return [f"what remains: named effects{terms} explain "
            f"{doc['explained_by_named_effects_mm']:.4f} "
            f"mm of the {doc['geometric_heldout_mm']:.4f} mm (held-out RMS, in quadrature); "
            f"{doc['predictable_not_named_mm']:.4f} mm more is predictable{where} but not "
            f"named; the rest ({doc['remaining_mm']:.4f} mm 3-D RMS) is the noise floor, "
            f"{doc['noise_per_axis_mm']:.4f} mm per axis from {doc['noise_source']}"]


def cyclic_entry(effect: CyclicError) -> dict:
    """The JSON fields a cyclic error adds to its effect entry; ``order_resolution``:
    orders closer than this (cycles per turn, 360 deg / the fitted span) are not told
    apart, so a dominant order is known to about that."""
    amplitudes = effect.amplitudes()
    orders = dominant_orders(effect)
    return {"max_order": effect.max_order, "min_order": effect.min_order,
            "dominant_orders": orders,
            "periods_deg": [360.0 / k for k in orders],
            "order_resolution": order_resolution(effect),
            "amplitudes_rad": amplitudes.tolist(),
            "q_range_deg": np.degrees(effect.q_range).tolist(), "ridge": effect.ridge}


def band_rounds(bands: BandOutcome | None) -> list[dict]:
    """The band scan's rounds for the JSON document."""
    if bands is None:
        return []
    return [{"threshold": threshold,
             "bands": [{"joint": r.effect.joint + 1, "max_order": r.effect.max_order,
                        "min_order": r.effect.min_order,
                        "heldout_gain": r.gain, "z": r.z, "p_value": r.p_value,
                        "ridge": r.ridge, "moves_over_heldout_rms": r.moves,
                        "separability": None if not np.isfinite(r.separability)
                        else r.separability,
                        "significant": r.significant} for r in results]}
            for threshold, results in zip(bands.thresholds, bands.rounds)]


def band_round_lines(bands: BandOutcome | None) -> list[str]:
    """One line per round of the band scan."""
    if bands is None:
        return []
    lines = [f"cyclic error bands: no band for joint {j + 1} (its axis passes within "
             f"{MIN_LEVER_M * 1e3:.0f} mm RMS of the measured points: its angle barely moves "
             f"them)" for j in bands.short_lever]
    if not bands.rounds:
        return lines + ["cyclic error bands: no joint's angles resolve a band"]
    for number, (threshold, results) in enumerate(zip(bands.thresholds, bands.rounds), 1):
        tested = ", ".join(f"j{r.effect.joint + 1} (orders {r.effect.min_order}-"
                           f"{r.effect.max_order}: {100 * r.gain:.1f} %, p = {r.p_value:.1e}"
                           + (f", moves the points {r.moves:.1f}x the held-out RMS: cancels "
                              f"against other terms" if r.moves > MAX_MOVES else "")
                           + (f", separability {r.separability:.3f} < {MIN_SEPARABILITY}: not "
                              f"separable from the geometry over these poses"
                              if not separable(r.separability) else "") + ")"
                           for r in results)
        kept = [r for r in results if r.significant]
        best = min(kept, key=lambda r: -r.gain) if kept else None
        verdict = ("no band is significant" if best is None
                   else f"kept the band of joint {best.effect.joint + 1}"
                   + ("" if separable(best.separability)
                      else " (not separable: a predictive term, not named)"))
        lines.append(f"cyclic band round {number} (threshold {threshold:.1e}): {tested}; "
                     f"{verdict}")
    return lines


def refusals_with_bands(refused: list[Refusal], bands: BandOutcome | None) -> list[Refusal]:
    """The refusals of the effect scans and the bands' (a band passing the test and the
    move rule but not separable), the first of each effect at each stage."""
    for threshold, results in zip(bands.thresholds if bands else [], bands.rounds if bands else []):
        refused += [Refusal(label=r.effect.label, kind=r.effect.kind, joint=r.effect.joint,
                            stage="cyclic bands", p_value=r.p_value,
                            separability=r.separability, moves_m=r.moves_m)
                    for r in results if r.p_value < threshold and r.moves <= MAX_MOVES
                    and not separable(r.separability)]
    out: dict[tuple, Refusal] = {}
    for r in refused:
        out.setdefault((r.label, r.stage), r)
    return list(out.values())


def band_refusal(bands: BandOutcome, band: CyclicError, confounded_with: str = ""
                 ) -> Refusal | None:
    """Why the kept ``band`` is not named (None: it is named): not separable from the
    unpenalized unknowns in the round that kept it, or ``confounded_with`` a significant
    inseparable effect (:func:`.after_bands.confounded_bands`). Carries its held-out gain
    in that round."""
    result = next((r for results in reversed(bands.rounds) for r in results
                   if r.significant and r.effect.joint == band.joint), None)
    if result is None or (separable(result.separability) and not confounded_with):
        return None
    drop = result.base_rms_m * (1.0 - np.sqrt(max(1.0 - result.gain, 0.0)))
    return Refusal(label=result.effect.label, kind=result.effect.kind, joint=band.joint,
                   stage="cyclic bands", p_value=result.p_value,
                   separability=result.separability, moves_m=result.moves_m,
                   gain=result.gain, gain_m=float(drop), confounded_with=confounded_with)
