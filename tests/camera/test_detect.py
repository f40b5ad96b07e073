"""Dot detection on rendered views against the true images of the dots, and the circle
centre perspective bias against the analytic conic centre.

Truth for a detected dot: the centroid of the area of its image, i.e. the projection of
the dot's centre plus :func:`circle_centre_bias` (checked on its own below).
"""

import math

import numpy as np
import pytest

from olp_compensate.camera.board import Board
from olp_compensate.camera.detect import (Detection, DetectionFailure, circle_centre_bias,
                                          detect_dots, detect_many)
from olp_compensate.camera.model import CameraIntrinsics, project_points
from olp_compensate.camera.render import RenderOptions, random_views, render_board
from olp_compensate.kinematics.conventions import pose_from_rotation_translation, rot_x

BOARD = Board(rows=9, cols=9, pitch_m=0.025, dot_diameter_m=0.005, marker_diameter_m=0.008)
CAMERA = CameraIntrinsics(fx=1100.0, mu=0.98, cx=484.0, cy=355.0, k1=0.1, width=960,
                          height=720)
ROUGH = RenderOptions(blur_sigma_px=1.0, noise_sigma=3.0, gradient=0.4, vignetting=0.3,
                      clutter=True)


def _truth(pose, camera=CAMERA):
    return project_points(camera, pose, BOARD.dot_positions()) + circle_centre_bias(
        camera, pose, BOARD)


