"""RAC stages (seed eqs. 66-69) against synthetic views of known cameras.

The helpers here (``grid``, ``random_poses``, ``synthetic_views``) are shared by the other
camera tests, which import them from this module.
"""

import numpy as np
import pytest

from olp_compensate.camera import rac
from olp_compensate.camera.board import Board
from olp_compensate.camera.model import CameraIntrinsics, project_points
from olp_compensate.kinematics.conventions import pose_from_rotation_translation, rot_x, rot_z
from olp_compensate.errors import DataError

TRUTH = CameraIntrinsics(fx=1500.0, mu=0.985, cx=652.3, cy=497.8, k1=0.12, k2=0.03,
                         width=1280, height=1024)


BOARD = Board(rows=9, cols=9, pitch_m=0.025, dot_diameter_m=0.005, marker_diameter_m=0.008)


def grid():
    """Dot centres (81, 3) of :data:`BOARD`, board frame, m, row-major."""
    return BOARD.dot_positions()


def area_centroid_pixels(intrinsics, camera_T_board, board=BOARD, rings=24, spokes=64):
    """Where a perfect detector puts each dot (n, 2) px: the centroid of the area of the
    dot's image, integrated over a polar grid on the printed disc (each sample weighted by
    its board area times the local image-area scale |det d pixel / d board|). Independent
    of the boundary-polygon formula of detect.circle_centre_bias."""
    h = 1e-6
    rho = (np.arange(rings) + 0.5) / rings
    phi = (np.arange(spokes) + 0.5) * 2 * np.pi / spokes
    rr, pp = np.meshgrid(rho, phi, indexing="ij")
    out = []
    for centre, radius in zip(board.dot_positions(), board.dot_radii()):
        xy = centre[:2] + radius * np.stack([rr * np.cos(pp), rr * np.sin(pp)], -1).reshape(-1, 2)

        def pix(offset):
            q = np.column_stack([xy + offset, np.zeros(len(xy))])
            return project_points(intrinsics, camera_T_board, q)

        p0 = pix(0.0)
        jx = (pix(np.array([h, 0.0])) - pix(np.array([-h, 0.0]))) / (2 * h)
        jy = (pix(np.array([0.0, h])) - pix(np.array([0.0, -h]))) / (2 * h)
        weight = np.abs(jx[:, 0] * jy[:, 1] - jx[:, 1] * jy[:, 0]) * rr.ravel()
        out.append(weight @ p0 / weight.sum())
    return np.array(out)


def random_poses(rng, n, points, tilt_deg=(30.0, 50.0), distance=(0.40, 0.60)):
    """camera_T_board (n, 4, 4): the board centre near the optical axis at ``distance`` m,
    its normal tilted by ``tilt_deg`` about a random in-plane axis, any roll."""
    centre = points.mean(axis=0)
    poses = []
    for _ in range(n):
        tilt = np.radians(rng.uniform(*tilt_deg))
        axis_angle = rng.uniform(0, 2 * np.pi)
        rotation = (rot_z(axis_angle) @ rot_x(tilt) @ rot_z(-axis_angle)
                    @ rot_z(rng.uniform(-np.pi, np.pi)))
        seen_at = np.array([rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03),
                            rng.uniform(*distance)])
        poses.append(pose_from_rotation_translation(rotation, seen_at - rotation @ centre))
    return np.array(poses)


def synthetic_views(rng, n_views=12, noise_px=0.1, intrinsics=TRUTH, **pose_options):
    """(points (n, 3), pixels list of (n, 2), camera_T_board (V, 4, 4)) with Gaussian noise."""
    points = grid()
    poses = random_poses(rng, n_views, points, **pose_options)
    pixels = [project_points(intrinsics, T, points) + rng.normal(0, noise_px, (len(points), 2))
              for T in poses]
    return points, pixels, poses


