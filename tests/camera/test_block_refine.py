"""The refinement's block normal equations (camera/block_lm.py) and the RAC's batched stages
(camera/rac_batch.py), each against an independent dense or one-view computation, and the
refinement against the dense Levenberg-Marquardt and the known camera."""

from dataclasses import replace

import numpy as np
import pytest

from olp_compensate.calibration.lm import levenberg_marquardt
from olp_compensate.camera import rac, rac_batch, refine
from olp_compensate.camera.board import Board
from olp_compensate.camera.calibrate import View, calibrate
from olp_compensate.camera.detect import circle_centre_bias, detect_dots
from olp_compensate.camera.model import CameraIntrinsics
from olp_compensate.camera.render import RenderOptions, random_views, render_board
from olp_compensate.kinematics.conventions import rotation_from_rotvec, rotvec_from_rotation

from test_rac import TRUTH, synthetic_views


def _uneven_views(rng, n_views=5, noise_px=0.1):
    """Synthetic views with different dot counts (some dots dropped per view)."""
    points, pixels, poses = synthetic_views(rng, n_views, noise_px=noise_px)
    kept = [np.sort(rng.choice(len(points), len(points) - 7 * k, replace=False))
            for k in range(n_views)]
    return [points[k] for k in kept], [p[k] for p, k in zip(pixels, kept)], poses


def _dense_jacobian(x_intr, poses, points, pixels):
    """Residuals (m,) and the dense Jacobian (m, 6 + 6 V) from project_with_jacobian, placed
    column by column (an independent assembly of what the block code sums)."""
    obs, pts, view = np.concatenate(pixels), np.concatenate(points), np.repeat(
        np.arange(len(points)), [len(p) for p in points])
    rotvecs, trans = rotvec_from_rotation(poses[:, :3, :3]), poses[:, :3, 3]
    pix, d_intr, d_extr = refine.project_with_jacobian(x_intr, rotvecs, trans, pts, view)
    jac = np.zeros((2 * len(obs), 6 + 6 * len(points)))
    for i in range(len(obs)):
        jac[2 * i:2 * i + 2, :6] = d_intr[i]
        jac[2 * i:2 * i + 2, 6 + 6 * view[i]:12 + 6 * view[i]] = d_extr[i]
    return (pix - obs).ravel(), jac, d_intr, d_extr, view


def test_block_normal_equals_the_dense_normal_equations_for_uneven_views():
    rng = np.random.default_rng(40)
    points, pixels, poses = _uneven_views(rng)
    x_intr = refine.intrinsics_vector(TRUTH) * [1.001, 1.0, 1.0, 1.0, 1.1, 0.9]
    r, jac, d_intr, d_extr, view = _dense_jacobian(x_intr, poses, points, pixels)
    starts = np.searchsorted(view, np.arange(len(points)))
    normal = refine._normal(d_intr, d_extr, r.reshape(-1, 2), starts)
    dense = jac.T @ jac
    scale = np.abs(dense).max()
    np.testing.assert_allclose(normal.dense(), dense, atol=1e-10 * scale)
    np.testing.assert_allclose(normal.gradient(), jac.T @ r,
                               atol=1e-10 * np.abs(jac.T @ r).max())
    damping = 1e-3 * np.diag(dense)
    expected = -np.linalg.solve(dense + np.diag(damping), jac.T @ r)
    np.testing.assert_allclose(normal.solve(damping), expected,
                               atol=1e-8 * np.abs(expected).max())
    inverse = np.linalg.inv(dense)
    np.testing.assert_allclose(normal.inverse(), inverse, rtol=1e-6,
                               atol=1e-9 * np.abs(inverse).max())


def test_singular_block_system_gives_no_step_and_an_infinite_covariance():
    rng = np.random.default_rng(41)
    points, pixels, poses = _uneven_views(rng, 3)
    r, jac, d_intr, d_extr, view = _dense_jacobian(refine.intrinsics_vector(TRUTH), poses,
                                                   points, pixels)
    d_intr[:, :, 4] = 0.0                       # k1 no longer observed: singular
    normal = refine._normal(d_intr, d_extr, r.reshape(-1, 2),
                            np.searchsorted(view, np.arange(3)))
    assert normal.solve(np.zeros(normal.size)) is None
    assert np.all(np.isinf(normal.inverse()))


