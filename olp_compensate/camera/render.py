"""What a camera sees of the board: the project's own renderer, for tests and benchmarks.

Every pixel (X, Y) is back-projected through the full camera model
(:meth:`CameraIntrinsics.rays`: centre, fx, mu, radial distortion) and its ray intersected
with the board plane z = 0; the point found is inside a dot (ink), on the sheet (paper) or
beyond it (background or clutter). Pixels whose footprint on the board may cross a dot or
sheet edge are supersampled (``supersample`` x ``supersample`` rays), the others take one
ray: the grey level of a pixel is the area-weighted mean of what its footprint covers.
Then light falloff (gradient, vignetting), Gaussian blur and Gaussian noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kinematics.conventions import invert_pose, pose_from_rotation_translation
from ..errors import DataError
from .board import CORNER_KINDS, Board
from .model import CameraIntrinsics, project_points

_CHUNK = 1 << 18  # rays per batch when supersampling


@dataclass(frozen=True)
class RenderOptions:
    """How to render. Grey levels are 0-255 under full light.

    supersample : rays per pixel side on pixels near an edge. paper, ink : grey levels of
    the sheet and the dots. background : grey level beyond the sheet (no clutter).
    blur_sigma_px : Gaussian blur, pixels (0: none). noise_sigma : additive Gaussian noise,
    grey levels. gradient : the light falls by this fraction from one image corner to the
    opposite one, along ``gradient_angle_deg`` (0 = towards +X). vignetting : the light
    falls by this fraction at the image corners (quadratic in the radius). clutter : random
    dark and light shapes beyond the sheet. seed : for noise and clutter.
    """

    supersample: int = 8
    paper: float = 215.0
    ink: float = 25.0
    background: float = 80.0
    blur_sigma_px: float = 0.0
    noise_sigma: float = 0.0
    gradient: float = 0.0
    gradient_angle_deg: float = 30.0
    vignetting: float = 0.0
    clutter: bool = False
    seed: int = 0

    def __post_init__(self):
        if not isinstance(self.supersample, int) or not 1 <= self.supersample <= 32:
            raise DataError(f"render: supersample must be an integer 1-32, got {self.supersample!r}")
        for name in ("blur_sigma_px", "noise_sigma", "gradient", "vignetting"):
            if not math.isfinite(getattr(self, name)) or getattr(self, name) < 0:
                raise DataError(f"render: {name} must be >= 0, got {getattr(self, name)!r}")
        if self.gradient >= 1 or self.vignetting >= 1:
            raise DataError("render: gradient and vignetting must be below 1")


def _image_size(intrinsics: CameraIntrinsics, size) -> tuple[int, int]:
    width, height = size if size is not None else (intrinsics.width, intrinsics.height)
    if int(width) <= 0 or int(height) <= 0:
        raise DataError(f"render: image size must be positive, got {width} x {height} "
                        "(give size= or intrinsics with width and height)")
    return int(width), int(height)


def _plane_from_camera(camera_T_board: np.ndarray) -> np.ndarray:
    """3x3 map from (x/z, y/z, 1) in the camera to (bx, by, 1) / depth on the board plane."""
    T = np.asarray(camera_T_board, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise DataError(f"render: camera_T_board must be a finite 4x4 pose, got shape {T.shape}")
    H = np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]])
    if abs(np.linalg.det(H)) < 1e-15:
        raise DataError("render: the camera centre lies in the board plane")
    return np.linalg.inv(H)


def board_points_at_pixels(intrinsics: CameraIntrinsics, camera_T_board: np.ndarray,
                           pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the rays of ``pixels`` (n, 2) meet the board plane: (n, 2) board x, y (m), and
    (n,) bool, True where the plane lies in front of the camera."""
    return _trace(intrinsics, _plane_from_camera(camera_T_board), pixels)


def _trace(intrinsics, plane_from_camera, pixels):
    u = intrinsics.rays(pixels)
    G = plane_from_camera
    q0 = G[0, 0] * u[..., 0] + G[0, 1] * u[..., 1] + G[0, 2]
    q1 = G[1, 0] * u[..., 0] + G[1, 1] * u[..., 1] + G[1, 2]
    q2 = G[2, 0] * u[..., 0] + G[2, 1] * u[..., 1] + G[2, 2]
    front = q2 > 1e-12
    safe = np.where(front, q2, 1.0)
    b = np.stack([np.where(front, q0 / safe, 1e9), np.where(front, q1 / safe, 1e9)], -1)
    return b, front


