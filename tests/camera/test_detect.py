"""Dot detection on rendered views against the true images of the dots, and the circle
centre perspective bias against the analytic conic centre.

Truth for a detected dot: the centroid of the area of its image, i.e. the projection of
the dot's centre plus :func:`circle_centre_bias` (checked on its own below).
"""

import math

import numpy as np
import pytest

from olp_compensate.camera.blobs import (CONTRAST_THRESHOLDS, dark_mask, darkness, find_blobs,
                                         paper_level)
from olp_compensate.camera.board import Board
from olp_compensate.camera.detect import (BORDER_MARGIN_PX, Detection, DetectionFailure,
                                          circle_centre_bias, detect_dots, detect_many, match_grid,
                                          refine_centres)
from olp_compensate.camera.centres import polygon_centre_bias
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


def _conic_centres(camera, pose):
    """The centre of each dot's image conic (px): the exact image of the dot's area
    centroid without distortion (C' = H^-T C H^-1, H the board plane's homography)."""
    K = np.array([[camera.fx, 0, camera.cx], [0, camera.fy, camera.cy], [0, 0, 1]])
    Hinv = np.linalg.inv(K @ np.column_stack([pose[:3, 0], pose[:3, 1], pose[:3, 3]]))
    out = []
    for (a, b, _), rho in zip(BOARD.dot_positions(), BOARD.dot_radii()):
        C = np.array([[1, 0, -a], [0, 1, -b], [-a, -b, a * a + b * b - rho * rho]])
        Q = Hinv.T @ C @ Hinv  # the circle's image conic
        out.append(-np.linalg.solve(Q[:2, :2], Q[:2, 2]))
    return np.array(out)


def test_bias_polygon_matches_analytic_conic_centre(steep):
    camera = CameraIntrinsics(fx=1100.0, mu=0.98, cx=484.0, cy=355.0, width=960, height=720)
    bias = polygon_centre_bias(camera, steep, BOARD)
    centres = project_points(camera, steep, BOARD.dot_positions())
    np.testing.assert_allclose(centres + bias, _conic_centres(camera, steep), atol=1e-4)
    assert np.abs(bias).max() > 0.02  # not trivially zero at 50 degrees


def test_bias_quadrature_matches_extrapolated_fine_polygons(views, steep):
    """The boundary quadrature against the centroid of polygons of 4096 and 8192 projected
    boundary points, Richardson-extrapolated (error O(1/n^4)), under strong distortion of
    either sign: closer than the 256-chord polygon by far, and already at 12 nodes."""
    for camera in (CameraIntrinsics(fx=1100.0, mu=0.98, cx=484.0, cy=355.0, k1=-0.4, k2=0.2),
                   CAMERA):
        for pose in list(views) + [steep]:
            reference = (4 * polygon_centre_bias(camera, pose, BOARD, 8192)
                         - polygon_centre_bias(camera, pose, BOARD, 4096)) / 3
            chords = np.abs(polygon_centre_bias(camera, pose, BOARD, 256) - reference).max()
            for nodes in (12, 24):
                error = np.abs(circle_centre_bias(camera, pose, BOARD, nodes) - reference).max()
                assert error < 2e-7 and error < chords / 20, (nodes, error, chords)


def test_bias_quadrature_is_the_conic_centre_without_distortion(steep):
    camera = CameraIntrinsics(fx=1100.0, mu=0.98, cx=484.0, cy=355.0)
    bias = circle_centre_bias(camera, steep, BOARD)
    centres = project_points(camera, steep, BOARD.dot_positions())
    np.testing.assert_allclose(centres + bias, _conic_centres(camera, steep), atol=1e-8)


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


# -- the fast paths against the plain definitions --------------------------------------------

def test_dark_mask_is_the_thresholded_darkness(views):
    image = render_board(BOARD, CAMERA, views[0], ROUGH)
    paper = paper_level(image, BOARD)
    dark = darkness(image, BOARD, paper)
    for threshold in CONTRAST_THRESHOLDS + (0.05, 0.95):
        np.testing.assert_array_equal(dark_mask(image, paper, threshold) > 0, dark > threshold)
    with pytest.raises(Exception, match="threshold must be between 0 and 1"):
        dark_mask(image, paper, 1.0)