def test_stage1_recovers_rotation_tx_ty_at_the_true_centre_and_mu():
    rng = np.random.default_rng(0)
    points, pixels, poses = synthetic_views(rng, 6, noise_px=0.0)
    for pix, T in zip(pixels, poses):
        s = rac.stage1(pix, points, TRUTH.cx, TRUTH.cy, TRUTH.mu)
        rot = s.rotation
        if np.sign(rot[0, 2]) != np.sign(T[0, 2]):   # the mirror completion: stage 2 decides
            rot = rac.flip_completion(rot)
        np.testing.assert_allclose(rot, T[:3, :3], atol=1e-9)
        np.testing.assert_allclose([s.tx, s.ty], T[:2, 3], atol=1e-11)
        assert np.max(np.abs(s.residuals)) < 1e-8    # RAC holds whatever the distortion


def test_stage2_recovers_tz_fx_and_k_and_picks_the_completion():
    rng = np.random.default_rng(1)
    pinhole = CameraIntrinsics(fx=1500.0, mu=0.985, cx=652.3, cy=497.8, k1=0.1,
                               width=1280, height=1024)
    points, pixels, poses = synthetic_views(rng, 6, noise_px=0.0, intrinsics=pinhole)
    s1 = [rac.stage1(p, points, pinhole.cx, pinhole.cy, pinhole.mu) for p in pixels]
    s2 = rac.stage2(s1, pixels, [points] * 6, pinhole.cx, pinhole.cy, pinhole.mu)
    np.testing.assert_allclose(s2.rotations, poses[:, :3, :3], atol=1e-9)
    # eq. 66 linearizes the distortion (1 + k r^2 ~ 1 / (1 - k r^2)): close, not exact
    np.testing.assert_allclose(s2.tz, poses[:, 2, 3], rtol=2e-3)
    assert s2.fx == pytest.approx(pinhole.fx, rel=2e-3)
    assert s2.k * s2.fx ** 2 == pytest.approx(pinhole.k1, rel=0.1)


def test_stage2_is_exact_for_a_pinhole_camera():
    rng = np.random.default_rng(2)
    pinhole = CameraIntrinsics(fx=1400.0, mu=1.02, cx=640.0, cy=512.0, width=1280,
                               height=1024)
    points, pixels, poses = synthetic_views(rng, 4, noise_px=0.0, intrinsics=pinhole)
    s1 = [rac.stage1(p, points, pinhole.cx, pinhole.cy, pinhole.mu) for p in pixels]
    s2 = rac.stage2(s1, pixels, [points] * 4, pinhole.cx, pinhole.cy, pinhole.mu)
    np.testing.assert_allclose(s2.tz, poses[:, 2, 3], rtol=1e-10)
    assert s2.fx == pytest.approx(1400.0, rel=1e-10)
    assert abs(s2.k) < 1e-15


def test_rac_residual_of_a_plane_does_not_depend_on_mu():
    # why mu is searched on the stage-2 residuals: the algebraic eq. 69 residual (divided by
    # Ty) absorbs a scale of Y' exactly, so its least-squares minimum cannot tell mu
    rng = np.random.default_rng(3)
    points, pixels, _ = synthetic_views(rng, 3, noise_px=0.2)

    def algebraic(pix, mu):
        s = rac.stage1(pix, points, TRUTH.cx, TRUTH.cy, mu)
        x = points[:, :2] @ s.rotation[0, :2] + s.tx
        y = points[:, :2] @ s.rotation[1, :2] + s.ty
        return ((pix[:, 0] - TRUTH.cx) * y - (pix[:, 1] - TRUTH.cy) / mu * x) / s.ty

    for pix in pixels:
        np.testing.assert_allclose(algebraic(pix, 0.9), algebraic(pix, 1.1), rtol=1e-7,
                                   atol=1e-9)
        assert np.max(np.abs(algebraic(pix, 1.1))) > 1e-3     # not trivially zero


def test_mu_search_finds_mu():
    rng = np.random.default_rng(4)
    points, pixels, _ = synthetic_views(rng, 10, noise_px=0.1)
    mu = rac.search_mu(pixels, [points] * 10, TRUTH.cx, TRUTH.cy)
    assert mu == pytest.approx(TRUTH.mu, abs=2e-3)


