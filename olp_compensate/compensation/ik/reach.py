"""A proof that targets lie beyond a 6R arm's reach near its stretched elbow: :class:`ReachBound`.

Frames ``(4, 4)`` and targets ``(k, 4, 4)`` in m, base frame; angles in rad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import ModelError
from ...kinematics.conventions import invert_pose
from .inputs import as_poses


_REACH_SPAN = 0.6         # rad: widest elbow interval (about the stretched elbow) examined
_REACH_CELLS = 8          # first subdivision of that interval
_REACH_ROUNDS = 14        # halvings of a cell before a target is left to the iteration
_REACH_MARGIN = 1e-12     # m^2: rounding allowance of the final comparison
_REACH_CONDITION = 1e-6   # an inverse cosine within this of +-1 is not trusted


def _circle_square(c0, c1, c2, point):
    """Bounds of ``|c0 + c1 cos t + c2 sin t - point|^2`` (a point on a circle, up to
    rounding): ``(A, B, phase, E)`` with the square ``A + B cos(t - phase) + e(t)``,
    ``|e(t)| <= E``, B >= 0."""
    d0 = c0 - point
    a = d0 @ d0 + 0.5 * (c1 @ c1 + c2 @ c2)
    bc, bs = 2.0 * (d0 @ c1), 2.0 * (d0 @ c2)
    error = np.hypot(0.5 * (c1 @ c1 - c2 @ c2), c1 @ c2) + 1e-15 * a
    return a, np.hypot(bc, bs), np.arctan2(bs, bc), error


def _circle(f):
    """Centre and the two half-axes ``(c0, c1, c2)`` of ``f(t) = c0 + c1 cos t + c2 sin t``
    (a point turned about an axis), from f at 0, pi/2 and pi."""
    at0, at90, at180 = f(0.0), f(0.5 * np.pi), f(np.pi)
    c0 = 0.5 * (at0 + at180)
    return c0, 0.5 * (at0 - at180), at90 - c0


def _closest_on_axes(point_a, axis_a, point_b, axis_b):
    """Parameters (s, t) of the closest points ``point_a + s axis_a`` and ``point_b + t
    axis_b`` of two unit axes, or None where they are (nearly) parallel."""
    ab = axis_a @ axis_b
    if 1.0 - ab * ab < 1e-6:
        return None
    w = point_b - point_a
    s, t = np.linalg.solve(np.array([[1.0, -ab], [ab, -1.0]]), np.array([w @ axis_a, w @ axis_b]))
    return s, t


@dataclass(frozen=True)
class _ReachTargets:
    """Per-target values :meth:`ReachBound.unreachable` uses, m: W6 in frame 1 (k, 3), its
    distance to axis 1 and to the circle of S (k,), axis 6 in frame 1 (k, 3), and the
    wrist bit asked for (k,)."""

    local: np.ndarray
    radial: np.ndarray
    distance: np.ndarray
    axis6: np.ndarray
    wrist: np.ndarray


def _turn(v, angle):
    """Vectors ``v (k, 3)`` turned about z by ``angle (k,)`` rad."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.empty_like(v)
    out[:, 0] = c * v[:, 0] - s * v[:, 1]
    out[:, 1] = s * v[:, 0] + c * v[:, 1]
    out[:, 2] = v[:, 2]
    return out


