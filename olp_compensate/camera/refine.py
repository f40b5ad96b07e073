"""Levenberg-Marquardt refinement on the reprojection error, with an analytic Jacobian
(beyond the seed, which kept the RAC estimates).

Unknowns: the intrinsics ``(fx, mu, cx, cy, k1, k2)`` shared by all views and, per view,
the pose camera_T_board as a rotation vector (rad) and a translation (m). Residuals: the
projected minus the observed pixels (column, row), two per point.

The derivative through the distortion is implicit, since the model distorts from distorted
to undistorted: with ``d`` the distorted normalized point, ``rho = |d|^2`` and
``g = 1 + k1 rho + k2 rho^2``, the undistorted point is ``u = g d``, so
``du = (g I + 2 g' d d^T) dd`` with ``g' = k1 + 2 k2 rho``; that matrix has the eigenvector
``d`` (eigenvalue ``g + 2 g' rho``), so its inverse is ``(I - 2 g' d d^T / (g + 2 g' rho)) / g``,
and ``dd/dk1 = -d rho / (g + 2 g' rho)``, ``dd/dk2 = -d rho^2 / (g + 2 g' rho)``.

The Jacobian is dense in the 6 intrinsic columns and block-diagonal in the 6 columns of
each view. It is never formed: each point's 2 x 12 derivative gives its share of the normal
equations' blocks (:class:`.block_lm.BlockNormal`: intrinsics x intrinsics, intrinsics x
view, view x view), summed per view, and each Levenberg-Marquardt step is solved by the
Schur complement on the views' 6 x 6 blocks (:mod:`.block_lm`). At 20 views of 81 dots
(3,240 x 126) that replaced a dense ``J^T J`` of 51 million multiply-adds per Jacobian by
0.5 million; the work grows linearly with the views (benchmarks/camera_speed.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..calibration.lm import levenberg_marquardt
from ..errors import DataError
from ..kinematics.conventions import (pose_from_rotation_translation, rotation_from_rotvec,
                                      rotvec_from_rotation, skew)
from .block_lm import BlockNormal, block_levenberg_marquardt
from .model import CameraIntrinsics

INTRINSIC_NAMES = ("fx", "mu", "cx", "cy", "k1", "k2")
"""Order of the intrinsic unknowns; units: px, 1, px, px, 1, 1."""

N_INTRINSIC = len(INTRINSIC_NAMES)
N_POSE = 6
"""Pose unknowns of one view: rotation vector (3, rad), then translation (3, m)."""


@dataclass(frozen=True)
class Layout:
    """Where each unknown lives in the parameter vector of :func:`refine`."""

    n_views: int

    @property
    def intrinsics(self) -> slice:
        return slice(0, N_INTRINSIC)

    def view(self, v: int) -> slice:
        """Rotation vector then translation of view ``v``."""
        start = N_INTRINSIC + N_POSE * v
        return slice(start, start + N_POSE)

    @property
    def size(self) -> int:
        return N_INTRINSIC + N_POSE * self.n_views


@dataclass(frozen=True)
class Refinement:
    """Result of :func:`refine`.

    intrinsics : refined. intrinsics_std : standard deviation of each of
    :data:`INTRINSIC_NAMES` (px, 1, px, px, 1, 1; 0 for a fixed one). camera_T_board : (V, 4, 4) m.
    pose_std : (V, 6) standard deviations of the rotation vector (rad) and translation (m).
    residuals : per view (n_v, 2) projected minus observed pixels. sigma_px : the residual
    standard deviation sqrt(RSS / (m - n)). covariance : (n, n) of the free unknowns in
    :class:`Layout` order (fixed ones removed). iterations, message : from the LM.
    """

    intrinsics: CameraIntrinsics
    intrinsics_std: dict
    camera_T_board: np.ndarray
    pose_std: np.ndarray
    residuals: list
    sigma_px: float
    covariance: np.ndarray
    iterations: int
    message: str


@dataclass(frozen=True)
class PoseFit:
    """Result of :func:`refine_pose`: camera_T_board (4, 4) m; covariance (6, 6) of
    (rotation vector rad, translation m); residuals (n, 2) px; sigma_px; rms_px."""

    camera_T_board: np.ndarray
    covariance: np.ndarray
    residuals: np.ndarray
    sigma_px: float
    rms_px: float


def intrinsics_vector(k: CameraIntrinsics) -> np.ndarray:
    """(fx, mu, cx, cy, k1, k2) of an intrinsics object."""
    return np.array([getattr(k, name) for name in INTRINSIC_NAMES], dtype=float)


def intrinsics_from_vector(x: np.ndarray, like: CameraIntrinsics) -> CameraIntrinsics:
    """Intrinsics with the values of ``x`` and the image size of ``like``."""
    return CameraIntrinsics(*(float(v) for v in x), width=like.width, height=like.height)


def left_jacobian(rotvec: np.ndarray) -> np.ndarray:
    """Left Jacobian of SO(3) (3, 3): ``R(w + dw) = exp(J_l(w) dw) R(w)`` to first order."""
    theta = float(np.linalg.norm(rotvec))
    k = skew(rotvec)
    if theta < 1e-6:
        return np.eye(3) + 0.5 * k + (k @ k) / 6.0
    return (np.eye(3) + (1.0 - np.cos(theta)) / theta ** 2 * k
            + (theta - np.sin(theta)) / theta ** 3 * (k @ k))


def left_jacobians(rotvecs: np.ndarray) -> np.ndarray:
    """:func:`left_jacobian` of every rotation vector (V, 3) at once: (V, 3, 3)."""
    rotvecs = np.asarray(rotvecs, dtype=float)
    theta = np.linalg.norm(rotvecs, axis=1)[:, None, None]
    k = skew(rotvecs)
    small = theta < 1e-6
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 0.5, (1.0 - np.cos(safe)) / safe ** 2)
    b = np.where(small, 1.0 / 6.0, (safe - np.sin(safe)) / safe ** 3)
    return np.eye(3) + a * k + b * (k @ k)


@dataclass(frozen=True)
class _Projected:
    """Pixels (N, 2) of board points and what their derivatives need: the rotated points
    (N, 3) and camera-frame points (N, 3), m; undistorted ``u`` and distorted ``d``
    normalized coordinates (N, 2); ``rho = |d|^2`` (N,)."""

    pixels: np.ndarray
    rotated: np.ndarray
    camera: np.ndarray
    u: np.ndarray
    d: np.ndarray
    rho: np.ndarray


def _project(x_intrinsics: np.ndarray, rotvecs: np.ndarray, translations: np.ndarray,
             points: np.ndarray, view: np.ndarray) -> _Projected:
    """Pixels of board points (see :func:`project_with_jacobian` for the arguments); a point
    behind the camera gives NaN pixels (the LM rejects the step)."""
    fx, mu, cx, cy, k1, k2 = x_intrinsics
    rotations = rotation_from_rotvec(rotvecs)
    rotated = np.einsum("nij,nj->ni", rotations[view], points)
    p = rotated + translations[view]
    z = np.where(p[:, 2] > 0, p[:, 2], np.nan)
    u = p[:, :2] / z[:, None]
    # distorted point d from u = g(|d|^2) d: Newton on the radius, as the model does
    ru = np.hypot(u[:, 0], u[:, 1])
    rd = ru.copy()
    for _ in range(30):
        r2 = rd * rd
        step = (rd * (1.0 + k1 * r2 + k2 * r2 * r2) - ru) / (1.0 + 3.0 * k1 * r2
                                                             + 5.0 * k2 * r2 * r2)
        rd -= step
        if np.all(np.abs(step) < 1e-15):
            break
    d = u * np.divide(rd, ru, out=np.ones_like(ru), where=ru > 0)[:, None]
    pixels = np.stack([cx + fx * d[:, 0], cy + mu * fx * d[:, 1]], 1)
    return _Projected(pixels, rotated, p, u, d, rd * rd)


def project_with_jacobian(x_intrinsics: np.ndarray, rotvecs: np.ndarray,
                          translations: np.ndarray, points: np.ndarray, view: np.ndarray,
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels of board points and their derivatives.

    x_intrinsics : (6,) as :data:`INTRINSIC_NAMES`. rotvecs, translations : (V, 3) of
    camera_T_board (rad, m). points : (N, 3) board frame, m. view : (N,) index of each
    point's view. Returns pixels (N, 2), d pixels / d intrinsics (N, 2, 6) and
    d pixels / d (rotation vector, translation) of the point's view (N, 2, 6).
    """
    fx, mu, _, _, k1, k2 = x_intrinsics
    proj = _project(x_intrinsics, rotvecs, translations, points, view)
    d, rho, u, z = proj.d, proj.rho, proj.u, proj.camera[:, 2]
    g = 1.0 + k1 * rho + k2 * rho * rho
    c = 2.0 * (k1 + 2.0 * k2 * rho)
    den = g + c * rho
    n = len(points)
    d_intr = np.zeros((n, 2, N_INTRINSIC))
    d_intr[:, 0, 0] = d[:, 0]
    d_intr[:, 1, 0] = mu * d[:, 1]
    d_intr[:, 1, 1] = fx * d[:, 1]
    d_intr[:, 0, 2] = 1.0
    d_intr[:, 1, 3] = 1.0
    scale = np.array([fx, mu * fx])
    dd_dk1 = -d * (rho / den)[:, None]
    d_intr[:, :, 4] = scale * dd_dk1
    d_intr[:, :, 5] = scale * dd_dk1 * rho[:, None]

    # d d / d u = M = (I - a d d^T) / g with a = c / den; d u / d p = [I | -u] / z, so
    # d pixels / d p = scale [M | -M u] / z; then d p / d w = -[R b]x J_l(w), and a row
    # vector times [v]x is its cross product with v
    a = c / den
    dot = np.sum(d * u, axis=1)
    m_over = np.empty((n, 2, 3))
    m_over[:, :, :2] = -(a / (g * z))[:, None, None] * d[:, :, None] * d[:, None, :]
    m_over[:, 0, 0] += 1.0 / (g * z)
    m_over[:, 1, 1] += 1.0 / (g * z)
    m_over[:, :, 2] = -(u - (a * dot)[:, None] * d) / (g * z)[:, None]
    dpix_dp = m_over * scale[None, :, None]
    cross = np.cross(dpix_dp, proj.rotated[:, None, :])
    dpix_dw = -(cross @ left_jacobians(rotvecs)[view])
    d_extr = np.concatenate([dpix_dw, dpix_dp], axis=2)
    return proj.pixels, d_intr, d_extr


