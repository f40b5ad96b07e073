"""Time per target of ik.solve() against roboticstoolbox-python's C++ ``ik_LM``.

Both solve the same 10,000 targets (seeded) of an ABB IRB 2400 whose DH parameters are off
by ~1 mm / ~0.1 deg from nominal, to 1 micrometre and 1 microradian:

- ``solve()``: nominal OPW closed form on the requested ABB configuration, then Newton on
  the perturbed model (analytic Jacobian below), all targets batched.
- ``ik_LM`` from the same start (our nominal closed-form branch, so it is asked for the
  same configuration), one C++ call per target, ``tol`` = 5e-13 (its residual is
  E = 0.5 e^T e, so E <= 5e-13 means |e| <= 1e-6 in m and rad together).
- ``ik_LM`` from its own random starts (its default use), on the first 1,000 targets.

Run: ``python benchmarks/ik_peer.py`` (roboticstoolbox-python is optional: without it only
solve() is timed). Exit code 0.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from olp_compensate.confdata import abb_confdata, select_branch
from olp_compensate.conventions import rotvec_from_rotation
from olp_compensate.ik import OPWParameters, opw_inverse, solve

PI = np.pi
# ABB IRB 2400 in standard DH, ABB joint directions (see tests/test_ik.py)
A = np.array([0.100, 0.705, 0.135, 0, 0, 0])
ALPHA = np.array([-PI / 2, 0, -PI / 2, PI / 2, -PI / 2, 0])
D = np.array([0.615, 0, 0, 0.755, 0, 0.085])
OFFSET = np.array([0, -PI / 2, 0, 0, 0, PI])
NOMINAL = OPWParameters(a1=0.100, a2=-0.135, b=0.0, c1=0.615, c2=0.705, c3=0.755, c4=0.085,
                        offsets=(0, 0, -PI / 2, 0, 0, 0))
LIMITS = np.deg2rad([[-180, 180], [-100, 110], [-60, 65], [-200, 200], [-120, 120],
                     [-400, 400]])


class DH:
    """The perturbed robot: forward kinematics and geometric Jacobian (base frame)."""

    def __init__(self, a, alpha, d, offset):
        self.a, self.alpha, self.d, self.offset = a, alpha, d, offset

    def frames(self, q):
        T = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
        out = [T]
        for i in range(6):
            c, s = np.cos(q[:, i] + self.offset[i]), np.sin(q[:, i] + self.offset[i])
            ca, sa = np.cos(self.alpha[i]), np.sin(self.alpha[i])
            L = np.zeros((len(q), 4, 4))
            L[:, 0] = np.stack([c, -s * ca, s * sa, self.a[i] * c], 1)
            L[:, 1] = np.stack([s, c * ca, -c * sa, self.a[i] * s], 1)
            L[:, 2, 1], L[:, 2, 2], L[:, 2, 3], L[:, 3, 3] = sa, ca, self.d[i], 1.0
            T = T @ L
            out.append(T)
        return out

    def fk(self, q):
        return self.frames(np.atleast_2d(q))[-1]

    def fk_jacobian(self, q):
        F = self.frames(q)
        J = np.empty((len(q), 6, 6))
        for i in range(6):
            z = F[i][:, :3, 2]
            J[:, :3, i] = np.cross(z, F[-1][:, :3, 3] - F[i][:, :3, 3])
            J[:, 3:, i] = z
        return F[-1], J


def errors(robot, q, target):
    reached = robot.fk(q)
    position = np.linalg.norm(reached[:, :3, 3] - target[:, :3, 3], axis=1)
    rotation = np.linalg.norm(rotvec_from_rotation(
        np.swapaxes(reached[:, :3, :3], 1, 2) @ target[:, :3, :3]), axis=1)
    return position, rotation


def report(name, seconds, count, ok, same_branch):
    print(f"{name:34s} {seconds / count * 1e6:9.1f} us/target {count / seconds:10.0f} "
          f"targets/s  reached {ok.mean():7.2%}  on requested branch {same_branch.mean():7.2%}")


def rtb_ets(robot):
    import roboticstoolbox as rtb
    ets = None
    for i in range(6):
        # constant Rz(offset) before the joint: ik_LM's C++ code takes no joint offsets
        links = [rtb.ET.Rz(robot.offset[i]), rtb.ET.Rz(), rtb.ET.tz(robot.d[i]),
                 rtb.ET.tx(robot.a[i]), rtb.ET.Rx(robot.alpha[i])]
        for link in links:
            ets = link if ets is None else ets * link
    return ets


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=10_000, help="number of targets")
    args = parser.parse_args(argv)

    rng = np.random.default_rng(0)
    robot = DH(A + rng.normal(0, 1e-3, 6), ALPHA + rng.normal(0, np.deg2rad(0.1), 6),
               D + rng.normal(0, 1e-3, 6), OFFSET + rng.normal(0, np.deg2rad(0.1), 6))
    q_true = rng.uniform(LIMITS[:, 0] * 0.95, LIMITS[:, 1] * 0.95, (args.n, 6))
    target = robot.fk(q_true)
    conf = abb_confdata(NOMINAL, q_true)
    print(f"{args.n} targets, IRB 2400 with ~1 mm / ~0.1 deg DH errors, goal 1 um / 1 urad")

    solve(NOMINAL, robot.fk_jacobian, target[:100], conf[:100], LIMITS)      # warm-up
    start = time.perf_counter()
    result = solve(NOMINAL, robot.fk_jacobian, target, conf, LIMITS)
    ours = time.perf_counter() - start
    position, rotation = errors(robot, result.q, target)
    ok = result.success & (position <= 1e-6) & (rotation <= 1e-6)
    same = ok & (abb_confdata(NOMINAL, result.q)[:, 3] == conf[:, 3])
    report("olp_compensate.ik.solve (batched)", ours, args.n, ok, same)
    worst = max(position[result.success].max(), rotation[result.success].max())
    reasons = {str(k): int(v) for k, v in zip(*np.unique(result.reason, return_counts=True))}
    print(f"    worst error {worst:.1e} (m or rad), reasons {reasons}")

    try:
        ets = rtb_ets(robot)
        ets.ik_LM(target[0], q0=q_true[0], tol=5e-13)
    except (ImportError, RuntimeError) as exc:
        print(f"roboticstoolbox-python ik_LM not available ({exc}); nothing to compare")
        return 0

    q0, _ = select_branch(opw_inverse(NOMINAL, target), conf, LIMITS)
    q0 = np.where(np.isfinite(q0), q0, 0.0)
    q_rtb = np.empty_like(q0)
    start = time.perf_counter()
    for i in range(args.n):
        q_rtb[i] = ets.ik_LM(target[i], q0=q0[i], ilimit=100, slimit=1, tol=5e-13,
                             joint_limits=False)[0]
    theirs = time.perf_counter() - start
    position, rotation = errors(robot, q_rtb, target)
    ok_rtb = (position <= 1e-6) & (rotation <= 1e-6)
    same_rtb = ok_rtb & (abb_confdata(NOMINAL, q_rtb)[:, 3] == conf[:, 3])
    report("rtb ik_LM, same start (C++)", theirs, args.n, ok_rtb, same_rtb)

    k = min(1000, args.n)
    q_free = np.empty((k, 6))
    start = time.perf_counter()
    for i in range(k):
        q_free[i] = ets.ik_LM(target[i], tol=5e-13, joint_limits=False)[0]
    free = time.perf_counter() - start
    position, rotation = errors(robot, q_free, target[:k])
    ok_free = (position <= 1e-6) & (rotation <= 1e-6)
    same_free = ok_free & (abb_confdata(NOMINAL, q_free)[:, 3] == conf[:k, 3])
    report("rtb ik_LM, random starts (C++)", free, k, ok_free, same_free)
    print(f"ratio rtb(same start) / solve per target: {theirs / ours:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
