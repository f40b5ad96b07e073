"""Cyclic angle errors of any order (issue 28): virtual robots hide one (the truth is the
virtual robot's pinocchio model, :mod:`olp_compensate.calibration.simulate`), the
diagnosis names it on the right joint with the right dominant order, the extended model
holds only where it was fitted, and the residual map and the remainder's account say
what they measured. benchmarks/cyclic.py runs more cases."""

import json
from dataclasses import replace

import numpy as np
import pytest

from olp_compensate.calibration.cyclic_scan import dominant_orders, resolvable_order
from olp_compensate.calibration.diagnose import diagnose, diagnosis_to_dict
from olp_compensate.calibration.effects import CyclicError, EffectInputs, effect_from_dict
from olp_compensate.calibration.simulate import (make_virtual_robot, random_cyclic_error,
                                                 random_joints, scaled_effect)
from olp_compensate.cli.cal import main
from olp_compensate.io.calibration_file import read_calibration
from olp_compensate.io.measurements import write_measurements
from olp_compensate.kinematics.robot import load_robot

NOISE = 0.05e-3
ROBOT = load_robot("abb_irb2400")


def cyclic_case(seed: int, poses: int = 300, band: bool = False, factor: float = 4.0,
                joint: int | None = None):
    """(virtual robot, joints, hidden effect): a cyclic error of orders 5-40 moving the
    measured point by ``factor`` x the per-axis noise (RMS)."""
    rng = np.random.default_rng([28, seed])
    virtual = make_virtual_robot(ROBOT, 2800 + seed)
    joints = random_joints(ROBOT, poses, rng, within_ranges=False)
    hidden = random_cyclic_error(ROBOT, rng, band=band, joint=joint)
    hidden = scaled_effect(virtual, hidden, joints, factor * NOISE)
    return replace(virtual, effects=(hidden,)), joints, hidden, rng


@pytest.mark.parametrize("seed,band", [(0, False), (1, False), (2, True)])
def test_a_cyclic_error_is_named_on_its_joint_with_its_order(seed, band):
    virtual, joints, hidden, rng = cyclic_case(seed, band=band)
    result = diagnose(ROBOT, virtual.measure(joints, NOISE, rng))
    assert [(k.effect.kind, k.effect.joint) for k in result.effects] == [
        ("cyclic_error", hidden.joint)], (hidden, [k.effect.label for k in result.effects])
    assert dominant_orders(result.effects[0].effect)[0] == hidden.dominant_order
    sigma3 = NOISE * np.sqrt(3)
    assert result.extended.heldout_rms < 1.25 * sigma3 < result.geometric.heldout_rms
    doc = diagnosis_to_dict(result)
    entry = doc["effects"][0]
    assert entry["joint"] == hidden.joint + 1 and entry["dominant_orders"][0] == hidden.dominant_order
    assert "cyclic angle error, dominant orders" in entry["text"]
    # nothing predictable is left, and the noise floor is the noise (no repeated poses: an
    # upper bound, held-out errors carry the models' own estimation error)
    assert doc["heldout_rms_mm"]["predictable"] <= doc["heldout_rms_mm"]["extended"]
    assert 0.95 * NOISE * 1e3 < doc["noise_mm"] < 1.25 * NOISE * 1e3


def test_effect_free_robots_name_no_cyclic_error():
    for seed in range(2):
        rng = np.random.default_rng([29, seed])
        virtual = make_virtual_robot(ROBOT, 2900 + seed)
        result = diagnose(ROBOT, virtual.measure(random_joints(ROBOT, 200, rng), NOISE, rng))
        assert result.effects == [], [k.effect.label for k in result.effects]
        assert all(not r.significant for r in result.bands.rounds[0])


def test_targets_outside_the_fitted_range_fall_back_and_are_no_worse():
    virtual, joints, hidden, rng = cyclic_case(5, poses=500, joint=1)
    q2 = joints[:, 1]
    cut = np.quantile(q2, 0.7)
    result = diagnose(ROBOT, virtual.measure(joints[q2 < cut], NOISE, rng))
    (kept,) = result.effects
    assert kept.effect.q_range[1] < cut
    outside = joints[q2 >= cut]
    names = ["tcp"] * len(outside)
    truth = virtual.true_points(outside, names)

    def rms(cal):
        return np.sqrt(np.mean(np.sum((cal.predict_points(outside, names) - truth) ** 2, axis=1)))
    assert rms(result.extended.calibration) <= 1.05 * rms(result.geometric.calibration)
    inputs = EffectInputs(q=outside)
    assert np.all(kept.effect.evaluate(inputs) == 0.0)


