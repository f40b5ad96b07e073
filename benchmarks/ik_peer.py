"""Time per target of ik.solve() against roboticstoolbox-python's C++ ``ik_LM``.

Both solve the same 10,000 targets (seeded) of an ABB IRB 2400 whose DH parameters are off
by ~1 mm / ~0.1 deg from nominal (the "calibrated model", class DH below):

- ``solve()``: nominal OPW closed form on the requested ABB configuration, then Newton on
  the perturbed model (its forward kinematics and analytic Jacobian in numpy, batched),
  all targets batched. Timed: the whole call (closed form, branch selection, every model
  evaluation, the configuration / limit / singularity checks). Run twice: with
  ``position_tol = rotation_tol = 1e-6 / sqrt(2)`` (then |e| <= 1e-6 in m and rad
  together, the peer's criterion below: the comparison line) and with 1e-9 (the library's
  default, a thousand times stricter than the peer is asked for).
- ``ik_LM`` from the same start (our nominal closed-form branch, so it is asked for the
  same configuration), one C++ call per target, ``tol`` = 5e-13 (its residual is
  E = 0.5 e^T e, so E <= 5e-13 means |e| <= 1e-6). Timed: the ik_LM calls only (its own
  forward kinematics and Jacobian in C++, and the Python call per target); the start, our
  closed form, is computed outside the timing.
- ``ik_LM`` from its own random starts (its default use), on the first 1,000 targets.

Each timing is the best of ``--repeat`` runs (default 5), for both sides alike: the
machine's noise only ever adds time. "reached": within 1 um and 1 urad, checked here on
the model; "on requested branch": reached, with the requested ABB cfx.

Run: ``python benchmarks/ik_peer.py`` (roboticstoolbox-python is optional: without it only
solve() is timed; with it installed in another environment, run that environment's python
with ``PYTHONPATH`` set to the repository). Exit code 0.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from olp_compensate.compensation.ik import OPWParameters, opw_inverse, solve
from olp_compensate.kinematics.conventions import rotvec_from_rotation
from olp_compensate.programs.object_model.confdata import abb_confdata, select_branch

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
    """The perturbed robot: forward kinematics and geometric Jacobian (base frame).

    Written for batches, as a calibrated model would be: each frame's axes and origin are
    updated as (3, m) arrays, link by link, and the Jacobian columns are z_i x (p_6 - p_i)
    and z_i."""

    def __init__(self, a, alpha, d, offset):
        self.a, self.alpha, self.d, self.offset = a, alpha, d, offset
        self.ca, self.sa = np.cos(alpha), np.sin(alpha)

    def _frames(self, q):
        """Axes z_0..z_5 (6, 3, m), origins p_0..p_6 (7, 3, m) and the last x, y (3, m)."""
        q = np.atleast_2d(q)
        m = len(q)
        theta = (q + self.offset).T
        cos, sin = np.cos(theta), np.sin(theta)
        x, y, z = np.zeros((3, 3, m))
        x[0], y[1], z[2] = 1.0, 1.0, 1.0
        p = np.zeros((3, m))
        axes, origins = np.empty((6, 3, m)), np.empty((7, 3, m))
        origins[0] = p
        for i in range(6):
            axes[i] = z
            c, s = cos[i], sin[i]
            x, y0 = c * x + s * y, c * y - s * x           # Rz(theta)
            y, z = self.ca[i] * y0 + self.sa[i] * z, self.ca[i] * z - self.sa[i] * y0   # Rx
            p = p + self.d[i] * axes[i] + self.a[i] * x     # Tz(d) Tx(a)
            origins[i + 1] = p
        return axes, origins, x, y, z

    @staticmethod
    def _pose(x, y, z, p):
        pose = np.zeros((x.shape[1], 4, 4))
        pose[:, :3, 0], pose[:, :3, 1], pose[:, :3, 2], pose[:, :3, 3] = x.T, y.T, z.T, p.T
        pose[:, 3, 3] = 1.0
        return pose

    def fk(self, q):
        axes, origins, x, y, z = self._frames(q)
        return self._pose(x, y, z, origins[6])

    def fk_jacobian(self, q):
        axes, origins, x, y, z = self._frames(q)
        r = origins[6] - origins[:6]                       # (6, 3, m)
        J = np.empty((len(x[0]), 6, 6))
        J[:, 0] = (axes[:, 1] * r[:, 2] - axes[:, 2] * r[:, 1]).T
        J[:, 1] = (axes[:, 2] * r[:, 0] - axes[:, 0] * r[:, 2]).T
        J[:, 2] = (axes[:, 0] * r[:, 1] - axes[:, 1] * r[:, 0]).T
        J[:, 3:] = axes.transpose(2, 1, 0)
        return self._pose(x, y, z, origins[6]), J


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


def best_of(repeat, run):
    """Best wall time (s) of ``repeat`` calls of ``run()``, and the last result."""
    best, result = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        result = run()
        best = min(best, time.perf_counter() - start)
    return best, result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=10_000, help="number of targets")
    parser.add_argument("--repeat", type=int, default=5, help="timed runs; the best counts")
    args = parser.parse_args(argv)

    rng = np.random.default_rng(0)
    robot = DH(A + rng.normal(0, 1e-3, 6), ALPHA + rng.normal(0, np.deg2rad(0.1), 6),
               D + rng.normal(0, 1e-3, 6), OFFSET + rng.normal(0, np.deg2rad(0.1), 6))
    q_true = rng.uniform(LIMITS[:, 0] * 0.95, LIMITS[:, 1] * 0.95, (args.n, 6))
    target = robot.fk(q_true)
    conf = abb_confdata(NOMINAL, q_true)
    print(f"{args.n} targets, IRB 2400 with ~1 mm / ~0.1 deg DH errors, goal 1 um / 1 urad, "
          f"best of {args.repeat} runs")

    model_time = [0.0]

    def timed_model(q):
        start = time.perf_counter()
        out = robot.fk_jacobian(q)
        model_time[0] += time.perf_counter() - start
        return out

    ours = {}
    for label, tol in (("1e-6/sqrt2", 1e-6 / np.sqrt(2)), ("1e-9", 1e-9)):
        def run(tol=tol):
            model_time[0] = 0.0
            return solve(NOMINAL, timed_model, target, conf, LIMITS, position_tol=tol,
                         rotation_tol=tol)
        run()                                                               # warm-up
        seconds, result = best_of(args.repeat, run)
        position, rotation = errors(robot, result.q, target)
        ok = result.success & (position <= 1e-6) & (rotation <= 1e-6)
        same = ok & (abb_confdata(NOMINAL, result.q)[:, 3] == conf[:, 3])
        report(f"ik.solve, tol {label}", seconds, args.n, ok, same)
        worst = max(position[result.success].max(), rotation[result.success].max())
        reasons = {str(k): int(v) for k, v in zip(*np.unique(result.reason, return_counts=True))}
        print(f"    worst error {worst:.1e} (m or rad), reasons {reasons}, of the time "
              f"~{model_time[0] / args.n * 1e6:.1f} us/target in the model (last run)")
        ours[label] = seconds

    try:
        ets = rtb_ets(robot)
        ets.ik_LM(target[0], q0=q_true[0], tol=5e-13)
    except (ImportError, RuntimeError) as exc:
        print(f"roboticstoolbox-python ik_LM not available ({exc}); nothing to compare")
        return 0

    q0, _ = select_branch(opw_inverse(NOMINAL, target), conf, LIMITS)
    q0 = np.where(np.isfinite(q0), q0, 0.0)

    def same_start():
        q = np.empty_like(q0)
        for i in range(args.n):
            q[i] = ets.ik_LM(target[i], q0=q0[i], ilimit=100, slimit=1, tol=5e-13,
                             joint_limits=False)[0]
        return q

    theirs, q_rtb = best_of(args.repeat, same_start)
    position, rotation = errors(robot, q_rtb, target)
    ok_rtb = (position <= 1e-6) & (rotation <= 1e-6)
    same_rtb = ok_rtb & (abb_confdata(NOMINAL, q_rtb)[:, 3] == conf[:, 3])
    report("rtb ik_LM, same start (C++)", theirs, args.n, ok_rtb, same_rtb)

    k = min(1000, args.n)

    def random_starts():
        q = np.empty((k, 6))
        for i in range(k):
            q[i] = ets.ik_LM(target[i], tol=5e-13, joint_limits=False)[0]
        return q

    free, q_free = best_of(args.repeat, random_starts)
    position, rotation = errors(robot, q_free, target[:k])
    ok_free = (position <= 1e-6) & (rotation <= 1e-6)
    same_free = ok_free & (abb_confdata(NOMINAL, q_free)[:, 3] == conf[:k, 3])
    report("rtb ik_LM, random starts (C++)", free, k, ok_free, same_free)
    for label, seconds in ours.items():
        print(f"ratio rtb(same start) / solve(tol {label}) per target: {theirs / seconds:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
