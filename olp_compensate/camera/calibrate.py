"""Camera calibration from views of the dot board: the seed's RAC (sections 8.1-8.3), then
by default the full refinement (:mod:`.refine`), with optional correction of the
perspective bias of the circles' centres.

How many views, and which:

- Both methods need at least :data:`MIN_VIEWS` = 3 views tilted by :data:`MIN_TILT_DEG` or
  more. The RAC's centre and mu searches average residuals over views, and one plane seen
  once fixes neither well (for a plane the eq. 69 residual does not even depend on mu, see
  :mod:`.rac`); the refinement's intrinsics need, as in Zhang's method, two constraints per
  view of a plane for four linear intrinsics plus the distortion: three views at the least.
  Ten to twenty views, tilted 30-50 degrees about different axes and filling the image, give
  standard deviations of a few tenths of a pixel.
- A view nearly parallel to the board (its normal within :data:`MIN_TILT_DEG` of the optical
  axis; the seed asks for 30 degrees) makes the RAC ill-conditioned: it is left out of the
  RAC stages (with its name and tilt in ``rac_excluded``) but still refined, where it is
  harmless.
- Views whose board normals all lie within :data:`MIN_SPREAD_DEG` of each other are refused:
  the focal length and the centre trade against each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ..errors import DataError
from . import rac
from .model import CameraIntrinsics, project_points
from .refine import INTRINSIC_NAMES, refine
from .scale import BoardScale
from .zhang import zhang_start

MIN_VIEWS = 3
"""Fewest usable views for either method (see the module docstring)."""

MIN_TILT_DEG = 20.0
"""A view whose board normal is closer than this to the optical axis is left out of the RAC."""

MIN_SPREAD_DEG = 10.0
"""The board normals of the views must span at least this angle."""

BIAS_ITERATIONS = 3
"""Passes of the circle-centre correction (each: bias at the current estimate, re-fit)."""

METHODS = ("rac", "rac-only")

STAGES = {"rac": "in the RAC stages, then refined",
          "rac-pose": "pose from the RAC's intrinsics (too near face-on for the RAC), refined",
          "homography": "pose and intrinsics from homographies (Zhang), refined"}
"""How a view entered the refinement."""

CentreBias = Callable[[CameraIntrinsics, np.ndarray], np.ndarray]
"""``bias(intrinsics, camera_T_board) -> (n, 2)`` px: detected centre minus the image of the
dot's centre, e.g. ``lambda k, T: detect.circle_centre_bias(k, T, board)``."""


@dataclass(frozen=True)
class View:
    """One image's detected dots: ``pixels`` (n, 2) column, row; ``points`` (n, 3) the
    same dots in the board frame, m."""

    name: str
    pixels: np.ndarray
    points: np.ndarray


@dataclass(frozen=True)
class ViewResult:
    """A calibrated view: camera_T_board (4, 4) m; reprojection ``rms_px`` (RMS of the
    distances) and ``max_px``; ``tilt_deg`` the angle between the board normal and the
    optical axis; ``in_rac`` whether the RAC stages used it; ``stage`` how it entered the
    refinement (:data:`STAGES`)."""

    name: str
    camera_T_board: np.ndarray
    rms_px: float
    max_px: float
    tilt_deg: float
    in_rac: bool
    stage: str = "rac"


@dataclass(frozen=True)
class Skipped:
    """A view not used, and why."""

    name: str
    reason: str


@dataclass(frozen=True)
class CameraCalibration:
    """The result of :func:`calibrate`.

    intrinsics : the estimate of ``method`` ("rac": refined; "rac-only": the RAC's).
    std : standard deviation per name of :data:`~.refine.INTRINSIC_NAMES` (px, 1, px, px, 1,
    1); NaN for the RAC-only estimate (the RAC gives none). rac : the RAC estimate (k2 = 0)
    on the detected centres (for "rac-only" with the circle-centre correction: the last one,
    on the corrected centres; then equal to ``intrinsics``).
    views : per used view. skipped : views not used. rms_px, max_px : over all dots.
    sigma_px : residual standard deviation sqrt(RSS / (m - n)) (NaN for rac-only).
    rac_excluded : views left out of the RAC stages, with reasons. bias_iterations : passes of
    the circle-centre correction (0: detected centres used as they are). scale : the board's
    scale the views' poses were measured with (:class:`.scale.BoardScale`). start : where
    the refinement started, "rac" or "homography" (then ``rac`` holds that start).
    """

    intrinsics: CameraIntrinsics
    std: dict
    rac: CameraIntrinsics
    method: str
    views: tuple
    skipped: tuple = ()
    rms_px: float = float("nan")
    max_px: float = float("nan")
    sigma_px: float = float("nan")
    rac_excluded: tuple = ()
    bias_iterations: int = 0
    scale: BoardScale = BoardScale()
    start: str = "rac"


