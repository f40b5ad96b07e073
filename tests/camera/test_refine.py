"""Full refinement (camera/refine.py) and the calibration pipeline (camera/calibrate.py):
analytic Jacobian against central differences, estimates against truth
within their reported standard deviations."""

import numpy as np
import pytest

from olp_compensate.camera import rac, refine
from olp_compensate.camera.model import project_points
from olp_compensate.camera.calibrate import MIN_VIEWS, View, calibrate
from olp_compensate.camera.detect import circle_centre_bias
from olp_compensate.errors import DataError
from olp_compensate.kinematics.conventions import rot_z, rotation_from_rotvec, rotvec_from_rotation

from test_rac import TRUTH, area_centroid_pixels, grid, random_poses, synthetic_views


def test_projection_matches_the_camera_model():
    rng = np.random.default_rng(10)
    points, _, poses = synthetic_views(rng, 3, noise_px=0.0)
    rotvecs = rotvec_from_rotation(poses[:, :3, :3])
    view = np.repeat(np.arange(3), len(points))
    pix, _, _ = refine.project_with_jacobian(refine.intrinsics_vector(TRUTH), rotvecs,
                                             poses[:, :3, 3], np.tile(points, (3, 1)), view)
    expected = np.concatenate([project_points(TRUTH, T, points) for T in poses])
    np.testing.assert_allclose(pix, expected, atol=1e-9)


def test_analytic_jacobian_matches_central_differences():
    rng = np.random.default_rng(11)
    points, _, poses = synthetic_views(rng, 2, noise_px=0.0)
    x_intr = refine.intrinsics_vector(TRUTH)
    rotvecs = rotvec_from_rotation(poses[:, :3, :3])
    trans = poses[:, :3, 3]
    pts = np.tile(points, (2, 1))
    view = np.repeat(np.arange(2), len(points))
    _, d_intr, d_extr = refine.project_with_jacobian(x_intr, rotvecs, trans, pts, view)

    def pix(xi, rv, tr):
        return refine.project_with_jacobian(xi, rv, tr, pts, view)[0]

    steps = np.array([1e-3, 1e-7, 1e-4, 1e-4, 1e-7, 1e-7])
    for k, h in enumerate(steps):
        e = np.zeros(6)
        e[k] = h
        numeric = (pix(x_intr + e, rotvecs, trans) - pix(x_intr - e, rotvecs, trans)) / (2 * h)
        np.testing.assert_allclose(d_intr[:, :, k], numeric, rtol=1e-5, atol=1e-6)
    for k in range(6):
        for v in range(2):
            rv, tr = rotvecs.copy(), trans.copy()
            h = 1e-7
            (rv if k < 3 else tr)[v, k % 3] += h
            plus = pix(x_intr, rv, tr)
            (rv if k < 3 else tr)[v, k % 3] -= 2 * h
            minus = pix(x_intr, rv, tr)
            numeric = (plus - minus) / (2 * h)
            rows = view == v
            np.testing.assert_allclose(d_extr[rows, :, k], numeric[rows], rtol=1e-5, atol=1e-3)


def test_left_jacobian_small_and_large_angles():
    for w in (np.array([1e-9, -2e-9, 3e-9]), np.array([0.3, -1.2, 0.7])):
        jl = refine.left_jacobian(w)
        dw = np.array([1e-7, -2e-7, 0.5e-7])
        delta = rotvec_from_rotation(rotation_from_rotvec(w + dw) @ rotation_from_rotvec(w).T)
        np.testing.assert_allclose(delta, jl @ dw, rtol=1e-5, atol=1e-14)