def _refine_one_by_one(grey, blobs, indices, iterations=2):
    """refine_centres as first written: each dot in its own window, plane by lstsq."""
    height, width = grey.shape
    centres, contrast = np.empty((len(indices), 2)), np.zeros(len(indices))
    inside = np.ones(len(indices), bool)
    image = grey.astype(np.float64)
    for k, b in enumerate(indices):
        centre = blobs.centres[b].copy()
        w, v = np.linalg.eigh(blobs.covariances[b])
        semi = 2 * np.sqrt(np.maximum(w, 0.25))
        window = semi + max(2.5, 0.35 * semi.min())
        outer = window + max(2.5, 0.35 * semi.min())
        half = int(math.ceil(outer.max())) + 2
        for _ in range(iterations):
            x0, y0 = int(round(centre[0])) - half, int(round(centre[1])) - half
            x1, y1 = x0 + 2 * half + 1, y0 + 2 * half + 1
            m = BORDER_MARGIN_PX
            if x0 < m or y0 < m or x1 > width - m or y1 > height - m:
                inside[k] = False
                break
            ys, xs = np.mgrid[y0:y1, x0:x1]
            px, py = xs - centre[0], ys - centre[1]
            u1, u2 = px * v[0, 0] + py * v[1, 0], px * v[0, 1] + py * v[1, 1]
            rw = (u1 / window[0]) ** 2 + (u2 / window[1]) ** 2
            ro = (u1 / outer[0]) ** 2 + (u2 / outer[1]) ** 2
            patch = image[y0:y1, x0:x1]
            ring, inner = (rw > 1) & (ro <= 1), rw <= 1
            A = np.stack([np.ones(ring.sum()), px[ring], py[ring]], -1)
            coef = np.linalg.lstsq(A, patch[ring], rcond=None)[0]
            paper = coef[0] + coef[1] * px[inner] + coef[2] * py[inner]
            weight = (paper - patch[inner]) / np.maximum(paper, 1.0)
            if weight.sum() <= 0:
                break
            centre = np.array([(weight * xs[inner]).sum(), (weight * ys[inner]).sum()]) \
                / weight.sum()
            contrast[k] = weight.max()
        centres[k] = centre
    return centres, contrast, inside


def test_refine_centres_all_at_once_matches_one_by_one(views):
    image = render_board(BOARD, CAMERA, views[1], ROUGH)
    blobs = find_blobs(dark_mask(image, paper_level(image, BOARD)))
    indices = match_grid(BOARD, blobs).blob_of_dot
    fast, slow = refine_centres(image, blobs, indices), _refine_one_by_one(image, blobs, indices)
    np.testing.assert_allclose(fast[0], slow[0], atol=1e-9)
    np.testing.assert_allclose(fast[1], slow[1], atol=1e-12)
    assert np.all(fast[2]) and np.all(slow[2])


def test_refine_centres_near_the_border():
    """Windows 2 px from the border are measured, one crossing the margin is reported
    outside, as one by one."""
    import cv2

    image = np.full((48, 90), 200, np.uint8)
    # own windows: 2 px from the left and right borders, crossing the top one
    for centre, radius in (((15, 24), 5), ((70, 24), 8), ((42, 8), 7)):
        cv2.circle(image, centre, radius, 30, -1, cv2.LINE_AA)
    image = cv2.GaussianBlur(image, (0, 0), 0.8)
    blobs = find_blobs(dark_mask(image, np.full_like(image, 200)))
    assert len(blobs.areas) == 3
    indices = np.arange(3)
    fast, slow = refine_centres(image, blobs, indices), _refine_one_by_one(image, blobs, indices)
    np.testing.assert_array_equal(fast[2], slow[2])
    assert np.sum(fast[2]) == 2  # the dot near the top crosses the margin
    ok = fast[2]
    np.testing.assert_allclose(fast[0][ok], slow[0][ok], atol=1e-9)
    np.testing.assert_allclose(fast[1][ok], slow[1][ok], atol=1e-12)
