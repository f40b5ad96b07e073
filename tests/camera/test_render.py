"""The renderer against geometry computed without it: projected dot areas and centroids,
sheet and background, light, noise and clutter, and the random view helper."""

import math

import numpy as np
import pytest

from olp_compensate.camera.board import Board
from olp_compensate.camera.model import CameraIntrinsics, project_points
from olp_compensate.camera.render import RenderOptions, board_in_view, random_views, render_board
from olp_compensate.errors import DataError
from olp_compensate.kinematics.conventions import invert_pose

BOARD = Board(rows=9, cols=9, pitch_m=0.025, dot_diameter_m=0.005, marker_diameter_m=0.008)
CAMERA = CameraIntrinsics(fx=1100.0, mu=0.98, cx=484.0, cy=355.0, k1=0.1, width=960,
                          height=720)


@pytest.fixture(scope="module")
def view():
    return random_views(BOARD, CAMERA, 1, np.random.default_rng(7),
                        distance_m=(0.4, 0.45), tilt_deg=(40, 45))[0]


def _projected_disc(pose, index, samples=720):
    """Area (px^2) and centroid (px) of the polygon a dot's projected boundary encloses."""
    t = np.linspace(0, 2 * np.pi, samples, endpoint=False)
    r = BOARD.dot_radii()[index]
    ring = BOARD.dot_positions()[index] + r * np.stack([np.cos(t), np.sin(t), 0 * t], -1)
    p = project_points(CAMERA, pose, ring)
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2
    return abs(area), np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6 * area)


def test_dot_coverage_matches_projected_area_and_centroid(view):
    options = RenderOptions(paper=200.0, ink=20.0)
    image = render_board(BOARD, CAMERA, view, options).astype(float)
    coverage = (options.paper - image) / (options.paper - options.ink)
    centres = project_points(CAMERA, view, BOARD.dot_positions())
    for index in (0, 8, 40, 72, 80):
        area, centroid = _projected_disc(view, index)
        half = int(math.sqrt(area) * 1.2) + 3
        x, y = np.rint(centres[index]).astype(int)
        patch = coverage[y - half:y + half + 1, x - half:x + half + 1]
        ys, xs = np.mgrid[y - half:y + half + 1, x - half:x + half + 1]
        assert patch.sum() == pytest.approx(area, rel=0.005)
        found = np.array([(patch * xs).sum(), (patch * ys).sum()]) / patch.sum()
        np.testing.assert_allclose(found, centroid, atol=0.01)
    # the marker's image is (8/5)^2 times a neighbour's, roughly (perspective varies)
    assert _projected_disc(view, 0)[0] / _projected_disc(view, 1)[0] == pytest.approx(
        2.56, rel=0.15)


def test_sheet_paper_and_background(view):
    options = RenderOptions(paper=200.0, ink=20.0, background=70.0)
    image = render_board(BOARD, CAMERA, view, options)
    sheet = BOARD.sheet_extent()
    on_sheet = [[sheet.x_min + 0.004, 0.1, 0], [0.0125, 0.0125, 0], [0.1, sheet.y_max - 0.004, 0]]
    beyond = [[sheet.x_min - 0.01, 0.1, 0], [0.1, sheet.y_max + 0.01, 0]]
    for point, level in [(p, 200) for p in on_sheet] + [(p, 70) for p in beyond]:
        x, y = np.rint(project_points(CAMERA, view, np.array([point]))[0]).astype(int)
        assert image[y, x] == level


def test_light_falloff_noise_and_seed(view):
    far = invert_pose(np.array([[1.0, 0, 0, 0.1], [0, 1, 0, 0.1], [0, 0, 1, -1.5],
                                [0, 0, 0, 1]]))  # small board in the middle, corners empty
    flat = RenderOptions(background=100.0, vignetting=0.3)
    image = render_board(BOARD, CAMERA, far, flat).astype(float)
    assert image[0, 0] == pytest.approx(70, abs=1) and image[-1, -1] == pytest.approx(70, abs=1)
    assert image[0, 480] > 85
    sloped = render_board(BOARD, CAMERA, far, RenderOptions(background=100.0, gradient=0.4,
                                                            gradient_angle_deg=0.0))
    assert sloped[360, 0] / sloped[360, -1] == pytest.approx(100 / 60, rel=0.03)

    noisy = RenderOptions(noise_sigma=4.0, seed=3)
    a = render_board(BOARD, CAMERA, view, noisy).astype(float)
    b = render_board(BOARD, CAMERA, view, noisy).astype(float)
    c = render_board(BOARD, CAMERA, view, RenderOptions(noise_sigma=4.0, seed=4)).astype(float)
    assert np.array_equal(a, b)
    assert np.std(a - c) / math.sqrt(2) == pytest.approx(4.0, rel=0.05)


def test_clutter_only_beyond_the_sheet(view):
    plain = render_board(BOARD, CAMERA, view, RenderOptions()).astype(float)
    busy = render_board(BOARD, CAMERA, view, RenderOptions(clutter=True, seed=1)).astype(float)
    changed = plain != busy
    assert changed.mean() > 0.2 and np.std(busy[changed]) > 20
    centre = np.rint(project_points(CAMERA, view, np.array([[0.1, 0.1, 0.0]]))[0]).astype(int)
    x, y = centre
    assert not changed[y - 60:y + 60, x - 60:x + 60].any()  # the middle of the sheet


def test_random_views_see_the_whole_board_from_the_front():
    rng = np.random.default_rng(11)
    views = random_views(BOARD, CAMERA, 12, rng, distance_m=(0.35, 0.8), tilt_deg=(20, 50))
    centre = np.array([0.1, 0.1, 0.0])
    for pose in views:
        board_T_camera = invert_pose(pose)
        eye, axis = board_T_camera[:3, 3], board_T_camera[:3, 2]
        assert eye[2] < 0  # the printed side
        assert 0.33 < np.linalg.norm(eye - centre) < 0.82
        tilt = math.degrees(math.acos(axis[2]))
        assert 20 - 1e-9 <= tilt <= 50 + 1e-9
        assert board_in_view(BOARD, CAMERA, pose, margin_px=10)
    rolls = [math.atan2(p[0, 1], p[0, 0]) for p in views]
    assert np.ptp(rolls) > math.pi  # turned every way about the optical axis
    again = random_views(BOARD, CAMERA, 12, np.random.default_rng(11))
    np.testing.assert_array_equal(np.array(views), np.array(again))


def test_needs_an_image_size(view):
    camera = CameraIntrinsics(fx=1100.0, mu=1.0, cx=480.0, cy=360.0)
    with pytest.raises(DataError, match="image size"):
        render_board(BOARD, camera, view)
    assert render_board(BOARD, camera, view, size=(320, 240)).shape == (240, 320)