@pytest.mark.parametrize("seed", [20, 21, 22])
def test_refined_parameters_within_three_reported_standard_deviations(seed):
    rng = np.random.default_rng(seed)
    n = 10
    points, pixels, poses = synthetic_views(rng, n, noise_px=0.2)
    start = rac.rac_calibrate(pixels, [points] * n, 1280, 1024)
    result = refine.refine(pixels, [points] * n, start.intrinsics, start.camera_T_board)
    assert result.sigma_px == pytest.approx(0.2, rel=0.1)
    for name in refine.INTRINSIC_NAMES:
        err = getattr(result.intrinsics, name) - getattr(TRUTH, name)
        std = result.intrinsics_std[name]
        assert 0 < std and abs(err) < 3 * std, (name, err, std)
    err_t = result.camera_T_board[:, :3, 3] - poses[:, :3, 3]
    assert np.all(np.abs(err_t) < 4 * result.pose_std[:, 3:])
    # the refinement is much closer to the truth than the RAC start
    assert abs(result.intrinsics.fx - TRUTH.fx) < abs(start.intrinsics.fx - TRUTH.fx) + 0.5


def test_fixed_intrinsic_stays_put_and_has_zero_std():
    rng = np.random.default_rng(23)
    points, pixels, poses = synthetic_views(rng, 5, noise_px=0.1)
    start = rac.rac_calibrate(pixels, [points] * 5, 1280, 1024)
    result = refine.refine(pixels, [points] * 5, start.intrinsics, start.camera_T_board,
                           fixed=("k2",))
    assert result.intrinsics.k2 == 0.0 and result.intrinsics_std["k2"] == 0.0


def test_pose_refinement_with_known_intrinsics():
    rng = np.random.default_rng(24)
    points, pixels, poses = synthetic_views(rng, 1, noise_px=0.0)
    start = poses[0].copy()
    start[:3, 3] += [0.002, -0.001, 0.01]
    fit = refine.refine_pose(pixels[0], points, TRUTH, start)
    np.testing.assert_allclose(fit.camera_T_board, poses[0], atol=1e-9)
    assert fit.rms_px < 1e-6


# -- the pipeline (camera/calibrate.py) ---------------------------------------------------


def _views(pixels, points):
    return [View(f"img{k:02d}.png", p, points) for k, p in enumerate(pixels)]


def test_calibrate_reports_both_estimates_and_per_view_rms():
    rng = np.random.default_rng(30)
    points, pixels, poses = synthetic_views(rng, 8, noise_px=0.1)
    cal = calibrate(_views(pixels, points), 1280, 1024)
    only = calibrate(_views(pixels, points), 1280, 1024, method="rac-only")
    assert cal.method == "rac" and only.method == "rac-only"
    assert cal.rac == only.intrinsics                    # the same RAC under both
    assert abs(cal.intrinsics.fx - TRUTH.fx) < 3 * cal.std["fx"]
    assert np.isnan(only.std["fx"])
    assert cal.rms_px == pytest.approx(0.1 * np.sqrt(2), rel=0.15)
    assert cal.rms_px < only.rms_px
    assert [v.name for v in cal.views] == [f"img{k:02d}.png" for k in range(8)]
    assert all(v.max_px >= v.rms_px > 0 for v in cal.views)


def test_too_few_views_are_refused_with_advice():
    rng = np.random.default_rng(31)
    points, pixels, _ = synthetic_views(rng, MIN_VIEWS - 1)
    with pytest.raises(DataError, match=f"at least {MIN_VIEWS}.*tilted 30-50 degrees"):
        calibrate(_views(pixels, points), 1280, 1024)


def test_views_parallel_to_the_board_are_left_out_of_the_rac_and_named():
    rng = np.random.default_rng(32)
    points = grid()
    poses = np.concatenate([random_poses(rng, 5, points),
                            random_poses(rng, 2, points, tilt_deg=(0.0, 8.0))])
    pixels = [project_points(TRUTH, T, points) + rng.normal(0, 0.1, (81, 2)) for T in poses]
    cal = calibrate(_views(pixels, points), 1280, 1024)
    assert [s.name for s in cal.rac_excluded] == ["img05.png", "img06.png"]
    assert "parallel" in cal.rac_excluded[0].reason
    assert len(cal.views) == 7 and not cal.views[6].in_rac   # still refined
    assert abs(cal.intrinsics.fx - TRUTH.fx) < 3 * cal.std["fx"]
    # issue 33: views all nearer to face-on than the RAC admits start from their
    # homographies (the RAC-only method still refuses them)
    flat = random_poses(rng, 8, points, tilt_deg=(8.0, 15.0))
    pixels = [project_points(TRUTH, T, points) for T in flat]
    frontal = calibrate(_views(pixels, points), 1280, 1024)
    assert frontal.start == "homography" and abs(frontal.intrinsics.fx - TRUTH.fx) < 0.05
    with pytest.raises(DataError, match="tilted by 20 degrees or more"):
        calibrate(_views(pixels, points), 1280, 1024, method="rac-only")


