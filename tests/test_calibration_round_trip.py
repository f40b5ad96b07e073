"""calib.json read and written again comes back byte for byte (every number of every
section: robot axis ranges, model, device frame, tools, effects, regions, residual map,
geometric fallback, warnings), for files identify writes on virtual sessions; a value that
did change is written anew, the rest as read.

The files are the project's own (identify's output), so the expected text is the file
itself; that the check can fail is shown by the same calibration written without the
document it was read from: its device frame's mm -> m -> mm and quaternion -> matrix ->
quaternion move last digits (the drift found on the ASTL LINE session)."""

import dataclasses
import json

import numpy as np
import pytest

from olp_compensate.calibration.calibration import ToolPoint
from olp_compensate.calibration.effects import make_effect
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.regions import identify_regions
from olp_compensate.calibration.remainder import ResidualMap
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.io.calibration_file import (calibration_from_dict, calibration_to_dict,
                                                dumps_calibration, read_calibration)
from olp_compensate.kinematics.conventions import rotation_from_rotvec
from olp_compensate.kinematics.robot import load_robot
from virtual_world import axis1_poses

ROBOT = "staubli_tx2_90l"
NOISE = 0.05e-3


def _measure(virtual, q, seed):
    return virtual.measure(q, NOISE, np.random.default_rng(seed))


def _sessions() -> dict:
    """name -> calibration identify wrote, on virtual sessions of several kinds."""
    robot = load_robot(ROBOT)
    rng = np.random.default_rng(7)
    out = {}
    three = make_virtual_robot(robot, seed=7, n_points=3)
    q = random_joints(robot, 40, rng)
    out["three tools"] = identify(robot, _measure(three, q, 1),
                                  IdentificationOptions(folds=3)).calibration
    one = make_virtual_robot(robot, seed=8)
    out["held tool"] = identify(robot, _measure(one, axis1_poses(robot, 50, 3), 2),
                                IdentificationOptions(folds=0)).calibration
    effect = make_effect("joint_compliance", 2, robot.n_joints)
    with_effect = identify(robot, _measure(one, q, 3),
                           IdentificationOptions(folds=0, effects=(effect,))).calibration
    out["effect"] = with_effect
    ranged = random_joints(robot, 90, rng)
    meas = _measure(one, ranged, 4)
    labels = ["left" if a > 0 else "right" for a in meas.joints[:, 0]]
    meas = dataclasses.replace(meas, extra={"region": labels})
    out["regions"] = identify_regions(robot, meas, IdentificationOptions(folds=0)
                                      ).result.calibration
    n = robot.n_joints
    rmap = ResidualMap(kinds=("revolute",) * n, center=rng.normal(size=n),
                       span=rng.uniform(1, 2, n), frequencies=rng.normal(size=(2 * n, 8)),
                       phases=rng.uniform(0, 6.3, 8), weights=rng.normal(0, 1e-4, (8, 3)),
                       length=0.7, penalty=1e-3, q_range=np.tile([-3.0, 3.0], (n, 1)),
                       validation={"heldout_rms_mm_with": 0.1})
    width = rmap.features(np.zeros((1, n))).shape[1]
    rmap = dataclasses.replace(rmap, weights=rng.normal(0, 1e-4, (width, 3)))
    out["map and fallback"] = dataclasses.replace(
        with_effect, residual_map=rmap, geometric_fallback=out["held tool"],
        warnings=("forced: a verdict",))
    return out


@pytest.fixture(scope="module")
def written() -> dict:
    """name -> calib.json text as identify (or diagnose, for the map) writes it."""
    return {name: dumps_calibration(cal) for name, cal in _sessions().items()}


@pytest.fixture(scope="module")
def line_written() -> str:
    """calib.json of a line session: a device-frame component held (device_motions)."""
    from test_device_motions import _session

    result = _session("line")[2]
    assert any(n.startswith("base.") for n in result.identifiability.motions)
    return dumps_calibration(result.calibration)


def _texts(written, line_written):
    return [*written.items(), ("line", line_written)]


def test_read_then_written_is_byte_identical(written, line_written, tmp_path):
    for name, text in _texts(written, line_written):
        path = tmp_path / "calib.json"
        path.write_text(text)
        again = dumps_calibration(read_calibration(path))
        assert again == text, name
        path.write_text(again)  # and again: nothing drifts over rounds
        assert dumps_calibration(read_calibration(path)) == text, name
        assert dumps_calibration(calibration_from_dict(json.loads(text))) == text, name


def test_without_the_document_read_the_conversions_drift(written, line_written):
    """The check above can fail: written from its SI values alone, some file moves."""
    drifted = [name for name, text in _texts(written, line_written)
               if dumps_calibration(dataclasses.replace(
                   calibration_from_dict(json.loads(text)), as_read=None)) != text]
    assert drifted


def _numbers(value, path=()):
    """{JSON path: number} of a document."""
    if isinstance(value, dict):
        return {p: v for k, item in value.items() for p, v in _numbers(item, path + (k,)).items()}
    if isinstance(value, list):
        return {p: v for k, item in enumerate(value)
                for p, v in _numbers(item, path + (k,)).items()}
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return {path: value}
    return {}


def test_a_changed_value_is_written_anew_the_rest_as_read(written):
    text = written["three tools"]
    cal = calibration_from_dict(json.loads(text))
    tools = dict(cal.tools)
    tools["tcp"] = ToolPoint(xyz_m=tools["tcp"].xyz_m + [1e-3, 0.0, -2e-3], for_programs=True)
    pose = cal.device_T_base.copy()
    pose[:3, :3] = pose[:3, :3] @ rotation_from_rotvec(np.array([0.0, 0.0, 1e-3]))
    pose[:3, 3] += [0.5e-3, -0.2e-3, 0.1e-3]
    changed = dataclasses.replace(cal, tools=tools, device_T_base=pose)
    out = json.loads(dumps_calibration(changed))
    fresh = calibration_to_dict(changed)  # the new values, converted anew
    assert out["tools"]["tcp"]["xyz_mm"] == fresh["tools"]["tcp"]["xyz_mm"]
    assert out["device_T_base"]["quat_wxyz"] == fresh["device_T_base"]["quat_wxyz"]
    assert out["device_T_base"]["xyz_mm"] == fresh["device_T_base"]["xyz_mm"]
    before, after = _numbers(json.loads(text)), _numbers(out)
    assert after[("tools", "tcp", "xyz_mm", 0)] != before[("tools", "tcp", "xyz_mm", 0)]
    assert after[("device_T_base", "quat_wxyz", 3)] != before[("device_T_base", "quat_wxyz", 3)]
    untouched = [p for p in before if p[0] != "device_T_base" and p[:2] != ("tools", "tcp")]
    assert len(untouched) > 80
    assert [p for p in untouched if after.get(p) != before[p]] == []