def tilt_deg(camera_T_board: np.ndarray) -> float:
    """Angle (deg) between the board normal and the optical axis of one pose."""
    return float(np.degrees(np.arccos(np.clip(abs(camera_T_board[2, 2]), 0.0, 1.0))))


def _reprojection(intrinsics, poses, pixels, points):
    """Per view the distances (n,) px between projected and observed dots."""
    return [np.hypot(*(project_points(intrinsics, T, q) - p).T)
            for T, p, q in zip(poses, pixels, points)]


def _check_views(views: Sequence[View]) -> tuple[list[View], list[Skipped]]:
    usable, skipped = [], []
    for view in views:
        pix = np.asarray(view.pixels, dtype=float)
        pts = np.asarray(view.points, dtype=float)
        if pix.ndim != 2 or pix.shape[1] != 2 or pts.ndim != 2 or pts.shape[1] != 3 \
                or len(pix) != len(pts):
            raise DataError(f"{view.name}: expected pixels (n, 2) and points (n, 3), got "
                            f"{pix.shape} and {pts.shape}")
        if not np.all(np.isfinite(pix)) or not np.all(np.isfinite(pts)):
            raise DataError(f"{view.name}: pixels or points are not all finite numbers")
        if np.any(np.abs(pts[:, 2]) > 1e-9):
            raise DataError(f"{view.name}: the board points must lie in the plane z = 0")
        if len(pix) < rac.MIN_POINTS:
            skipped.append(Skipped(view.name, f"{len(pix)} dots, at least {rac.MIN_POINTS} "
                                              f"needed"))
            continue
        usable.append(View(view.name, pix, pts))
    return usable, skipped


def initial_pose(pixels: np.ndarray, points: np.ndarray,
                 intrinsics: CameraIntrinsics) -> np.ndarray:
    """camera_T_board (4, 4) of one view with known intrinsics: the RAC's stage 1 on the
    undistorted rays (exact, so the distortion needs no second stage), then Tz by linear
    least squares (eq. 66 with fx = 1 and k = 0 on the rays)."""
    rays = intrinsics.rays(pixels)
    s1 = rac.stage1(rays, points, 0.0, 0.0, 1.0)
    s2 = rac.stage2([s1], [rays], [points], 0.0, 0.0, 1.0, with_k=False)
    unit = CameraIntrinsics(fx=1.0, mu=1.0, cx=0.0, cy=0.0)
    return rac.rac_poses([rays], [points], unit, s2, [s1])[0]


def _rac_stage(pixels, points, width, height, tilted, start=None):
    """The RAC on the tilted views, then every view's pose: (RacResult, poses (V, 4, 4))."""
    centre = None if start is None else (start.cx, start.cy)
    found = rac.rac_calibrate([pixels[k] for k in tilted], [points[k] for k in tilted],
                              width, height, mu=1.0 if start is None else start.mu,
                              centre=centre)
    poses = np.empty((len(pixels), 4, 4))
    for k in range(len(pixels)):
        if k in tilted:
            poses[k] = found.camera_T_board[tilted.index(k)]
        else:
            poses[k] = initial_pose(pixels[k], points[k], found.intrinsics)
    return found, poses


