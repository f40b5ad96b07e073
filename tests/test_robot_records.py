"""Robot records: the nine robots that were hand-written URDFs stay what they were, old
calibration files still load, and a bad record is one clear error."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.calibration.simulate import VirtualRobot, random_joints
from olp_compensate.errors import ModelError
from olp_compensate.io.calibration_file import read_calibration
from olp_compensate.kinematics.model import build_model, forward
from olp_compensate.kinematics.records import read_record
from olp_compensate.kinematics.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
LEGACY = ROOT / "tests" / "fixtures" / "legacy_robots"
LEGACY_CALIBRATIONS = ROOT / "tests" / "fixtures" / "legacy_calibrations"
FORMER = sorted(p.stem for p in LEGACY.glob("*.urdf"))


def test_the_nine_former_robots_are_kept_as_fixtures():
    assert len(FORMER) == 9
    assert sorted(p.name.split(".")[0] for p in LEGACY_CALIBRATIONS.glob("*.calib.json")) == FORMER


@pytest.mark.parametrize("name", FORMER)
def test_record_is_the_former_urdf(name):
    """Same kinematic fingerprint, forward kinematics to 1e-9 m at random joints (the record's
    and the former file's own chains), controller ranges, coupling and joint limits."""
    new = load_robot(name)
    old = load_robot(str(LEGACY / f"{name}.urdf"))   # with its .controller.json, if any
    assert new.fingerprint == old.fingerprint
    q = random_joints(old, 200, np.random.default_rng(4), margin=0.0)
    q = np.vstack([q, np.random.default_rng(5).uniform(-np.pi, np.pi, (50, 6))])
    model_new, model_old = build_model(new), build_model(old)
    a = forward(model_new, model_new.nominal, new.joints_from_controller(q)).flange
    b = forward(model_old, model_old.nominal, old.joints_from_controller(q)).flange
    assert np.max(np.abs(a - b)) < 1e-9
    np.testing.assert_allclose(new.controller_ranges, old.controller_ranges, rtol=0, atol=1e-12)
    old_coupling = np.eye(6) if old.urdf_from_controller is None else old.urdf_from_controller
    new_coupling = np.eye(6) if new.urdf_from_controller is None else new.urdf_from_controller
    np.testing.assert_array_equal(new_coupling, old_coupling)
    np.testing.assert_allclose(new.lower_limits, old.lower_limits, rtol=0, atol=1e-12)
    np.testing.assert_allclose(new.upper_limits, old.upper_limits, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", FORMER)
def test_calibration_written_before_the_records_still_loads(name):
    """A calib.json written by olp-compensate 4ee01a9 (``olp-cal nominal``, former URDFs)
    loads for the bundled robot of that name and keeps its fingerprint."""
    path = LEGACY_CALIBRATIONS / f"{name}.calib.json"
    robot = load_robot(name)
    cal = read_calibration(path, robot)
    assert cal.robot.fingerprint == robot.fingerprint
    assert json.loads(path.read_text())["robot"]["fingerprint"] == robot.fingerprint
    q = random_joints(robot, 20, np.random.default_rng(6))
    model = build_model(robot)
    expected = forward(model, model.nominal, robot.joints_from_controller(q)).flange
    np.testing.assert_allclose(cal.flange_poses(q), expected, atol=1e-9)


@pytest.mark.parametrize("sample, name", [("irb2400_truth.json", "abb_irb2400"),
                                          ("puma560_truth.json", "unimation_puma560")])
def test_shipped_virtual_robots_still_match(sample, name):
    text = (ROOT / "samples" / sample).read_text()
    VirtualRobot.from_json(text, load_robot(name))   # raises on a fingerprint mismatch


def test_a_calibration_of_another_robot_is_refused():
    with pytest.raises(ModelError, match="not for 'kuka_kr16_2'"):
        read_calibration(LEGACY_CALIBRATIONS / "abb_irb2400.calib.json", load_robot("kuka_kr16_2"))


def _write(tmp_path, doc) -> Path:
    path = tmp_path / "mine.robot.json"
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc), encoding="utf-8")
    return path


def _minimal() -> dict:
    doc = json.loads((ROOT / "robots" / "abb_irb120_3_58.robot.json").read_text())
    doc["name"] = "mine"
    return doc


def test_a_record_given_by_path_is_a_robot(tmp_path):
    robot = load_robot(str(_write(tmp_path, _minimal())))
    assert robot.name == "mine" and robot.record.maker == "ABB"
    assert robot.fingerprint == load_robot("abb_irb120_3_58").fingerprint


@pytest.mark.parametrize("change, message", [
    (lambda d: d.pop("geometry"), "'geometry' must be an object"),
    (lambda d: d["geometry"].pop("c3"), "geometry: 'c3' is missing"),
    (lambda d: d["geometry"].update(signs=[1, 1, 2, 1, 1, 1]), "'signs' must be six values"),
    (lambda d: d.update(coupling="abb_parallell"), "unknown coupling 'abb_parallell'"),
    (lambda d: d.update(axis_ranges_deg=[[0, 1]] * 5), "'axis_ranges_deg' must be six"),
    (lambda d: d.update(axis_ranges_deg=[[10, -10]] * 6), "lower <= upper"),
    (lambda d: d.update(maker=""), "'maker' must be a non-empty string"),
    (lambda d: d.update(name='x" y'), "'name' must be letters, digits"),
    (lambda d: d.update(axis_ranges_deg="wide"), "'axis_ranges_deg' must be six"),
    (lambda d: d.update(axis_ranges_deg=[[0, 1], [0]] * 3), "'axis_ranges_deg' must be six"),
    (lambda d: d.update(max_speed_deg_s=[1, 2]), "'max_speed_deg_s' must be 6 numbers"),
    (lambda d: d.update(links=[{}] * 7), "links/0: 'mass_kg' is missing"),
])
def test_a_bad_record_is_one_clear_error(tmp_path, change, message):
    doc = _minimal()
    change(doc)
    path = _write(tmp_path, doc)
    with pytest.raises(ModelError, match=message) as info:
        load_robot(str(path))
    assert str(path) in str(info.value)


def test_model_text_cannot_break_the_generated_urdf(tmp_path):
    doc = _minimal()
    doc["model"] = "IRB <120> -- & \"odd\""
    robot = load_robot(str(_write(tmp_path, doc)))
    assert robot.fingerprint == load_robot("abb_irb120_3_58").fingerprint
    assert robot.pinocchio_model.nq == 6


def test_a_record_that_is_not_json_names_line_and_column(tmp_path):
    path = _write(tmp_path, '{\n  "name": "x",\n  "maker": oops\n}')
    with pytest.raises(ModelError, match=r"mine.robot.json:3:12: not valid JSON"):
        read_record(path)


def test_a_missing_record_and_an_unknown_name_are_clear(tmp_path):
    with pytest.raises(ModelError, match="no such robot record"):
        load_robot(str(tmp_path / "none.robot.json"))
    with pytest.raises(ModelError, match="unknown robot .abb_irb9999.*olp-cal robots. lists"):
        load_robot("abb_irb9999")
