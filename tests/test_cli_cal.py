"""olp-cal end to end: the command-line contract and one clear line for bad input."""

import json

import numpy as np
import pytest

from olp_compensate.cli.cal import main


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cal")
    meas, truth = folder / "meas.csv", folder / "truth.json"
    assert main(["simulate", "--robot", "abb_irb2400", "--poses", "30", "--noise-mm", "0.05",
                 "--seed", "3", "-o", str(meas), "--truth", str(truth)]) == 0
    return folder, meas, truth


def test_simulate_identify_predict_export(measured, capsys):
    folder, meas, truth = measured
    calib = folder / "calib.json"
    assert main(["identify", str(meas), "--robot", "abb_irb2400", "-o", str(calib)]) == 0
    out = capsys.readouterr().out
    for words in ("30 poses", "condition number", "frozen", "held-out", "mm"):
        assert words in out
    doc = json.loads(calib.read_text())
    assert doc["version"] == 1 and "tcp" in doc["tools"]
    points = folder / "points.csv"
    assert main(["predict", "--model", str(calib), str(meas), "-o", str(points)]) == 0
    rows = [ln.split(",") for ln in points.read_text().splitlines()]
    header = rows[0]
    assert header[-3:] == ["x_mm", "y_mm", "z_mm"] and "pose" in header
    measured_rows = [ln.split(",") for ln in meas.read_text().splitlines() if not ln.startswith("#")]
    predicted = np.array([[float(v) for v in r[-3:]] for r in rows[1:]])
    observed = np.array([[float(v) for v in r[-3:]] for r in measured_rows[1:]])
    assert np.sqrt(np.mean(np.sum((predicted - observed) ** 2, axis=1))) < 0.2  # mm
    urdf = folder / "cal.urdf"
    assert main(["export-urdf", "--model", str(calib), "-o", str(urdf)]) == 0
    assert "tcp_point" in urdf.read_text()


def test_nominal_calibration_is_the_nominal_robot(tmp_path):
    from olp_compensate.io.calibration_file import read_calibration

    out = tmp_path / "nominal.json"
    assert main(["nominal", "--robot", "ur5e", "-o", str(out)]) == 0
    cal = read_calibration(out)
    np.testing.assert_array_equal(cal.values, cal.model.nominal)
    np.testing.assert_array_equal(cal.device_T_base, np.eye(4))


def _bad(tmp_path, text):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    return path


GOOD_HEADER = "pose,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm\n"


@pytest.mark.parametrize("body,message", [
    ("pose,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm\n1,0,0,0,0,0,0,1,2\n", "missing column 'z_mm'"),
    (GOOD_HEADER + "1,0,0,0,0,0,0,1,2,nan\n", "bad.csv:2: column 'z_mm'"),
    (GOOD_HEADER + "1,0,0,abc,0,0,0,1,2,3\n", "column 'q3_deg': 'abc' is not a number"),
    (GOOD_HEADER + "1,0,0,0,0,0,0,1,2,3\n", "only 1 distinct pose"),
    ("pose,q1_deg,q2_deg,q3_deg,x_mm,y_mm,z_mm\n1,0,0,0,1,2,3\n", "3 joint columns"),
])
def test_bad_measurements_give_one_clear_line(tmp_path, capsys, body, message):
    code = main(["identify", str(_bad(tmp_path, body)), "--robot", "abb_irb2400"])
    err = capsys.readouterr().err
    assert code == 1
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_unknown_robot(tmp_path, capsys):
    assert main(["nominal", "--robot", "kuka_nonexistent", "-o", str(tmp_path / "x.json")]) == 1
    assert "unknown robot 'kuka_nonexistent'" in capsys.readouterr().err


def test_calibration_for_another_robot_or_version_is_refused(tmp_path, measured):
    from olp_compensate.errors import ModelError
    from olp_compensate.io.calibration_file import read_calibration
    from olp_compensate.kinematics.robot import load_robot

    out = tmp_path / "nominal.json"
    assert main(["nominal", "--robot", "ur5e", "-o", str(out)]) == 0
    with pytest.raises(ModelError, match="not for 'abb_irb2400'"):
        read_calibration(out, robot=load_robot("abb_irb2400"))
    doc = json.loads(out.read_text())
    doc["version"] = 2
    out.write_text(json.dumps(doc))
    with pytest.raises(ModelError, match="version 2"):
        read_calibration(out)
    doc["version"] = 1
    doc["robot"]["fingerprint"] = 12
    out.write_text(json.dumps(doc))
    with pytest.raises(ModelError, match="invalid calibration at robot/fingerprint: 12 is not"):
        read_calibration(out)


def test_calibration_schema_is_a_valid_schema():
    """The reader trusts the published schema (it is not checked at every read)."""
    import jsonschema

    from olp_compensate.io.calibration_file import calibration_schema

    schema = calibration_schema()
    jsonschema.validators.validator_for(schema).check_schema(schema)


def test_inputs_are_never_overwritten_and_output_is_atomic(tmp_path, measured):
    folder, meas, _ = measured
    before = meas.read_bytes()
    calib = tmp_path / "calib.json"
    assert main(["identify", str(meas), "--robot", "abb_irb2400", "-o", str(calib), "--folds", "0"]) == 0
    assert meas.read_bytes() == before
    assert not list(tmp_path.glob("*.tmp"))


def test_help_and_unknown_commands_list_every_command(capsys):
    """Only the chosen command's sub-parser is built; without one (help, a typo) every
    command is still listed."""
    from olp_compensate.cli.cal import COMMANDS

    for argv, stream in ((["--help"], "out"), (["idnetify", "x.csv"], "err")):
        with pytest.raises(SystemExit):
            main(argv)
        text = getattr(capsys.readouterr(), stream)
        assert all(name in text for name in COMMANDS), (argv, text)
    with pytest.raises(SystemExit) as stop:
        main(["identify", "--help"])
    assert stop.value.code == 0 and "--robot" in capsys.readouterr().out