def calibrate(views: Sequence[View], width: int, height: int, *, method: str = "rac",
              centre_bias: CentreBias | None = None,
              bias_iterations: int = BIAS_ITERATIONS) -> CameraCalibration:
    """Calibrate a camera of ``width`` x ``height`` px from views of a planar board.

    method : "rac" (the seed's RAC, then the full refinement) or "rac-only" (the seed's
    estimate kept). centre_bias : when given, the perspective bias of the detected circle
    centres is estimated at the current calibration and subtracted from the detections,
    then the calibration is redone, ``bias_iterations`` times; the first estimate is taken
    at the RAC's start, not after a refinement on the uncorrected centres that the next
    pass would only replace (three passes land within 1e-6 px of eight either way; one
    refinement of six iterations, 13 % of the corrected calibration, saved).
    Raises :class:`DataError` with advice when the views cannot calibrate the camera.
    """
    if method not in METHODS:
        raise DataError(f"calibrate: method must be one of {', '.join(METHODS)}, got "
                        f"{method!r}")
    if not (width > 0 and height > 0):
        raise DataError(f"calibrate: image size must be positive, got {width} x {height}")
    usable, skipped = _check_views(views)
    advice = ("take 10-20 views with the board tilted 30-50 degrees about different axes, "
              "filling most of the image")
    if len(usable) < MIN_VIEWS:
        raise DataError(f"calibrate: {len(usable)} usable view(s); the RAC's centre and mu "
                        f"searches and the refinement need at least {MIN_VIEWS}: {advice}")
    pixels = [v.pixels for v in usable]
    points = [v.points for v in usable]
    # tilt of each view from a first stage 1 at the middle of the image, mu = 1
    guess = ((width - 1) / 2.0, (height - 1) / 2.0)
    first = rac.stage1_all(pixels, points, guess[0], guess[1], 1.0)
    tilts = [float(np.degrees(np.arccos(np.clip(abs(s.rotation[2, 2]), 0, 1)))) for s in first]
    tilted = [k for k, t in enumerate(tilts) if t >= MIN_TILT_DEG]
    found, start, poses, stages, reason = _start(pixels, points, width, height, tilted,
                                                 method, first, advice)
    if found is None:
        tilted = []
    excluded = tuple(Skipped(usable[k].name, f"tilt {tilts[k]:.0f} deg < {MIN_TILT_DEG:.0f}: "
                                             f"{reason}")
                     for k in range(len(usable)) if k not in tilted)
    kind = "rac" if found is not None else "homography"
    intrinsics, refined, passes = start, None, 0
    if method == "rac" and (centre_bias is None or bias_iterations < 1):
        refined = refine(pixels, points, intrinsics, poses)
        intrinsics, poses = refined.intrinsics, refined.camera_T_board
    if centre_bias is not None:
        detected = pixels
        for passes in range(1, bias_iterations + 1):
            pixels = [p - centre_bias(intrinsics, T) for p, T in zip(detected, poses)]
            if method == "rac":
                refined = refine(pixels, points, intrinsics, poses)
                intrinsics, poses = refined.intrinsics, refined.camera_T_board
            else:
                found, poses = _rac_stage(pixels, points, width, height, tilted, intrinsics)
                intrinsics = found.intrinsics
    distances = _reprojection(intrinsics, poses, pixels, points)
    every = np.concatenate(distances)
    if refined is None:
        std = {name: float("nan") for name in INTRINSIC_NAMES}
        sigma = float("nan")
    else:
        std, sigma = refined.intrinsics_std, refined.sigma_px
    results = tuple(ViewResult(v.name, T, float(np.sqrt(np.mean(d ** 2))), float(np.max(d)),
                               tilt_deg(T), k in tilted, stages[k])
                    for k, (v, T, d) in enumerate(zip(usable, poses, distances)))
    return CameraCalibration(
        intrinsics=intrinsics, std=std, rac=start if found is None else found.intrinsics,
        method=method, views=results, skipped=tuple(skipped),
        rms_px=float(np.sqrt(np.mean(every ** 2))), max_px=float(np.max(every)),
        sigma_px=sigma, rac_excluded=excluded, bias_iterations=passes, start=kind)


def _start(pixels, points, width, height, tilted, method, first, advice):
    """Where the refinement starts: (RAC result or None, intrinsics, poses (V, 4, 4), each
    view's stage, why views were left out of the RAC). The RAC on the tilted views when
    there are :data:`MIN_VIEWS`, else (method "rac") every view from its homography.
    ``first``: every view's RAC stage 1 at the image's middle, mu = 1 (its board normal)."""
    n = len(pixels)
    if len(tilted) >= MIN_VIEWS:
        _check_spread(np.array([first[k].rotation[:, 2] * np.sign(first[k].rotation[2, 2])
                                for k in tilted]), advice)
        found, poses = _rac_stage(pixels, points, width, height, tilted)
        stages = ["rac" if k in tilted else "rac-pose" for k in range(n)]
        return (found, found.intrinsics, poses, stages, "too close to parallel to the board "
                "for the RAC; pose from the RAC's intrinsics")
    if method == "rac-only":
        raise DataError(f"calibrate: only {len(tilted)} of {n} views have the board "
                        f"tilted by {MIN_TILT_DEG:.0f} degrees or more (the RAC is "
                        f"ill-conditioned nearer to parallel; the seed asks for 30); "
                        f"{MIN_VIEWS} are needed for rac-only (the default method starts "
                        f"such views from their homographies): {advice}")
    start, poses = zhang_start(pixels, points, width, height)
    _check_spread(poses[:, :3, 2] * np.sign(poses[:, 2:3, 2]), advice)
    return (None, start, poses, ["homography"] * n,
            f"fewer than {MIN_VIEWS} views tilted {MIN_TILT_DEG:.0f} deg or more: every "
            f"view started from its homography (Zhang)")


def _check_spread(normals: np.ndarray, advice: str) -> None:
    """:class:`DataError` when the board normals (k, 3) span less than MIN_SPREAD_DEG."""
    spread = np.degrees(np.arccos(np.clip(np.min(normals @ normals.T), -1.0, 1.0)))
    if spread < MIN_SPREAD_DEG:
        raise DataError(f"calibrate: the board normals of the views span only {spread:.1f} "
                        f"degrees (at least {MIN_SPREAD_DEG:.0f} needed): the views are too "
                        f"alike to separate the focal length from the centre; {advice}")
