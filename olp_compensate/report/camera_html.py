"""A camera calibration as a self-contained HTML page: the intrinsics with their standard
deviations and the RAC estimate, the reprojection error of every view, the residuals of all
views over the image (a pattern there is a model error, noise has none), and every view with
its detected dots and magnified residual arrows (:func:`..camera.drawing.draw_detection`).

Residuals are *projected minus observed* pixels; when the calibration corrected the
perspective bias of the circle centres, "observed" is the detected centroid minus that bias
(what the fit saw).
"""

from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..camera.board import Board
from ..camera.calibrate import CameraCalibration
from ..camera.detect import circle_centre_bias
from ..camera.drawing import draw_detection
from ..camera.model import project_points
from ..errors import DataError
from ..io.atomic import write_text_atomic
from ..io.images import read_grey
from .figures import figure_html, png, pyplot

PICTURE_WIDTH_PX = 800
"""Detection pictures wider than this are shrunk for the page."""

_UNITS = {"fx": "px", "mu": "(fy / fx)", "cx": "px", "cy": "px", "k1": "", "k2": ""}


@dataclass(frozen=True)
class ViewResiduals:
    """One calibrated view: detected ``pixels`` (n, 2) px and ``residuals`` (n, 2) px,
    projected minus observed (the observed centres corrected for the circle bias when the
    calibration did so)."""

    name: str
    pixels: np.ndarray
    residuals: np.ndarray


def view_residuals(cal: CameraCalibration, board: Board,
                   detected: dict[str, np.ndarray]) -> list[ViewResiduals]:
    """Residuals of every calibrated view whose detected pixels (n, 2) are in ``detected``
    (by image name)."""
    points = board.dot_positions()
    out = []
    for view in cal.views:
        if view.name not in detected:
            continue
        pixels = np.asarray(detected[view.name], dtype=float)
        observed = pixels
        if cal.bias_iterations:
            observed = pixels - circle_centre_bias(cal.intrinsics, view.camera_T_board, board)
        residuals = project_points(cal.intrinsics, view.camera_T_board, points) - observed
        out.append(ViewResiduals(view.name, pixels, residuals))
    return out