def _rms(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


@pytest.fixture(scope="module")
def views():
    return random_views(BOARD, CAMERA, 3, np.random.default_rng(5))


@pytest.fixture(scope="module")
def clean(views):
    """Noise-free renders of ``views`` (made once; tests copy before drawing on them)."""
    return [render_board(BOARD, CAMERA, pose) for pose in views]


@pytest.fixture(scope="module")
def steep():
    """A close view, 50 degrees from the board normal: a large perspective bias."""
    return random_views(BOARD, CAMERA, 1, np.random.default_rng(2), distance_m=(0.36, 0.4),
                        tilt_deg=(50, 50))[0]


def test_bias_polygon_matches_analytic_conic_centre(steep):
    camera = CameraIntrinsics(fx=1100.0, mu=0.98, cx=484.0, cy=355.0, width=960, height=720)
    bias = circle_centre_bias(camera, steep, BOARD)
    K = np.array([[camera.fx, 0, camera.cx], [0, camera.fy, camera.cy], [0, 0, 1]])
    Hinv = np.linalg.inv(K @ np.column_stack([steep[:3, 0], steep[:3, 1], steep[:3, 3]]))
    centres = project_points(camera, steep, BOARD.dot_positions())
    for (a, b, _), rho, centre, d in zip(BOARD.dot_positions(), BOARD.dot_radii(), centres,
                                         bias):
        C = np.array([[1, 0, -a], [0, 1, -b], [-a, -b, a * a + b * b - rho * rho]])
        Q = Hinv.T @ C @ Hinv  # the circle's image conic
        conic_centre = -np.linalg.solve(Q[:2, :2], Q[:2, 2])
        np.testing.assert_allclose(centre + d, conic_centre, atol=1e-4)
    assert np.abs(bias).max() > 0.02  # not trivially zero at 50 degrees


def test_no_bias_when_the_board_faces_a_distortion_free_camera():
    camera = CameraIntrinsics(fx=1100.0, mu=0.98, cx=484.0, cy=355.0)
    facing = pose_from_rotation_translation(np.eye(3), [-0.1, -0.1, 0.5])
    assert np.abs(circle_centre_bias(camera, facing, BOARD)).max() < 1e-6
    tilted = pose_from_rotation_translation(rot_x(math.radians(40)), [-0.1, -0.1, 0.5])
    assert np.abs(circle_centre_bias(camera, tilted, BOARD)).max() > 0.01


def test_noise_free_views_subpixel(views, clean, steep):
    for pose, image in zip(views + [steep], clean + [render_board(BOARD, CAMERA, steep)]):
        found = detect_dots(image, BOARD, "clean.png")
        assert isinstance(found, Detection), found
        assert found.pixels.shape == (81, 2)
        assert _rms(found.pixels, _truth(pose)) < 0.015  # measured 0.004-0.007
    # the detector finds the centroid of the dot's image, not the image of its centre
    plain = project_points(CAMERA, steep, BOARD.dot_positions())
    assert _rms(found.pixels, plain) > 3 * _rms(found.pixels, _truth(steep))


def test_blur_noise_uneven_light_and_clutter(views):
    for seed, pose in enumerate(views[:2]):
        image = render_board(BOARD, CAMERA, pose, RenderOptions(**{**ROUGH.__dict__,
                                                                   "seed": seed}))
        found = detect_dots(image, BOARD, "rough.png")
        assert isinstance(found, Detection), found
        assert _rms(found.pixels, _truth(pose)) < 0.06  # measured 0.02-0.03


def test_weighted_centroid_beats_contour_ellipse_fit(views, clean):
    image = clean[0]
    centroid = detect_dots(image, BOARD, method="centroid")
    ellipse = detect_dots(image, BOARD, method="ellipse")
    assert _rms(centroid.pixels, _truth(views[0])) < 0.3 * _rms(ellipse.pixels,
                                                               _truth(views[0]))


def _rotate_pixels(pixels, k, width, height):
    """Pixel coordinates after np.rot90(image, k) (counter-clockwise quarter turns)."""
    p = pixels.copy()
    for _ in range(k):
        p = np.stack([p[:, 1], width - 1 - p[:, 0]], -1)
        width, height = height, width
    return p


@pytest.mark.parametrize("k", [1, 2, 3])
def test_order_follows_the_marker_under_quarter_turns(views, clean, k):
    image = clean[1]
    turned = np.ascontiguousarray(np.rot90(image, k))
    found = detect_dots(turned, BOARD)
    assert isinstance(found, Detection), found
    expected = _rotate_pixels(_truth(views[1]), k, 960, 720)
    assert np.max(np.linalg.norm(found.pixels - expected, axis=1)) < 0.05


def test_strong_perspective_with_a_wide_lens():
    camera = CameraIntrinsics(fx=620.0, mu=1.0, cx=480.0, cy=360.0, k1=0.25, width=960,
                              height=720)
    pose = random_views(BOARD, camera, 1, np.random.default_rng(4), distance_m=(0.28, 0.3),
                        tilt_deg=(62, 65))[0]
    found = detect_dots(render_board(BOARD, camera, pose), BOARD)
    assert isinstance(found, Detection), found
    areas = found.area_px[1:]
    assert areas.max() / areas.min() > 2.5  # near dots much larger than far ones
    assert _rms(found.pixels, _truth(pose, camera)) < 0.03


@pytest.mark.parametrize("seed", [21, 22])
def test_clutter_does_not_break_it(views, seed):
    image = render_board(BOARD, CAMERA, views[2], RenderOptions(clutter=True, seed=seed))
    found = detect_dots(image, BOARD)
    assert isinstance(found, Detection), found
    assert _rms(found.pixels, _truth(views[2])) < 0.02


def _shifted(pose, index, target_px):
    """``pose`` with the camera moved sideways so that dot ``index`` images near
    ``target_px`` (the image shifts by about the same amount everywhere)."""
    p = project_points(CAMERA, pose, BOARD.dot_positions()[index:index + 1])[0]
    moved = pose.copy()
    depth = (pose[:3, :3] @ BOARD.dot_positions()[index] + pose[:3, 3])[2]
    moved[0, 3] += (target_px[0] - p[0]) / CAMERA.fx * depth
    moved[1, 3] += (target_px[1] - p[1]) / CAMERA.fy * depth
    return moved


def test_board_partly_outside_the_image_is_skipped(views):
    pose = views[0]
    dots = project_points(CAMERA, pose, BOARD.dot_positions())
    # push the corner opposite the marker out over the nearest image border
    far = dots[80] - dots[0]
    axis = int(np.argmax(np.abs(far)))
    target = dots[80].copy()
    size = (CAMERA.width, CAMERA.height)[axis]
    target[axis] = size + 15 if far[axis] > 0 else -15
    found = detect_dots(render_board(BOARD, CAMERA, _shifted(pose, 80, target)), BOARD,
                        "cut.png")
    assert isinstance(found, DetectionFailure)
    assert found.name == "cut.png" and "border" in found.reason
    assert found.reason.startswith("found ") and "outside the image" in found.reason
    # the marker's corner cut off instead
    target = dots[0].copy()
    target[axis] = size + 15 if far[axis] < 0 else -15
    found = detect_dots(render_board(BOARD, CAMERA, _shifted(pose, 0, target)), BOARD)
    assert isinstance(found, DetectionFailure)
    assert found.reason.startswith("no marker dot") and "border" in found.reason


def test_covered_dots_are_reported_by_count(views, clean):
    import cv2

    pose = views[0]
    image = clean[0].copy()
    dots = project_points(CAMERA, pose, BOARD.dot_positions())
    for index in (40, 41, 49):  # a hand over three dots in the middle
        cv2.circle(image, tuple(int(v) for v in np.rint(dots[index])), 14, 215, -1)
    found = detect_dots(image, BOARD, "hand.png")
    assert isinstance(found, DetectionFailure)
    assert found.reason.startswith("found 78 of 81 dots")


def test_hidden_marker_and_empty_images(views, clean):
    import cv2

    image = clean[0].copy()
    marker = project_points(CAMERA, views[0], BOARD.dot_positions()[:1])[0]
    cv2.circle(image, tuple(int(v) for v in np.rint(marker)), 20, 215, -1)
    found = detect_dots(image, BOARD)
    assert isinstance(found, DetectionFailure) and found.reason == "no marker dot"
    blank = detect_dots(np.full((480, 640), 200, np.uint8), BOARD, "blank.png")
    assert isinstance(blank, DetectionFailure) and "found 0" in blank.reason


def test_detect_many_reads_a_folder_in_name_order(tmp_path, views):
    import cv2

    image = render_board(BOARD, CAMERA, views[1], RenderOptions(noise_sigma=1.0))
    cv2.imwrite(str(tmp_path / "b.png"), image)
    cv2.imwrite(str(tmp_path / "a.JPG"), cv2.cvtColor(image, cv2.COLOR_GRAY2BGR),
                [cv2.IMWRITE_JPEG_QUALITY, 95])
    (tmp_path / "c.png").write_bytes(b"not a png")
    (tmp_path / "notes.txt").write_text("ignored")
    results = list(detect_many(tmp_path, BOARD))
    assert [r.name for r in results] == ["a.JPG", "b.png", "c.png"]
    assert results[0].ok and results[1].ok and not results[2].ok
    assert "cannot read" in results[2].reason
    assert _rms(results[1].pixels, _truth(views[1])) < 0.03
    assert _rms(results[0].pixels, _truth(views[1])) < 0.1  # JPEG artefacts
    listed = list(detect_many([tmp_path / "b.png"], BOARD))
    assert len(listed) == 1 and listed[0].ok
