"""A new robot language is one folder and one ``register`` call: the toy language of
``tests/toy_language`` (``MOVE x y z a b c`` lines) goes through olp-fix's whole command,
compensated on a virtual IRB 2400 and run through the test's own toy controller."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.simulate import random_joints
from olp_compensate.cli.fix import main
from olp_compensate.compensation.ik import closed_form_inverse
from olp_compensate.io.calibration_file import write_calibration
from olp_compensate.kinematics.conventions import (euler_zyx_from_matrix, invert_pose,
                                                   matrix_from_euler_zyx)
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs.languages import language_of, names, register, unregister
from toy_language.language import LANGUAGE
from virtual_world import assert_the_gap_closed, identified_world, misses_mm, nominal_arm

ROBOT = load_robot("abb_irb2400")


@pytest.fixture()
def toy():
    register(LANGUAGE)
    yield LANGUAGE
    unregister("toy")


def _pose(numbers) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = matrix_from_euler_zyx(*np.radians(numbers[3:]))
    T[:3, 3] = np.asarray(numbers[:3]) * 1e-3
    return T


def _numbers(T) -> np.ndarray:
    return np.concatenate([T[:3, 3] * 1e3, np.degrees(euler_zyx_from_matrix(T[:3, :3]))])


def _moves(text: str) -> list[np.ndarray]:
    return [np.array([float(v) for v in line.split()[1:]]) for line in text.splitlines()
            if line.startswith("MOVE")]


class ToyController:
    """The toy controller of this test: the data-sheet arm's closed form, the branch inside
    the axis ranges nearest the previous move's joints (zero for the first)."""

    def __init__(self, tool: np.ndarray):
        self.nominal, self.family = nominal_arm(ROBOT)
        self.flange_T_tool = tool

    def run(self, moves: list[np.ndarray]) -> np.ndarray:
        joints, previous = [], np.zeros(ROBOT.n_joints)
        for numbers in moves:
            flange = _pose(numbers) @ invert_pose(self.flange_T_tool)
            branches = ROBOT.controller_from_joints(
                closed_form_inverse(self.family, flange[None])[0])
            ranges = ROBOT.controller_ranges
            finite = branches[np.all(np.isfinite(branches), axis=1)
                              & np.all((branches >= ranges[:, 0]) & (branches <= ranges[:, 1]),
                                       axis=1)]
            previous = finite[np.argmin(np.sum((finite - previous) ** 2, axis=1))]
            joints.append(previous)
        return np.array(joints)


def _program(cal, tool: np.ndarray, seed: int) -> str:
    """Eight moves at random joints, written as the data-sheet arm's TCP poses."""
    nominal, _ = nominal_arm(ROBOT)
    q = random_joints(ROBOT, 8, np.random.default_rng(seed))
    lines = ["; a toy program", "TOOL gripper"]
    for T in nominal.flange_poses(q) @ tool:
        lines.append("MOVE " + " ".join(f"{v:.3f}" for v in _numbers(T)))
    return "\n".join(lines) + "\n"


def test_a_registered_language_is_compensated_by_the_command(toy, tmp_path):
    virtual, cal = identified_world(ROBOT, 11, "gripper")
    tool = np.eye(4)
    tool[:3, 3] = cal.tools["gripper"].xyz_m
    text = _program(cal, tool, 3)
    source = tmp_path / "cell.toy"
    source.write_text(text)
    model = tmp_path / "calib.json"
    write_calibration(model, cal)
    report = tmp_path / "report.csv"
    assert "toy" in names() and language_of(source) is LANGUAGE
    assert main([str(source), "--model", str(model), "--report", str(report), "-q"]) == 0
    written = (tmp_path / "cell_compensated.toy").read_text()
    controller = ToyController(tool)
    meant = [(cal.device_T_base @ _pose(m))[:3, 3] for m in _moves(text)]
    before, after = controller.run(_moves(text)), controller.run(_moves(written))
    assert_the_gap_closed("toy language on IRB 2400", *misses_mm(virtual, meant, before,
                                                                 after))
    rows = list(csv.DictReader(report.open()))
    assert [r["status"] for r in rows] == ["ok"] * 8
    assert [int(r["line"]) for r in rows] == list(range(3, 11))
    # only the numbers changed: every other byte is kept
    assert [line for line in written.splitlines() if not line.startswith("MOVE")] == \
        [line for line in text.splitlines() if not line.startswith("MOVE")]


def test_the_nominal_calibration_gives_the_bytes_back(toy, tmp_path):
    cal = nominal_calibration(ROBOT)
    text = _program(cal, np.eye(4), 4).replace("TOOL gripper\n", "")    # flange poses
    source = tmp_path / "cell.toy"
    source.write_bytes(text.encode())
    model = tmp_path / "calib.json"
    write_calibration(model, cal)
    assert main([str(source), "--model", str(model), "-q"]) == 0
    assert (tmp_path / "cell_compensated.toy").read_bytes() == text.encode()
    # a tool calib.json does not know: every move reported, none written changed
    source.write_text("TOOL gripper\n" + text)
    report = tmp_path / "report.csv"
    assert main([str(source), "--model", str(model), "--report", str(report), "-q"]) == 2
    rows = list(csv.DictReader(report.open()))
    assert len(rows) == 8 and all(r["status"] == "unresolved" and "gripper" in r["note"]
                                  for r in rows)


def test_unregistered_the_extension_is_refused(tmp_path, capsys):
    source = tmp_path / "cell.toy"
    source.write_text("MOVE 1 2 3 4 5 6\n")
    assert main([str(source), "--model", "nowhere.json", "-q"]) == 1
    assert "unknown program extension '.toy'" in capsys.readouterr().err