def test_left_jacobians_match_the_one_view_function():
    w = np.array([[1e-9, -2e-9, 3e-9], [0.3, -1.2, 0.7], [0.0, 0.0, 0.0], [2.0, 1.0, -1.5]])
    np.testing.assert_allclose(refine.left_jacobians(w),
                               [refine.left_jacobian(v) for v in w], rtol=1e-12, atol=1e-15)


def _dense_refine(pixels, points, start_intrinsics, start_poses):
    """The refinement on the dense Jacobian and calibration.lm (the former solver)."""
    x0 = np.concatenate([refine.intrinsics_vector(start_intrinsics)] + [
        np.concatenate([rotvec_from_rotation(T[:3, :3]), T[:3, 3]]) for T in start_poses])

    def fun(x):
        poses = np.array([np.eye(4)] * len(points))
        ext = x[6:].reshape(-1, 6)
        poses[:, :3, :3], poses[:, :3, 3] = rotation_from_rotvec(ext[:, :3]), ext[:, 3:]
        r, jac = _dense_jacobian(x[:6], poses, points, pixels)[:2]
        return r, jac

    return levenberg_marquardt(fun, x0)


@pytest.mark.parametrize("seed", [42, 43])
def test_block_refinement_reaches_the_dense_solvers_minimum_and_the_truth(seed):
    rng = np.random.default_rng(seed)
    points, pixels, poses = _uneven_views(rng, 6, noise_px=0.2)
    start = rac.rac_calibrate(pixels, points, 1280, 1024)
    result = refine.refine(pixels, points, start.intrinsics, start.camera_T_board)
    dense = _dense_refine(pixels, points, start.intrinsics, start.camera_T_board)
    rss = sum(float(np.sum(r ** 2)) for r in result.residuals)
    assert rss == pytest.approx(2 * dense.cost, rel=1e-9)
    np.testing.assert_allclose(refine.intrinsics_vector(result.intrinsics), dense.x[:6],
                               rtol=1e-7)
    covariance = 2 * dense.cost / (2 * sum(map(len, points)) - len(dense.x)) * np.linalg.inv(
        dense.normal)
    np.testing.assert_allclose(result.covariance, covariance, rtol=1e-5,
                               atol=1e-9 * np.abs(covariance).max())
    for name in refine.INTRINSIC_NAMES:      # and the known camera within 3 std
        err = getattr(result.intrinsics, name) - getattr(TRUTH, name)
        assert abs(err) < 3 * result.intrinsics_std[name], (name, err)


def test_refine_refuses_a_view_without_points():
    rng = np.random.default_rng(44)
    points, pixels, poses = synthetic_views(rng, 3, noise_px=0.0)
    with pytest.raises(Exception, match="view 1 has no points"):
        refine.refine([pixels[0], pixels[1][:0], pixels[2]], [points, points[:0], points],
                      TRUTH, poses)


@pytest.mark.parametrize("centre, mu", [((652.3, 497.8), 0.985), ((600.0, 530.0), 1.05)])
def test_batched_rac_stages_match_the_one_view_stages(centre, mu):
    rng = np.random.default_rng(45)
    points, pixels, _ = synthetic_views(rng, 8, noise_px=0.1)
    cx, cy = centre
    stacked = rac_batch.stack(pixels, [points] * 8, cx, cy, mu)
    first = rac_batch.stage1(stacked)
    one = [rac.stage1(p, points, cx, cy, mu) for p in pixels]
    np.testing.assert_allclose(first.rotation, [s.rotation for s in one], atol=1e-10)
    np.testing.assert_allclose(first.tx, [s.tx for s in one], rtol=1e-9)
    np.testing.assert_allclose(first.ty, [s.ty for s in one], rtol=1e-9)
    np.testing.assert_allclose(first.residuals, [s.residuals for s in one], atol=1e-9)
    # stage 2 in its one-view form: the uneven path, views of different sizes
    rows = []
    for s, p in zip(one, pixels):
        rot = s.rotation
        a = rac._stage2_rows(p, points, cx, cy, mu, rot, s.tx, s.ty)
        if rac._solve_stage2([a])[1] < 0:
            a = rac._stage2_rows(p, points, cx, cy, mu, rac.flip_completion(rot), s.tx, s.ty)
        rows.append(a)
    tz, fx, kfx, residuals = rac._solve_stage2(rows)
    second = rac_batch.stage2(stacked, first)
    assert second.fx == pytest.approx(fx, rel=1e-10)
    assert second.kfx == pytest.approx(kfx, rel=1e-8)
    np.testing.assert_allclose(second.tz, tz, rtol=1e-10)
    np.testing.assert_allclose(second.residuals, residuals, atol=1e-8)


