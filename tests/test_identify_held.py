"""A tool or device-frame component the poses cannot separate is held at its start value
(stage 3's registration), as a frozen geometric parameter is held at nominal: it is not
fitted, its std reads 'frozen', and the rest of the model still predicts the truth."""

import numpy as np

from olp_compensate.calibration.identify import (IdentificationOptions, _checked_setup,
                                                 _start_values, identify)
from olp_compensate.calibration.simulate import make_virtual_robot
from olp_compensate.cli.cal_identify import report
from olp_compensate.kinematics.robot import load_robot
from virtual_world import axis1_poses

NOISE = 0.05e-3
ROBOT = "staubli_tx2_90l"


def _poses(robot, n, seed):
    """:func:`virtual_world.axis1_poses`, inside the URDF limits."""
    q = axis1_poses(robot, n, seed)
    assert np.all((q > robot.lower_limits) & (q < robot.upper_limits))
    return q


def test_an_inseparable_tool_component_is_held_at_its_start_value():
    robot = load_robot(ROBOT)
    virtual = make_virtual_robot(robot, seed=2)
    meas = virtual.measure(_poses(robot, 60, 3), NOISE, np.random.default_rng(5))
    options = IdentificationOptions(folds=3)
    result = identify(robot, meas, options)
    cal = result.calibration
    held = [n for n in cal.frozen if n.startswith(("tool.", "base."))]
    assert "tool.tcp.x" in held  # the tie this pose set builds
    # held: exactly the start value of stage 3 (main fitted it along the null direction,
    # 5 mm away, with a std of 2 m and 47 iterations)
    start = _start_values(_checked_setup(robot, meas, options))
    axis = "xyz".index("x")
    assert cal.tools["tcp"].xyz_m[axis] == start.tools[0][axis]
    assert cal.tools["tcp"].std_m[axis] == 0.0
    assert "maximum number of iterations" not in result.message
    # the unknowns counted and their std: the held ones are not fitted
    assert result.n_unknowns == len(result.unknown_names) - len(held)
    for name in held:
        assert np.isnan(result.unknown_std[result.unknown_names.index(name)])
    fitted = [s for n, s in zip(result.unknown_names, result.unknown_std) if n not in held]
    assert np.all(np.isfinite(fitted))
    assert "std (frozen, " in report(result)
    # the model still predicts the truth on new poses of the same kind, to the noise level
    q_new = _poses(robot, 40, 9)
    truth = virtual.true_points(q_new, ["tcp"] * len(q_new))
    error = np.linalg.norm(cal.predict_points(q_new, ["tcp"] * len(q_new)) - truth, axis=1)
    assert np.sqrt(np.mean(error**2)) < 2 * NOISE
    assert result.heldout_rms < 2.5 * NOISE


def test_held_components_leave_a_separable_problem_unchanged():
    # Random poses separate everything: nothing is held and the unknowns are all fitted.
    robot = load_robot(ROBOT)
    virtual = make_virtual_robot(robot, seed=4)
    rng = np.random.default_rng(7)
    from olp_compensate.calibration.simulate import random_joints

    meas = virtual.measure(random_joints(robot, 40, rng), NOISE, rng)
    result = identify(robot, meas, IdentificationOptions(folds=0))
    assert not any(n.startswith(("tool.", "base.")) for n in result.calibration.frozen)
    assert result.n_unknowns == len(result.unknown_names)
    assert np.all(np.isfinite(result.unknown_std))
