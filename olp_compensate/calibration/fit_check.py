"""One rule for every fit that writes a file: a residual its own statistics reject.

A fit of a rigid model (a tool point, a base frame, the arm's geometry) to touches or
measured points leaves a residual of the order of the stated noise: tenths of a millimetre
for a touch, hundredths for a tracker. An RMS residual above :data:`MAX_RMS_M` (5 mm) is not
noise: a wrong mark, a wrong frame, a wrong robot model. The tool fit has refused such
results since it was written; base recalibration and identification apply the same rule,
with the same words: the command refuses (nothing written) unless the user forces it, and a
forced result carries the verdict in the written file (calib.json ``"warnings"``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics.conventions import MM

MAX_RMS_M = 5e-3
"""Largest accepted RMS residual of a fit that writes a file, m: 5 mm is 100 times a
tracker's 0.05 mm and over 15 times a careful touch's 0.3 mm, so no noise reaches it."""


@dataclass(frozen=True)
class FitVerdict:
    """``rejected``: the rule's outcome; ``message``: one line naming the RMS, the threshold
    and the worst row (empty when accepted)."""

    rejected: bool
    message: str = ""


def judge_residual(what: str, residuals_m, names=None, max_rms_m: float = MAX_RMS_M,
                   noise: str = "", rms_m: float | None = None) -> FitVerdict:
    """The verdict on a fit's residual distances ``residuals_m`` (k,), m, one per touch or
    row named by ``names`` (k,): rejected when the RMS exceeds ``max_rms_m`` or a residual
    is not finite. ``what`` starts the message ("tool t1: the touches do not fit one tool
    point"); ``noise`` is an optional clause stating the noise the data was declared with."""
    r = np.asarray(residuals_m, dtype=float).ravel()
    if not len(r):
        return FitVerdict(False)
    if not np.all(np.isfinite(r)):
        return FitVerdict(True, f"{what}: the fit gave non-finite residuals")
    rms = float(np.sqrt(np.mean(r ** 2))) if rms_m is None else float(rms_m)
    if rms <= max_rms_m:
        return FitVerdict(False)
    worst = int(np.argmax(r))
    label = names[worst] if names is not None else f"row {worst + 1}"
    stated = f", {noise}" if noise else ""
    return FitVerdict(True, f"{what} (RMS residual "
                            f"{rms / MM:.3f} mm, above the {max_rms_m / MM:g} mm limit{stated}; "
                            f"worst {label}: {r[worst] / MM:.3f} mm): wrong marks, frame or "
                            f"robot model?")


def forced_warning(verdict: FitVerdict) -> str:
    """The line written into a forced result's file."""
    return f"written with --force although refused: {verdict.message}"

