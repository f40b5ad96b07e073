"""The package root is the front door: its public names resolve, work together, and cost
nothing to import until used."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

import olp_compensate
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints


def test_every_public_name_resolves_and_is_documented():
    for name in olp_compensate.__all__:
        value = getattr(olp_compensate, name)
        assert value is not None
        if callable(value) and name[0] != "_":
            assert value.__doc__, f"{name} has no docstring"
        if name not in ("__version__",):
            assert name in olp_compensate.__doc__, f"{name} is not in the package docstring"


def test_unknown_names_raise_attribute_error():
    try:
        olp_compensate.no_such_name
    except AttributeError as exc:
        assert "no_such_name" in str(exc)
    else:
        raise AssertionError("expected AttributeError")


def test_importing_the_package_loads_no_submodule_with_heavy_dependencies():
    probe = ("import sys, olp_compensate; "
             "print(sorted(m for m in sys.modules if m.startswith(('olp_compensate.', 'scipy', "
             "'numpy', 'lark', 'pinocchio'))))")
    loaded = subprocess.run([sys.executable, "-c", probe], check=True, capture_output=True,
                            text=True).stdout
    assert loaded.strip() == "['olp_compensate.errors']", loaded


def test_a_script_through_the_front_door_calibrates_and_compensates(tmp_path):
    """Simulate a campaign, write and read it as CSV, identify, compensate a reachable pose:
    the real arm (the virtual truth) then reaches what was meant."""
    from olp_compensate.io.measurements import write_measurements

    robot = olp_compensate.load_robot("abb_irb2400")
    virtual = make_virtual_robot(robot, seed=8)
    rng = np.random.default_rng(8)
    meas = virtual.measure(random_joints(robot, 40, rng), 0.01e-3, rng)
    path = tmp_path / "m.csv"
    write_measurements(path, meas, [j.unit for j in robot.joints])
    again = olp_compensate.read_measurements(path, robot)
    assert np.allclose(again.joints, meas.joints, atol=1e-8)
    result = olp_compensate.identify(robot, again, olp_compensate.IdentificationOptions(folds=0))
    cal = result.calibration
    comp = olp_compensate.Compensator(cal)
    q = random_joints(robot, 1, np.random.default_rng(3), margin=0.4)
    joints = robot.joints_from_controller(q)
    tool = np.eye(4)
    tool[:3, 3] = cal.tools["tcp"].xyz_m            # the calibrated measured point
    meant = comp.nominal_flange(joints)[0] @ tool    # a TCP pose the arm can reach, base frame
    config = tuple(int(c) for c in comp.confdata(joints)[0])
    out = olp_compensate.compensate_pose(comp, meant, tool=tool, config=config)
    assert out.status in ("ok", "singular"), out.note
    # the virtual real arm, at the joints the nominal controller takes for the written
    # target, puts its real tcp where the calibration placed the meant one (device frame)
    reached = virtual.true_frames(out.joints[None], ["tcp"])[0, :3, 3]
    wanted = (cal.device_T_base @ meant)[:3, 3]
    assert np.linalg.norm(reached - wanted) < 0.1e-3
    # and the untouched target misses by much more
    missed = virtual.true_frames(q, ["tcp"])[0, :3, 3]
    assert np.linalg.norm(missed - wanted) > 10 * np.linalg.norm(reached - wanted)
