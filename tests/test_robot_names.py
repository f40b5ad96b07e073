"""robot_named_in: the robot a program declares, in each dialect's comment or header."""

import pytest

from olp_compensate.errors import DataError
from olp_compensate.kinematics.robot import bundled_robot_names
from olp_compensate.kinematics.robot_names import robot_named_in


@pytest.mark.parametrize("text, name", [
    ("MODULE Cell\n  ! olp-robot: abb_irb1200_7_70\n  CONST robtarget p1 := [[1,2,3],[1,0,0,0],"
     "[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\nENDMODULE\n", "abb_irb1200_7_70"),
    ("&ACCESS RVP\n&REL 1\n&PARAM OLP_ROBOT = kuka_kr16_2\n&PARAM EDITMASK = *\nDEFDAT cell\n"
     "ENDDAT\n", "kuka_kr16_2"),
    ("DEF cell()\n; OLP-Robot: kuka_kr6_r900_sixx\nEND\n", "kuka_kr6_r900_sixx"),
    ("/PROG  CELL\n/ATTR\nOWNER\t\t= MNEDITOR;\nCOMMENT\t\t= \"olp-robot: fanuc_m20ia\";\n"
     "/MN\n   1:  J P[1] 100% FINE    ;\n/END\n", "fanuc_m20ia"),
    ("// olp-robot: staubli_tx2_60\nbegin\nend\n", "staubli_tx2_60"),
    ("def prog():\n  # olp-robot: ur10e\n  movej(p[0.1, 0.2, 0.3, 0, 0, 0])\nend\n", "ur10e"),
    ("\r\n! olp-robot:\tabb_irb2400\r\n", "abb_irb2400"),
])
def test_each_dialect_names_its_robot(text, name):
    assert robot_named_in(text) == name
    assert name in bundled_robot_names()


@pytest.mark.parametrize("text", [
    "MODULE Cell\n  ! written for an IRB 2400\nENDMODULE\n",
    "MODULE Cell\n  TPWrite \"! olp-robot: abb_irb2400\";\nENDMODULE\n",  # not a comment line
    "&PARAM TEMPLATE = C:\\KRC\\Roboter\\Template\\vorgabe\n",
    "",
])
def test_no_declaration_is_none(text):
    assert robot_named_in(text) is None


def test_the_same_robot_twice_is_one_name():
    assert robot_named_in("! olp-robot: ur5e\n! olp-robot: ur5e\n") == "ur5e"


def test_two_robots_are_refused_with_their_lines():
    with pytest.raises(DataError, match=r"'ur5e' \(line 1\), 'ur10e' \(line 3\)"):
        robot_named_in("# olp-robot: ur5e\nmovej()\n# olp-robot: ur10e\n")


def test_olp_fix_refuses_a_calibration_of_another_robot_than_the_header_names(tmp_path, capsys):
    """A KRL program whose &PARAM names an IRB 2400, compensated with a KR 16-2 calibration:
    exit 1, one line naming the file and the header's line; a FANUC /ATTR likewise."""
    from olp_compensate.calibration.calibration import nominal_calibration
    from olp_compensate.cli.fix import main as fix
    from olp_compensate.io.calibration_file import write_calibration
    from olp_compensate.kinematics.robot import load_robot

    model = tmp_path / "kr16.json"
    write_calibration(model, nominal_calibration(load_robot("kuka_kr16_2")))
    src = tmp_path / "cell.src"
    src.write_text("&ACCESS RVP\n&PARAM OLP_ROBOT = abb_irb2400\nDEF cell( )\n"
                   "  PTP {X 900, Y 0, Z 900, A 0, B 90, C 0}\nEND\n")
    assert fix([str(src), "--model", str(model), "-o", str(tmp_path / "out.src")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{src}:2:" in err[0] and "abb_irb2400" in err[0], err
    assert not (tmp_path / "out.src").exists()
