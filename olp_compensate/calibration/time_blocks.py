"""Cross-validation in blocks of time for the cyclic bands and the remainder (issue 28).

Random folds by pose put a row's neighbours in time into the training set. Along a path
(the ASTL CURVE and LINE sessions: one curve through joint space, recorded in order) the
slow drift of the arm and the tracker is then as predictable as joint structure: the
bands' nested cross-validation chose orders 45-48 on CURVE. When the rows carry
``time_s``, the diagnosis therefore chooses the bands (which joints, their orders'
penalty) on contiguous blocks of time (:func:`.cross_validation.time_blocked_folds`)
and reports two sets of figures:

- ``heldout_rms_mm`` (the contract's, unchanged in meaning): 5-fold by pose, of the
  model with the bands chosen on the time blocks; ``predictable`` by pose as well;
- ``heldout_rms_mm_time_blocked``: the same models held out by time block, what a new
  session along a path may expect (drift included); ``predictable`` there is what the
  flexible model of the joints predicts across time blocks.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..kinematics.robot import Robot
from .cyclic_scan import BandOutcome, BandScan, scan_bands
from .effect_scan import EffectScan, Heldout
from .remainder import Predictability, predictability

METHOD = ("{k} contiguous blocks of acquisition time (time_s), every row of a pose in one "
          "block; the cyclic bands chosen on them")


@dataclass(frozen=True)
class BlockedFigures:
    """Held-out figures by time block: ``extended_m`` (3-D RMS, m, the named effects and
    bands), ``remainder`` (the flexible model across the blocks), ``folds`` (k) and the
    ``method`` text."""

    extended_m: float
    remainder: Predictability | None
    folds: int
    method: str


def by_pose(scan: EffectScan, robot: Robot, q_ctrl: np.ndarray, bands: BandOutcome
            ) -> Heldout:
    """Held-out residuals by the scan's pose folds of the model with the bands chosen on
    time blocks (the same joints at the same penalties)."""
    pose_bands = BandScan(scan, robot, q_ctrl)
    kept = [(b.joint, b.ridge) for b in bands.bands if b.joint in pose_bands.columns]
    held, _ = pose_bands.current(kept)
    return held


def blocked_figures(scan: EffectScan, bands: BandOutcome | None, folds: list[np.ndarray],
                    q_ctrl: np.ndarray, kinds, meas, account: bool) -> BlockedFigures:
    """The time-blocked figures of a diagnosis whose bands were chosen on ``folds``."""
    if bands is not None and bands.bands:
        held = bands.heldout
    else:
        held = EffectScan(scan.result, scan.meas, scan.inputs, folds).base
    extended = float(np.sqrt(np.mean(np.sum(held.residuals ** 2, axis=1))))
    remainder = None
    if account:
        remainder = predictability(q_ctrl, kinds, -held.residuals, folds, meas.temperature_c,
                                   meas.time_s, map_target=None)
    return BlockedFigures(extended_m=extended, remainder=remainder, folds=len(folds),
                          method=METHOD.format(k=len(folds)))


def scan_bands_blocked(scan: EffectScan, robot: Robot, q_ctrl: np.ndarray, options,
                       blocks: list[np.ndarray] | None):
    """(bands, blocked figures or None): the band scan on ``blocks`` (the scan's pose folds
    when None), its held-out residuals then again by pose (the contract's figures)."""
    bands = scan_bands(scan, robot, q_ctrl, options.alpha, folds=blocks)
    if blocks is None:
        return bands, None
    blocked = blocked_figures(scan, bands, blocks, q_ctrl, tuple(j.kind for j in robot.joints),
                              scan.meas, options.account)
    if bands.bands:
        bands = dataclasses.replace(bands, heldout=by_pose(scan, robot, q_ctrl, bands))
    return bands, blocked


def _mm(value_m: float | None) -> float | None:
    return None if value_m is None else value_m * 1e3


def blocked_entry(blocked: BlockedFigures | None) -> dict:
    """The d.json keys ``heldout_rms_mm_time_blocked`` (``extended``, ``predictable``)
    and ``heldout_time_blocked_method``; none without time blocks."""
    if blocked is None:
        return {}
    remainder = blocked.remainder
    return {"heldout_rms_mm_time_blocked": {
        "extended": _mm(blocked.extended_m),
        "predictable": _mm(None if remainder is None else remainder.rms_after)},
        "heldout_time_blocked_method": blocked.method}


def blocked_line(blocked: BlockedFigures) -> str:
    """The text report's line of the time-blocked figures."""
    remainder = blocked.remainder
    predictable = ("" if remainder is None else
                   f", predictable remainder {remainder.rms_after * 1e3:.4f} mm")
    return (f"held out by time instead ({blocked.method}): named effects "
            f"{blocked.extended_m * 1e3:.4f} mm{predictable} (the figures above are by pose; "
            f"a block of time is a new stretch of the acquisition: drift, and along a path a "
            f"new part of joint space, are not predicted from its neighbours)")