def _normal(d_intr: np.ndarray, d_extr: np.ndarray, r: np.ndarray,
            starts: np.ndarray) -> BlockNormal:
    """Blocks of the normal equations from per-point derivatives d_intr (N, 2, p) and
    d_extr (N, 2, 6) and residuals r (N, 2), views contiguous from ``starts`` (V,): each
    view's rows ``J_v`` (2 n_v, p + 6) give ``J_v^T J_v`` and ``J_v^T r_v`` by one product
    (views of equal size as one stacked product)."""
    p = d_intr.shape[2]
    jac = np.concatenate([d_intr, d_extr], axis=2).reshape(-1, p + N_POSE)
    res = r.reshape(-1, 1)
    sizes = np.diff(np.append(starts, len(r)))
    if np.all(sizes == sizes[0]):
        rows = jac.reshape(len(starts), -1, p + N_POSE)
        both = np.swapaxes(rows, 1, 2) @ np.concatenate(
            [rows, res.reshape(len(starts), -1, 1)], axis=2)
    else:
        both = np.array([jac[2 * a:2 * b].T @ np.hstack([jac[2 * a:2 * b], res[2 * a:2 * b]])
                         for a, b in zip(starts, np.append(starts[1:], len(r)))])
    per_view, grad = both[:, :, :-1], both[:, :, -1]
    return BlockNormal(shared=per_view[:, :p, :p].sum(0), cross=per_view[:, :p, p:],
                       blocks=per_view[:, p:, p:], g_shared=grad[:, :p].sum(0),
                       g_blocks=grad[:, p:])


