"""Validation figures against an independent computation from a virtual robot's truth
(pinocchio forward kinematics, scipy's rotation alignment) and against hand arithmetic."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from olp_compensate.calibration.calibration import ToolPoint, nominal_calibration
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.measurements import Measurements
from olp_compensate.calibration.simulate import VirtualRobot, make_virtual_robot, random_joints
from olp_compensate.calibration.validation import OUTSIDE, error_stats, validate, validation_to_dict
from olp_compensate.cli import cal_validate
from olp_compensate.cli.common import run_guarded
from olp_compensate.io.calibration_file import write_calibration
from olp_compensate.kinematics.conventions import MM, rot_z
from olp_compensate.kinematics.robot import load_robot


@pytest.fixture(scope="module")
def robot():
    return load_robot("abb_irb2400")


def test_error_stats_by_hand():
    s = error_stats(np.array([1.0, 2.0, 3.0, 4.0, 10.0]) * MM)
    assert s.n == 5
    assert s.mean == pytest.approx(4.0 * MM)
    # deviations -3, -2, -1, 0, 6: squares 9 + 4 + 1 + 0 + 36 = 50; 50 / (5 - 1)
    assert s.std == pytest.approx(math.sqrt(12.5) * MM)
    assert s.median == pytest.approx(3.0 * MM)
    # 95th percentile: rank 0.95 * (5 - 1) = 3.8 -> 4 + 0.8 * (10 - 4) = 8.8
    assert s.p95 == pytest.approx(8.8 * MM)
    assert s.max == pytest.approx(10.0 * MM)
    one = error_stats([2.0 * MM])
    assert math.isnan(one.std) and one.to_dict_mm()["std"] is None


def _by_hand(errors: np.ndarray) -> dict:
    """mean, sample std, median, p95 and max computed from their definitions."""
    e = sorted(float(v) for v in errors)
    n = len(e)
    mean = sum(e) / n
    std = math.sqrt(sum((v - mean) ** 2 for v in e) / (n - 1))
    median = e[n // 2] if n % 2 else 0.5 * (e[n // 2 - 1] + e[n // 2])
    rank = 0.95 * (n - 1)
    low = int(math.floor(rank))
    p95 = e[low] + (rank - low) * (e[min(low + 1, n - 1)] - e[low])
    return {"mean": mean, "std": std, "median": median, "p95": p95, "max": e[-1]}


def _check(stats_mm: dict, errors_m: np.ndarray):
    for key, value in _by_hand(errors_m * 1e3).items():
        assert stats_mm[key] == pytest.approx(value, rel=1e-9, abs=1e-9), key


def test_figures_match_an_independent_computation_from_the_truth(robot):
    virtual = make_virtual_robot(robot, seed=11)
    rng = np.random.default_rng(5)
    q = random_joints(robot, 41, rng)
    meas = virtual.measure(q, 0.0, rng, points_per_pose=["tcp"])
    labels = ["near" if k % 3 else "far" for k in range(len(q))]
    meas = dataclasses.replace(meas, extra={"region": labels})
    # a calibration whose prediction we can compute elsewhere: the nominal arm with a
    # chosen device frame and tool point
    device = virtual.device_T_base.copy()
    device[:3, :3] = device[:3, :3] @ rot_z(0.002)
    device[:3, 3] += [0.001, -0.002, 0.0005]
    tool = virtual.tools["tcp"] + np.array([0.0004, 0.0, -0.0003])
    cal = dataclasses.replace(nominal_calibration(robot), device_T_base=device,
                              tools={"tcp": ToolPoint(xyz_m=tool)})
    report = validate(cal, meas)
    doc = validation_to_dict(report)

    # after: pinocchio on the nominal URDF, the chosen device frame and tool
    nominal_truth = VirtualRobot(robot=robot, origin_errors=np.zeros((6, 6)),
                                 joint_offsets=np.zeros(6), device_T_base=device,
                                 tools={"tcp": tool})
    after = np.linalg.norm(meas.points - nominal_truth.true_points(q, ["tcp"] * len(q)), axis=1)
    # before: the nominal arm's base-frame points registered by scipy's rotation alignment
    base = dataclasses.replace(nominal_truth, device_T_base=np.eye(4)).true_points(
        q, ["tcp"] * len(q))
    rotation, _ = Rotation.align_vectors(meas.points - meas.points.mean(0),
                                         base - base.mean(0))
    registered = rotation.apply(base - base.mean(0)) + meas.points.mean(0)
    before = np.linalg.norm(meas.points - registered, axis=1)

    assert doc["n"] == 41
    _check(doc["after_mm"], after)
    _check(doc["before_mm"], before)
    near = np.array(labels) == "near"
    assert set(doc["regions"]) == {"near", "far"}
    assert doc["regions"]["near"]["n"] == int(near.sum())
    _check(doc["regions"]["near"]["after_mm"], after[near])
    _check(doc["regions"]["far"]["before_mm"], before[~near])
    # the registration leaves errors of the arm's size (mm), not of the device's placement
    assert 0.2 < doc["before_mm"]["mean"] < 20


def test_identified_model_beats_the_registered_nominal_on_new_poses(robot):
    virtual = make_virtual_robot(robot, seed=3)
    rng = np.random.default_rng(8)
    train = virtual.measure(random_joints(robot, 40, rng), 0.03 * MM, rng)
    cal = identify(robot, train, IdentificationOptions(folds=0)).calibration
    test = virtual.measure(random_joints(robot, 80, rng), 0.03 * MM, rng)
    report = validate(cal, test)
    assert report.after.mean < 0.15 * MM
    assert report.before.mean > 5 * report.after.mean


class _Box:
    """A volume as validation sees one (base frame): name, centre, contains()."""

    def __init__(self, name, centre_m, half_m):
        self.name, self.centre_m, self.half_m = name, np.asarray(centre_m, float), half_m

    def contains(self, points):
        return np.all(np.abs(points - self.centre_m) <= self.half_m, axis=1)


def test_volumes_label_rows_and_give_the_centre(robot):
    cal = dataclasses.replace(nominal_calibration(robot),
                              tools={"tcp": ToolPoint(xyz_m=np.array([0.0, 0.0, 0.1]))})
    q = random_joints(robot, 30, np.random.default_rng(2))
    points = cal.predict_points(q, ["tcp"] * 30)
    meas = Measurements(joints=q, points=points, pose_ids=np.arange(30).astype(str),
                        point_names=np.array(["tcp"] * 30, dtype=object))
    box = _Box("cell", points[0], 0.3)
    report = validate(cal, meas, volumes=[box])
    assert np.allclose(report.centre_m, points[0])
    inside = box.contains(points)
    labels = report.labels
    assert list(labels[inside]) == ["cell"] * int(inside.sum())
    assert list(labels[~inside]) == [OUTSIDE] * int((~inside).sum())
    assert report.after.max < 1e-12          # the model is the truth here


def _write_csv(path, q_rad, points_m, regions):
    head = ",".join(f"q{k + 1}_deg" for k in range(6))
    rows = [f"pose,{head},x_mm,y_mm,z_mm,region"]
    for k, (q, p, r) in enumerate(zip(q_rad, points_m, regions)):
        rows.append(f"{k + 1}," + ",".join(f"{v:.9f}" for v in np.degrees(q)) + ","
                    + ",".join(f"{v:.6f}" for v in p / MM) + f",{r}")
    path.write_text("\n".join(rows) + "\n")


def _run(argv):
    parser = argparse.ArgumentParser()
    cal_validate.add_arguments(parser)
    args = parser.parse_args(argv)
    return run_guarded(lambda: cal_validate.run(args), 0, "olp-cal")


def test_cli_prints_writes_json_and_html(robot, tmp_path, capsys):
    virtual = make_virtual_robot(robot, seed=4)
    rng = np.random.default_rng(1)
    q = random_joints(robot, 25, rng)
    meas = virtual.measure(q, 0.0, rng)
    cal = dataclasses.replace(nominal_calibration(robot), device_T_base=virtual.device_T_base,
                              tools={"tcp": ToolPoint(xyz_m=virtual.tools["tcp"])})
    write_calibration(tmp_path / "calib.json", cal)
    _write_csv(tmp_path / "meas.csv", q, meas.points, ["R1"] * 10 + ["R2"] * 15)
    code = _run(["--model", str(tmp_path / "calib.json"), str(tmp_path / "meas.csv"),
                 "--json", str(tmp_path / "v.json"), "--html", str(tmp_path / "v.html")])
    out = capsys.readouterr().out
    assert code == 0
    assert "before" in out and "after" in out and "region R2: 15 points" in out
    doc = json.loads((tmp_path / "v.json").read_text())
    assert doc["n"] == 25 and set(doc["regions"]) == {"R1", "R2"}
    assert set(doc["after_mm"]) == {"mean", "std", "median", "p95", "max"}
    page = (tmp_path / "v.html").read_text()
    assert page.count("<img") == 4
    # never over an input
    assert _run(["--model", str(tmp_path / "calib.json"), str(tmp_path / "meas.csv"),
                 "--json", str(tmp_path / "meas.csv")]) == 1
    assert "input" in capsys.readouterr().err
