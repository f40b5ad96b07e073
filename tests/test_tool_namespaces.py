"""Program tools and measured points are two namespaces of calib.json's tools: the
identification's measured point (``tcp`` by default in every measurement CSV) never
replaces a program's tool, even one named ``tcp`` (a URScript set_tcp, a RAPID tooldata);
only a tool calibrated for programs (``olp-cal tool``, marked ``for_programs``) does, by
name, and the row's note says so. A version-1 calib.json without the marker reads as
before, its points not program tools."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from olp_compensate.calibration.calibration import ToolPoint, nominal_calibration
from olp_compensate.cli.fix import main as fix
from olp_compensate.io.calibration_file import read_calibration, write_calibration
from olp_compensate.kinematics.robot import load_robot

OFFSET_M = np.array([0.0, 0.073, 0.150])   # a tracker target: 73 mm off the tool axis
SCRIPT = ("def cell():\n  set_tcp(p[0.0, 0.0, 0.15, 0.0, 0.0, 0.0])\n"
          "  movel(p[0.40, -0.20, 0.30, 0.0, 3.1416, 0.0], a=1.2, v=0.25)\n"
          "  movel(p[0.45, 0.10, 0.35, 0.0, 3.1416, 0.0], a=1.2, v=0.25)\nend\n")
MODULE = ("MODULE M\n  PERS tooldata tcp:=[TRUE,[[0,0,150],[1,0,0,0]],"
          "[1,[0,0,50],[1,0,0,0],0,0,0]];\n"
          "  CONST robtarget p1:=[[1200,100,900],[0,0,1,0],[0,0,0,0],"
          "[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
          "  PROC main()\n    MoveL p1,v100,fine,tcp;\n  ENDPROC\nENDMODULE\n")


def _calibration(robot: str, path: Path, for_programs: bool) -> Path:
    """The nominal calibration with a point 'tcp' 73 mm off the programs' tool."""
    cal = nominal_calibration(load_robot(robot))
    cal = dataclasses.replace(cal, tools={"tcp": ToolPoint(xyz_m=OFFSET_M,
                                                           for_programs=for_programs)})
    write_calibration(path, cal)
    return path


@pytest.mark.parametrize("robot, name, text", [("ur10e", "cell.script", SCRIPT),
                                               ("abb_irb2400", "cell.mod", MODULE)])
@pytest.mark.parametrize("taught_on", [False, True])
def test_a_measured_point_never_replaces_a_programs_tool(tmp_path, robot, name, text,
                                                         taught_on):
    program = tmp_path / name
    program.write_text(text)
    model = _calibration(robot, tmp_path / "calib.json", for_programs=False)
    out, report = tmp_path / f"out_{name}", tmp_path / "r.csv"
    extra = ["--taught-on", str(model)] if taught_on else []
    fix([str(program), "--model", str(model), "-o", str(out), "--report", str(report), "-q",
         *extra])
    # nominal geometry, the program's own tool: every byte comes back
    assert out.read_bytes() == program.read_bytes()
    assert "real TCP" not in report.read_text()


@pytest.mark.parametrize("robot, name, text", [("ur10e", "cell.script", SCRIPT),
                                               ("abb_irb2400", "cell.mod", MODULE)])
def test_a_tool_calibrated_for_programs_replaces_it_by_name(tmp_path, robot, name, text):
    program = tmp_path / name
    program.write_text(text)
    model = _calibration(robot, tmp_path / "calib.json", for_programs=True)
    out, report = tmp_path / f"out_{name}", tmp_path / "r.csv"
    fix([str(program), "--model", str(model), "-o", str(out), "--report", str(report), "-q"])
    assert out.read_bytes() != program.read_bytes()
    rows = [r for r in csv.DictReader(report.open()) if r["status"] != "frame"]  # set_tcp's
    assert rows and all("real TCP of tcp from the calibration (tool 'tcp', olp-cal tool)"
                        in r["note"] for r in rows)


def test_the_marker_round_trips_and_old_files_read_without_it(tmp_path):
    path = _calibration("abb_irb2400", tmp_path / "a.json", for_programs=True)
    assert read_calibration(path).tools["tcp"].for_programs
    doc = json.loads(path.read_text())
    assert doc["tools"]["tcp"]["for_programs"] is True
    old = _calibration("abb_irb2400", tmp_path / "old.json", for_programs=False)
    assert "for_programs" not in json.loads(old.read_text())["tools"]["tcp"]   # as before
    assert not read_calibration(old).tools["tcp"].for_programs
