"""The entries of a diagnosis's ``--json`` document and text report for single effects and
candidates (:func:`.diagnose.diagnosis_to_dict`, :func:`.diagnose.summary`)."""

from __future__ import annotations

import numpy as np

from .cyclic_scan import band_text
from .diagnose_account import cyclic_entry
from .effect_scan import CandidateResult
from .effects import CyclicError, Effect, GearHarmonic, ThermalExpansion


def effect_entry(kept) -> dict:
    """The JSON entry of a kept effect (a :class:`.diagnose.KeptEffect`; SI values; see
    :func:`.diagnose.diagnosis_to_dict`)."""
    e = kept.effect
    value, std, unit = e.headline()
    entry = {"kind": e.kind, "joint": None if e.joint is None else e.joint + 1,
             "value": value, "std": None if not np.isfinite(std) else std, "unit": unit,
             "parameters": dict(zip(e.parameter_names, e.values)),
             "parameter_std": {k: (None if not np.isfinite(v) else v)
                               for k, v in zip(e.parameter_names, e.std)},
             "units": dict(zip(e.parameter_names, e.units)),
             "p_value": kept.p_value, "point_rms_mm": kept.point_rms_m * 1e3,
             "point_max_mm": kept.point_max_m * 1e3, "alternatives": kept.alternatives}
    if isinstance(e, GearHarmonic):
        entry["order"] = e.order
        entry["phase_rad"] = e.phase_rad
    if isinstance(e, ThermalExpansion):
        entry["reference_temperature_c"] = e.reference_temperature_c
    if isinstance(e, CyclicError):
        entry.update(cyclic_entry(e), text=band_text(e))
    return entry


def finite(value: float) -> float | None:
    """``value`` as a JSON number, None when not finite."""
    return None if not np.isfinite(value) else float(value)


def candidate_entry(c: CandidateResult) -> dict:
    """The JSON entry of a candidate in a round of the effect scan."""
    return {"effect": c.effect.label, "kind": c.effect.kind,
            "joint": None if c.effect.joint is None else c.effect.joint + 1,
            "status": c.status, "reason": c.reason or None, "heldout_gain": finite(c.gain),
            "z": finite(c.t), "p_value": finite(c.p_value), "significant": c.significant,
            "separability": finite(c.separability)}


def value_text(effect: Effect) -> str:
    """The effect's headline value in words (with its standard deviation and unit)."""
    value, std, unit = effect.headline()
    name = "amplitude" if isinstance(effect, GearHarmonic) else effect.parameter_names[0]
    text = f"{name} = {value:.3g} +- {std:.2g} {unit}"
    if unit == "rad":
        text += f" ({np.degrees(value) * 1e3:.3g} mdeg)"
    if isinstance(effect, GearHarmonic):
        text += f", phase {np.degrees(effect.phase_rad):.0f} deg"
    if isinstance(effect, ThermalExpansion):
        text += f", reference {effect.reference_temperature_c:.1f} C"
    return text