def test_views_too_alike_are_refused():
    rng = np.random.default_rng(33)
    points = grid()
    base = random_poses(rng, 1, points, tilt_deg=(40, 40))[0]
    poses = []
    for k in range(4):   # the same view, turned about the optical axis by a few degrees
        turn = np.eye(4)
        turn[:3, :3] = rot_z(np.radians(1.0 * k))
        poses.append(turn @ base)
    pixels = [project_points(TRUTH, T, points) for T in poses]
    with pytest.raises(DataError, match="too alike"):
        calibrate(_views(pixels, points), 1280, 1024)


def _big_dot_views(seed: int):
    """Eight steep views (40-55 deg tilt, 0.35-0.45 m) of a 9x9 board of 12 mm dots at a
    25 mm pitch, the dots' area centroids with 0.01 px of noise: (board, points, pixels)."""
    from olp_compensate.camera.board import Board

    board = Board(rows=9, cols=9, pitch_m=0.025, dot_diameter_m=0.012,
                  marker_diameter_m=0.016)
    rng = np.random.default_rng(seed)
    points = board.dot_positions()
    poses = random_poses(rng, 8, points, tilt_deg=(40, 55), distance=(0.35, 0.45))
    pixels = [area_centroid_pixels(TRUTH, T, board, rings=12, spokes=32)
              + rng.normal(0, 0.01, (81, 2)) for T in poses]
    return board, points, pixels


def test_circle_centre_correction_removes_the_perspective_bias():
    # big dots, little noise: the bias of the area centroids dominates
    board, points, pixels = _big_dot_views(seed=34)
    plain = calibrate(_views(pixels, points), 1280, 1024)
    corrected = calibrate(_views(pixels, points), 1280, 1024,
                          centre_bias=lambda k, T: circle_centre_bias(k, T, board))
    assert corrected.bias_iterations == 3
    assert corrected.rms_px == pytest.approx(0.01 * np.sqrt(2), rel=0.2)
    assert corrected.max_px < 0.3 * plain.max_px
    err_plain = np.hypot(plain.intrinsics.cx - TRUTH.cx, plain.intrinsics.cy - TRUTH.cy)
    err_corr = np.hypot(corrected.intrinsics.cx - TRUTH.cx, corrected.intrinsics.cy - TRUTH.cy)
    assert err_corr < err_plain
    assert abs(corrected.intrinsics.fx - TRUTH.fx) < 3 * corrected.std["fx"]


def test_circle_centre_correction_passes_reach_their_fixed_point():
    """The correction's first bias is taken at the RAC's start (no refinement on the
    uncorrected centres first): three passes still land where many do, far inside the
    intrinsics' standard deviations, with the bias computed from big dots at steep tilts."""
    board, points, pixels = _big_dot_views(seed=35)
    bias = lambda k, T: circle_centre_bias(k, T, board)   # noqa: E731
    three = calibrate(_views(pixels, points), 1280, 1024, centre_bias=bias)
    many = calibrate(_views(pixels, points), 1280, 1024, centre_bias=bias, bias_iterations=8)
    for name in ("fx", "cx", "cy"):
        a, b = getattr(three.intrinsics, name), getattr(many.intrinsics, name)
        assert abs(a - b) < 1e-4 and abs(a - b) < 1e-3 * three.std[name], name
    assert abs(three.intrinsics.fy - many.intrinsics.fy) < 1e-4
