"""The compensating RoboDK post against the uncompensated one plus the library's solve,
measured side by side in one run.

A 1,000-target program (``--targets``), generated as RoboDK's script drives a post
(``ProgStart``, ``setFrame``, ``setTool``, ``MoveJ``/``MoveL`` with ``robodk.robomath``
poses in mm and joints in degrees, ``ProgFinish``, ``ProgSave``), through the vendor-like
RAPID post of the tests (``tests/robodk_posts/vendor_abb.py``):

- ``plain``: the vendor post alone;
- ``library``: ``compensate_poses`` of the same targets in one batch (what compensation
  costs at least);
- ``wrapped``: ``compensated(VendorPost, calibration=...)`` (its construction, reading
  calib.json and fitting the closed form, included; ``set-up`` is that construction
  alone, printed too);

best of ``--repeats`` (default 5), interleaved. Prints the times and wrapped / (plain +
library) (target <= 1.5), and, for reference, the library one target at a time (what a post
that solved each target as RoboDK passes it would cost).

Run: ``python benchmarks/robodk_post.py [--targets 1000] [--repeats 5]``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "robodk_posts"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from vendor_abb import RobotPost as VendorPost  # noqa: E402


def scene(comp, count: int, rng):
    """(frame, tool, [(pose Mat mm, joints deg, conf_RLF)]) reached by the calibrated arm."""
    from robodk.robomath import Mat

    from service import make_poses

    frame = np.array([[0, -1, 0, 300.0], [1, 0, 0, -100.0], [0, 0, 1, 200.0], [0, 0, 0, 1]])
    tool = np.array([[1, 0, 0, 50.0], [0, 1, 0, 0], [0, 0, 1, 150.0], [0, 0, 0, 1]])
    poses = make_poses(comp, count, rng, frames=True)
    robot = comp.robot
    targets = []
    for p in poses:
        target = np.array(p["target"])
        base_T_flange = np.array(p["wobj"]) @ target @ np.linalg.inv(np.array(p["tool"]))
        base_T_flange[:3, 3] *= 1e-3
        q = comp.solve_nominal(base_T_flange[None], np.array([p["config"]]))[0]
        joints = robot.to_degrees_or_mm(robot.controller_from_joints(q[None]))[0].tolist()
        wobj_T_target = np.linalg.inv(frame) @ np.array(p["wobj"]) @ target \
            @ np.linalg.inv(np.array(p["tool"])) @ tool
        targets.append((Mat(wobj_T_target.tolist()), joints, [0, 0, int(joints[4] < 0)]))
    return Mat(frame.tolist()), Mat(tool.tolist()), targets


def generate(post_class, folder: Path, frame, tool, targets) -> float:
    """Seconds to make the program as RoboDK's script does (the post built first)."""
    started = time.perf_counter()
    r = post_class("ABB_RAPID", "ABB IRB 2400", 6, axes_type=["R"] * 6)
    r.ProgStart("Prog1")
    r.setFrame(frame, 1, "Frame 2")
    r.setTool(tool, 1, "tGun")
    r.setSpeed(250.0)
    r.setZoneData(5.0)
    for k, (pose, joints, conf) in enumerate(targets):
        (r.MoveJ if k == 0 else r.MoveL)(pose, joints, conf)
    r.ProgFinish("Prog1")
    r.ProgSave(str(folder), "Prog1", False)
    return time.perf_counter() - started


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    from olp_compensate import Compensator, compensate_pose, compensate_poses, read_calibration
    from olp_compensate.robodk import compensated

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        calib = folder / "calib.json"
        subprocess.run([sys.executable, "-m", "olp_compensate.cli.cal", "identify",
                        str(ROOT / "samples" / "irb2400_measurements.csv"), "--robot",
                        "abb_irb2400", "-o", str(calib)], check=True, capture_output=True)
        comp = Compensator(read_calibration(calib))
        frame, tool, targets = scene(comp, args.targets, np.random.default_rng(1))
        wrapped_class = compensated(VendorPost, calibration=calib)
        arrays = [np.array(t[0].rows) for t in targets]
        wobj_T_target = np.array(arrays)
        wobj_T_target[:, :3, 3] *= 1e-3
        tool_m, frame_m = np.array(tool.rows), np.array(frame.rows)
        tool_m[:3, 3] *= 1e-3
        frame_m[:3, 3] *= 1e-3
        best = {"plain": np.inf, "library": np.inf, "wrapped": np.inf, "set-up": np.inf}
        problems = 0
        for _ in range(args.repeats):
            best["plain"] = min(best["plain"], generate(VendorPost, folder, frame, tool,
                                                        targets))
            started = time.perf_counter()
            batch = compensate_poses(comp, wobj_T_target, tool_m, frame_m)
            best["library"] = min(best["library"], time.perf_counter() - started)
            best["wrapped"] = min(best["wrapped"], generate(wrapped_class, folder, frame,
                                                            tool, targets))
            problems = int(np.sum(~batch.success))
            started = time.perf_counter()
            wrapped_class("ABB_RAPID", "ABB IRB 2400", 6)      # reads calib.json, fits
            best["set-up"] = min(best["set-up"], time.perf_counter() - started)
        started = time.perf_counter()
        for k in range(min(100, len(targets))):
            compensate_pose(comp, wobj_T_target[k], tool_m, frame_m)
        one_by_one = (time.perf_counter() - started) / min(100, len(targets)) * len(targets)
    n = len(targets)
    print(f"{n} targets, best of {args.repeats}:")
    for key in best:
        print(f"  {key:8s} {best[key]:7.3f} s  {best[key] / n * 1e6:8.1f} us/target")
    ratio = best["wrapped"] / (best["plain"] + best["library"])
    print(f"  wrapped / (plain + library) = {ratio:.2f} (target <= 1.5); without the "
          f"wrapper's set-up (its post built: calib.json read, closed form fitted) "
          f"{(best['wrapped'] - best['set-up']) / (best['plain'] + best['library']):.2f}")
    print(f"  for reference: the library one target at a time {one_by_one:.3f} s "
          f"({one_by_one / n * 1e6:.0f} us/target); targets not compensated: {problems}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