def test_cyclic_effect_derivatives_and_file_round_trip():
    rng = np.random.default_rng(3)
    effect = CyclicError(joint=2, max_order=7, q_range=(-1.0, 1.2),
                         values=tuple(rng.normal(0, 1e-4, 14)))
    q = rng.uniform(-0.9, 1.1, (20, 6))
    step = 1e-6
    shifted = q.copy()
    shifted[:, 2] += step
    numeric = (effect.evaluate(EffectInputs(q=shifted))
               - effect.evaluate(EffectInputs(q=q))) / step
    analytic = effect.evaluate_dq(EffectInputs(q=q))[:, 2]
    assert np.allclose(numeric, analytic, rtol=1e-4, atol=1e-9)
    again = effect_from_dict(json.loads(json.dumps(effect.to_dict())), 6)
    assert (again.joint, again.values, again.max_order, again.q_range) == (
        effect.joint, effect.values, effect.max_order, effect.q_range)
    assert effect.amplitudes().shape == (7,)


def test_resolvable_order_follows_the_spread_and_density_of_the_angles():
    dense = np.linspace(-np.pi, np.pi, 3000)
    assert resolvable_order(dense, 9000) == 48
    assert resolvable_order(np.linspace(-np.pi, np.pi, 60), 180) == 9  # 10 % of 180 equations
    assert resolvable_order(np.linspace(-0.1, 0.1, 300), 900) == 45  # 8 deg periods in 11.5
    assert resolvable_order(np.linspace(-0.01, 0.01, 300), 900) == 0  # no period fits
    assert resolvable_order(np.full(50, 0.3), 150) == 0


def test_cli_residual_map_is_stored_applied_inside_and_refused_outside(tmp_path, capsys):
    rng = np.random.default_rng(31)
    virtual = make_virtual_robot(ROBOT, 31)
    joints = random_joints(ROBOT, 300, rng, within_ranges=False)
    hidden = scaled_effect(virtual, random_cyclic_error(ROBOT, rng, orders=(1, 1), joint=0),
                           joints, 6 * NOISE)
    virtual = replace(virtual, effects=(hidden,))
    units = [j.unit for j in ROBOT.joints]
    meas = tmp_path / "meas.csv"
    write_measurements(meas, virtual.measure(joints, NOISE, rng), units)
    calib = tmp_path / "calib.json"
    # nothing may be named: the cyclic error stays in the remainder, for the map to take
    assert main(["diagnose", str(meas), "--robot", "abb_irb2400", "-o", str(calib), "--json",
                 str(tmp_path / "d.json"), "--residual-map", "--kinds", "backlash",
                 "--no-cyclic"]) == 0
    text = capsys.readouterr().out
    assert "residual map stored" in text
    doc = json.loads((tmp_path / "d.json").read_text())
    held = doc["heldout_rms_mm"]
    assert held["predictable"] < 0.85 * held["extended"]
    cal = read_calibration(calib)
    assert cal.residual_map is not None
    raw = json.loads(calib.read_text())["residual_map"]
    assert raw["kind"] == "random_fourier_ridge" and raw["validation"]["heldout_rms_mm_with"] > 0
    # fresh poses of the same robot, half of them beyond the fitted range of axis 1
    fresh = random_joints(ROBOT, 40, rng, within_ranges=False)
    fresh[20:, 0] = cal.residual_map.q_range[0, 1] + 0.05
    fresh = fresh[np.all(fresh <= ROBOT.upper_limits, axis=1)]
    targets = virtual.measure(fresh, 0.0, rng)
    write_measurements(tmp_path / "fresh.csv", targets, units)
    outputs = {}
    for flag in ([], ["--no-residual-map"]):
        out = tmp_path / f"p{len(flag)}.csv"
        assert main(["predict", "--model", str(calib), str(tmp_path / "fresh.csv"), "-o",
                     str(out)] + flag) == 0
        rows = [ln.split(",") for ln in out.read_text().splitlines() if not ln.startswith("#")]
        cols = [rows[0].index(c) for c in ("x_mm", "y_mm", "z_mm")]
        outputs[len(flag)] = np.array([[float(r[c]) for c in cols] for r in rows[1:]]) * 1e-3
    text = capsys.readouterr().out
    inside = cal.residual_map.inside(fresh)
    assert 15 <= inside.sum() <= 20 and not inside[20:].any()
    assert "residual map" in text and f"applied to {inside.sum()} of {len(fresh)}" in text
    assert "outside the joint region of the residual map" in text
    err = {k: np.linalg.norm(v - targets.points, axis=1) for k, v in outputs.items()}
    assert np.sqrt(np.mean(err[0][inside] ** 2)) < 0.85 * np.sqrt(np.mean(err[1][inside] ** 2))
    assert np.array_equal(outputs[0][~inside], outputs[1][~inside])


