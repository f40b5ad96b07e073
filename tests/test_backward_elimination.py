"""Backward elimination after the cyclic bands (issue 28): a virtual robot whose only
non-geometric error is a cyclic error of joint 2 (orders 2-40, peak 20, like the replica
of the issue's arm) makes the forward scan name a backlash and a gear harmonic of joint 2
it does not have; once the band is in they are dropped. A robot with a real backlash and
a cyclic error keeps both. The truth is the virtual robot (pinocchio on its URDF)."""

from dataclasses import replace

import numpy as np
import pytest

from olp_compensate.calibration.cross_validation import time_blocked_folds
from olp_compensate.calibration.diagnose import (DiagnoseOptions, diagnose, diagnosis_to_dict,
                                                 summary)
from olp_compensate.calibration.simulate import (CYCLIC_KIND, HiddenEffect, make_virtual_robot,
                                                 random_joints, scaled_effect)
from olp_compensate.kinematics.robot import load_robot

NOISE = 0.05e-3
ROBOT = load_robot("abb_irb2400")


def band(peak: int, rng: np.random.Generator) -> tuple:
    """(order, weight, phase) of orders 2-40: ``peak`` at 1, its neighbours at 0.4, the
    rest at 0.35 x U(0.3, 1) (x 1.3 below order 8)."""
    return tuple((k, 1.0 if k == peak else 0.4 if abs(k - peak) == 1
                  else 0.35 * rng.uniform(0.3, 1.0) * (1.3 if k < 8 else 1.0),
                  float(rng.uniform(-np.pi, np.pi))) for k in range(2, 41))


def case(seed: int, backlash_noise: float = 0.0, backlash_joint: int = 1, poses: int = 800):
    """(virtual robot, joints, rng): ``poses`` poses, joint 2's cyclic error moving the point by
    12x the noise (RMS), and with ``backlash_noise`` > 0 a backlash of ``backlash_joint``
    (0-based) moving it by that many times the noise."""
    rng = np.random.default_rng([77, seed])
    virtual = make_virtual_robot(ROBOT, 7700 + seed)
    joints = random_joints(ROBOT, poses, rng)
    hidden = [scaled_effect(virtual, HiddenEffect(CYCLIC_KIND, 1, 1e-4, band=band(20, rng)),
                            joints, 12 * NOISE)]
    if backlash_noise:
        hidden.append(scaled_effect(virtual, HiddenEffect("backlash", backlash_joint, 1e-4), joints,
                                    backlash_noise * NOISE))
    return replace(virtual, effects=tuple(hidden)), joints, rng


def test_a_backlash_the_band_explains_is_dropped_after_the_band():
    virtual, joints, rng = case(2)
    result = diagnose(ROBOT, virtual.measure(joints, NOISE, rng))
    # the forward scan (before the bands) names what the truth does not have
    named_first = [r.chosen.kind for r in result.rounds if r.chosen is not None]
    assert "backlash" in named_first, named_first
    kept = [(k.effect.kind, k.effect.joint) for k in result.effects]
    assert kept == [(CYCLIC_KIND, 1)], kept
    dropped = [s.effect.kind for s in result.elimination if s.dropped]
    assert "backlash" in dropped, result.elimination
    assert "dropped after the bands: backlash j2" in summary(result)
    doc = diagnosis_to_dict(result)
    assert [e["kind"] for e in doc["effects"]] == [CYCLIC_KIND]
    assert any(s["dropped"] and s["kind"] == "backlash" and s["joint"] == 2
               for s in doc["backward_elimination"])
    # the model without the dropped effects still predicts unseen poses better than the
    # geometry, against the noise-free truth
    fresh = random_joints(ROBOT, 300, np.random.default_rng([77, 99]))
    q_lo, q_hi = result.effects[0].effect.q_range
    fresh = fresh[(fresh[:, 1] >= q_lo) & (fresh[:, 1] <= q_hi)]
    truth = virtual.true_points(fresh, ["tcp"] * len(fresh))

    def error(calibration):
        predicted = calibration.predict_points(fresh, ["tcp"] * len(fresh))
        return float(np.sqrt(np.mean(np.sum((predicted - truth) ** 2, axis=1))))

    assert error(result.extended.calibration) < 0.5 * error(result.geometric.calibration)


def test_a_real_backlash_and_a_band_are_both_kept():
    virtual, joints, rng = case(2, backlash_noise=10.0, backlash_joint=1)
    result = diagnose(ROBOT, virtual.measure(joints, NOISE, rng))
    kept = {(k.effect.kind, k.effect.joint) for k in result.effects}
    assert kept == {("backlash", 1), (CYCLIC_KIND, 1)}, kept
    assert not any(s.dropped and s.effect.kind == "backlash"
                   for s in result.elimination)
    backlash = next(k.effect for k in result.effects if k.effect.kind == "backlash")
    true_gap = next(e.value for e in virtual.effects if e.kind == "backlash")
    assert abs(backlash.values[0] / true_gap - 1) < 0.2, (backlash.values, true_gap)


def test_with_acquisition_times_the_elimination_runs_on_the_time_blocks():
    virtual, joints, rng = case(2)
    meas = virtual.measure(joints, NOISE, rng, time_s=np.arange(len(joints)) * 2.0)
    result = diagnose(ROBOT, meas)
    blocks = time_blocked_folds(meas.time_s, meas.pose_ids, 5)
    assert all(np.array_equal(eq, np.repeat(block, 3))
               for eq, block in zip(result.bands.scan.fold_eq, blocks))
    assert [(k.effect.kind, k.effect.joint) for k in result.effects] == [(CYCLIC_KIND, 1)]
    assert any(s.dropped for s in result.elimination)


@pytest.mark.slow
def test_a_weaker_backlash_beside_a_band_is_named_by_the_scan_after_the_bands():
    """A 6x-noise backlash of joint 3 beside a 12x-noise cyclic error of joint 2: before
    the bands it is not significant (the band's error dominates), and without the scan
    after the bands a high-order band of joint 3 stood in for it (checked on these 400
    poses, backlash candidates only, with the scan after the bands switched off: bands of
    joints 2 and 3 named). Now it is named, within 20 % of its true gap, and joint 3 gets
    no band. (Backlash candidates only: the same outcome at half the time.)"""
    virtual, joints, rng = case(2, backlash_noise=6.0, backlash_joint=2, poses=400)
    result = diagnose(ROBOT, virtual.measure(joints, NOISE, rng),
                      DiagnoseOptions(kinds=("backlash",)))
    kept = {(k.effect.kind, k.effect.joint) for k in result.effects}
    assert kept == {("backlash", 2), (CYCLIC_KIND, 1)}, kept
    assert any(r.chosen is not None and r.chosen.kind == "backlash" for r in result.after_bands)
    backlash = next(k.effect for k in result.effects if k.effect.kind == "backlash")
    true_gap = next(e.value for e in virtual.effects if e.kind == "backlash")
    assert abs(backlash.values[0] / true_gap - 1) < 0.2, (backlash.values, true_gap)
    doc = diagnosis_to_dict(result)
    assert doc["effect_scan_after_bands"][0]["chosen"] == "backlash j3"
    assert "effect scan after the bands, round 1" in summary(result)
