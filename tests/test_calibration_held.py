"""calib.json names the tool and device-frame components the poses could not separate
(held at their start value, std 0: not an uncertainty) under ``"held"``, keeps every key
and type it had, and reads files with and without the key; the identify text prints a held
zero as 0.000, not -0.000."""

import dataclasses
import json

import numpy as np
import pytest

from olp_compensate.calibration.calibration import ToolPoint
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.simulate import make_virtual_robot
from olp_compensate.cli.cal_identify import _unsigned_zero, report
from olp_compensate.errors import ModelError
from olp_compensate.io.calibration_file import (calibration_from_dict, dumps_calibration,
                                                read_calibration, write_calibration)
from olp_compensate.kinematics.robot import load_robot

ROBOT = "staubli_tx2_90l"


@pytest.fixture(scope="module")
def held_result():
    """An identification whose poses turn the flange about axis 1 only (axes 1 and 2
    random, j2 + j3 at 30 deg, the wrist still): a tool component is held."""
    robot = load_robot(ROBOT)
    virtual = make_virtual_robot(robot, seed=2)
    rng = np.random.default_rng(3)
    q = np.empty((60, 6))
    q[:, 0] = rng.uniform(-2.5, 2.5, 60)
    q[:, 1] = rng.uniform(-1.0, 1.2, 60)
    q[:, 2] = np.radians(30.0) - q[:, 1]
    q[:, 3:] = np.radians([10.0, 40.0, 20.0])
    meas = virtual.measure(q, 0.05e-3, np.random.default_rng(5))
    return identify(robot, meas, IdentificationOptions(folds=0))


def _same(a, b) -> bool:
    """Equal JSON values: the same keys, texts and types; numbers within 1e-14 relative."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, float) and isinstance(b, float):
        return abs(a - b) <= 1e-14 * max(abs(a), abs(b), 1.0)
    return type(a) is type(b) and a == b


def _round_trip(text: str) -> str:
    """calib.json text read and written again: the same document, byte for byte (numbers
    whose value did not change are written as read: tests/test_calibration_round_trip.py)."""
    again = dumps_calibration(calibration_from_dict(json.loads(text)))
    assert _same(json.loads(text), json.loads(again))
    assert again == text
    return again


def _held_names(cal, prefix):
    return {n[len(prefix):]: why for n, why in cal.frozen.items() if n.startswith(prefix)}


def test_held_tool_components_are_named_and_read_back(tmp_path, held_result):
    cal = held_result.calibration
    held = _held_names(cal, "tool.tcp.")
    assert held  # the poses built hold at least one
    text = dumps_calibration(cal)
    tool = json.loads(text)["tools"]["tcp"]
    assert tool["held"] == held
    # the keys and types every reader knew are kept: std 0 where held
    assert isinstance(tool["std_mm"], list) and len(tool["std_mm"]) == 3
    assert all(tool["std_mm"]["xyz".index(c)] == 0.0 for c in held)
    assert all(isinstance(v, float) for v in tool["xyz_mm"] + tool["std_mm"])
    path = tmp_path / "calib.json"
    write_calibration(path, cal)
    back = read_calibration(path)
    assert _held_names(back, "tool.tcp.") == held
    _round_trip(text)


def test_a_held_device_frame_component_is_named_too(held_result):
    # (the ASTL LINE session holds base.ty: a straight path leaves it tied to the tool)
    cal = dataclasses.replace(held_result.calibration,
                              frozen={**held_result.calibration.frozen, "base.ty": "tied"})
    text = dumps_calibration(cal)
    doc = json.loads(text)
    assert doc["device_T_base"]["held"] == {"ty": "tied"}
    assert set(doc["device_T_base"]) == {"xyz_mm", "quat_wxyz", "held"}
    back = calibration_from_dict(doc)
    assert back.frozen["base.ty"] == "tied"
    _round_trip(text)


def test_a_file_without_the_key_reads_as_before(held_result):
    doc = json.loads(dumps_calibration(held_result.calibration))
    del doc["tools"]["tcp"]["held"]
    old_text = json.dumps(doc, indent=2) + "\n"       # as written before the key existed
    back = calibration_from_dict(json.loads(old_text))
    assert not _held_names(back, "tool.") and not _held_names(back, "base.")
    assert '"held"' not in _round_trip(old_text)
    # nothing held: no key written (the samples' files stay byte-identical)
    free = dataclasses.replace(back, frozen={})
    assert '"held"' not in dumps_calibration(free)


@pytest.mark.parametrize("held", [{"w": "why"}, ["x"], {"x": 1}])
def test_a_malformed_held_is_refused(held_result, held):
    doc = json.loads(dumps_calibration(held_result.calibration))
    doc["tools"]["tcp"]["held"] = held
    with pytest.raises(ModelError, match="tools/tcp/held"):
        calibration_from_dict(doc, "c.json")


def test_a_held_zero_prints_without_a_sign(held_result):
    assert _unsigned_zero("-0.000") == "0.000"
    assert _unsigned_zero("-0.0000") == "0.0000"
    for text in ("0.000", "-0.001", "-10.000", "-100.500", "12.000"):
        assert _unsigned_zero(text) == text
    cal = held_result.calibration
    tool = dataclasses.replace(cal.tools["tcp"], xyz_m=np.array([-0.0, -1e-12, 0.2]))
    result = dataclasses.replace(
        held_result, calibration=dataclasses.replace(cal, tools={"tcp": tool}))
    assert "tool tcp: (0.000, 0.000, 200.000) mm" in report(result)


def test_a_tool_calibrated_for_programs_in_place_of_a_held_point_holds_nothing(held_result):
    # olp-cal tool --name tcp on this file replaces the point by a tool measured on its own
    cal = held_result.calibration
    tools = {"tcp": ToolPoint(xyz_m=np.array([0.0, 0.0, 0.1]), std_m=np.full(3, 1e-5),
                              for_programs=True)}
    doc = json.loads(dumps_calibration(dataclasses.replace(cal, tools=tools)))
    assert "held" not in doc["tools"]["tcp"]
