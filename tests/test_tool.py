"""Tool recalibration on a virtual IRB 2400 (standard D-H) with a changed tool."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.optimize import least_squares

from olp_compensate.calibration.tool import (COND_LIMIT, PoorlyDeterminedTool, ToolRequest,
                                             calibrate_tool, rapid_tooldata, tool_from_fixed_point,
                                             tool_from_known_marks)
from olp_compensate.errors import DataError
from olp_compensate.io.tool_marks import format_marks_csv, read_marks_csv, write_tool_json
from olp_compensate.kinematics.conventions import MM, rotation_from_rotvec

DH_A = np.array([0.1, 0.705, 0.135, 0.0, 0.0, 0.0])
DH_ALPHA = np.array([-np.pi / 2, 0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, 0.0])
DH_D = np.array([0.615, 0.0, 0.0, 0.755, 0.0, 0.085])
DH_OFFSET = np.array([0.0, -np.pi / 2, 0.0, 0.0, 0.0, np.pi])
TOOL_M = np.array([12.345, -45.678, 234.567]) * MM  # the changed tool, flange frame
Q_HOME = np.radians([5.0, 10.0, 15.0, 0.0, 50.0, 0.0])


def irb2400_flange_pose(q):
    """Virtual robot: joints (m, 6) rad -> base_T_flange (m, 4, 4), metres (standard D-H)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    pose = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    for j in range(6):
        th = q[:, j] + DH_OFFSET[j]
        ct, st = np.cos(th), np.sin(th)
        ca, sa = np.cos(DH_ALPHA[j]), np.sin(DH_ALPHA[j])
        link = np.zeros((len(q), 4, 4))
        link[:, 0] = np.stack([ct, -st * ca, st * sa, DH_A[j] * ct], -1)
        link[:, 1] = np.stack([st, ct * ca, -ct * sa, DH_A[j] * st], -1)
        link[:, 2, 1:] = [sa, ca, DH_D[j]]
        link[:, 3, 3] = 1.0
        pose = pose @ link
    return pose