def _stack(pixels: Sequence[np.ndarray], points: Sequence[np.ndarray]):
    """All views' observations in one array: pixels (N, 2), points (N, 3), view (N,)."""
    if len(pixels) != len(points):
        raise DataError(f"refine: {len(pixels)} pixel sets for {len(points)} point sets")
    pts3 = []
    for k, (pix, pts) in enumerate(zip(pixels, points)):
        pts = np.asarray(pts, dtype=float)
        if pts.shape[1] == 2:
            pts = np.column_stack([pts, np.zeros(len(pts))])
        if len(pix) != len(pts):
            raise DataError(f"refine: view {k} has {len(pix)} pixels for {len(pts)} points")
        if len(pts) == 0:
            raise DataError(f"refine: view {k} has no points")
        pts3.append(pts)
    view = np.concatenate([np.full(len(p), k) for k, p in enumerate(pixels)])
    return (np.concatenate([np.asarray(p, float) for p in pixels]), np.concatenate(pts3),
            view)


def refine(pixels: Sequence[np.ndarray], points: Sequence[np.ndarray],
           intrinsics: CameraIntrinsics, camera_T_board: np.ndarray, *,
           fixed: Sequence[str] = (), max_iterations: int = 100) -> Refinement:
    """Refine intrinsics and poses on the reprojection error (pixels).

    pixels : per view (n_v, 2) observed column, row. points : per view (n_v, 3) board frame,
    m. intrinsics, camera_T_board (V, 4, 4) : the start (the RAC estimate). ``fixed``: names
    from :data:`INTRINSIC_NAMES` kept at their start value (e.g. ``("k2",)``).
    Levenberg-Marquardt on the block normal equations (:mod:`.block_lm`, Schur complement on
    the views' poses). Standard deviations from ``sigma^2 (J^T J)^-1`` with
    ``sigma^2 = RSS / (m - n)``.
    """
    bad = [name for name in fixed if name not in INTRINSIC_NAMES]
    if bad:
        raise DataError(f"refine: unknown intrinsic {bad[0]!r}; expected one of "
                        f"{', '.join(INTRINSIC_NAMES)}")
    obs, pts, view = _stack(pixels, points)
    layout = Layout(len(pixels))
    free_intr = np.array([name not in fixed for name in INTRINSIC_NAMES])
    free = np.concatenate([free_intr, np.ones(layout.size - N_INTRINSIC, dtype=bool)])
    x_full = np.empty(layout.size)
    x_full[layout.intrinsics] = intrinsics_vector(intrinsics)
    poses = np.asarray(camera_T_board, dtype=float)
    x_full[N_INTRINSIC:] = np.column_stack([rotvec_from_rotation(poses[:, :3, :3]),
                                            poses[:, :3, 3]]).ravel()
    m, n = 2 * len(obs), int(free.sum())
    if m <= n:
        raise DataError(f"refine: {m} residuals for {n} unknowns; give more views or dots")
    starts = np.searchsorted(view, np.arange(layout.n_views))

    def unpack(x):
        full = x_full.copy()
        full[free] = x
        ext = full[N_INTRINSIC:].reshape(-1, N_POSE)
        return full, ext[:, :3], ext[:, 3:]

    def residuals(x):
        full, rotvecs, trans = unpack(x)
        if full[0] <= 0 or full[1] <= 0:
            return np.full(m, np.inf)
        return (_project(full[:N_INTRINSIC], rotvecs, trans, pts, view).pixels - obs).ravel()

    def evaluate(x):
        full, rotvecs, trans = unpack(x)
        if full[0] <= 0 or full[1] <= 0:
            return np.full(m, np.inf), None
        pix, d_intr, d_extr = project_with_jacobian(full[:N_INTRINSIC], rotvecs, trans, pts,
                                                    view)
        r = pix - obs
        return r.ravel(), _normal(d_intr[:, :, free_intr], d_extr, r, starts)

    result = block_levenberg_marquardt(evaluate, residuals, x_full[free],
                                       max_iterations=max_iterations)
    full, rotvecs, trans = unpack(result.x)
    sigma2 = 2.0 * result.cost / (m - n)
    covariance = sigma2 * result.normal.inverse()
    std_full = np.zeros(layout.size)
    std_full[free] = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    residual = result.residuals.reshape(-1, 2)
    return Refinement(
        intrinsics=intrinsics_from_vector(full[:N_INTRINSIC], intrinsics),
        intrinsics_std={name: float(std_full[k]) for k, name in enumerate(INTRINSIC_NAMES)},
        camera_T_board=pose_from_rotation_translation(rotation_from_rotvec(rotvecs), trans),
        pose_std=std_full[N_INTRINSIC:].reshape(-1, N_POSE),
        residuals=np.split(residual, starts[1:]), sigma_px=float(np.sqrt(sigma2)),
        covariance=covariance, iterations=result.iterations, message=result.message)