class ReachBound:
    """A sound test that targets lie beyond the reach of a 6R arm near its stretched elbow.

    The arm is given by its joint frames at zero (``frames (6, 4, 4)``, base frame, z on
    each joint axis, as just before the joint's own motion) and the flange at zero
    (``flange (4, 4)``), m: frame k + 1 is ``frame_k Rz(q_k) K_k`` with ``K_k`` constant
    (the structure of the calibrated model). Axes 2 and 3 need not be parallel, nor need
    axes 4, 5 and 6 meet: only exact invariants are used. With S a point on axis 2, P4 on
    axis 4 and W6 on axis 6 (near the wrist centre), and R4 the rotation of frame 4,

    - ``|P4 - S|^2 = f3(q3)`` and ``a3(q3) = R4^T (P4 - S)`` depend on the elbow angle
      alone, ``w(q4, q5) = R4^T (W6 - P4)`` on the wrist angles alone, so that
      ``|W6 - S(q1)|^2 = f3 + 2 a3 . w + |w|^2`` exactly;
    - W6 is a point of the flange: the target places it, and ``|W6 - S(q1)|`` is at least
      its distance to the circle S turns on about axis 1;
    - every joint of a solution follows from its elbow angle and the target: axis 1 from
      ``(P4 - S) . u2 = n3(q3)`` (P4 in the plane of axis 2, up to a q3-dependent offset),
      axis 2 from the direction of P4, the wrist from the rotation ``R4^T R_target``; P4 is
      within :attr:`wrist_offset` of W6. The wrist offset w is evaluated on this arm over
      a subdivision of the possible elbow angles, with bounds for all a cell and the
      wrist offset can change (each shoulder and wrist solution separately).

    A target is declared unreachable only when every cell's bound of ``|W6 - S|^2`` lies
    below the squared distance; the requested wrist configuration (sign of sin(theta5), see
    :func:`configuration_bits`) may exclude the other wrist solution. What the bounds
    cannot settle (wrist or shoulder near singular, elbow far from stretched, a reachable
    target) is left to the iteration: the test never rejects a reachable target.
    ``branches``: the chain's joints are the ones the configuration is read on (False when
    joint effects stand between them: the wrist configuration asked for is then not used).
    """

    def __init__(self, frames, flange, branches: bool = True):
        frames = np.asarray(frames, dtype=float)
        flange = np.asarray(flange, dtype=float)
        if frames.shape != (6, 4, 4) or flange.shape != (4, 4):
            raise ModelError(f"ReachBound needs 6 joint frames (6, 4, 4) and a flange (4, 4), "
                             f"got {frames.shape} and {flange.shape}")
        self.branches = bool(branches)
        links = [invert_pose(frames[k]) @ frames[k + 1] for k in range(5)]
        links.append(invert_pose(frames[5]) @ flange)
        self.first = frames[0]
        self.links = np.array(links)                          # K_1 .. K_6
        origin, axis = frames[:, :3, 3], frames[:, :3, 2]
        on45 = _closest_on_axes(origin[3], axis[3], origin[4], axis[4])
        if on45 is None:
            raise ModelError("ReachBound: axes 4 and 5 are parallel")
        z4 = on45[0]                                          # P4 = (0, 0, z4) in frame 4
        p5 = origin[4] + on45[1] * axis[4]
        z6 = (p5 - origin[5]) @ axis[5]                       # W6 = (0, 0, z6) in frame 6
        p4 = origin[3] + z4 * axis[3]
        p3 = origin[2] + ((p4 - origin[2]) @ axis[2]) * axis[2]
        z_s = (p3 - origin[1]) @ axis[1]                      # S = (0, 0, z_s) in frame 2
        self.z4, self.z_s = z4, z_s
        flange_inv = invert_pose(flange)
        self.w6_flange = flange_inv[:3, :3] @ (origin[5] + z6 * axis[5]) + flange_inv[:3, 3]
        self.axis6_flange = flange_inv[:3, :3] @ axis[5]
        K1, K2, K3, K4, K5 = self.links[:5]
        self.rotations = self.links[:5, :3, :3]
        self.offsets = self.links[:5, :3, 3]
        # the circle of S about axis 1, frame 1
        self.s0 = K1[:3, :3] @ np.array([0.0, 0.0, z_s]) + K1[:3, 3]
        self.u2 = K1[:3, 2]
        self.radius_s, self.height_s = np.hypot(self.s0[0], self.s0[1]), self.s0[2]
        # the elbow: P4 in frame 2 turned by q2 is Rz(q2) m(q3), m = K2 Rz(q3) p4_in3
        self.p4_in3 = K3[:3, :3] @ np.array([0.0, 0.0, z4]) + K3[:3, 3]
        s_point = np.array([0.0, 0.0, z_s])
        self.f3 = _circle_square(*_circle(lambda t: self._m(np.array([t]))[0]), s_point)
        if not self.f3[1] > 0:
            raise ModelError("ReachBound: the elbow does not change the reach")
        self.sin23 = np.linalg.norm(np.cross([0.0, 0.0, 1.0], K2[:3, 2]))
        self.r_s3 = np.linalg.norm(np.cross(s_point - K2[:3, 3], K2[:3, 2]))   # S to axis 3
        self.r_43 = np.hypot(self.p4_in3[0], self.p4_in3[1])                 # P4 to axis 3
        # the wrist: axis 6 in frame 4 is Rz(q4) h(q5), h = K4 Rz(q5) g; h_z = p . Rz(q5) g
        p, g = K4[2, :3], K5[:3, 2]
        self.g = g
        self.g_xy = np.hypot(g[0], g[1])
        cc, ss = p[0] * g[0] + p[1] * g[1], p[1] * g[0] - p[0] * g[1]
        self.a5, self.rho5, self.phase5 = p[2] * g[2], np.hypot(cc, ss), np.arctan2(ss, cc)
        if not self.rho5 > 0:
            raise ModelError("ReachBound: axis 5 does not turn axis 6 about axis 4")
        # W6 in frame 4 is Rz(q4) (K4 Rz(q5) w6_in5), w6_in5 = W6 in frame 5
        self.w6_in5 = K5[:3, :3] @ np.array([0.0, 0.0, z6]) + K5[:3, 3]
        c0, c1, c2 = _circle(lambda t: self._w5(np.array([t]))[0])
        a, b, _, e = _circle_square(c0, c1, c2, np.array([0.0, 0.0, z4]))
        self.wrist_offset = np.sqrt(a + b + e) + 1e-12        # largest |W6 - P4|, m
        self.r_w4 = (np.hypot(c0[0], c0[1])                   # largest distance W6 to axis 4
                     + np.sqrt(c1[0] ** 2 + c1[1] ** 2 + c2[0] ** 2 + c2[1] ** 2))
        self.r_w5 = np.hypot(self.w6_in5[0], self.w6_in5[1])  # W6 to axis 5

    def _m(self, t):
        """P4 in frame 2 at q2 = 0, ``(k, 3)``, for elbow angles ``t (k,)``."""
        turned = _turn(np.broadcast_to(self.p4_in3, (len(t), 3)), t)
        return turned @ self.rotations[1].T + self.offsets[1]

    def _w5(self, q5):
        """W6 in frame 4 at q4 = 0, ``(k, 3)``, for wrist angles ``q5 (k,)``."""
        turned = _turn(np.broadcast_to(self.w6_in5, (len(q5), 3)), q5)
        return turned @ self.rotations[3].T + self.offsets[3]

    def unreachable(self, target, wrist=None, params=None, tolerance: float = 1e-9):
        """``(k,) bool``: True where no joints put the flange on ``target (k, 4, 4)`` (m),
        a proof; False where it is not settled. ``wrist (k,)``: the wrist bit asked for
        (0 or 1, -1 any; None: any), read with the conventions of ``params`` (the nominal
        family) with ``tolerance`` as in :func:`configuration_bits`."""
        T = as_poses(target, "target")
        k = len(T)
        out = np.zeros(k, bool)
        if k == 0:
            return out
        first_r = self.first[:3, :3]
        w6 = T[:, :3, :3] @ self.w6_flange + T[:, :3, 3]
        local = (w6 - self.first[:3, 3]) @ first_r                        # frame 1
        radial = np.hypot(local[:, 0], local[:, 1])
        distance = np.hypot(radial - self.radius_s, local[:, 2] - self.height_s)
        a3, b3, phase3, e3 = self.f3
        delta = self.wrist_offset
        shortest = distance - delta                       # |P4 - S| of any solution
        kappa = (shortest * np.abs(shortest) - a3 - e3) / b3
        out[kappa > 1.0] = True
        rows = np.flatnonzero((kappa <= 1.0) & (kappa > np.cos(_REACH_SPAN)) & (shortest > 0))
        if len(rows) == 0:
            return out
        if wrist is None or params is None or not self.branches:
            wrist, params = np.full(k, -1), None
        wrist = np.broadcast_to(np.asarray(wrist, dtype=int), (k,))
        axis6 = (T[:, :3, :3] @ self.axis6_flange) @ first_r
        data = _ReachTargets(local, radial, distance, axis6, wrist)
        half = np.arccos(kappa[rows])
        # each shoulder root whose S stays far enough from W6 whatever the elbow: settled
        reach_max = np.sqrt(a3 + b3 + e3) + delta
        keep_root = []
        for s1 in (1.0, -1.0):
            _, _, floor, bad = self._shoulder(data, rows, np.full(len(rows), s1),
                                              np.full(len(rows), phase3), half)
            keep_root.append(bad | ~(reach_max ** 2 < floor ** 2 - _REACH_MARGIN))
        # cells of (row, shoulder root, wrist root, elbow interval [lo, hi])
        row, s1, s5, lo, hi = [], [], [], [], []
        edges = np.linspace(-1.0, 1.0, _REACH_CELLS + 1)
        for i, root in enumerate((1.0, -1.0)):
            for wrist_root in (1.0, -1.0):
                r = np.flatnonzero(keep_root[i])
                row.append(np.repeat(rows[r], _REACH_CELLS))
                s1.append(np.full(len(r) * _REACH_CELLS, root))
                s5.append(np.full(len(r) * _REACH_CELLS, wrist_root))
                lo.append((phase3 + half[r, None] * edges[:-1]).ravel())
                hi.append((phase3 + half[r, None] * edges[1:]).ravel())
        row, s1, s5, lo, hi = map(np.concatenate, (row, s1, s5, lo, hi))
        open_ = np.zeros(k, bool)                         # not to be settled: left to Newton
        for round_ in range(_REACH_ROUNDS + 1):
            settled, stuck = self._cells(data, params, tolerance, row, s1, s5, lo, hi)
            open_[row[stuck]] = True
            split = ~settled & ~open_[row]
            if not np.any(split):
                break
            if round_ == _REACH_ROUNDS:
                open_[row[split]] = True
                break
            mid = 0.5 * (lo[split] + hi[split])
            row, s1, s5 = (np.repeat(a[split], 2) for a in (row, s1, s5))
            lo = np.stack([lo[split], mid], 1).ravel()
            hi = np.stack([mid, hi[split]], 1).ravel()
        out[rows] = ~open_[rows]
        return out

    def _shoulder(self, data, r, s1, t, half):
        """Axis 1 of the solutions on shoulder root ``s1`` with elbow angles within ``half``
        of ``t`` (all ``(n,)``, rad): the centre's q1, a bound of |q1 - centre|, a lower
        bound of ``|W6 - S(q1)|`` (m), and where the bound does not apply."""
        m_z = self._m(t)[:, 2]
        u2 = self.u2
        x, y = data.local[r, 0], data.local[r, 1]
        alpha, beta = u2[0] * x + u2[1] * y, u2[0] * y - u2[1] * x
        big = np.hypot(alpha, beta)
        with np.errstate(divide="ignore", invalid="ignore"):
            x1 = (m_z - self.z_s + self.s0 @ u2 - u2[2] * data.local[r, 2]) / big
            dx1 = (self.wrist_offset + self.r_43 * self.sin23 * half) / big
            reach1 = np.abs(x1) + dx1
            bad = ~(reach1 < 1.0 - _REACH_CONDITION)
            dq1 = dx1 / np.sqrt(1.0 - np.minimum(reach1, 1.0 - _REACH_CONDITION) ** 2)
        q1 = np.arctan2(beta, alpha) + s1 * np.arccos(np.clip(x1, -1.0, 1.0))
        # |W6 - S(q1)| = |Rz(-q1) W6 - s0| in frame 1; S moves radius_s per rad of q1
        to_s = np.linalg.norm(_turn(data.local[r], -q1) - self.s0, axis=1)
        floor = np.maximum(data.distance[r], to_s - self.radius_s * dq1)
        return q1, dq1, floor, bad

    def _cells(self, data, params, tolerance, row, s1, s5, lo, hi):
        """Settle cells of elbow angles [lo, hi] (rad): ``(settled, stuck)``, each
        ``(n,) bool``. Settled: no solution on this shoulder root (``s1`` = +-1) and wrist
        root (``s5``) has its elbow angle in the cell. Stuck: not even a cell of no width
        at its centre would be settled (bounds that do not apply, or a reachable target)."""
        a3, b3, phase3, e3 = self.f3
        delta = self.wrist_offset
        n = len(row)
        settled = np.zeros(n, bool)
        stuck = np.zeros(n, bool)
        # the largest f3 in the cell; a first test without the wrist's direction
        before, after = lo - phase3, hi - phase3
        top = np.where((before <= 0) & (after >= 0), 1.0,
                       np.maximum(np.cos(before), np.cos(after)))
        f3_max = a3 + e3 + b3 * top
        coarse = f3_max + 2.0 * np.sqrt(np.maximum(f3_max, 0.0)) * delta + delta * delta
        settled |= coarse < data.distance[row] ** 2 - _REACH_MARGIN
        live = np.flatnonzero(~settled)
        if len(live) == 0:
            return settled, stuck
        r, t, half = row[live], 0.5 * (lo[live] + hi[live]), 0.5 * (hi[live] - lo[live])
        K1, K2, K3, K4 = self.rotations[:4]
        q1, _, _, _ = self._shoulder(data, r, s1[live], t, half)
        m = self._m(t)
        tw = (_turn(data.local[r], -q1) - self.offsets[0]) @ K1         # W6 in frame 2
        tw_xy, m_xy = np.hypot(tw[:, 0], tw[:, 1]), np.hypot(m[:, 0], m[:, 1])
        q2 = np.arctan2(tw[:, 1], tw[:, 0]) - np.arctan2(m[:, 1], m[:, 0])
        # axis 6 in frame 4: R4^T a, R4 = first Rz(q1) K1 Rz(q2) K2 Rz(q3) K3
        e = _turn(_turn(_turn(data.axis6[r], -q1) @ K1, -q2) @ K2, -t) @ K3
        x5 = (e[:, 2] - self.a5) / self.rho5
        q5 = self.phase5 + s5[live] * np.arccos(np.clip(x5, -1.0, 1.0))
        e_xy = np.hypot(e[:, 0], e[:, 1])
        h = _turn(np.broadcast_to(self.g, (len(live), 3)), q5) @ K4.T
        q4 = np.arctan2(e[:, 1], e[:, 0]) - np.arctan2(h[:, 1], h[:, 0])
        w = _turn(self._w5(q5), q4)
        w[:, 2] -= self.z4                                                  # W6 - P4, frame 4
        arm = _turn((m - np.array([0.0, 0.0, self.z_s])) @ K2, -t) @ K3     # P4 - S, frame 4
        centre = 2.0 * np.einsum("ij,ij->i", arm, w) + np.einsum("ij,ij->i", w, w)
        arm_norm, w_norm = np.linalg.norm(arm, axis=1), np.linalg.norm(w, axis=1)
        f3_mid = a3 + e3 + b3 * np.cos(t - phase3)
        results = []
        for width, f3_top in ((half, f3_max[live]), (np.zeros_like(half), f3_mid)):
            # how far a solution with its elbow in the cell is from the centre's joints
            _, dq1, floor, bad = self._shoulder(data, r, s1[live], t, width)
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                ratio_a = (delta + data.radial[r] * dq1) / tw_xy
                ratio_b = self.r_43 * width / m_xy
                dq2 = np.arcsin(np.minimum(ratio_a, 1.0)) + np.arcsin(np.minimum(ratio_b, 1.0))
                turn = dq1 + dq2 + width                   # the angle R4 may differ by
                reach5 = np.abs(x5) + turn / self.rho5
                dq5 = (turn / self.rho5) / np.sqrt(
                    1.0 - np.minimum(reach5, 1.0 - _REACH_CONDITION) ** 2)
                ratio_c, ratio_d = turn / e_xy, self.g_xy * dq5 / e_xy
                dq4 = np.arcsin(np.minimum(ratio_c, 1.0)) + np.arcsin(np.minimum(ratio_d, 1.0))
                bad |= ~((ratio_a < 1.0) & (ratio_b < 1.0) & (reach5 < 1.0 - _REACH_CONDITION)
                         & (ratio_c < 1.0) & (ratio_d < 1.0))
                dw = self.r_w4 * dq4 + self.r_w5 * dq5          # |w - w(centre)|
                bound = (f3_top + centre + 2.0 * self.r_s3 * width * delta
                         + 2.0 * arm_norm * dw + dw * (2.0 * w_norm + dw))
                below = bound < floor * floor - _REACH_MARGIN
            if params is not None:           # the other wrist configuration than asked for
                wanted = data.wrist[r]
                margin = params.signs[4] * np.sin(params.signs[4] * q5 - params.offsets[4])
                below |= (((wanted == 0) & (margin + dq5 < -tolerance))
                          | ((wanted == 1) & (margin - dq5 >= tolerance)))
            results.append(below & ~bad)
        settled[live] = results[0]
        stuck[live] = ~results[1]
        return settled, stuck