def test_olp_fix_residual_map_pass_reaches_the_target_on_the_model_plus_map():
    """The truth here is the calibration plus its residual map (a map built at random):
    after the pass, that arm puts the flange on the desired position."""
    from olp_compensate.calibration.calibration import nominal_calibration
    from olp_compensate.calibration.remainder import ResidualMap
    from olp_compensate.compensation.pose import Compensator
    from olp_compensate.compensation.residual_map import APPLIED

    rng = np.random.default_rng(5)
    cal = nominal_calibration(ROBOT)
    n_in, features = 12, 20
    rmap = ResidualMap(kinds=("revolute",) * 6, center=np.zeros(6), span=np.ones(6),
                       frequencies=rng.standard_normal((n_in, features)),
                       phases=rng.uniform(0, 2 * np.pi, features), weights=np.zeros((1, 3)),
                       length=1.0, penalty=1.0,
                       q_range=np.column_stack([ROBOT.lower_limits, ROBOT.upper_limits]))
    p = rmap.features(np.zeros((1, 6))).shape[1]
    rmap = replace(rmap, weights=rng.normal(0, 1e-4, (p, 3)))
    comp = Compensator(replace(cal, residual_map=rmap))
    joints = random_joints(ROBOT, 12, rng)
    desired = cal.flange_poses(joints)
    q, flange, solution, _ = comp.compensate_flanges(desired, None, comp.confdata(
        ROBOT.joints_from_controller(joints)))
    notes = [""] * len(q)
    q2 = comp.fitted_parts(desired, q, flange, solution.success, notes).q
    q2_ctrl = ROBOT.controller_from_joints(q2)
    reached = cal.flange_poses(q2_ctrl)[:, :3, 3] + rmap.predict(q2_ctrl)  # device = base
    before = cal.flange_poses(ROBOT.controller_from_joints(q))[:, :3, 3] + rmap.predict(
        ROBOT.controller_from_joints(q))
    ok = solution.success
    assert ok.sum() >= 10 and all(n == APPLIED for n, k in zip(notes, ok) if k)
    miss_before = np.linalg.norm(before[ok] - desired[ok, :3, 3], axis=1)
    miss_after = np.linalg.norm(reached[ok] - desired[ok, :3, 3], axis=1)
    assert miss_before.max() > 2e-4 and miss_after.max() < 0.1 * miss_before.max()


def test_cli_simulate_hides_a_cyclic_error_of_the_order_asked(tmp_path):
    truth = tmp_path / "truth.json"
    assert main(["simulate", "--robot", "abb_irb2400", "--poses", "20", "--seed", "3",
                 "--effect", "cyclic_error:2:0.0003:17", "-o", str(tmp_path / "m.csv"),
                 "--truth", str(truth)]) == 0
    (effect,) = json.loads(truth.read_text())["hidden_effects"]
    assert effect["kind"] == "cyclic_error" and effect["joint"] == 2
    assert effect["value"] == 0.0003 and [k for k, _, _ in effect["band"]] == [17]
    assert main(["simulate", "--robot", "abb_irb2400", "--poses", "5", "--effect",
                 "gear_harmonic:2::17", "-o", str(tmp_path / "n.csv")]) == 1
