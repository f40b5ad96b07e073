"""The seed's volume study (Motta 2006, sections 6 and 10) on virtual robots.

For virtual IRB 2000, IRB 2400 and PUMA 560 robots (random geometric errors of about 1 mm and
0.1 deg per link, 0.05 mm noise, and joint compliance on axis 2 moving the tool point by
0.3 mm RMS over the workspace, as real arms sag under gravity), calibrate in cubes of three
sizes in two regions (27 poses each: the 3 x 3 x 3 grid, orientations chosen by
:func:`olp_compensate.calibration.volumes.cube_pose_set`), and a global calibration with the
same number of random poses over the workspace. The PUMA 560 (0.86 m reach) gets cubes of 100,
200 and 300 mm: a 600 mm cube with tilted tool orientations does not fit in its workspace. Each calibration is validated with
:func:`olp_compensate.calibration.validation.validate` on new poses inside the volume and in
the rest of the workspace: 'before' is the nominal arm registered rigidly to those
measurements, 'after' the calibrated model (geometric only; the compliance is not modelled).

Run: ``python benchmarks/volumes.py`` (a few minutes on one core).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.simulate import (HiddenEffect, make_virtual_robot,
                                                 random_joints, scaled_effect)
from olp_compensate.calibration.validation import validate
from olp_compensate.calibration.volumes import (_reachable, candidate_orientations,
                                                cube_pose_set)
from olp_compensate.errors import OlpError
from olp_compensate.kinematics.robot import load_robot

NOISE_M = 0.05e-3
COMPLIANCE_RMS_M = 0.3e-3
POSES = 27
TEST_INSIDE = 150
TEST_REST = 300
TOOL_M = np.array([0.05, 0.0, 0.15])
STUDY = {   # robot: (cube edges m, {region: centre m, base frame})
    "abb_irb2000": ((0.2, 0.4, 0.6), {"R1": (1.0, 0.0, 0.7), "R2": (0.5, 0.8, 1.0)}),
    "abb_irb2400": ((0.2, 0.4, 0.6), {"R1": (1.0, 0.0, 0.8), "R2": (0.5, 0.8, 1.0)}),
    "unimation_puma560": ((0.1, 0.2, 0.3), {"R1": (0.45, 0.15, 0.05), "R2": (0.1, 0.5, 0.3)}),
}


def virtual_arm(robot, seed: int):
    """A virtual robot with the tool point TOOL_M and compliance on axis 2."""
    virtual = make_virtual_robot(robot, seed)
    virtual = type(virtual)(**{**virtual.__dict__, "tools": {"tcp": TOOL_M}})
    sample = random_joints(robot, 200, np.random.default_rng(seed + 1))
    effect = scaled_effect(virtual, HiddenEffect("joint_compliance", 1, 1e-6), sample,
                           COMPLIANCE_RMS_M)
    return type(virtual)(**{**virtual.__dict__, "effects": (effect,)})


def poses_inside(robot, centre, edge, n, rng) -> np.ndarray:
    """Joints (<= n, 6) bringing the tool point to random points inside the cube, each with
    a random reachable candidate orientation."""
    points = np.asarray(centre) + edge * (rng.random((n, 3)) - 0.5)
    rotations = candidate_orientations()
    pick = rotations[rng.integers(0, len(rotations), 6)]
    joints, _ = _reachable(robot, points, pick, TOOL_M)
    out = []
    for k in range(n):
        ok = np.flatnonzero(np.all(np.isfinite(joints[k]), axis=1))
        if len(ok):
            out.append(joints[k, ok[0]])
    return np.array(out)


def stats(report):
    return (report.before.mean * 1e3, report.before.std * 1e3, report.after.mean * 1e3,
            report.after.std * 1e3)
# 'before' is always taken from the global calibration's validation: the nominal arm with
# its well-determined tool point (a tool identified in a 100 mm cube is not)


def study(robot_name: str, seed: int = 7) -> list[dict]:
    robot = load_robot(robot_name)
    virtual = virtual_arm(robot, seed)
    rng = np.random.default_rng(seed)
    options = IdentificationOptions(folds=0)
    edges, regions = STUDY[robot_name]
    workspace = random_joints(robot, TEST_REST * 3, rng)
    global_q = random_joints(robot, POSES, rng)
    global_cal = identify(robot, virtual.measure(global_q, NOISE_M, rng), options).calibration
    rows = []
    for region, centre in regions.items():
        for edge in edges:
            try:
                pose_set = cube_pose_set(robot, np.array(centre), edge, "grid", tool_m=TOOL_M)
            except OlpError as exc:
                print(f"  {robot_name} {region} {edge * 1e3:.0f} mm: skipped ({exc})")
                continue
            cal = identify(robot, virtual.measure(pose_set.joints, NOISE_M, rng),
                           options).calibration
            inside_q = poses_inside(robot, centre, edge, TEST_INSIDE, rng)
            inside = virtual.measure(inside_q, NOISE_M, rng)
            rest_q = workspace[~pose_set.volume.contains(
                _tool_points(global_cal, workspace))][:TEST_REST]
            rest = virtual.measure(rest_q, NOISE_M, rng)
            rows.append({"robot": robot_name, "region": region, "edge_mm": edge * 1e3,
                         "inside_local": stats(validate(cal, inside)),
                         "inside_global": stats(validate(global_cal, inside)),
                         "rest_local": stats(validate(cal, rest)),
                         "rest_global": stats(validate(global_cal, rest)),
                         "n_inside": len(inside_q), "n_rest": len(rest_q)})
    return rows


def _tool_points(cal, q):
    """Base-frame tool points of joints q (the nominal-enough calibrated model), m."""
    flange = cal.flange_poses(q)
    return flange[:, :3, 3] + flange[:, :3, :3] @ cal.tools["tcp"].xyz_m


def main() -> int:
    start = time.perf_counter()
    print(f"noise {NOISE_M * 1e3:.2f} mm per axis; joint compliance on axis 2 moving the tool "
          f"point {COMPLIANCE_RMS_M * 1e3:.2f} mm RMS; {POSES} poses per calibration "
          f"(3x3x3 grid in the cube, or random over the workspace for 'global')")
    print("mean +- std of the position error, mm; before = nominal arm registered to the "
          "test points, after = calibrated model")
    header = (f"{'robot':<18}{'reg':<4}{'edge':>6} | {'inside: before':>16} {'local':>14} "
              f"{'global':>14} | {'rest: before':>15} {'local':>14} {'global':>14}")
    all_rows = []
    for name in STUDY:
        rows = study(name)
        all_rows += rows
        print(header)
        for r in rows:
            il, ig, rl, rg = r["inside_local"], r["inside_global"], r["rest_local"], \
                r["rest_global"]
            print(f"{r['robot']:<18}{r['region']:<4}{r['edge_mm']:>4.0f}mm | "
                  f"{ig[0]:7.3f} +- {ig[1]:5.3f} {il[2]:6.3f} +- {il[3]:5.3f} "
                  f"{ig[2]:6.3f} +- {ig[3]:5.3f} | {rg[0]:6.3f} +- {rg[1]:5.3f} "
                  f"{rl[2]:6.3f} +- {rl[3]:5.3f} {rg[2]:6.3f} +- {rg[3]:5.3f}")
    print(verdict(all_rows))
    print(f"run time {time.perf_counter() - start:.0f} s")
    return 0


def verdict(rows) -> str:
    """Whether the seed's findings hold on these runs, in words."""
    grows_before = grows_after = pairs = 0
    for name in STUDY:
        for region in ("R1", "R2"):
            r = [x for x in rows if x["robot"] == name and x["region"] == region]
            r.sort(key=lambda x: x["edge_mm"])
            for small, large in zip(r, r[1:]):
                pairs += 1
                grows_before += large["inside_global"][0] > small["inside_global"][0]
                grows_after += large["inside_local"][2] > small["inside_local"][2]
    local_better = sum(x["inside_local"][2] < x["inside_global"][2] for x in rows)
    rest_worse = sum(x["rest_local"][2] > x["rest_global"][2] for x in rows)
    return (f"seed's finding, errors larger in larger volumes: before {grows_before}/{pairs}, "
            f"after {grows_after}/{pairs} size steps; local calibration better than global "
            f"inside its volume in {local_better}/{len(rows)} volumes, worse in the rest of "
            f"the workspace in {rest_worse}/{len(rows)}")


if __name__ == "__main__":
    sys.exit(main())
