"""A small replica of issue 28's real arm (benchmarks/issue_arm.py runs the full one): cyclic
errors of many orders on joints 1 and 2 (joint 2's strongest at 20 cycles per turn, joint
1's at 12, a floor of orders 8-30 under both), a tracker's noise, 400 random poses. The
diagnosis names joint 2's band with its dominant order, and the extended model, on poses
the diagnosis never saw, lies far closer to the truth (the virtual robot without noise,
pinocchio on the perturbed URDF) than the geometric model."""

from dataclasses import replace

import numpy as np

from olp_compensate.calibration.cyclic_scan import dominant_orders
from olp_compensate.calibration.diagnose import diagnose
from olp_compensate.calibration.simulate import (CYCLIC_KIND, HiddenEffect, make_virtual_robot,
                                                 random_joints, scaled_effect)
from olp_compensate.kinematics.robot import load_robot

NOISE = 0.05e-3
ROBOT = load_robot("abb_irb2400")


def band(peak: int, rng: np.random.Generator) -> tuple:
    """(order, weight, phase) of a band peaking at ``peak`` over a floor of orders 8-30."""
    return tuple((k, 1.0 if k == peak else 0.4 if abs(k - peak) == 1
                  else 0.15 * rng.uniform(0.5, 1.0), float(rng.uniform(-np.pi, np.pi)))
                 for k in range(8, 31))


def test_the_replica_names_joint_2s_band_and_predicts_unseen_poses():
    rng = np.random.default_rng(2828)
    virtual = make_virtual_robot(ROBOT, 2828)
    joints = random_joints(ROBOT, 400, rng)
    hidden = tuple(scaled_effect(virtual, HiddenEffect(CYCLIC_KIND, j, 1e-4, band=band(k, rng)),
                                 joints, size * NOISE)
                   for j, k, size in ((1, 20, 8.0), (0, 12, 5.0)))
    virtual = replace(virtual, effects=hidden)
    result = diagnose(ROBOT, virtual.measure(joints, NOISE, rng))
    bands = {k.effect.joint: k.effect for k in result.effects if k.effect.kind == "cyclic_error"}
    assert 1 in bands, [k.effect.label for k in result.effects]
    assert dominant_orders(bands[1])[0] == 20
    assert result.extended.heldout_rms < 0.5 * result.geometric.heldout_rms
    # unseen poses inside the fitted ranges, against the noise-free truth
    fresh = random_joints(ROBOT, 300, np.random.default_rng(2829))
    inside = np.all([(fresh[:, j] >= b.q_range[0]) & (fresh[:, j] <= b.q_range[1])
                     for j, b in bands.items()], axis=0)
    fresh = fresh[inside]
    truth = virtual.true_points(fresh, ["tcp"] * len(fresh))

    def error(calibration):
        predicted = calibration.predict_points(fresh, ["tcp"] * len(fresh))
        return float(np.sqrt(np.mean(np.sum((predicted - truth) ** 2, axis=1))))

    geometric, extended = error(result.geometric.calibration), error(result.extended.calibration)
    assert extended < 0.5 * geometric, (geometric, extended)
