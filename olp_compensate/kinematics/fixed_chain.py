"""A chain at fixed parameter values, fused per joint: fast flange poses and joint
Jacobians of a 6R arm for batches of poses (inverse kinematics).

Made by :func:`olp_compensate.kinematics.model.fixed_chain`, which checks it against
:func:`olp_compensate.kinematics.model.forward`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_FIXED_CHAIN_BLOCK = 4096   # poses per pass of FixedChain.flange


@dataclass(frozen=True)
class FixedChain:
    """The model at fixed parameter values, for a 6R arm: the constant steps between two
    joints fused into one link, so a pass costs six turns about z and six 4x4 products
    (:func:`forward` evaluates every elementary step, for identification). Joint k's frame
    (z on its axis, before its motion) is ``first`` for k = 1, else the previous frame
    times ``Rz(q) links[k - 2]``; the flange is the last frame times ``Rz(q6) links[5]``.
    ``first`` (4, 4), ``links`` (6, 4, 4), m. Made by :func:`fixed_chain`."""

    first: np.ndarray
    links: np.ndarray

    def flange_and_jacobian(self, q: np.ndarray):
        """Flange poses (m, 4, 4) for joints q (m, 6) rad, and the geometric Jacobian
        (m, 6, 6) (flange-origin velocity, then angular velocity, base frame). Both are
        built with the batch last and handed out as transposed views."""
        return self._pass(q, jacobian=True)

    def flange(self, q: np.ndarray) -> np.ndarray:
        """Flange poses (m, 4, 4) for joints q (m, 6) rad, in blocks of a few thousand (the
        arrays of a block stay in the processor's cache)."""
        out = np.empty((len(q), 4, 4))
        for start in range(0, len(q), _FIXED_CHAIN_BLOCK):
            block = slice(start, start + _FIXED_CHAIN_BLOCK)
            out[block] = self._pass(q[block])[0]
        return out

    def _pass(self, q: np.ndarray, jacobian: bool = False):
        """Flange poses, and with ``jacobian`` the Jacobian, as transposed views of arrays
        with the batch last: (4, 4, m) and (joint, twist row, m)."""
        m = len(q)
        angle = np.ascontiguousarray(q.T)
        c, s = np.cos(angle), np.sin(angle)
        frame = np.empty((4, 3, m))                  # rows: x, y, z axes and the origin
        frame[:] = self.first[:3, :, None].transpose(1, 0, 2)
        turned = np.empty((4, 3, m))                 # the frame turned about its z axis
        scratch = np.empty((3, m))
        if jacobian:
            jac = np.empty((6, 6, m))                # (joint, twist row, pose)
            points = np.empty((6, 3, m))
        for k in range(6):
            if jacobian:
                jac[k, 3:], points[k] = frame[2], frame[3]
            np.multiply(c[k], frame[0], out=turned[0])
            turned[0] += np.multiply(s[k], frame[1], out=scratch)
            np.multiply(c[k], frame[1], out=turned[1])
            turned[1] -= np.multiply(s[k], frame[0], out=scratch)
            turned[2:] = frame[2:]
            np.matmul(self.links[k].T, turned.reshape(4, -1), out=frame.reshape(4, -1))
        flange = np.zeros((4, 4, m))
        flange[:3] = frame.transpose(1, 0, 2)
        flange[3, 3] = 1.0
        if not jacobian:
            return flange.transpose(2, 0, 1), None
        r = frame[3] - points                         # flange origin from each axis
        w = jac[:, 3:]
        jac[:, 0] = w[:, 1] * r[:, 2] - w[:, 2] * r[:, 1]
        jac[:, 1] = w[:, 2] * r[:, 0] - w[:, 0] * r[:, 2]
        jac[:, 2] = w[:, 0] * r[:, 1] - w[:, 1] * r[:, 0]
        return flange.transpose(2, 0, 1), jac.transpose(2, 1, 0)

    def frames(self) -> tuple[np.ndarray, np.ndarray]:
        """Joint frames at zero (6, 4, 4) and the flange at zero (4, 4), base frame, m."""
        frames = [self.first]
        for link in self.links[:5]:
            frames.append(frames[-1] @ link)
        return np.array(frames), frames[-1] @ self.links[5]
