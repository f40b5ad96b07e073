"""``olp-cal camera board | calibrate | measure`` on rendered images of a known camera."""

import argparse
import contextlib
import csv
import io
import json

import numpy as np
import pytest

from olp_compensate.camera.board import Board, read_board, write_board
from olp_compensate.camera.model import CameraIntrinsics
from olp_compensate.camera.render import RenderOptions, random_views, render_board
from olp_compensate.cli import cal_camera
from olp_compensate.cli.common import run_guarded
from olp_compensate.io.camera_file import camera_schema, read_camera
from olp_compensate.io.images import write_png
from olp_compensate.io.measurements import parse_measurements
from olp_compensate.kinematics.conventions import invert_pose, matrix_from_quat_wxyz

CAMERA = CameraIntrinsics(fx=800.0, mu=0.99, cx=330.0, cy=236.0, k1=0.08, width=640,
                          height=480)
BOARD = Board(rows=7, cols=7, pitch_m=0.02, dot_diameter_m=0.005, marker_diameter_m=0.008)


def olp_cal_camera(argv):
    """Run ``olp-cal camera ARGV`` (through olp-cal once the lead registers the command)."""
    from olp_compensate.cli import cal

    if "camera" in cal.COMMANDS:
        return cal.main(["camera"] + list(argv))
    parser = argparse.ArgumentParser(prog="olp-cal camera")
    cal_camera.add_arguments(parser)
    args = parser.parse_args(argv)
    return run_guarded(lambda: cal_camera.run(args), 0, "olp-cal")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A folder of 8 calibration views, a folder of 3 measurement views, board.json."""
    root = tmp_path_factory.mktemp("camera")
    rng = np.random.default_rng(50)
    poses = random_views(BOARD, CAMERA, 11, rng, distance_m=(0.28, 0.38),
                         tilt_deg=(28, 45))
    (root / "cal").mkdir()
    (root / "meas").mkdir()
    for k, T in enumerate(poses):
        image = render_board(BOARD, CAMERA, T, RenderOptions(supersample=4, noise_sigma=1.0,
                                                             seed=k))
        folder = "cal" if k < 8 else "meas"
        suffix = ".PNG" if k == 3 else ".png"      # any case
        write_png(root / folder / f"view{k:02d}{suffix}", image)
    write_png(root / "meas" / "view99_blank.png", np.full((480, 640), 200, np.uint8))
    write_board(BOARD, root / "board.json")
    return root, poses


@pytest.fixture(scope="module")
def calibration_run(scene):
    """(exit code, printed text, camera.json) of one calibration of the scene."""
    root, _ = scene
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = olp_cal_camera(["calibrate", str(root / "cal"), "--board",
                               str(root / "board.json"), "-o", str(root / "camera.json")])
    return code, printed.getvalue(), root / "camera.json"


@pytest.fixture(scope="module")
def calibrated(calibration_run):
    assert calibration_run[0] == 0, calibration_run[1]
    return calibration_run[2]


def test_board_writes_json_svg_and_png(tmp_path, capsys):
    out = tmp_path / "board.json"
    code = olp_cal_camera(["board", "--rows", "9", "--cols", "9", "--pitch-mm", "25",
                           "--dot-mm", "5", "--marker-mm", "8", "-o", str(out),
                           "--svg", str(tmp_path / "b.svg"), "--png", str(tmp_path / "b.png"),
                           "--dpi", "100"])
    assert code == 0
    assert json.loads(out.read_text()) == {"rows": 9, "cols": 9, "pitch_mm": 25.0,
                                           "dot_diameter_mm": 5.0, "marker_diameter_mm": 8.0}
    assert (tmp_path / "b.svg").read_text().lstrip().startswith("<")
    assert (tmp_path / "b.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_calibrate_prints_rms_and_parameters_and_writes_valid_camera_json(calibration_run):
    code, text, out = calibration_run
    assert code == 0, text
    assert "view03.PNG" in text and "overall: rms" in text and "fx " in text
    assert "+/-" in text and " px" in text
    doc = json.loads(out.read_text())
    import jsonschema

    jsonschema.validators.validator_for(camera_schema()).check_schema(camera_schema())
    jsonschema.validate(doc, camera_schema())
    cal = read_camera(out)
    k = cal.intrinsics
    assert abs(k.fx - CAMERA.fx) < max(3 * cal.std["fx"], 2.0)
    assert abs(k.cx - CAMERA.cx) < 3.0 and abs(k.cy - CAMERA.cy) < 3.0
    assert abs(k.mu - CAMERA.mu) < 2e-3
    assert cal.rms_px < 0.2 and len(cal.views) == 8
    assert doc["fit"]["circle_bias_iterations"] == 3


def test_calibrate_rac_only_keeps_the_rac_estimates(scene, capsys):
    root, _ = scene
    out = root / "camera_rac.json"
    assert olp_cal_camera(["calibrate", str(root / "cal"), "--board", str(root / "board.json"),
                           "-o", str(out), "--method", "rac-only",
                           "--no-circle-correction"]) == 0
    doc = json.loads(out.read_text())
    assert doc["method"] == "rac-only" and doc["std"]["fx_px"] is None
    assert doc["intrinsics"] == doc["rac_estimate"]
    assert "n/a" in capsys.readouterr().out


def test_measure_writes_camera_poses_in_the_board_frame(scene, calibrated, capsys):
    root, poses = scene
    out = root / "poses.csv"
    code = olp_cal_camera(["measure", str(root / "meas"), "--camera", str(calibrated),
                           "--board", str(root / "board.json"), "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "view99_blank.png: board not found" in text
    rows = list(csv.DictReader(out.open()))
    assert list(rows[0]) == ["image", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz",
                             "rms_px"]
    assert [r["image"] for r in rows] == ["view08.png", "view09.png", "view10.png"]
    for row, T in zip(rows, poses[8:]):
        truth = invert_pose(T)
        xyz = np.array([float(row[c]) for c in ("x_mm", "y_mm", "z_mm")])
        assert np.linalg.norm(xyz - truth[:3, 3] * 1e3) < 1.0     # mm at ~330 mm
        q = np.array([float(row[c]) for c in ("qw", "qx", "qy", "qz")])
        assert q[0] >= 0
        np.testing.assert_allclose(matrix_from_quat_wxyz(q), truth[:3, :3], atol=3e-3)


def test_measure_with_joints_writes_a_measurement_csv_for_identify(scene, calibrated, capsys):
    root, _ = scene
    joints = root / "joints.csv"
    joints.write_text("image,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,note\n"
                      "view10.png,1,2,3,4,5,6,last\n"
                      "view08.png,0,-10,20,0,30,0,first\n"
                      "view99_blank.png,0,0,0,0,0,0,blank\n")
    out = root / "meas.csv"
    code = olp_cal_camera(["measure", str(root / "meas"), "--camera", str(calibrated),
                           "--board", str(root / "board.json"), "-o", str(out),
                           "--joints", str(joints), "--name", "cam1"])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "view99_blank.png: board not found" in text
    assert "view09.png: no row in" in text
    meas = parse_measurements(out.read_text(), ["deg"] * 6, str(out))
    assert list(meas.pose_ids) == ["1", "2"]
    assert list(meas.point_names) == ["cam1", "cam1"]
    assert meas.orientation is not None and meas.extra["image"] == ["view10.png", "view08.png"]
    assert meas.extra["note"] == ["last", "first"]
    np.testing.assert_allclose(np.degrees(meas.joints[1]), [0, -10, 20, 0, 30, 0])
    sigma = np.array(meas.extra["sigma_mm"], dtype=float)
    assert np.all((sigma > 0) & (sigma < 1.0))


@pytest.mark.parametrize("case", ["unreadable", "board_key", "joints_no_image",
                                  "joints_missing_image", "over_input"])
def test_bad_input_exits_1_with_one_line(scene, calibrated, tmp_path, capsys, case):
    root, _ = scene
    board, camera = str(root / "board.json"), str(calibrated)
    image = str(root / "meas" / "view08.png")
    if case == "unreadable":
        bad = tmp_path / "broken.png"
        bad.write_bytes(b"not a png at all")
        argv = ["measure", str(bad), "--camera", camera, "--board", board,
                "-o", str(tmp_path / "o.csv")]
    elif case == "board_key":
        bad = tmp_path / "board.json"
        bad.write_text(json.dumps({"rows": 7, "cols": 7, "pitch_mm": 20, "dot_diameter_mm": 5}))
        argv = ["calibrate", str(root / "cal"), "--board", str(bad),
                "-o", str(tmp_path / "c.json")]
    elif case == "joints_no_image":
        j = tmp_path / "j.csv"
        j.write_text("file,q1_deg\nview08.png,1\n")
        argv = ["measure", image, "--camera", camera, "--board", board,
                "-o", str(tmp_path / "o.csv"), "--joints", str(j)]
    elif case == "joints_missing_image":
        j = tmp_path / "j.csv"
        j.write_text("image,q1_deg\nview08.png,1\nnowhere.png,2\n")
        argv = ["measure", image, "--camera", camera, "--board", board,
                "-o", str(tmp_path / "o.csv"), "--joints", str(j)]
    else:
        argv = ["measure", image, "--camera", camera, "--board", board, "-o", board]
    before = (root / "board.json").read_bytes()
    assert olp_cal_camera(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("olp-cal: error:")
    assert (root / "board.json").read_bytes() == before
    assert read_board(root / "board.json") == BOARD
