"""Issue 25 item 4: a fit that writes a file refuses (or, forced, flags) a result its own
statistics reject: identify with another robot's data, a CSV whose '# robot:' line names
another robot, per-region models worse held-out than the global one, and validate's words
when the calibration makes things worse. Truth: virtual robots of known geometry."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from olp_compensate.calibration.calibration import ToolPoint, nominal_calibration
from olp_compensate.calibration.identify import IdentificationOptions
from olp_compensate.calibration.regions import identify_regions
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.calibration.validation import change_words
from olp_compensate.cli.cal import main
from olp_compensate.io.calibration_file import read_calibration, write_calibration
from olp_compensate.io.measurements import write_measurements
from olp_compensate.kinematics.robot import load_robot


@pytest.fixture(scope="module")
def irb2400():
    return load_robot("abb_irb2400")


def _csv(path, robot, meas, robot_line: str | None):
    write_measurements(path, meas, [j.unit for j in robot.joints],
                       metadata=[f"# robot: {robot_line}"] if robot_line else None)
    return path


@pytest.fixture(scope="module")
def measured(irb2400):
    virtual = make_virtual_robot(irb2400, seed=11)
    rng = np.random.default_rng(11)
    return virtual, virtual.measure(random_joints(irb2400, 40, rng), 0.05e-3, rng)


def test_a_robot_line_naming_another_robot_is_refused(irb2400, measured, tmp_path, capsys):
    csv = _csv(tmp_path / "m.csv", irb2400, measured[1], "abb_irb2400")
    out = tmp_path / "calib.json"
    assert main(["identify", str(csv), "--robot", "ur10e", "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "'# robot: abb_irb2400'" in err and "ur10e" in err and not out.exists()
    assert len(err.strip().splitlines()) == 1
    # the robot the line names is accepted
    assert main(["identify", str(csv), "--robot", "abb_irb2400", "--folds", "0",
                 "-o", str(out)]) == 0
    assert "warnings" not in json.loads(out.read_text())


def test_a_fit_far_beyond_the_noise_is_refused_then_flagged_when_forced(
        irb2400, measured, tmp_path, capsys):
    """IRB 2400 data identified as a UR10e (no '# robot:' line to catch it): RMS residual
    hundreds of mm, refused under the shared 5 mm rule naming the worst line."""
    csv = _csv(tmp_path / "m.csv", irb2400, measured[1], None)
    out = tmp_path / "calib.json"
    argv = ["identify", str(csv), "--robot", "ur10e", "--folds", "0", "-o", str(out)]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "above the 5 mm limit" in err and "worst line" in err and "0.05 mm" in err
    assert not out.exists()
    assert main(argv + ["--force"]) == 0
    assert "WARNING" in capsys.readouterr().out
    warning = read_calibration(out).warnings
    assert len(warning) == 1 and "above the 5 mm limit" in warning[0]


def test_regions_worse_held_out_than_the_global_model_are_left_out(irb2400, tmp_path):
    """No hidden effect: the global model (all rows) is the truth's geometry and each local
    model, fitted on a third of the rows, can only be noisier. Both held-out figures say so
    and the truth agrees; the regions are kept out of the calibration olp-fix reads."""
    virtual = make_virtual_robot(irb2400, seed=5)
    rng = np.random.default_rng(5)
    q = random_joints(irb2400, 90, rng)
    meas = virtual.measure(q, 0.05e-3, rng)
    meas = dataclasses.replace(meas, extra={"region": ["A"] * 30 + ["B"] * 30 + [""] * 30})
    regional = identify_regions(irb2400, meas, IdentificationOptions(folds=5))
    assert set(regional.left_out) == {"A", "B"}
    assert regional.result.calibration.regions == ()
    assert [r.name for r in regional.candidates] == ["A", "B"]
    fresh = random_joints(irb2400, 60, np.random.default_rng(50))
    names = ["tcp"] * len(fresh)
    truth = virtual.true_points(fresh, names)
    global_error = np.linalg.norm(regional.result.calibration.predict_points(fresh, names)
                                  - truth, axis=1)
    for region in regional.candidates:
        local = region.calibration.validation.heldout_rms_mm
        assert local > region.global_heldout_rms_mm
        assert f"{local:.3f} mm" in regional.left_out[region.name]
        local_error = np.linalg.norm(region.calibration.predict_points(fresh, names) - truth,
                                     axis=1)
        assert np.sqrt(np.mean(local_error ** 2)) > np.sqrt(np.mean(global_error ** 2))


def test_cli_prints_why_a_region_is_left_out(irb2400, tmp_path, capsys):
    virtual = make_virtual_robot(irb2400, seed=5)
    rng = np.random.default_rng(5)
    meas = virtual.measure(random_joints(irb2400, 90, rng), 0.05e-3, rng)
    path = _csv(tmp_path / "m.csv", irb2400, meas, "abb_irb2400")
    lines = path.read_text().splitlines()
    header = next(k for k, line in enumerate(lines) if not line.startswith("#"))
    lines[header] += ",region"
    for k in range(90):
        lines[header + 1 + k] += "," + ("A" if k < 30 else "")
    path.write_text("\n".join(lines) + "\n")
    out = tmp_path / "calib.json"
    assert main(["identify", str(path), "--robot", "abb_irb2400", "--per-region",
                 "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "0 regions kept of 1" in text and "LEFT OUT" in text and "global model" in text
    assert "regions" not in json.loads(out.read_text())


@pytest.mark.parametrize("before_mm, after_mm, words", [
    (1.0, 0.1, "10.0x smaller"), (1.0, 1001.0, "1001.0x LARGER"), (0.5, 0.5, "unchanged"),
    (1.0, 0.0, "infinitely smaller")])
def test_validate_words_follow_the_sign_of_the_change(before_mm, after_mm, words):
    text = change_words(before_mm * 1e-3, after_mm * 1e-3)
    assert words in text
    assert ("smaller" in text) == (after_mm < before_mm)


def test_cli_validate_says_larger_when_the_calibration_is_1000_mm_off(irb2400, tmp_path,
                                                                     capsys):
    virtual = make_virtual_robot(irb2400, seed=4)
    rng = np.random.default_rng(1)
    q = random_joints(irb2400, 25, rng)
    meas = virtual.measure(q, 0.0, rng)
    wrong = dataclasses.replace(nominal_calibration(irb2400),
                                device_T_base=virtual.device_T_base,
                                tools={"tcp": ToolPoint(xyz_m=virtual.tools["tcp"]
                                                        + [1.0, 0.0, 0.0])})
    write_calibration(tmp_path / "calib.json", wrong)
    csv = _csv(tmp_path / "m.csv", irb2400, meas, None)
    assert main(["validate", "--model", str(tmp_path / "calib.json"), str(csv)]) == 0
    out = capsys.readouterr().out
    assert "LARGER after calibration" in out and "smaller" not in out
