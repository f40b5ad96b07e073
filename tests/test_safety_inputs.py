"""Finite numbers in and out, spreadsheet CSVs, degenerate data, the program's robot."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.cli import fix as fix_cli
from olp_compensate.cli.cal import main as cal
from olp_compensate.cli.fix import main as fix
from olp_compensate.errors import DataError
from olp_compensate.io.measurements import parse_cell_number, read_measurements

SAMPLES = Path(__file__).resolve().parent.parent / "samples"
MEAS = SAMPLES / "irb2400_measurements.csv"
ROBOT = "abb_irb2400"


def _lines(path: Path) -> tuple[list[str], int]:
    lines = path.read_text().splitlines()
    return lines, next(k for k, ln in enumerate(lines) if ln.startswith("pose"))


def _err(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    return err


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("model") / "c.json"
    assert cal(["nominal", "--robot", ROBOT, "-o", str(path)]) == 0
    return path


def test_a_byte_order_mark_and_semicolons_read_as_the_plain_file(tmp_path):
    lines, h = _lines(MEAS)
    plain = read_measurements(MEAS, ["deg"] * 6)
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + "\n".join(lines[h:]).encode() + b"\n")
    german = tmp_path / "de.csv"
    german.write_text("\n".join(ln if ln.startswith("#") else
                                ln.replace(",", ";").replace(".", ",") for ln in lines) + "\n")
    for path in (bom, german):
        read = read_measurements(path, ["deg"] * 6)
        assert np.array_equal(read.joints, plain.joints)
        assert np.array_equal(read.points, plain.points)
        assert list(read.pose_ids) == list(plain.pose_ids)


def test_a_thousands_separator_is_refused_not_misread():
    assert parse_cell_number("1,5", "f.csv", 2, "x_mm", decimal_comma=True) == 1.5
    with pytest.raises(DataError, match="thousands separator"):
        parse_cell_number("1.234,5", "f.csv", 2, "x_mm", decimal_comma=True)
    with pytest.raises(DataError, match="not a number"):
        parse_cell_number("1,5", "f.csv", 2, "x_mm")


@pytest.mark.parametrize("text", ["nan", "inf", "-Infinity", "1e308", "1e7"])
def test_non_finite_and_implausible_cells_name_file_line_and_column(text):
    with pytest.raises(DataError, match=r"f\.csv:7: column 'x_mm'"):
        parse_cell_number(text, "f.csv", 7, "x_mm")


def test_a_309_digit_number_is_not_printed_whole():
    with pytest.raises(DataError) as caught:
        parse_cell_number("9" * 309, "f.csv", 2, "q1_deg")
    assert len(str(caught.value)) < 200


def test_a_marks_file_with_a_byte_order_mark_reads(tmp_path, capsys):
    marks = tmp_path / "marks.csv"
    marks.write_bytes(b"\xef\xbb\xbf" + (SAMPLES / "marks.csv").read_bytes())
    assert cal(["tool", "--robot", ROBOT, "--marks", str(marks), "-o",
                str(tmp_path / "t.json")]) == 0, capsys.readouterr().err
    assert "tGripper" in json.loads((tmp_path / "t.json").read_text())["tools"]


def _mutated_measurements(tmp_path: Path, change) -> Path:
    lines, h = _lines(MEAS)
    rows = [r.split(",") for r in lines[h + 1:]]
    rows = change(rows)
    path = tmp_path / "m.csv"
    path.write_text("\n".join(lines[:h + 1] + [",".join(r) for r in rows]) + "\n")
    return path


@pytest.mark.parametrize("change, words", [
    (lambda rows: [r[:-3] + ["0", "0", "0"] for r in rows], "every measured point is the same"),
    (lambda rows: [rows[0]] * 40, "only 1 distinct pose"),
    (lambda rows: [rows[0][:-1] + ["1e308"]] + rows[1:], "m.csv:5: column 'z_mm'"),
])
def test_degenerate_measurements_are_refused_with_what_to_add(tmp_path, capsys, change,
                                                              words):
    path = _mutated_measurements(tmp_path, change)
    out = tmp_path / "c.json"
    assert cal(["identify", str(path), "--robot", ROBOT, "-o", str(out)]) == 1
    assert words in _err(capsys)
    assert not out.exists()


def test_predict_counts_comment_lines_and_refuses_joints_beyond_the_limits(tmp_path, capsys,
                                                                           model):
    joints = tmp_path / "j.csv"
    joints.write_text("# a\n# b\nq1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,30,0\n"
                      "0,0,0,0,30,0\n720,0,0,0,0,0\n")
    out = tmp_path / "p.csv"
    assert cal(["predict", "--model", str(model), str(joints), "-o", str(out)]) == 1
    assert "j.csv:6: q1 = 720" in _err(capsys)
    assert not out.exists()


def test_a_nan_in_the_calibration_is_named_by_its_json_path(tmp_path, capsys, model):
    doc = json.loads(model.read_text())
    doc["model"]["parameters"][4]["value"] = float("nan")
    bad = tmp_path / "nan.json"
    bad.write_text(json.dumps(doc))
    name = doc["model"]["parameters"][4]["name"]
    for argv in (["export-urdf", "--model", str(bad), "-o", str(tmp_path / "x.urdf")],
                 ["predict", "--model", str(bad), str(SAMPLES / "joints.csv"), "-o",
                  str(tmp_path / "p.csv")]):
        assert cal(argv) == 1
        assert f"model/parameters/4/value ({name}): nan" in _err(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nan.json"]


def test_the_calibration_writer_never_writes_a_non_finite_number(tmp_path, model):
    from dataclasses import replace

    from olp_compensate.io.calibration_file import read_calibration, write_calibration

    cal_ = read_calibration(model)
    values = cal_.values.copy()
    values[3] = np.inf
    with pytest.raises(DataError, match="model/parameters/3/value"):
        write_calibration(tmp_path / "x.json", replace(cal_, values=values))
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("mark", ["0", "1e308"])
def test_tool_marks_all_at_zero_or_huge_write_nothing(tmp_path, capsys, mark):
    lines = (SAMPLES / "marks.csv").read_text().splitlines()
    rows = [ln.split(",") for ln in lines[3:]]
    if mark == "0":
        rows = [r[:7] + ["0", "0", "0"] + r[10:] for r in rows]
    else:
        rows[0][7] = mark
    marks = tmp_path / "k.csv"
    marks.write_text("\n".join(lines[:3] + [",".join(r) for r in rows]) + "\n")
    out = tmp_path / "t.json"
    assert cal(["tool", "--robot", ROBOT, "--marks", str(marks), "-o", str(out)]) == 1
    capsys.readouterr()
    assert not out.exists()


def test_a_tool_fit_far_off_one_point_is_refused(tmp_path, capsys):
    lines = (SAMPLES / "marks.csv").read_text().splitlines()
    rows = [ln.split(",") for ln in lines[3:]]
    rows[1][7] = f"{float(rows[1][7]) + 40.0:.4f}"   # one mark 40 mm off
    marks = tmp_path / "k.csv"
    marks.write_text("\n".join(lines[:3] + [",".join(r) for r in rows]) + "\n")
    out = tmp_path / "t.json"
    assert cal(["tool", "--robot", ROBOT, "--marks", str(marks), "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "do not fit one tool point" in err and "Nothing written" in err
    assert not out.exists()


def test_the_cli_constants_match_the_library():
    from olp_compensate.programs.object_model.program import EMIT_MODES
    from olp_compensate.programs import DIALECTS as TEXT_DIALECTS
    from olp_compensate.programs.languages import extensions, names

    dialect = next(a for a in fix_cli.build_parser()._actions if a.dest == "dialect")
    assert fix_cli.EMIT_MODES == EMIT_MODES and tuple(dialect.choices) == names()
    assert set(TEXT_DIALECTS) <= set(names())
    assert all(extensions()[ext] == name for ext, name in
               [(".mod", "rapid"), (".pg", "vplus"), (".src", "krl"), (".dat", "krl"),
                (".ls", "fanuc"), (".dtx", "val3"), (".script", "urscript")])


@pytest.mark.parametrize("comment, line", [(b"! olp-robot: abb_irb2400\n", 2),
                                           (b"  ;OLP-Robot:abb_irb2400 (cell 3)\n", 2)])
def test_the_robot_comment_is_found(tmp_path, comment, line):
    path = tmp_path / "p.mod"
    path.write_bytes(b"MODULE m\n" + comment + b"ENDMODULE\n")
    assert fix_cli.program_robot(path) == ("abb_irb2400", line)


def test_a_calibration_of_another_robot_than_the_program_names_is_refused(tmp_path, capsys,
                                                                          model):
    program = tmp_path / "cell_a.mod"
    text = (SAMPLES / "cell_a.mod").read_bytes()
    program.write_bytes(b"! olp-robot: unimation_puma560\r\n" + text)
    assert fix([str(program), "--model", str(model)]) == 1
    assert "program is for robot 'unimation_puma560'" in _err(capsys)
    assert not (tmp_path / "cell_a_compensated.mod").exists()


def test_olp_fix_names_the_robot_and_refuses_a_program_without_targets(tmp_path, capsys,
                                                                       model):
    program = tmp_path / "cell_a.mod"
    shutil.copy(SAMPLES / "cell_a.mod", program)
    assert fix([str(program), "--model", str(model)]) == 2   # runtime targets reported
    assert f"  robot {ROBOT} (calibration {model})" in capsys.readouterr().out.splitlines()
    for name, data in (("empty.pg", b""), ("cut.pg", (SAMPLES / "cell_b.pg").read_bytes()[:55])):
        path = tmp_path / name
        path.write_bytes(data)
        code = fix([str(path), "--model", str(model)])
        err = capsys.readouterr().err
        assert code == 1 and "Traceback" not in err, err
        assert not list(tmp_path.glob(f"{Path(name).stem}_compensated*"))
