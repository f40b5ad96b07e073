"""Named effects hold only in the joint ranges they were fitted on (issue 28): outside,
predict and olp-fix use the geometric model of the same rows, with a note. The truth is
a virtual robot (:mod:`olp_compensate.calibration.simulate`) and, for the geometric model,
an independent ``olp-cal identify`` of the same measurements."""

import json
from dataclasses import replace

import numpy as np

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.effect_ranges import (outside_fitted, with_fitted_ranges,
                                                      with_geometric_fallback)
from olp_compensate.calibration.effects import GearHarmonic
from olp_compensate.calibration.simulate import (make_virtual_robot, random_cyclic_error,
                                                 random_joints, scaled_effect)
from olp_compensate.cli.cal import main
from olp_compensate.io.calibration_file import (calibration_from_dict, calibration_to_dict,
                                                read_calibration)
from olp_compensate.io.measurements import write_measurements
from olp_compensate.kinematics.robot import load_robot

NOISE = 0.05e-3
ROBOT = load_robot("abb_irb2400")


def _predict(tmp_path, calib, joints_csv, name):
    out = tmp_path / name
    assert main(["predict", "--model", str(calib), str(joints_csv), "-o", str(out)]) == 0
    rows = [ln.split(",") for ln in out.read_text().splitlines() if not ln.startswith("#")]
    cols = [rows[0].index(c) for c in ("x_mm", "y_mm", "z_mm")]
    return np.array([[float(r[c]) for c in cols] for r in rows[1:]]) * 1e-3


def test_an_effect_fitted_on_half_of_joint_2_falls_back_to_geometry_on_the_other(
        tmp_path, capsys):
    rng = np.random.default_rng([28, 7])
    virtual = make_virtual_robot(ROBOT, 2807)
    joints = random_joints(ROBOT, 600, rng)
    hidden = scaled_effect(virtual, random_cyclic_error(ROBOT, rng, orders=(8, 8), joint=1),
                           joints, 5 * NOISE)
    virtual = replace(virtual, effects=(hidden,))
    cut = np.median(joints[:, 1])
    fit = joints[joints[:, 1] < cut][:300]
    fresh = random_joints(ROBOT, 300, rng)
    fresh = np.vstack([fresh[fresh[:, 1] >= cut][:40], fresh[fresh[:, 1] < cut - 0.05][:40]])
    units = [j.unit for j in ROBOT.joints]
    write_measurements(tmp_path / "meas.csv", virtual.measure(fit, NOISE, rng), units)
    truth = virtual.measure(fresh, 0.0, rng)
    write_measurements(tmp_path / "fresh.csv", truth, units)
    calib, geo = tmp_path / "calib.json", tmp_path / "geo.json"
    assert main(["diagnose", str(tmp_path / "meas.csv"), "--robot", "abb_irb2400", "-o",
                 str(calib), "--kinds", "joint_scale"]) == 0
    assert main(["identify", str(tmp_path / "meas.csv"), "--robot", "abb_irb2400", "-o",
                 str(geo)]) == 0
    cal = read_calibration(calib)
    assert [e.kind for e in cal.effects] == ["cyclic_error"] and cal.effects[0].joint == 1
    assert cal.effects[0].fitted_range[1][2] < cut and cal.geometric_fallback is not None
    capsys.readouterr()
    extended = _predict(tmp_path, calib, tmp_path / "fresh.csv", "ext.csv")
    notes = capsys.readouterr().out
    geometric = _predict(tmp_path, geo, tmp_path / "fresh.csv", "geo_out.csv")
    outside = cal.outside_fitted(fresh)
    assert outside[:40].all() and (~outside[40:]).sum() >= 30
    # outside: the geometric model's prediction, to the 1e-6 mm printed
    assert np.allclose(extended[outside], geometric[outside], atol=2e-9, rtol=0)
    lines = [ln for ln in notes.splitlines() if "geometric model used" in ln]
    assert len(lines) == outside.sum() and sum("q2 = " in ln for ln in lines) >= 40
    assert f"{outside.sum()} of {len(fresh)} rows lie outside the joint ranges" in notes
    # inside: the effect is used, and it is the better model of the truth there
    err = {k: np.linalg.norm(v[~outside] - truth.points[~outside], axis=1)
           for k, v in (("ext", extended), ("geo", geometric))}
    assert np.sqrt(np.mean(err["ext"] ** 2)) < 0.7 * np.sqrt(np.mean(err["geo"] ** 2))