def per_view_figure(cal: CameraCalibration):
    """Bar chart: reprojection RMS and max of every view, px."""
    plt = pyplot()
    names = [v.name for v in cal.views]
    fig, ax = plt.subplots(figsize=(max(6.0, 0.35 * len(names) + 2), 3.6))
    x = np.arange(len(names))
    ax.bar(x - 0.2, [v.rms_px for v in cal.views], 0.4, label="RMS")
    ax.bar(x + 0.2, [v.max_px for v in cal.views], 0.4, label="max")
    ax.set_xticks(x, names, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("reprojection error, px")
    ax.legend()
    fig.tight_layout()
    return fig


def residual_field_figure(views: list[ViewResiduals], width: int, height: int,
                          magnify: float):
    """Residual arrows of every view over the image frame (``magnify`` times longer)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 6.4 * height / width + 0.6))
    if views:
        p = np.concatenate([v.pixels for v in views])
        r = np.concatenate([v.residuals for v in views])
        ax.quiver(p[:, 0], p[:, 1], magnify * r[:, 0], magnify * r[:, 1], angles="xy",
                  scale_units="xy", scale=1.0, width=0.002, color="#d62728")
    ax.set_xlim(0, width)
    ax.set_ylim(height, 0)
    ax.set_aspect("equal")
    ax.set_xlabel("column, px")
    ax.set_ylabel("row, px")
    ax.set_title(f"residuals of all views, x{magnify:g}", fontsize=10)
    fig.tight_layout()
    return fig


def _jpeg(image: np.ndarray) -> bytes:
    import cv2

    height, width = image.shape[:2]
    if width > PICTURE_WIDTH_PX:
        scale = PICTURE_WIDTH_PX / width
        image = cv2.resize(image, (PICTURE_WIDTH_PX, int(round(height * scale))),
                           interpolation=cv2.INTER_AREA)
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, 85])
    if not ok:
        raise DataError("camera report: cannot encode a picture")
    return data.tobytes()


def _magnify(views: list[ViewResiduals], width: int) -> float:
    """A round factor that draws the 95th-percentile residual about 2 % of the width long."""
    if not views:
        return 100.0
    size = float(np.percentile(np.concatenate(
        [np.hypot(*v.residuals.T) for v in views]), 95))
    if size <= 0:
        return 100.0
    raw = 0.02 * width / size
    decade = 10 ** np.floor(np.log10(raw))
    lead = raw / decade
    return float(decade * (5 if lead >= 5 else 2 if lead >= 2 else 1))


def calibration_html(cal: CameraCalibration, board: Board, detected: dict[str, np.ndarray],
                     images: dict[str, np.ndarray] | None = None, title: str = "") -> str:
    """The HTML page of a calibration. ``detected``: image name -> detected dots (n, 2) px;
    ``images``: image name -> 8-bit image, for the detection pictures (views without one
    get none)."""
    k = cal.intrinsics
    views = view_residuals(cal, board, detected)
    magnify = _magnify(views, k.width)
    rows = []
    for name, unit in _UNITS.items():
        std = cal.std.get(name, float("nan"))
        std_text = f"{std:.4g}" if np.isfinite(std) else "n/a"
        rows.append(f"<tr><td>{name}</td><td>{getattr(k, name):.6g}</td><td>{std_text}</td>"
                    f"<td>{getattr(cal.rac, name):.6g}</td><td>{html.escape(unit)}</td></tr>")
    centre = np.array([(board.cols - 1) * board.pitch_m / 2,
                       (board.rows - 1) * board.pitch_m / 2, 0.0, 1.0])
    view_rows = "".join(
        f"<tr><td>{html.escape(v.name)}</td><td>{v.rms_px:.3f}</td><td>{v.max_px:.3f}</td>"
        f"<td>{v.tilt_deg:.1f}</td><td>{'yes' if v.in_rac else 'no'}</td>"
        f"<td>{np.linalg.norm((v.camera_T_board @ centre)[:3]) * 1e3:.0f}</td></tr>"
        for v in cal.views)
    skipped = "".join(f"<li>{html.escape(s.name)}: {html.escape(s.reason)}</li>"
                      for s in tuple(cal.skipped) + tuple(cal.rac_excluded))
    field = residual_field_figure(views, k.width, k.height, magnify)
    figures = [figure_html(png(per_view_figure(cal), dpi=100),
                           "reprojection error per view, px"),
               figure_html(png(field, dpi=100), f"residuals of all views over the image, "
                                                f"x{magnify:g} (projected minus observed)")]
    for v in views:
        if images is not None and v.name in images:
            picture = draw_detection(images[v.name], v.pixels, v.residuals, magnify)
            figures.append(figure_html(_jpeg(picture), f"{v.name}: detected dots (marker in "
                                       f"blue) and residuals x{magnify:g}", kind="jpeg"))
    sigma = f", sigma {cal.sigma_px:.3f} px" if np.isfinite(cal.sigma_px) else ""
    heading = html.escape(title or "Camera calibration")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>{heading}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 1100px; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
td, th {{ border: 1px solid #ccc; padding: 3px 8px; text-align: right; }}
figure {{ margin: 1.5em 0; }} img {{ max-width: 100%; }}
figcaption {{ color: #555; font-size: 0.9em; }}
</style></head><body>
<h1>{heading}</h1>
<p>{k.width} x {k.height} px, {len(cal.views)} views, method {html.escape(cal.method)},
circle-centre correction passes: {cal.bias_iterations}. Reprojection RMS {cal.rms_px:.3f} px,
max {cal.max_px:.3f} px{sigma}.</p>
<table><tr><th>parameter</th><th>value</th><th>std</th><th>RAC estimate</th><th>unit</th></tr>
{''.join(rows)}</table>
<table><tr><th>view</th><th>RMS px</th><th>max px</th><th>tilt deg</th><th>in RAC</th>
<th>distance to the board centre, mm</th></tr>{view_rows}</table>
{f'<p>Not used or not in the RAC:</p><ul>{skipped}</ul>' if skipped else ''}
{''.join(figures)}
</body></html>
"""


def write_calibration_html(path: str | Path, cal: CameraCalibration, board: Board,
                           detected: dict[str, np.ndarray],
                           image_files: dict[str, Path] | None = None) -> None:
    """Write :func:`calibration_html` atomically, reading the views' images from
    ``image_files`` (image name -> path)."""
    images = None
    if image_files is not None:
        images = {name: read_grey(p) for name, p in image_files.items()
                  if name in {v.name for v in cal.views}}
    write_text_atomic(path, calibration_html(cal, board, detected, images))
