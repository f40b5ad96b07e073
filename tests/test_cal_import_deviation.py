"""olp-cal import of tables that give the error beside the commanded position (the UR5 /
Barrett WAM tracker tables of github.com/pauljac7700/serial_robots_datasets: x_t, y_t,
z_t target and x_dif, y_dif, z_dif): measured = commanded + deviation, checked against
a virtual robot's true points; a map giving both or the deviation alone is refused."""

import numpy as np
import pytest

from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.cli.cal import main
from olp_compensate.io.measurements import read_measurements
from olp_compensate.kinematics.robot import load_robot

ROBOT = load_robot("ur5")
MAP = ("pose=step_order,q1=joint_1,q2=joint_2,q3=joint_3,q4=joint_4,q5=joint_5,q6=joint_6,"
       "cmd_x=x_t,cmd_y=y_t,cmd_z=z_t")


def _table(tmp_path):
    """A table as the data set writes it: the true points of a virtual UR5, a made-up
    commanded position 1-3 mm away, and their difference (mm, joints deg)."""
    virtual = make_virtual_robot(ROBOT, 5)
    rng = np.random.default_rng(5)
    joints = random_joints(ROBOT, 12, rng)
    true = virtual.true_points(joints, ["tcp"] * len(joints)) * 1e3
    target = true + rng.uniform(1, 3, true.shape) * rng.choice([-1, 1], true.shape)
    lines = ["step_order,x_t,y_t,z_t,x_dif,y_dif,z_dif," + ",".join(
        f"joint_{k}" for k in range(1, 7))]
    for k, (t, p, q) in enumerate(zip(target, true, joints)):
        lines.append(",".join([str(k)] + [repr(float(v)) for v in [*t, *(p - t),
                                                                   *np.degrees(q)]]))
    source = tmp_path / "3D_UR5_grid.csv"
    source.write_text("\n".join(lines) + "\n")
    return source, joints, true


def test_deviation_columns_give_the_measured_points(tmp_path):
    source, joints, true = _table(tmp_path)
    out = tmp_path / "meas.csv"
    assert main(["import", str(source), "--columns", MAP + ",dx=x_dif,dy=y_dif,dz=z_dif",
                 "--robot", "ur5", "-o", str(out)]) == 0
    meas = read_measurements(str(out), ROBOT)
    assert np.allclose(meas.points * 1e3, true, atol=1e-6)
    assert np.allclose(meas.joints, joints, atol=1e-9)
    assert "commanded (cmd_x, cmd_y, cmd_z) + deviation" in out.read_text()


@pytest.mark.parametrize("extra, message", [
    (",x=x_t,y=y_t,z=z_t,dx=x_dif,dy=y_dif,dz=z_dif", "not both"),
    (",dx=x_dif,dy=y_dif", "missing dz"),
])
def test_incomplete_or_double_position_maps_are_refused(tmp_path, capsys, extra, message):
    source, _, _ = _table(tmp_path)
    out = tmp_path / "meas.csv"
    assert main(["import", str(source), "--columns", MAP + extra, "-o", str(out)]) != 0
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()