class _Scene:
    """Signed distances to the dot edges and the sheet edge of one board (m)."""

    def __init__(self, board: Board):
        if board.kind in CORNER_KINDS:
            raise DataError(f"render: {board.kind} boards are not rendered here (use an olp-dots "
                            "or OpenCV circle-grid board for virtual views)")
        self.board = board
        self.sheet = board.sheet_extent()
        self.dot_r = board.dot_diameter_m / 2
        self.marker_r = float(np.max(board.dot_radii()))

    def distances(self, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance to the nearest dot's edge and to the sheet's edge (m, < 0 inside)."""
        bx, by = b[..., 0], b[..., 1]
        x, y, in_grid, marker = self.board.nearest_dot(bx, by)
        radius = np.where(marker, self.marker_r, self.dot_r)
        s_dot = np.where(in_grid, np.hypot(bx - x, by - y) - radius, np.inf)
        s = self.sheet
        s_sheet = np.maximum(np.maximum(s.x_min - bx, bx - s.x_max),
                             np.maximum(s.y_min - by, by - s.y_max))
        return s_dot, s_sheet

    def shade(self, b, front, outside_value, options: RenderOptions, distances=None):
        """Grey level of board points ``b`` under full light (``distances`` from
        :meth:`distances`, if already known)."""
        s_dot, s_sheet = distances if distances is not None else self.distances(b)
        on_sheet = front & (s_sheet <= 0)
        return np.where(on_sheet, np.where(s_dot <= 0, options.ink, options.paper),
                        outside_value)


def _clutter(width: int, height: int, rng: np.random.Generator) -> np.ndarray:
    """A random cluttered scene in image space: shapes of every grey level and size."""
    import cv2

    image = np.full((height, width), rng.uniform(60, 170), np.float32)
    scale = max(width, height)
    for _ in range(int(rng.integers(60, 120))):
        grey = float(rng.choice([rng.uniform(0, 60), rng.uniform(60, 255)]))
        x, y = int(rng.integers(0, width)), int(rng.integers(0, height))
        kind = rng.integers(0, 4)
        if kind == 0:  # discs of dot-like and larger sizes
            cv2.circle(image, (x, y), int(rng.uniform(2, 0.04 * scale)), grey, -1, cv2.LINE_AA)
        elif kind == 1:
            w, h = rng.uniform(5, 0.15 * scale, 2)
            box = cv2.boxPoints(((x, y), (w, h), rng.uniform(0, 180)))
            cv2.fillPoly(image, [np.round(box).astype(np.int32)], grey, cv2.LINE_AA)
        elif kind == 2:
            x2, y2 = x + int(rng.normal(0, 0.1 * scale)), y + int(rng.normal(0, 0.1 * scale))
            cv2.line(image, (x, y), (x2, y2), grey, int(rng.integers(1, 8)), cv2.LINE_AA)
        else:
            axes = (int(rng.uniform(3, 0.03 * scale)), int(rng.uniform(3, 0.03 * scale)))
            cv2.ellipse(image, (x, y), axes, rng.uniform(0, 180), 0, 360, grey, -1,
                        cv2.LINE_AA)
    return image


def _light(width: int, height: int, options: RenderOptions) -> np.ndarray | None:
    if options.gradient == 0 and options.vignetting == 0:
        return None
    X = np.arange(width, dtype=np.float32) - (width - 1) / 2
    Y = np.arange(height, dtype=np.float32)[:, None] - (height - 1) / 2
    light = np.ones((height, width), np.float32)
    if options.gradient:
        a = math.radians(options.gradient_angle_deg)
        along = (X * math.cos(a) + Y * math.sin(a))
        span = abs(width * math.cos(a)) + abs(height * math.sin(a))
        light *= 1 - options.gradient * (along / span + 0.5)
    if options.vignetting:
        corner2 = ((width - 1) / 2) ** 2 + ((height - 1) / 2) ** 2
        light *= 1 - options.vignetting * (X * X + Y * Y) / corner2
    return light


def render_board(board: Board, intrinsics: CameraIntrinsics, camera_T_board: np.ndarray,
                 options: RenderOptions | None = None,
                 size: tuple[int, int] | None = None) -> np.ndarray:
    """8-bit grey image (height, width) of ``board`` seen by a camera with ``intrinsics`` at
    pose ``camera_T_board`` (4, 4; board coordinates to camera coordinates, m).

    ``size`` = (width, height) in pixels, default the intrinsics' width and height.
    """
    import cv2

    options = options or RenderOptions()
    width, height = _image_size(intrinsics, size)
    G = _plane_from_camera(camera_T_board)
    scene = _Scene(board)
    rng = np.random.default_rng(options.seed)
    outside = (_clutter(width, height, rng) if options.clutter
               else np.full((height, width), options.background, np.float32))

    Y, X = np.mgrid[0:height, 0:width].astype(np.float64)
    b, front = _trace(intrinsics, G, np.stack([X, Y], -1))
    s_dot, s_sheet = scene.distances(b)
    value = scene.shade(b, front, outside, options, (s_dot, s_sheet)).astype(np.float32)

    # footprint of each pixel on the board (m), with a safety factor for its curvature
    dx = np.linalg.norm(np.diff(b, axis=1), axis=-1)
    dy = np.linalg.norm(np.diff(b, axis=0), axis=-1)
    dx = np.concatenate([dx, dx[:, -1:]], axis=1)
    dy = np.concatenate([dy, dy[-1:, :]], axis=0)
    reach = 0.75 * (dx + dy)
    r_max = max(scene.dot_r, scene.marker_r)
    mixed = (np.abs(s_dot) <= reach) | (np.abs(s_sheet) <= reach) \
        | (reach >= board.pitch_m / 2 - r_max)
    near_front = cv2.dilate(front.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    mixed &= near_front
    rows, cols = np.nonzero(mixed)
    if rows.size and options.supersample > 1:
        n = options.supersample
        offsets = (np.arange(n) + 0.5) / n - 0.5
        oy, ox = [o.ravel() for o in np.meshgrid(offsets, offsets, indexing="ij")]
        per_chunk = max(1, _CHUNK // (n * n))
        for start in range(0, rows.size, per_chunk):
            r = rows[start:start + per_chunk]
            c = cols[start:start + per_chunk]
            pix = np.stack([c[:, None] + ox, r[:, None] + oy], -1)
            bs, fs = _trace(intrinsics, G, pix)
            shade = scene.shade(bs, fs, outside[r, c][:, None], options)
            value[r, c] = shade.mean(axis=1)

    light = _light(width, height, options)
    if light is not None:
        value *= light
    if options.blur_sigma_px > 0:
        value = cv2.GaussianBlur(value, (0, 0), options.blur_sigma_px,
                                 borderType=cv2.BORDER_REFLECT)
    if options.noise_sigma > 0:
        value += rng.normal(0.0, options.noise_sigma, value.shape).astype(np.float32)
    return np.clip(np.rint(value), 0, 255).astype(np.uint8)


def _look_at(eye: np.ndarray, target: np.ndarray, roll: float) -> np.ndarray:
    """camera_T_board of a camera at ``eye`` looking at ``target`` (board frame, m), turned
    by ``roll`` (rad) about its optical axis."""
    z = target - eye
    z /= np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x0 = np.cross(helper, z)
    x0 /= np.linalg.norm(x0)
    y0 = np.cross(z, x0)
    x = math.cos(roll) * x0 + math.sin(roll) * y0
    y = np.cross(z, x)
    board_T_camera = pose_from_rotation_translation(np.column_stack([x, y, z]), eye)
    return invert_pose(board_T_camera)


def board_in_view(board: Board, intrinsics: CameraIntrinsics, camera_T_board: np.ndarray,
                  margin_px: float = 10.0, size: tuple[int, int] | None = None) -> bool:
    """True if every printed dot lies inside the image with ``margin_px`` to spare."""
    width, height = _image_size(intrinsics, size)
    angles = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ring = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], -1)
    points = (board.dot_positions()[:, None, :]
              + board.dot_radii()[:, None, None] * ring).reshape(-1, 3)
    T = np.asarray(camera_T_board, dtype=float)
    if np.any((points @ T[:3, :3].T + T[:3, 3])[:, 2] <= 0.05):
        return False
    pix = project_points(intrinsics, T, points)
    return bool(np.all((pix[:, 0] >= margin_px) & (pix[:, 0] <= width - 1 - margin_px)
                       & (pix[:, 1] >= margin_px) & (pix[:, 1] <= height - 1 - margin_px)))


def random_views(board: Board, intrinsics: CameraIntrinsics, count: int,
                 rng: np.random.Generator, distance_m: tuple[float, float] = (0.35, 0.8),
                 tilt_deg: tuple[float, float] = (20.0, 50.0), margin_px: float = 10.0,
                 size: tuple[int, int] | None = None, max_tries: int = 2000) -> list[np.ndarray]:
    """``count`` random camera_T_board poses (4, 4; m) that see the whole board.

    Each camera looks from the printed side (board z < 0) at a point near the board centre
    from ``distance_m`` away, its optical axis ``tilt_deg`` from the board normal, turned
    by a uniform random angle about that axis; views where a dot comes within ``margin_px``
    of the image border are drawn again.
    """
    centre = board.centre()
    spread = 0.1 * np.ptp(board.dot_positions(), axis=0)
    views = []
    for _ in range(max_tries):
        if len(views) == count:
            return views
        distance = rng.uniform(*distance_m)
        tilt = math.radians(rng.uniform(*tilt_deg))
        azimuth = rng.uniform(0, 2 * math.pi)
        target = centre + spread * np.append(rng.uniform(-1, 1, 2), 0.0)
        direction = np.array([math.sin(tilt) * math.cos(azimuth),
                              math.sin(tilt) * math.sin(azimuth), -math.cos(tilt)])
        pose = _look_at(target + distance * direction, target, rng.uniform(0, 2 * math.pi))
        if board_in_view(board, intrinsics, pose, margin_px, size):
            views.append(pose)
    if len(views) < count:
        raise DataError(f"render: found only {len(views)} of {count} views that see the whole "
                        f"board in {max_tries} tries; widen the distance range or the lens")
    return views