def solve_touch(point_m, rotvec, tool=TOOL_M, q0=Q_HOME):
    """Joints putting the tool tip at ``point_m`` with the flange turned by ``rotvec``
    (about base axes) from its home orientation (numerical IK, test helper)."""
    target_rot = rotation_from_rotvec(rotvec) @ irb2400_flange_pose(q0)[0, :3, :3]

    def error(q):
        pose = irb2400_flange_pose(q)[0]
        return np.concatenate([pose[:3, :3] @ tool + pose[:3, 3] - point_m,
                               0.5 * (pose[:3, :3] - target_rot).ravel()])
    sol = least_squares(error, q0, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert np.max(np.abs(sol.fun)) < 1e-9
    return sol.x


TILTS_DEG = [(0, 0, 0), (35, 0, 0), (-35, 0, 0), (0, 35, 0), (0, -35, 0), (20, 20, 40)]
# Fixed point: the TCP error is about noise * cond / sqrt(m); tilts of 60 degrees give
# cond 2.5 and errors of 0.04 mm mean, 0.085 mm max over 30 seeds at 0.05 mm noise.
FIXED_TILTS_DEG = [(0, 0, 0), (60, 0, 0), (-60, 0, 0), (0, 60, 0), (0, -60, 0), (40, 40, 120)]


def touches(points_m, tilts_deg=TILTS_DEG):
    return np.array([solve_touch(p, np.radians(t)) for p, t in zip(points_m, tilts_deg)])


@pytest.fixture(scope="module")
def marks_case():
    """Six marks on a table, touched with varied tilts; marks known to 0.05 mm."""
    rng = np.random.default_rng(0)
    true_marks = np.array([[1.10, -0.25, 0.40], [1.25, 0.10, 0.40], [1.05, 0.30, 0.42],
                           [1.30, -0.05, 0.38], [0.95, 0.05, 0.45], [1.15, 0.20, 0.40]])
    joints = touches(true_marks)
    known = true_marks + rng.normal(0.0, 0.05 * MM, true_marks.shape)
    return joints, true_marks, known


def test_known_marks_base_recovers_tcp_within_0p1_mm(marks_case):
    joints, _, known = marks_case
    result = calibrate_tool(ToolRequest("tGun", "known_marks", joints, known), irb2400_flange_pose)
    error_mm = np.linalg.norm(result.xyz_m - TOOL_M) / MM
    assert error_mm < 0.1
    assert result.quat_wxyz is None and result.point_m is None
    assert result.residuals_m.shape == (6,) and np.all(result.residuals_m < 0.3 * MM)
    assert np.all(result.xyz_std_m < 0.1 * MM)
    assert result.condition_number == pytest.approx(1.0)
    assert result.mark_names == ("M1", "M2", "M3", "M4", "M5", "M6")


def test_fixed_point_recovers_tcp_within_0p1_mm():
    rng = np.random.default_rng(1)
    point = np.array([1.1, 0.1, 0.4])
    touched = point + rng.normal(0.0, 0.05 * MM, (6, 3))  # where the tip really landed
    request = ToolRequest("tGun", "fixed_point", touches(touched, FIXED_TILTS_DEG))
    result = calibrate_tool(request, irb2400_flange_pose)
    assert np.linalg.norm(result.xyz_m - TOOL_M) / MM < 0.1
    assert np.linalg.norm(result.point_m - point) / MM < 0.1
    assert result.condition_number < COND_LIMIT
    assert np.all(np.isfinite(result.xyz_std_m)) and np.all(result.xyz_std_m < 0.2 * MM)


def test_world_frame_solves_world_T_base(marks_case):
    joints, true_marks, _ = marks_case
    rng = np.random.default_rng(2)
    world_T_base = np.eye(4)
    world_T_base[:3, :3] = rotation_from_rotvec([0.02, -0.03, 1.2])
    world_T_base[:3, 3] = [2.0, -1.0, 0.1]
    world_marks = true_marks @ world_T_base[:3, :3].T + world_T_base[:3, 3]
    world_marks += rng.normal(0.0, 0.05 * MM, world_marks.shape)
    result = tool_from_known_marks(irb2400_flange_pose(joints), world_marks, frame="world")
    assert np.linalg.norm(result.xyz_m - TOOL_M) / MM < 0.2
    assert np.allclose(result.world_T_base, world_T_base, atol=0.5 * MM)


def test_nearly_identical_orientations_are_refused_with_what_to_add():
    rng = np.random.default_rng(3)
    point = np.array([1.1, 0.1, 0.4])
    tilts = [(0, 0, 0), (0.5, 0, 0), (0, 0.5, 0), (0.3, 0.3, 0.2)]
    joints = touches(point + rng.normal(0, 0.05 * MM, (4, 3)), tilts)
    with pytest.raises(PoorlyDeterminedTool) as info:
        calibrate_tool(ToolRequest("t", "fixed_point", joints), irb2400_flange_pose)
    assert "at least 30 degrees about two different axes" in str(info.value)
    assert info.value.condition_number > COND_LIMIT


def test_rotations_about_one_axis_name_the_missing_direction():
    point = np.array([1.1, 0.1, 0.4])
    tilts = [(0, 0, a) for a in (0, 40, 80, -40, -80)]  # all about base z
    joints = touches(np.tile(point, (5, 1)), tilts)
    with pytest.raises(PoorlyDeterminedTool) as info:
        tool_from_fixed_point(irb2400_flange_pose(joints))
    message = str(info.value)
    assert "one axis, the base z axis (vertical)" in message
    assert "TCP component along the flange z axis is undetermined" in message
    assert "about a horizontal axis" in message


def test_world_frame_refuses_pure_translations(marks_case):
    _, true_marks, _ = marks_case
    joints = touches(true_marks, [(0, 0, 0)] * 6)
    with pytest.raises(PoorlyDeterminedTool, match="two different axes"):
        tool_from_known_marks(irb2400_flange_pose(joints), true_marks, frame="world")


def test_too_few_marks_and_bad_shapes_are_data_errors():
    poses = irb2400_flange_pose(np.zeros((2, 6)))
    with pytest.raises(DataError, match="at least 3"):
        tool_from_known_marks(poses, np.zeros((2, 3)))
    with pytest.raises(DataError, match=r"shape \(3, 3\)"):
        tool_from_known_marks(irb2400_flange_pose(np.zeros((3, 6))), np.zeros((2, 3)))


NUM = r"(-?\d+(?:\.\d+)?)"


def test_rapid_tooldata_parses_back_to_the_same_numbers(marks_case):
    joints, _, known = marks_case
    result = calibrate_tool(ToolRequest("tGun", "known_marks", joints, known), irb2400_flange_pose)
    text = rapid_tooldata(result, mass_kg=2.5, cog_mm=(0, 0, 120.5))
    pattern = (rf"\[TRUE,\[\[{NUM},{NUM},{NUM}\],\[{NUM},{NUM},{NUM},{NUM}\]\],"
               rf"\[{NUM},\[{NUM},{NUM},{NUM}\],\[{NUM},{NUM},{NUM},{NUM}\],{NUM},{NUM},{NUM}\]\]")
    found = re.fullmatch(pattern, text)
    assert found, text
    values = [float(v) for v in found.groups()]
    assert np.allclose(values[:3], result.xyz_m / MM, atol=0.0005)
    assert values[3:7] == [1, 0, 0, 0]
    assert values[7:11] == [2.5, 0, 0, 120.5]
    with pytest.raises(DataError, match="mass"):
        rapid_tooldata(result, mass_kg=0.0)


def test_marks_csv_round_trip_and_errors(tmp_path, marks_case):
    joints, _, known = marks_case
    request = ToolRequest("tGun", "known_marks", joints, known)
    path = tmp_path / "marks.csv"
    path.write_text(format_marks_csv(request))
    back = read_marks_csv(path, 6)
    assert back.name == "tGun" and back.method == "known_marks" and back.frame == "base"
    assert np.allclose(back.joints, joints, atol=1e-8) and np.allclose(back.marks, known,
                                                                       atol=1e-7)
    lines = path.read_text().splitlines()
    bad = lines[:4] + [lines[4].replace(lines[4].split(",")[2], "abc", 1)] + lines[5:]
    path.write_text("\n".join(bad))
    with pytest.raises(DataError, match=r"marks.csv:5: column 'q2_deg': 'abc' is not a number"):
        read_marks_csv(path, 6)
    path.write_text("\n".join(lines[:3] + [lines[3] + ",nan"] + lines[4:]))
    with pytest.raises(DataError, match="fields"):
        read_marks_csv(path, 6)
    path.write_text("mark,q1_deg,x_mm,y_mm,z_mm\nM1,1,2,3,4\n")
    with pytest.raises(DataError, match=r"marks.csv:1: missing column 'q2_deg'"):
        read_marks_csv(path, 6)
    path.write_text("mark,q1_deg,q2_deg,x_mm,y_mm,z_mm\nM1,1,2,1,2,3\nM2,1,2,,,\n")
    with pytest.raises(DataError, match=r"marks.csv:3: coordinates .* every row"):
        read_marks_csv(path, 2)
    path.write_text("mark,q1_deg,q2_deg,x_mm,y_mm,z_mm\nM1,1,nan,1,2,3\n")
    with pytest.raises(DataError, match=r"marks.csv:2: column 'q2_deg': nan is not a finite"):
        read_marks_csv(path, 2)


def test_fixed_point_csv_has_empty_coordinates(tmp_path):
    point = np.array([1.1, 0.1, 0.4])
    joints = touches(np.tile(point, (6, 1)))
    path = tmp_path / "fp.csv"
    path.write_text(format_marks_csv(ToolRequest("tPin", "fixed_point", joints)))
    request = read_marks_csv(path, 6)
    assert request.method == "fixed_point" and request.marks is None
    result = calibrate_tool(request, irb2400_flange_pose)
    assert np.linalg.norm(result.xyz_m - TOOL_M) / MM < 1e-3
    write_tool_json(result, tmp_path / "tool.json")
    assert '"tPin"' in (tmp_path / "tool.json").read_text()
