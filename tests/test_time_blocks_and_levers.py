"""Issue 28 on path data: folds in blocks of time (slow drift is not joint structure) and
the moment-arm check of the cyclic bands (a wrist axis through the measured point names
no band). Truth: virtual robots (:mod:`olp_compensate.calibration.simulate`) with the
drift, the tool and the hidden error put there by the test."""

from dataclasses import replace

import numpy as np

from olp_compensate.calibration.cross_validation import pose_folds, time_blocked_folds
from olp_compensate.calibration.cyclic_scan import BandScan
from olp_compensate.calibration.diagnose import DiagnoseOptions, diagnose, diagnosis_to_dict
from olp_compensate.calibration.effect_scan import EffectScan
from olp_compensate.calibration.effects import JointCompliance
from olp_compensate.calibration.identify import (IdentificationOptions, identify,
                                                 measurement_inputs)
from olp_compensate.calibration.simulate import (make_virtual_robot, random_cyclic_error,
                                                 random_joints, scaled_effect)
from olp_compensate.kinematics.robot import load_robot

NOISE = 0.05e-3
ROBOT = load_robot("abb_irb2400")


def test_time_blocks_are_contiguous_and_keep_a_pose_together():
    time_s = np.array([5.0, 1.0, 2.0, 9.0, 3.0, 7.0, 8.0, 4.0, 6.0, 1.0])
    poses = np.array(["e", "a", "b", "i", "c", "g", "h", "d", "f", "a"], dtype=object)
    folds = time_blocked_folds(time_s, poses, 3)
    assert len(folds) == 3 and np.all(sum(f.astype(int) for f in folds) == 1)
    firsts = [sorted(set(poses[f])) for f in folds]
    assert firsts == [["a", "b", "c"], ["d", "e", "f"], ["g", "h", "i"]]
    assert time_blocked_folds(None, poses, 3) is None
    assert time_blocked_folds(np.zeros(10), poses, 3) is None


def _path(rng, n: int) -> np.ndarray:
    """Controller joints along one smooth path (every joint a slow sine of time)."""
    t = np.linspace(0.0, 1.0, n)
    mid = 0.5 * (ROBOT.lower_limits + ROBOT.upper_limits)
    half = 0.35 * (ROBOT.upper_limits - ROBOT.lower_limits)
    freq = rng.uniform(0.6, 1.4, ROBOT.n_joints)
    phase = rng.uniform(0, 2 * np.pi, ROBOT.n_joints)
    return np.clip(mid + half * np.sin(2 * np.pi * freq * t[:, None] + phase),
                   -2.5, 2.5)


def test_slow_drift_along_a_path_is_not_named_with_time_blocks():
    rng = np.random.default_rng([28, 30])
    virtual = make_virtual_robot(ROBOT, 2830)
    joints = _path(rng, 400)
    time_s = np.linspace(0.0, 4000.0, len(joints))
    meas = virtual.measure(joints, NOISE, rng, time_s=time_s)
    # the tracker drifts: a slow 3-D wander of 6x the noise, three turns over the session
    phase = 2 * np.pi * 3 * time_s / time_s[-1]
    drift = 6 * NOISE * np.column_stack([np.sin(phase), np.cos(phase + 1), np.sin(phase + 2)])
    meas = replace(meas, points=meas.points + drift)
    options = DiagnoseOptions(kinds=("backlash",))
    blocked = diagnose(ROBOT, meas, options)
    assert not [k for k in blocked.effects if k.effect.kind == "cyclic_error"], \
        [k.effect.label for k in blocked.effects]
    doc = diagnosis_to_dict(blocked)
    assert set(doc["heldout_rms_mm"]) == {"geometric", "extended", "predictable"}
    assert doc["heldout_rms_mm_time_blocked"]["extended"] > 0
    assert "contiguous blocks of acquisition time" in doc["heldout_time_blocked_method"]
    # without the time column the folds are by pose, as before: no time-blocked keys
    plain = diagnose(ROBOT, replace(meas, time_s=None), options)
    assert "heldout_rms_mm_time_blocked" not in diagnosis_to_dict(plain)


def _arms_and_bands(tool_xyz, seed: int):
    """A cyclic error of joint 6 (order 12) that moves a point 200 mm off axis 6 by 4x the
    noise; the same angle error with the tool at ``tool_xyz`` (flange frame, m)."""
    rng = np.random.default_rng([28, seed])
    virtual = replace(make_virtual_robot(ROBOT, 2840 + seed),
                      tools={"tcp": np.array([0.2, 0.0, 0.05])})
    joints = random_joints(ROBOT, 300, rng, within_ranges=False)
    hidden = scaled_effect(virtual, random_cyclic_error(ROBOT, rng, orders=(12, 12), joint=5),
                           joints, 4 * NOISE)
    virtual = replace(virtual, effects=(hidden,), tools={"tcp": np.array(tool_xyz)})
    return virtual, joints, rng


def test_moment_arm_is_the_distance_from_the_axis_and_decides_the_wrist_band():
    for tool, expected in (((0.0, 0.0, 0.15), 0.0), ((0.2, 0.0, 0.05), 0.2)):
        virtual, joints, rng = _arms_and_bands(tool, 41)
        meas = virtual.measure(joints, NOISE, rng)
        geometric = identify(ROBOT, meas, IdentificationOptions(folds=5))
        tools = {n: t.xyz_m for n, t in geometric.calibration.tools.items()}
        inputs = measurement_inputs(ROBOT, meas, tools, [JointCompliance(joint=0)])
        scan = EffectScan(geometric, meas, inputs, pose_folds(meas.pose_ids, 5))
        arms = BandScan(scan, ROBOT, inputs.q).arms
        # axis 6 is the flange's z: the arm is the tool's distance from it, for every row
        assert abs(arms.rms_m[5] - expected) < 2e-3, arms.rms_m
        assert arms.rms_m[0] > 0.5 and arms.allows(0)
        result = diagnose(ROBOT, meas, DiagnoseOptions(kinds=("backlash",)))
        named = [k.effect.joint for k in result.effects if k.effect.kind == "cyclic_error"]
        if expected == 0.0:
            assert 5 in result.bands.short_lever and 5 not in named
        else:
            assert 5 not in result.bands.short_lever and named == [5], named