def test_views_with_different_dot_counts_take_the_one_view_path():
    rng = np.random.default_rng(46)
    points, pixels, _ = synthetic_views(rng, 6, noise_px=0.1)
    uneven = [p[:70] if k == 2 else p for k, p in enumerate(pixels)]
    uneven_points = [points[:70] if k == 2 else points for k in range(6)]
    assert rac_batch.stack(uneven, uneven_points, 650.0, 500.0, 1.0) is None
    cost = rac.rac_cost(uneven, uneven_points, 652.3, 497.8, 0.985)
    total = np.concatenate([rac.stage1(p, q, 652.3, 497.8, 0.985).residuals
                            for p, q in zip(uneven, uneven_points)])
    assert cost == pytest.approx(np.sqrt(np.mean(total ** 2)), rel=1e-12)
    found = rac.rac_calibrate(uneven, uneven_points, 1280, 1024)
    assert abs(found.intrinsics.fx - TRUTH.fx) < 5.0


def test_rac_calibrate_batched_agrees_with_the_one_view_code(monkeypatch):
    rng = np.random.default_rng(48)
    points, pixels, _ = synthetic_views(rng, 8, noise_px=0.1)
    batched = rac.rac_calibrate(pixels, [points] * 8, 1280, 1024)
    monkeypatch.setattr(rac_batch, "stack", lambda *args: None)
    one_view = rac.rac_calibrate(pixels, [points] * 8, 1280, 1024)
    a, b = batched.intrinsics, one_view.intrinsics
    # the searches stop at 5e-3 px (centre) and 2e-6 (mu): rounding may move them within that
    assert abs(a.cx - b.cx) < 5e-3 and abs(a.cy - b.cy) < 5e-3 and abs(a.mu - b.mu) < 2e-6
    assert a.fx == pytest.approx(b.fx, abs=0.05) and a.k1 == pytest.approx(b.k1, abs=1e-4)
    np.testing.assert_allclose(batched.camera_T_board, one_view.camera_T_board, atol=1e-4)


@pytest.mark.parametrize("k1, k2", [(0.12, -0.05), (-0.3, 0.1), (0.5, 0.3), (0.0, 0.0)])
def test_distortion_inverse_is_exact_to_rounding(k1, k2):
    camera = CameraIntrinsics(fx=1500.0, mu=1.0, cx=640.0, cy=480.0, k1=k1, k2=k2)
    u = np.random.default_rng(47).uniform(-0.45, 0.45, (2000, 2))
    np.testing.assert_allclose(camera.undistort_normalized(camera.distort_normalized(u)), u,
                               atol=1e-15)


def test_rendered_views_calibrate_to_the_rendering_camera_within_three_std():
    """Eight rendered 640 x 480 views (noise 1 grey level, blur 0.8 px), detected by the
    project's detector, calibrated with the circle-centre correction: every intrinsic of the
    camera that rendered them within three of its reported standard deviations."""
    camera = CameraIntrinsics(fx=800.0, mu=1.0, cx=322.5, cy=241.0, k1=0.1, k2=-0.04,
                              width=640, height=480)
    board = Board(rows=7, cols=7, pitch_m=0.025, dot_diameter_m=0.007,
                  marker_diameter_m=0.011)
    options = RenderOptions(supersample=4, noise_sigma=1.0, blur_sigma_px=0.8)
    poses = random_views(board, camera, 8, np.random.default_rng(1), (0.3, 0.5), (25.0, 45.0),
                         margin_px=10.0)
    views = []
    for k, T in enumerate(poses):
        found = detect_dots(render_board(board, camera, T, replace(options, seed=10 + k)), board)
        assert found.ok, found.reason
        views.append(View(f"v{k}", found.pixels, board.dot_positions()))
    cal = calibrate(views, 640, 480, centre_bias=lambda k, T: circle_centre_bias(k, T, board))
    for name in refine.INTRINSIC_NAMES:
        err = getattr(cal.intrinsics, name) - getattr(camera, name)
        assert abs(err) < 3 * cal.std[name], (name, err, cal.std[name])
    assert abs(cal.intrinsics.fx - camera.fx) < 0.2 and cal.rms_px < 0.05