def test_centre_search_finds_the_centre():
    rng = np.random.default_rng(5)
    points, pixels, _ = synthetic_views(rng, 10, noise_px=0.1)
    cx, cy = rac.search_centre(pixels, [points] * 10, TRUTH.mu, (639.5, 511.5))
    assert np.hypot(cx - TRUTH.cx, cy - TRUTH.cy) < 3.0


@pytest.mark.parametrize("start", [0.82, 0.95, 1.2])
def test_mu_search_finds_mu_from_any_start(start):
    """The least-squares search from either side of the truth, far or near, and its result
    a minimum of the stage-2 cost: no neighbour 1e-4 away is lower."""
    rng = np.random.default_rng(4)
    points, pixels, _ = synthetic_views(rng, 10, noise_px=0.1)
    mu = rac.search_mu(pixels, [points] * 10, TRUTH.cx, TRUTH.cy, start=start)
    assert mu == pytest.approx(TRUTH.mu, abs=2e-3)
    cost = rac.stage2_cost(pixels, [points] * 10, TRUTH.cx, TRUTH.cy, mu)
    for other in (mu - 1e-4, mu + 1e-4):
        assert cost <= rac.stage2_cost(pixels, [points] * 10, TRUTH.cx, TRUTH.cy, other)


def test_centre_search_ends_at_a_minimum_of_the_rac_cost():
    rng = np.random.default_rng(5)
    points, pixels, _ = synthetic_views(rng, 10, noise_px=0.1)
    cx, cy = rac.search_centre(pixels, [points] * 10, TRUTH.mu, (620.0, 530.0))
    cost = rac.rac_cost(pixels, [points] * 10, cx, cy, TRUTH.mu)
    for dx, dy in ((0.05, 0), (-0.05, 0), (0, 0.05), (0, -0.05)):
        assert cost <= rac.rac_cost(pixels, [points] * 10, cx + dx, cy + dy, TRUTH.mu)


def test_rac_calibrate_end_to_end():
    rng = np.random.default_rng(6)
    points, pixels, poses = synthetic_views(rng, 12, noise_px=0.1)
    result = rac.rac_calibrate(pixels, [points] * 12, 1280, 1024)
    k = result.intrinsics
    assert k.fx == pytest.approx(TRUTH.fx, rel=0.01)
    assert k.mu == pytest.approx(TRUTH.mu, abs=3e-3)
    assert np.hypot(k.cx - TRUTH.cx, k.cy - TRUTH.cy) < 3.0
    assert k.k1 == pytest.approx(TRUTH.k1, abs=0.05)
    np.testing.assert_allclose(result.camera_T_board[:, :3, 3], poses[:, :3, 3], atol=5e-3)


def test_a_view_with_too_few_points_is_refused():
    points = grid()[:5]
    with pytest.raises(DataError, match="at least"):
        rac.rac_calibrate([np.zeros((5, 2))], [points], 1280, 1024)


def test_small_least_squares_converges_or_says_it_did_not():
    target = np.array([3.0, -2.0])
    found, converged = rac._small_lm(lambda x: np.array([x[0] - 3.0, 2 * (x[1] + 2.0),
                                                         x[0] * x[1] + 6.0]),
                                     np.zeros(2), 1e-6, 10.0, 1e-9)
    assert converged and np.allclose(found, target, atol=1e-7)
    # undefined beyond the start: its derivatives cannot be taken
    found, converged = rac._small_lm(lambda x: None if x[0] > 0 else x - 1.0,
                                     np.zeros(1), 1e-6, 1.0, 1e-9)
    assert not converged and found[0] == 0.0
    assert rac._small_lm(lambda x: None, np.zeros(1), 1e-6, 1.0, 1e-9) == (None, False)


def test_mu_search_falls_back_to_the_bounded_search(monkeypatch):
    rng = np.random.default_rng(4)
    points, pixels, _ = synthetic_views(rng, 10, noise_px=0.1)
    monkeypatch.setattr(rac, "_small_lm", lambda fun, x0, *a, **k: (x0, False))
    mu = rac.search_mu(pixels, [points] * 10, TRUTH.cx, TRUTH.cy)
    assert mu == pytest.approx(TRUTH.mu, abs=2e-3)
