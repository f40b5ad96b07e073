"""olp-cal import: instrument tables in, the measurement CSV out. The expected rotations
are built here from elementary rotation matrices (not from the importer's library), the
tables are written here as the instruments write them."""

import numpy as np
import pytest

from olp_compensate.calibration.measurements import row_sigma_scales
from olp_compensate.cli.cal import main
from olp_compensate.io.measurements import read_measurements
from olp_compensate.kinematics.conventions import matrix_from_quat_wxyz


def rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rotvec_matrix(v):
    """Rodrigues' formula."""
    angle = np.linalg.norm(v)
    k = v / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


@pytest.fixture
def rows():
    rng = np.random.default_rng(28)
    return [np.concatenate([rng.uniform(-90, 90, 6), rng.uniform(-1500, 1500, 3),
                            rng.uniform(-170, 170, 3)]) for _ in range(6)]


def test_robodk_table_with_semicolons_and_decimal_commas(tmp_path, rows, capsys):
    source = tmp_path / "robodk.csv"
    source.write_text("".join(";".join(f"{v:.5f}".replace(".", ",") for v in r) + "\n"
                              for r in rows))
    out = tmp_path / "meas.csv"
    assert main(["import", str(source), "--format", "robodk", "-o", str(out)]) == 0
    assert "Rz(r) Ry(p) Rx(w)" in capsys.readouterr().out
    meas = read_measurements(out, ["deg"] * 6)
    for k, r in enumerate(rows):
        assert np.allclose(np.degrees(meas.joints[k]), r[:6], atol=1e-5)
        assert np.allclose(meas.points[k] * 1e3, r[6:9], atol=1e-5)
        w, p, rr = np.radians(r[9:12])
        assert np.allclose(matrix_from_quat_wxyz(meas.orientation[k]), rz(rr) @ ry(p) @ rx(w),
                           atol=1e-7)
    assert source.read_text().count(";") == 11 * len(rows)  # the input is untouched


def test_column_map_rotation_vectors_radians_sigmas_commanded_pose(tmp_path, rows):
    header = ("j1,j2,j3,j4,j5,j6,X,Y,Z,RX,RY,RZ,cx,cy,cz,sdx,sdy,sdz,T\n")
    lines = []
    for r in rows:
        rot = np.radians(r[9:12]) / 3
        lines.append(",".join(f"{v:.9f}" for v in [*np.radians(r[:6]), *(r[6:9] / 1e3), *rot,
                                                   *(r[6:9] / 1e3 + 0.001), 1e-5, 2e-5, 2e-5,
                                                   21.5]))
    source = tmp_path / "tracker.csv"
    source.write_text(header + "\n".join(lines) + "\n")
    out = tmp_path / "meas.csv"
    mapping = ("q1=j1,q2=j2,q3=j3,q4=j4,q5=j5,q6=j6,x=X,y=Y,z=Z,rx=RX,ry=RY,rz=RZ,"
               "cmd_x=cx,cmd_y=cy,cmd_z=cz,sx=sdx,sy=sdy,sz=sdz,temperature=T")
    assert main(["import", str(source), "--columns", mapping, "--joints-unit", "rad",
                 "--length-unit", "m", "--angles-unit", "rad", "--euler", "rotvec",
                 "-o", str(out)]) == 0
    meas = read_measurements(out, ["deg"] * 6)
    for k, r in enumerate(rows):
        assert np.allclose(np.degrees(meas.joints[k]), r[:6], atol=1e-6)
        assert np.allclose(meas.points[k] * 1e3, r[6:9], atol=1e-5)
        assert np.allclose(matrix_from_quat_wxyz(meas.orientation[k]),
                           rotvec_matrix(np.radians(r[9:12]) / 3), atol=1e-7)
    assert np.allclose(meas.temperature_c, 21.5)
    assert np.allclose(np.array(meas.extra["cmd_x_mm"], float), [r[6] + 1 for r in rows])
    # the per-axis sigmas become the row's sigma_mm (their RMS), which weights the fit
    sigma = np.sqrt((1e-2**2 + 2e-2**2 + 2e-2**2) / 3)
    assert np.allclose(np.array(meas.extra["sigma_mm"], float), sigma, rtol=1e-5)
    position_scale, _ = row_sigma_scales(meas, 0.05e-3, np.radians(0.01))
    assert np.allclose(position_scale, 0.05 / np.hypot(sigma, 0.05), rtol=1e-5)  # quadrature


def test_intrinsic_euler_sequence(tmp_path, rows):
    source = tmp_path / "t.txt"
    source.write_text("\n".join(" ".join(f"{v:.6f}" for v in r) for r in rows) + "\n")
    out = tmp_path / "meas.csv"
    mapping = ",".join([f"q{k + 1}={k}" for k in range(6)]
                       + ["x=6", "y=7", "z=8", "rx=9", "ry=10", "rz=11"])
    assert main(["import", str(source), "--columns", mapping, "--euler", "ZYX",
                 "-o", str(out)]) == 0
    meas = read_measurements(out, ["deg"] * 6)
    a, b, c = np.radians(rows[0][9:12])
    # intrinsic Z, then the new Y, then the new X
    assert np.allclose(matrix_from_quat_wxyz(meas.orientation[0]), rz(a) @ ry(b) @ rx(c),
                       atol=1e-7)


@pytest.mark.parametrize("args,message", [
    (["--columns", "q1=0,x=6"], "missing y, z"),
    (["--robot", "abb_irb2400", "--columns", "q1=0,x=6,y=7,z=8"], "maps 1 joints, the robot has 6"),
    (["--columns", "q1=0,q2=1,q3=2,q4=3,q5=4,q6=5,x=6,y=7,z=99"], "column 99 is beyond"),
    (["--columns", "q1=0,bogus=3"], "unknown key 'bogus'"),
    (["--format", "robodk", "--euler", "XYQ"], "--euler must be"),
])
def test_bad_maps_are_one_line_errors(tmp_path, rows, capsys, args, message):
    source = tmp_path / "t.csv"
    source.write_text("\n".join(",".join(f"{v:.3f}" for v in r) for r in rows) + "\n")
    out = tmp_path / "meas.csv"
    assert main(["import", str(source), "-o", str(out)] + args) == 1
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_a_bad_cell_names_file_line_and_column(tmp_path, rows, capsys):
    source = tmp_path / "t.csv"
    text = [",".join(f"{v:.3f}" for v in r) for r in rows]
    text[2] = text[2].replace(",", ",abc,", 1).rsplit(",", 1)[0]
    source.write_text("\n".join(text) + "\n")
    assert main(["import", str(source), "--format", "robodk", "-o", str(tmp_path / "m.csv")]) == 1
    err = capsys.readouterr().err
    assert "t.csv:3" in err and "q2" in err
