"""Pose measurement with fixed intrinsics: exact without noise, its reported uncertainty
against the scatter of repeated noisy views, the circle-centre correction."""

import numpy as np
import pytest

from olp_compensate.camera.detect import circle_centre_bias
from olp_compensate.camera.measure import measure_pose, pose_covariance
from olp_compensate.camera.model import project_points
from olp_compensate.errors import DataError
from olp_compensate.kinematics.conventions import (invert_pose, matrix_from_quat_wxyz,
                                                   rotation_angle_between, rotation_from_rotvec,
                                                   rotvec_from_rotation)

from test_rac import BOARD, TRUTH, area_centroid_pixels, grid, random_poses


def test_pose_in_the_board_frame_is_exact_without_noise():
    rng = np.random.default_rng(40)
    points = grid()
    for T in random_poses(rng, 4, points):
        m = measure_pose(project_points(TRUTH, T, points), points, TRUTH, name="a.png")
        truth = invert_pose(T)
        np.testing.assert_allclose(m.board_T_camera, truth, atol=1e-9)
        np.testing.assert_allclose(m.position_mm, truth[:3, 3] * 1e3, atol=1e-6)
        np.testing.assert_allclose(matrix_from_quat_wxyz(m.quat_wxyz), truth[:3, :3],
                                   atol=1e-9)
        assert m.quat_wxyz[0] >= 0 and m.rms_px < 1e-6 and m.name == "a.png"


def test_reported_uncertainty_matches_the_scatter_of_repeated_views():
    rng = np.random.default_rng(41)
    points = grid()
    T = random_poses(rng, 1, points)[0]
    clean = project_points(TRUTH, T, points)
    truth = invert_pose(T)
    positions, rotations, sigmas = [], [], []
    for _ in range(150):
        m = measure_pose(clean + rng.normal(0, 0.2, clean.shape), points, TRUTH)
        positions.append(m.board_T_camera[:3, 3])
        # small rotation about the camera's own axes
        rotations.append(rotvec_from_rotation(truth[:3, :3].T @ m.board_T_camera[:3, :3]))
        sigmas.append(np.concatenate([m.position_std_mm * 1e-3, np.radians(m.rotation_std_deg)]))
    scatter = np.concatenate([np.std(positions, axis=0), np.std(rotations, axis=0)])
    reported = np.mean(sigmas, axis=0)
    np.testing.assert_allclose(reported, scatter, rtol=0.2)
    assert np.all(np.abs(np.mean(positions, axis=0) - truth[:3, 3]) < 3 * scatter[:3] / 10)


def test_pose_covariance_propagation_matches_finite_differences():
    rng = np.random.default_rng(42)
    T = random_poses(rng, 1, grid())[0]
    w0, t0 = rotvec_from_rotation(T[:3, :3]), T[:3, 3]

    def outputs(x):
        R = rotation_from_rotvec(x[:3])
        centre = -R.T @ x[3:]
        turn = rotvec_from_rotation(T[:3, :3] @ R.T)   # R^T = T^T exp(e): e about camera axes
        return np.concatenate([centre, turn])

    x0 = np.concatenate([w0, t0])
    jac = np.empty((6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = 1e-7
        jac[:, k] = (outputs(x0 + e) - outputs(x0 - e)) / 2e-7
    cov = np.diag([1e-6, 4e-6, 2e-6, 1e-8, 3e-8, 2e-8])
    np.testing.assert_allclose(pose_covariance(T, cov), jac @ cov @ jac.T, rtol=1e-5,
                               atol=1e-18)


def test_circle_centre_correction_in_measurement():
    rng = np.random.default_rng(43)
    points = grid()
    errors_plain, errors_corrected = [], []
    for T in random_poses(rng, 3, points, tilt_deg=(45, 55), distance=(0.3, 0.35)):
        pixels = area_centroid_pixels(TRUTH, T)
        truth = invert_pose(T)
        plain = measure_pose(pixels, points, TRUTH)
        corrected = measure_pose(pixels, points, TRUTH,
                                 centre_bias=lambda k, X: circle_centre_bias(k, X, BOARD))
        errors_plain.append(np.linalg.norm(plain.board_T_camera[:3, 3] - truth[:3, 3]))
        errors_corrected.append(np.linalg.norm(corrected.board_T_camera[:3, 3] - truth[:3, 3]))
        assert corrected.rms_px < 1e-3 < plain.rms_px
        assert rotation_angle_between(corrected.board_T_camera[:3, :3], truth[:3, :3]) < 1e-6
    assert max(errors_corrected) < 1e-6 < min(errors_plain)


def test_too_few_dots_are_refused():
    with pytest.raises(DataError, match="at least 8"):
        measure_pose(np.zeros((5, 2)), grid()[:5], TRUTH, name="x.png")
