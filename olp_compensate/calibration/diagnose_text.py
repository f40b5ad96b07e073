"""The text report of a diagnosis (``olp-cal diagnose``'s output, :func:`summary`) and its
account of what remains (:func:`account_of`); ``d`` is a :class:`.diagnose.Diagnosis`."""

from __future__ import annotations

import numpy as np

from .after_bands import after_bands_lines
from .backward_elimination import elimination_lines
from .cyclic_scan import band_text
from .diagnose_account import account, account_lines, band_round_lines
from .diagnose_entries import value_text
from .effects import CyclicError
from .separability import predictive_gain_m, predictive_lines, refusal_lines, separable
from .time_blocks import blocked_line


def account_of(d) -> dict:
    """The d.json ``account`` of the diagnosis ``d``."""
    return account(d.geometric.heldout_rms, d.extended.heldout_rms, d.remainder,
                   d.noise.sigma_m, d.noise.source, len(d.predictive))


def summary(d) -> str:
    """The diagnosis in words, as printed by ``olp-cal diagnose``; the last line concludes."""
    sigma3 = d.noise.sigma_m * np.sqrt(3)
    g, x = d.geometric, d.extended
    lines = [f"robot {d.robot.name}: {d.measurements.n_poses} poses, {d.measurements.n_rows} "
             f"measured points",
             f"noise floor: {d.noise.sigma_m * 1e3:.4f} mm per axis ({sigma3 * 1e3:.4f} mm 3-D "
             f"RMS), from {d.noise.source}",
             f"geometric model: held-out RMS {g.heldout_rms * 1e3:.4f} mm "
             f"({g.heldout_rms / sigma3:.2f}x the noise), max {g.heldout_max * 1e3:.4f} mm "
             f"({g.calibration.validation.method})"]
    first = d.rounds[0]
    tested = sorted((c for c in first.candidates if c.status == "tested"), key=lambda c: c.p_value)
    lines.append(f"residual structure: {len(tested)} candidate terms tested, share of the "
                 f"geometric model's held-out squared error each removes (best first):")
    for c in tested[:5]:
        mark = ("not significant" if not c.significant else "significant"
                if separable(c.separability) else "significant, not separable")
        lines.append(f"  {c.effect.label:<24} {100 * c.gain:6.1f} %   z = {c.t:6.2f}, "
                     f"p = {c.p_value:.1e} ({mark})")
    if d.untestable:
        lines.append("not testable with these data: " + "; ".join(
            f"{label} ({why})" for label, why in d.untestable.items()))
    lines.append(f"test: {d.test}; alpha = {d.alpha}")
    for number, r in enumerate(d.rounds, start=1):
        if r.chosen is not None and r.unnamed is not None:
            lines.append(f"round {number}: kept a predictive term, not named (p = "
                         f"{r.unnamed.p_value:.1e} < {r.threshold:.1e}; below)")
        elif r.chosen is not None:
            chosen = next(c for c in r.candidates if c.effect is r.chosen)
            alt = (f"; the data cannot tell it from {', '.join(r.alternatives)}"
                   if r.alternatives else "")
            lines.append(f"round {number}: kept {r.chosen.label} (p = {chosen.p_value:.1e} < "
                         f"{r.threshold:.1e}){alt}")
        else:
            lines.append(f"round {number}: no further term is significant (threshold "
                         f"{r.threshold:.1e})")
    lines += (band_round_lines(d.bands) + after_bands_lines(d.after_bands)
              + elimination_lines(d.elimination) + refusal_lines(d.refused)
              + predictive_lines([t.unnamed for t in d.predictive]))
    if d.drift:
        lines.append(f"WARNING: {d.drift}")
    lines += account_lines(account_of(d)) + ([blocked_line(d.blocked)] if d.blocked else [])
    n = len(d.predictive)
    unnamed = (f"predictable, not named: {n} term{'s' if n > 1 else ''} kept in the extended "
               f"model (gain {predictive_gain_m([t.unnamed for t in d.predictive]) * 1e3:.4f} "
               f"mm held-out)") if n else ""
    if not d.found and n:
        lines.append(f"no effect named: the significant terms are not separable from the "
                     f"geometry over these poses; {unnamed}; held-out RMS "
                     f"{g.heldout_rms * 1e3:.4f} -> {x.heldout_rms * 1e3:.4f} mm "
                     f"({g.heldout_rms / sigma3:.2f}x -> {x.heldout_rms / sigma3:.2f}x the "
                     f"noise)")
        return "\n".join(lines)
    if not d.found:
        why = ("the significant ones are not separable from the geometry (not named, above)"
               if d.refused else "no candidate lowers the held-out error significantly")
        lines.append(f"no effect found: {why}; "
                     f"the geometric model stands (held-out RMS {g.heldout_rms * 1e3:.4f} mm, "
                     f"{g.heldout_rms / sigma3:.2f}x the noise)")
        return "\n".join(lines)
    lines.append(f"found {len(d.effects)} effect{'s' if len(d.effects) > 1 else ''}:")
    for k in d.effects:
        text = (band_text(k.effect) if isinstance(k.effect, CyclicError)
                else f"{value_text(k.effect)}; {k.effect.description}")
        lines.append(f"  {k.effect.label}: {text}; "
                     f"moves the measured point by {k.point_rms_m * 1e3:.3f} mm RMS, "
                     f"{k.point_max_m * 1e3:.3f} mm max")
    lines.append(f"held-out RMS {g.heldout_rms * 1e3:.4f} -> {x.heldout_rms * 1e3:.4f} mm "
                 f"({g.heldout_rms / sigma3:.2f}x -> {x.heldout_rms / sigma3:.2f}x the noise), "
                 f"max {g.heldout_max * 1e3:.4f} -> {x.heldout_max * 1e3:.4f} mm: found "
                 + ", ".join(k.effect.label for k in d.effects) + (f"; {unnamed}" if n else ""))
    return "\n".join(lines)
