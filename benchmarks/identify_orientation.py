"""Full-pose rows against position-only rows on virtual robots (one measured point per pose).

Run: python benchmarks/identify_orientation.py   (one core: OMP_NUM_THREADS=1 is set below)

For an ABB IRB 2400 with noise 0.05 mm per axis and 0.01 degree per axis, identifies each
virtual robot twice from the same poses, once from the positions only and once with the
measured orientation of the tool frame, and prints the RMS error against the truth at 1,000
new poses: position of the tool point (mm) for both, and the orientation of the tool frame
(deg) for the full-pose fit (a position-only fit does not know the tool's rotation).
"""

import os
from dataclasses import replace

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from olp_compensate.kinematics.conventions import rotation_angle_between  # noqa: E402
from olp_compensate.calibration.identify import IdentificationOptions, identify  # noqa: E402
from olp_compensate.kinematics.robot import load_robot  # noqa: E402
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints  # noqa: E402

NOISE = 0.05e-3
ORIENTATION_NOISE = np.radians(0.01)
ROBOT = load_robot("abb_irb2400")


def errors(poses: int, seeds=range(5)) -> tuple[float, float, float]:
    """(position-only position RMS, full-pose position RMS, full-pose orientation RMS), m, m,
    rad, over 1,000 new poses of each of the robots."""
    position_only, full_pose, angle = [], [], []
    options = IdentificationOptions(folds=0)
    for seed in seeds:
        virtual = make_virtual_robot(ROBOT, seed)
        rng = np.random.default_rng(1000 + seed)
        meas = virtual.measure(random_joints(ROBOT, poses, rng), NOISE, rng,
                               orientation_noise_rad=ORIENTATION_NOISE)
        without = identify(ROBOT, replace(meas, orientation=None), options).calibration
        with_ = identify(ROBOT, meas, options).calibration
        test = random_joints(ROBOT, 1000, np.random.default_rng(5000 + seed))
        names = ["tcp"] * len(test)
        truth = virtual.true_frames(test, names)
        for cal, out in ((without, position_only), (with_, full_pose)):
            diff = cal.predict_points(test, names) - truth[:, :3, 3]
            out.append(np.sum(diff**2, axis=1))
        angle.append(rotation_angle_between(with_.predict_rotations(test, names),
                                            truth[:, :3, :3]) ** 2)
    return tuple(float(np.sqrt(np.mean(np.concatenate(e)))) for e in (position_only, full_pose, angle))


def main() -> None:
    print(f"IRB 2400, one point per pose, noise {NOISE * 1e3} mm and "
          f"{np.degrees(ORIENTATION_NOISE):.3f} deg per axis; RMS error at 1,000 new poses "
          f"(5 robots):")
    for poses in (15, 30):
        pos_only, full, angle = errors(poses)
        print(f"  {poses:>3} poses: position-only {pos_only * 1e3:.4f} mm, with orientation "
              f"{full * 1e3:.4f} mm ({pos_only / full:.2f}x lower), tool-frame orientation "
              f"{np.degrees(angle):.4f} deg")


if __name__ == "__main__":
    main()
