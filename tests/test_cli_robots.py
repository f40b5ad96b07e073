"""olp-cal robots: the library listed, one robot shown, every name usable with --robot."""

import json
import re

import numpy as np
import pytest

from olp_compensate.cli.cal import main
from olp_compensate.io.calibration_file import read_calibration
from olp_compensate.kinematics.robot import bundled_record, bundled_robot_names, load_robot
from olp_compensate.kinematics.urdf import read_urdf_chain

NAMES = bundled_robot_names()


def test_list_names_every_robot_with_its_maker_reach_payload_and_source(capsys):
    assert main(["robots"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:7] == ["name", "maker", "model", "reach", "payload", "axes", "source"]
    assert lines[-1].startswith(f"{len(NAMES)} robots")
    listed = [ln.split()[0] for ln in lines[1:-1]]
    assert listed == NAMES
    row = next(ln for ln in lines if ln.startswith("kuka_kr6_r900_sixx "))
    assert "KUKA" in row and "900 mm" in row and "6 kg" in row and "ROS-Industrial" in row


def test_json_list_holds_the_contract_keys(capsys):
    assert main(["robots", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [d["name"] for d in doc] == NAMES and len(doc) >= 40
    for d in doc:
        assert {"name", "maker", "model", "axes", "axis_ranges_deg"} <= set(d)
        record = bundled_record(d["name"])
        assert d["axes"] == 6 and d["maker"] == record.maker
        np.testing.assert_array_equal(d["axis_ranges_deg"], record.axis_ranges_deg)


def test_show_prints_parameters_ranges_and_sources(capsys):
    assert main(["robots", "--show", "abb_irb1600_6_12"]) == 0
    out = capsys.readouterr().out
    assert "ABB IRB 1600-6/1.2" in out
    assert "a1 150, a2 0, b 0, c1 486.5, c2 475, c3 600, c4 65 mm" in out
    assert "coupling      abb_parallel" in out
    ranges = re.findall(r"^\s+(\d)\s+(-?[\d.]+) \.\. (-?[\d.]+)", out, re.M)
    assert [(float(lo), float(hi)) for _, lo, hi in ranges] == [
        tuple(r) for r in bundled_record("abb_irb1600_6_12").axis_ranges_deg.tolist()]
    assert "source" in out and "fingerprint   sha256:" in out


def test_urdf_prints_the_generated_chain(capsys):
    assert main(["robots", "--urdf", "yaskawa_gp7"]) == 0
    doc = read_urdf_chain(capsys.readouterr().out)
    assert doc.name == "yaskawa_gp7" and len(doc.joints) == 7


def test_unknown_robot_is_one_line_with_suggestions(capsys):
    assert main(["robots", "--show", "irb120"]) == 1
    err = capsys.readouterr().err
    assert "unknown robot 'irb120' (did you mean " in err and "abb_irb120_3_58" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("name", NAMES)
def test_every_name_works_with_robot(tmp_path, name, capsys):
    """``--robot NAME`` of a command (here ``olp-cal nominal``) takes every library name."""
    out = tmp_path / "calib.json"
    assert main(["nominal", "--robot", name, "-o", str(out)]) == 0
    cal = read_calibration(out, load_robot(name))
    assert cal.robot.name == name
    np.testing.assert_allclose(cal.robot.controller_ranges, load_robot(name).controller_ranges)
