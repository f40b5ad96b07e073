"""The calibration report: residuals against a known camera, the page's content, and
``olp-cal camera calibrate --html``."""

import argparse
import base64
import contextlib
import io
import re

import numpy as np
import pytest

from olp_compensate.camera.board import Board, write_board
from olp_compensate.camera.calibrate import View, calibrate
from olp_compensate.camera.detect import circle_centre_bias
from olp_compensate.camera.model import CameraIntrinsics, project_points
from olp_compensate.camera.render import RenderOptions, random_views, render_board
from olp_compensate.cli import cal_camera
from olp_compensate.cli.common import run_guarded
from olp_compensate.io.images import write_png
from olp_compensate.report.camera_html import (calibration_html, residual_field_figure,
                                               view_residuals)

CAMERA = CameraIntrinsics(fx=800.0, mu=1.0, cx=318.0, cy=242.0, k1=0.05, width=640,
                          height=480)
BOARD = Board(rows=7, cols=7, pitch_m=0.02, dot_diameter_m=0.005, marker_diameter_m=0.008)


@pytest.fixture(scope="module")
def exact():
    """A calibration from exact images of circle centres (area centroids), 5 views."""
    rng = np.random.default_rng(61)
    poses = random_views(BOARD, CAMERA, 5, rng, distance_m=(0.28, 0.38), tilt_deg=(28, 45))
    points = BOARD.dot_positions()
    detected = {}
    for k, T in enumerate(poses):
        detected[f"v{k}.png"] = (project_points(CAMERA, T, points)
                                 + circle_centre_bias(CAMERA, T, BOARD))
    views = [View(name, p, points) for name, p in detected.items()]
    cal = calibrate(views, 640, 480,
                    centre_bias=lambda k, T: circle_centre_bias(k, T, BOARD))
    return cal, detected, poses


def test_residuals_of_exact_detections_vanish_and_follow_a_disturbed_dot(exact):
    cal, detected, poses = exact
    residuals = view_residuals(cal, BOARD, detected)
    assert [r.name for r in residuals] == list(detected)
    assert max(np.abs(r.residuals).max() for r in residuals) < 1e-4
    # a detection moved by (0.5, -0.3) px shows as a residual of (-0.5, +0.3) at that dot
    moved = {name: p.copy() for name, p in detected.items()}
    moved["v2.png"][10] += (0.5, -0.3)
    shifted = view_residuals(cal, BOARD, moved)[2].residuals
    np.testing.assert_allclose(shifted[10], (-0.5, 0.3), atol=1e-4)
    assert np.abs(np.delete(shifted, 10, axis=0)).max() < 1e-4


def _images(page: str) -> list[bytes]:
    return [base64.b64decode(m) for m in
            re.findall(r"data:image/(?:png|jpeg);base64,([A-Za-z0-9+/=]+)", page)]


def test_page_has_parameters_views_and_one_picture_per_view(exact):
    cal, detected, poses = exact
    images = {name: render_board(BOARD, CAMERA, T, RenderOptions(supersample=2))
              for name, T in zip(detected, poses)}
    page = calibration_html(cal, BOARD, detected, images, title="bench camera")
    assert page.startswith("<!DOCTYPE html>") and "<title>bench camera</title>" in page
    for name in ("fx", "mu", "cx", "cy", "k1", "k2"):
        assert f"<td>{name}</td>" in page
    for name in detected:
        assert f"<td>{name}</td>" in page
    pictures = _images(page)
    assert len(pictures) == 2 + len(detected)         # two charts, one picture per view
    assert all(p[:4] == b"\x89PNG" for p in pictures[:2])
    assert all(p[:2] == b"\xff\xd8" for p in pictures[2:])   # JPEG
    assert len(_images(calibration_html(cal, BOARD, detected))) == 2   # no images given


def test_residual_field_draws_one_arrow_per_dot(exact):
    cal, detected, _ = exact
    views = view_residuals(cal, BOARD, detected)
    fig = residual_field_figure(views, 640, 480, 100.0)
    (quiver,) = fig.axes[0].collections
    assert len(quiver.U) == sum(len(v.pixels) for v in views)
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_cli_calibrate_writes_the_html_report(tmp_path):
    rng = np.random.default_rng(62)
    (tmp_path / "cal").mkdir()
    for k, T in enumerate(random_views(BOARD, CAMERA, 6, rng, distance_m=(0.28, 0.38),
                                       tilt_deg=(28, 45))):
        write_png(tmp_path / "cal" / f"c{k}.png",
                  render_board(BOARD, CAMERA, T, RenderOptions(supersample=4, noise_sigma=1.0,
                                                               seed=k)))
    write_board(BOARD, tmp_path / "board.json")
    parser = argparse.ArgumentParser(prog="olp-cal camera")
    cal_camera.add_arguments(parser)
    args = parser.parse_args(["calibrate", str(tmp_path / "cal"), "--board",
                              str(tmp_path / "board.json"), "-o", str(tmp_path / "camera.json"),
                              "--html", str(tmp_path / "report.html")])
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = run_guarded(lambda: cal_camera.run(args), 0, "olp-cal")
    assert code == 0, printed.getvalue()
    page = (tmp_path / "report.html").read_text()
    assert len(_images(page)) == 2 + 6 and "c5.png" in page
    assert f"wrote {tmp_path / 'report.html'}" in printed.getvalue()
