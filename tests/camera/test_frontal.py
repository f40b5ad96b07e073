"""Issue 33 item 2: views nearer to face-on than the RAC admits still calibrate.

Ten views all within 15 degrees of face-on were refused ("0 of 10 views tilted >= 20
deg"). They now start from their homographies (Zhang) and join the refinement. Truth: the
rendering camera; accuracy as the README states it, the camera's position measured on new
views against the rendered pose, as a fraction of the distance.

How well face-on views fix the focal length depends on their tilt (the information grows
with its square): with views tilted 10-15 degrees the rendered set below measures at 1:17,000
(median); tilts spread over 2-15 degrees give 1:6,800 on the same kind of set (the focal
length's standard deviation is then 0.25 px of 1500, which is that ratio: a limit of the
views, not of the method).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from olp_compensate.camera.board import Board
from olp_compensate.camera.calibrate import View, calibrate
from olp_compensate.camera.detect import circle_centre_bias, detect_dots
from olp_compensate.camera.measure import measure_pose
from olp_compensate.camera.model import CameraIntrinsics, project_points
from olp_compensate.camera.render import RenderOptions, random_views, render_board
from olp_compensate.camera.zhang import zhang_start
from olp_compensate.errors import DataError
from olp_compensate.kinematics.conventions import invert_pose

CAMERA = CameraIntrinsics(fx=1500.0, mu=1.0, cx=645.5, cy=477.0, k1=0.12, k2=-0.05,
                          width=1280, height=960)
BOARD = Board(rows=9, cols=9, pitch_m=0.025, dot_diameter_m=0.006, marker_diameter_m=0.01)
RENDER = RenderOptions(supersample=8, noise_sigma=2.0, blur_sigma_px=0.8, gradient=0.3,
                       vignetting=0.15)
FRONTAL = (10.0, 15.0)


def _exact_views(count, tilt, seed, camera=CAMERA):
    poses = random_views(BOARD, camera, count, np.random.default_rng(seed), (0.35, 0.8), tilt,
                         margin_px=15.0)
    points = BOARD.dot_positions()
    return [View(f"v{k}", project_points(camera, T, points), points)
            for k, T in enumerate(poses)], poses


def test_homographies_start_near_the_truth_on_exact_frontal_views():
    pinhole = replace(CAMERA, k1=0.0, k2=0.0)
    views, poses = _exact_views(10, FRONTAL, 1, pinhole)
    start, started = zhang_start([v.pixels for v in views], [v.points for v in views],
                                 1280, 960)
    assert abs(start.fx - pinhole.fx) / pinhole.fx < 0.05
    for T, truth in zip(started, poses):
        assert np.linalg.norm(T[:3, 3] - truth[:3, 3]) < 0.05 * np.linalg.norm(truth[:3, 3])


def test_frontal_views_calibrate_and_say_how_they_entered():
    views, _ = _exact_views(10, FRONTAL, 2)
    cal = calibrate(views, 1280, 960)
    assert cal.start == "homography"
    assert {v.stage for v in cal.views} == {"homography"}
    assert all(v.tilt_deg < 15.5 for v in cal.views)
    assert abs(cal.intrinsics.fx - CAMERA.fx) < 1.0 and cal.rms_px < 1e-3
    with pytest.raises(DataError, match="rac-only"):
        calibrate(views, 1280, 960, method="rac-only")
    # mixed: tilted views go through the RAC, the frontal ones start from its intrinsics
    tilted, _ = _exact_views(6, (25.0, 45.0), 3)
    mixed = calibrate(tilted + views[:4], 1280, 960)
    assert mixed.start == "rac"
    assert [v.stage for v in mixed.views] == ["rac"] * 6 + ["rac-pose"] * 4


def _detected(poses, seed):
    out = []
    for k, T in enumerate(poses):
        found = detect_dots(render_board(BOARD, CAMERA, T, replace(RENDER, seed=seed + k)),
                            BOARD)
        assert found.ok, found.reason
        out.append(found.pixels)
    return out


@pytest.mark.slow
def test_ten_rendered_frontal_views_measure_better_than_1_in_10000():
    rng = np.random.default_rng(40)
    cal_poses = random_views(BOARD, CAMERA, 10, rng, (0.35, 0.8), FRONTAL, margin_px=15.0)
    points = BOARD.dot_positions()
    views = [View(f"f{k}", p, points) for k, p in enumerate(_detected(cal_poses, 100))]
    bias = lambda k, T: circle_centre_bias(k, T, BOARD)           # noqa: E731
    cal = calibrate(views, 1280, 960, centre_bias=bias)
    assert cal.start == "homography" and max(v.tilt_deg for v in cal.views) < 15.5
    new_poses = random_views(BOARD, CAMERA, 10, rng, (0.35, 0.8), (20.0, 50.0),
                             margin_px=15.0)
    ratios = []
    for pixels, T in zip(_detected(new_poses, 300), new_poses):
        m = measure_pose(pixels, points, cal.intrinsics, centre_bias=bias)
        truth = invert_pose(T)[:3, 3]
        distance = np.linalg.norm(truth - points.mean(axis=0))
        ratios.append(distance / np.linalg.norm(m.board_T_camera[:3, 3] - truth))
    assert np.median(ratios) > 10_000, np.median(ratios)