def _inverse(normal: np.ndarray) -> np.ndarray:
    """Inverse of a normal matrix; a singular one (unidentifiable unknowns) gives inf."""
    try:
        return np.linalg.inv(normal)
    except np.linalg.LinAlgError:
        return np.full_like(normal, np.inf)


def refine_pose(pixels: np.ndarray, points: np.ndarray, intrinsics: CameraIntrinsics,
                camera_T_board: np.ndarray, max_iterations: int = 50) -> PoseFit:
    """One view's camera_T_board (4, 4) refined with the intrinsics fixed (6 unknowns).

    pixels : (n, 2) observed. points : (n, 3) board frame, m. Covariance of the rotation
    vector and translation from ``sigma^2 (J^T J)^-1``, ``sigma^2 = RSS / (2n - 6)``.
    """
    obs, pts, view = _stack([pixels], [points])
    m = 2 * len(obs)
    if m <= N_POSE:
        raise DataError(f"pose: {len(obs)} points cannot fix 6 pose unknowns")
    x_intr = intrinsics_vector(intrinsics)
    pose = np.asarray(camera_T_board, dtype=float)
    x0 = np.concatenate([rotvec_from_rotation(pose[:3, :3]), pose[:3, 3]])

    def fun(x):
        pix, _, d_extr = project_with_jacobian(x_intr, x[None, :3], x[None, 3:], pts, view)
        return (pix - obs).ravel(), d_extr.reshape(m, N_POSE)

    result = levenberg_marquardt(fun, x0, max_iterations=max_iterations)
    sigma2 = 2.0 * result.cost / (m - N_POSE) if m > N_POSE else np.nan
    residual = result.residuals.reshape(-1, 2)
    T = pose_from_rotation_translation(rotation_from_rotvec(result.x[:3]), result.x[3:])
    return PoseFit(T, sigma2 * _inverse(result.normal), residual, float(np.sqrt(sigma2)),
                   float(np.sqrt(np.mean(np.sum(residual ** 2, axis=1)))))