def _pair(rng):
    """(extended, geometric): a nominal arm with a gear harmonic of joint 2 fitted on
    q2 < 0.1 rad, and a geometric model that differs from it by 0.3 mm offsets."""
    geometric = nominal_calibration(ROBOT)
    values = geometric.values + rng.normal(0, 3e-4, geometric.values.shape)
    geometric = replace(geometric, values=values)
    effect = GearHarmonic(joint=1, order=2, values=(2e-4, -1e-4))
    ranges = np.clip(ROBOT.controller_ranges, -np.pi, np.pi)
    fitted = ranges.T.copy()  # the whole range of every axis but 2, fitted below 0.1 rad
    fitted[1, 1] = 0.1
    extended = replace(nominal_calibration(ROBOT), effects=(effect,))
    return with_geometric_fallback(extended, geometric, fitted), geometric


def test_file_round_trip_and_older_files_use_the_effects_everywhere():
    rng = np.random.default_rng(11)
    cal, geometric = _pair(rng)
    again = calibration_from_dict(json.loads(json.dumps(calibration_to_dict(cal))))
    assert again.effects[0].fitted_range == cal.effects[0].fitted_range
    assert np.allclose(again.geometric_fallback.values, geometric.values)
    q = random_joints(ROBOT, 50, rng)
    outside = q[:, 1] > cal.effects[0].fitted_range[1][2]
    assert outside.any() and (~outside).any()
    assert np.array_equal(again.outside_fitted(q), outside)
    assert np.allclose(again.flange_poses(q)[outside], geometric.flange_poses(q[outside]))
    inside_ext = replace(cal, geometric_fallback=None).flange_poses(q[~outside])
    assert np.allclose(again.flange_poses(q)[~outside], inside_ext)
    # an older file: no ranges, no fallback -> the effect everywhere, as before
    doc = calibration_to_dict(cal)
    doc.pop("geometric_fallback")
    for e in doc["effects"]:
        e.pop("fitted_range")
    old = calibration_from_dict(doc)
    assert not old.outside_fitted(q).any()
    assert np.allclose(old.flange_poses(q), replace(cal, geometric_fallback=None).flange_poses(q))
    assert outside_fitted(with_fitted_ranges(cal.effects, q), q).sum() == 0


def test_olp_fix_pass_solves_outside_rows_on_the_geometric_model():
    from olp_compensate.compensation.pose import Compensator

    rng = np.random.default_rng(12)
    cal, geometric = _pair(rng)
    comp = Compensator(cal)
    joints = random_joints(ROBOT, 30, rng)
    desired = nominal_calibration(ROBOT).flange_poses(joints)
    q, flange, solution, _ = comp.compensate_flanges(desired, None, comp.confdata(
        ROBOT.joints_from_controller(joints)))
    ok = solution.success
    notes = [""] * len(q)
    parts = comp.fitted_parts(desired, q, flange, ok, notes)
    q2 = parts.q
    q2_ctrl = ROBOT.controller_from_joints(q2)
    outside = ok & cal.outside_fitted(ROBOT.controller_from_joints(q))
    inside = ok & ~outside
    assert outside.sum() >= 5 and inside.sum() >= 5
    # outside: the geometric model reaches the target; inside: the extended model does
    reach_geo = geometric.flange_poses(q2_ctrl[outside])[:, :3, 3]
    assert np.abs(reach_geo - desired[outside, :3, 3]).max() < 1e-8
    reach_ext = replace(cal, geometric_fallback=None).flange_poses(q2_ctrl[inside])[:, :3, 3]
    assert np.abs(reach_ext - desired[inside, :3, 3]).max() < 1e-8
    assert np.array_equal(q2[inside], q[inside])
    assert np.array_equal(parts.fallback, outside)   # every outside row reached geometrically
    for i in np.flatnonzero(ok):
        assert ("geometric model used" in notes[i]) == parts.fallback[i]
    assert sum("geometric model used" in n for n in notes) >= 0.8 * outside.sum()
