"""The camera model shared by calibration, measurement and rendering (seed section 8.1).

Tsai's Radial Alignment Constraint camera, in pixels:

- A point ``(x, y, z)`` in the camera frame (origin at the optical centre, z along the
  optical axis into the scene, x along increasing image column, y along increasing image
  row; metres) has the *undistorted* normalized coordinates ``xu = x / z``, ``yu = y / z``.
- The *distorted* normalized coordinates ``(xd, yd)`` are those the lens really images; as in
  Tsai (1987) and the seed's eqs. 62-63 the distortion is written from distorted to
  undistorted, ``(xu, yu) = (xd, yd) * (1 + k1 r^2 + k2 r^4)`` with ``r^2 = xd^2 + yd^2``.
- Pixels (column ``X``, row ``Y``; integer values at pixel centres):
  ``X = cx + fx * xd``, ``Y = cy + mu * fx * yd``: ``fx`` is the focal length in column
  pixels (the seed's fx, eq. 58), ``mu = fy / fx`` the seed's scale ratio (eq. 67) and
  ``(cx, cy)`` the image centre (section 8.3).

``k1`` and ``k2`` are dimensionless (per squared normalized radius). The seed's ``k`` is per
squared pixel radius: ``k = k1 / fx**2`` when ``k2 = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataError


@dataclass(frozen=True)
class CameraIntrinsics:
    """Intrinsic parameters of one camera (see the module docstring for the model).

    fx : focal length, column pixels. mu : fy / fx. cx, cy : image centre, pixels.
    k1, k2 : radial distortion, distorted -> undistorted, dimensionless.
    width, height : image size, pixels.
    """

    fx: float
    mu: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    width: int = 0
    height: int = 0

    def __post_init__(self):
        for name in ("fx", "mu", "cx", "cy", "k1", "k2"):
            if not np.isfinite(getattr(self, name)):
                raise DataError(f"camera: {name} must be finite, got {getattr(self, name)}")
        if self.fx <= 0 or self.mu <= 0:
            raise DataError(f"camera: fx and mu must be positive, got fx={self.fx}, mu={self.mu}")

    @property
    def fy(self) -> float:
        """Focal length in row pixels, ``mu * fx``."""
        return self.mu * self.fx

    def radial_factor(self, r2: np.ndarray) -> np.ndarray:
        """``1 + k1 r^2 + k2 r^4`` for squared distorted normalized radii ``r2``."""
        return 1.0 + self.k1 * r2 + self.k2 * r2 * r2

    def undistort_normalized(self, distorted: np.ndarray) -> np.ndarray:
        """Undistorted normalized coordinates ``(n, 2)`` from distorted ones ``(n, 2)``."""
        d = np.asarray(distorted, dtype=float)
        return d * self.radial_factor(np.sum(d * d, axis=-1))[..., None]

    def distort_normalized(self, undistorted: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Distorted normalized coordinates ``(n, 2)`` from undistorted ones ``(n, 2)``.

        Solves ``ru = rd (1 + k1 rd^2 + k2 rd^4)`` for ``rd`` by Newton's method, started at
        ``rd = ru``; exact to rounding after a few steps for the distortions of real lenses.
        Newton's error after a step is about ``C step^2`` with ``C = |f'' / 2 f'|`` (below
        13 for |k1|, |k2| < 1 and rd < 1), so the iteration stops once every step is below
        1e-10: the error left is then below 1e-19.
        """
        u = np.asarray(undistorted, dtype=float)
        ru = np.sqrt(u[..., 0] * u[..., 0] + u[..., 1] * u[..., 1])   # not a sum over axis
        rd = ru.copy()
        k1, k2 = self.k1, self.k2
        for _ in range(iterations):
            r2 = rd * rd
            df = 1.0 + r2 * (3.0 * k1 + 5.0 * k2 * r2)
            step = (rd * (1.0 + r2 * (k1 + k2 * r2)) - ru) / np.where(np.abs(df) > 1e-12, df,
                                                                     1e-12)
            rd -= step
            if np.max(np.abs(step), initial=0.0) < 1e-10:
                break
        scale = np.divide(rd, ru, out=np.ones_like(ru), where=ru > 0)
        return u * scale[..., None]

    def pixels_from_normalized(self, distorted: np.ndarray) -> np.ndarray:
        """Pixels ``(n, 2)`` (column, row) from distorted normalized coordinates ``(n, 2)``."""
        d = np.asarray(distorted, dtype=float)
        return np.stack([self.cx + self.fx * d[..., 0], self.cy + self.fy * d[..., 1]], -1)

    def normalized_from_pixels(self, pixels: np.ndarray) -> np.ndarray:
        """Distorted normalized coordinates ``(n, 2)`` from pixels ``(n, 2)``."""
        p = np.asarray(pixels, dtype=float)
        return np.stack([(p[..., 0] - self.cx) / self.fx, (p[..., 1] - self.cy) / self.fy], -1)

    def project(self, points_camera: np.ndarray) -> np.ndarray:
        """Pixels ``(n, 2)`` of points ``(n, 3)`` in the camera frame (m, z > 0)."""
        p = np.asarray(points_camera, dtype=float)
        if np.any(p[..., 2] <= 0):
            raise DataError("camera: a point lies behind the camera (z <= 0)")
        undistorted = p[..., :2] / p[..., 2:3]
        return self.pixels_from_normalized(self.distort_normalized(undistorted))

    def rays(self, pixels: np.ndarray) -> np.ndarray:
        """Undistorted normalized coordinates ``(n, 2)`` (``x/z, y/z``) seen at pixels ``(n, 2)``."""
        return self.undistort_normalized(self.normalized_from_pixels(pixels))


def project_points(intrinsics: CameraIntrinsics, camera_T_board: np.ndarray,
                   points_board: np.ndarray) -> np.ndarray:
    """Pixels ``(n, 2)`` of points ``(n, 3)`` given in the board frame (m), seen by a camera
    whose pose is ``camera_T_board`` (4, 4): board coordinates to camera coordinates, m."""
    T = np.asarray(camera_T_board, dtype=float)
    p = np.asarray(points_board, dtype=float) @ T[:3, :3].T + T[:3, 3]
    return intrinsics.project(p)
