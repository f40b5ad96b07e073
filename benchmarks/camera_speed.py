"""Camera calibration speed against cv2.calibrateCamera on the same detected centres.

Run: python benchmarks/camera_speed.py [--views 20] [--seed 1] [--rounds 7] [--centres F.npz]
         [--baseline DIR]

The views are those of benchmarks/camera.py (1280 x 960 px, noise 2 grey levels, blur 0.8 px,
a 9 x 9 dot board 350-800 mm away, tilted 20-50 degrees), rendered and detected by the
project's detector once (saved to ``--centres``, default in the temporary folder keyed by
views and seed). Then, on one core (OMP/OPENBLAS threads 1, ``cv2.setNumThreads(1)``), the
contenders are timed in CPU time of the process (``time.process_time``), interleaved: each
round runs every contender once, in turn, so that load from other processes falls on all
alike; the table gives the median and the minimum over the rounds.

- OpenCV ``calibrateCamera`` (Zhang's start, then its Levenberg-Marquardt; 5 distortion
  coefficients) at its default termination (30 iterations, DBL_EPSILON) and at the
  (100, 1e-12) that benchmarks/camera.py uses;
- ours, the refinement alone (``camera.refine.refine`` from the RAC's start): on the block
  normal equations (Schur complement on the views' poses, the current code), and, for the
  A/B, the same problem on the dense Jacobian and ``calibration.lm`` (how it was solved
  before: one dense ``J^T J`` per Jacobian);
- ours, the whole ``calibrate``: the seed's RAC then the refinement, without and with the
  circle-centre correction (the default of ``olp-cal camera calibrate``; OpenCV has no
  such correction, it is the source of our smaller focal-length error).

Accuracy: errors of fx, fy, cx, cy against the truth (px), the reprojection RMS (px); the
refinement's two solvers must reach the same cost (printed); the circle-centre bias's
largest error over the views against polygons of 4096 and 8192 boundary points
extrapolated, next to the 256-point polygon's (the method before issue 32). Ratios: CPU against OpenCV at
its defaults, in the same run.

``--baseline DIR`` (an older package exported with ``git archive REV olp_compensate | tar -x
-C DIR``) instead times the whole calibrate of that tree and of this one in alternating
processes (each process: OpenCV, then ours without and with the correction), for the A/B
of the whole pipeline.

Target (issue 32): camera calibration from 20 views within 5x of cv2.calibrateCamera on the
same centres, accuracy kept.
"""

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from camera import BOARD, TRUTH, detect_all, rendered_views  # noqa: E402
from olp_compensate.calibration.lm import levenberg_marquardt  # noqa: E402
from olp_compensate.camera import rac  # noqa: E402
from olp_compensate.camera.calibrate import View, calibrate  # noqa: E402
from olp_compensate.camera.detect import circle_centre_bias  # noqa: E402
from olp_compensate.camera.refine import (N_INTRINSIC, N_POSE,  # noqa: E402
                                          intrinsics_from_vector, intrinsics_vector,
                                          project_with_jacobian, refine)
from olp_compensate.kinematics.conventions import rotvec_from_rotation  # noqa: E402

cv2.setNumThreads(1)


def centres(views: int, seed: int, path: Path) -> list:
    """Detected centres of ``views`` rendered views, from ``path`` or rendered and saved."""
    if path.exists():
        return list(np.load(path)["pixels"])
    images, _ = rendered_views(views, np.random.default_rng(seed), 1000 * seed)
    pixels, _ = detect_all(images)
    np.savez(path, pixels=np.array(pixels))
    return pixels


class Estimate:
    """A contender's intrinsics (fx, fy, cx, cy px) and reprojection RMS (px)."""

    def __init__(self, fx, fy, cx, cy, rms):
        self.fx, self.fy, self.cx, self.cy, self.rms = fx, fy, cx, cy, rms


def opencv(pixels, criteria):
    objects = [BOARD.dot_positions().astype(np.float32)] * len(pixels)
    images = [p.astype(np.float32).reshape(-1, 1, 2) for p in pixels]
    rms, K, _, _, _ = cv2.calibrateCamera(objects, images, (TRUTH.width, TRUTH.height), None,
                                          None, criteria=criteria)
    return Estimate(K[0, 0], K[1, 1], K[0, 2], K[1, 2], rms)


BIAS_SECONDS = []
"""CPU time spent in circle_centre_bias (detect.py) per corrected calibrate."""


def timed_bias(intrinsics, camera_T_board):
    begin = time.process_time()
    out = circle_centre_bias(intrinsics, camera_T_board, BOARD)
    BIAS_SECONDS[-1] += time.process_time() - begin
    return out


def ours(views, correct):
    bias = timed_bias if correct else None
    if correct:
        BIAS_SECONDS.append(0.0)
    cal = calibrate(views, TRUTH.width, TRUTH.height, centre_bias=bias)
    k = cal.intrinsics
    return Estimate(k.fx, k.fy, k.cx, k.cy, cal.rms_px)


def refined(result):
    k = result.intrinsics
    rss = sum(float(np.sum(r ** 2)) for r in result.residuals)
    return Estimate(k.fx, k.fy, k.cx, k.cy, np.sqrt(rss / (sum(len(r) for r in
                                                               result.residuals))))


def dense_refine(pixels, points, start, poses):
    """The refinement on the dense Jacobian and calibration.lm (the solver before the block
    one): same unknowns, residuals and analytic derivatives. Returns (Estimate, cost)."""
    obs = np.concatenate(pixels)
    pts = np.concatenate(points)
    view = np.repeat(np.arange(len(pixels)), [len(p) for p in pixels])
    m = 2 * len(obs)
    n = N_INTRINSIC + N_POSE * len(pixels)
    rows = np.arange(m)
    cols = N_INTRINSIC + N_POSE * np.repeat(view, 2)[:, None] + np.arange(N_POSE)
    x0 = np.concatenate([intrinsics_vector(start)] + [
        np.concatenate([rotvec_from_rotation(T[:3, :3]), T[:3, 3]]) for T in poses])

    def fun(x):
        ext = x[N_INTRINSIC:].reshape(-1, N_POSE)
        if x[0] <= 0 or x[1] <= 0:
            return np.full(m, np.inf), np.zeros((m, n))
        pix, d_intr, d_extr = project_with_jacobian(x[:N_INTRINSIC], ext[:, :3], ext[:, 3:],
                                                    pts, view)
        jac = np.zeros((m, n))
        jac[:, :N_INTRINSIC] = d_intr.reshape(m, N_INTRINSIC)
        jac[rows[:, None], cols] = d_extr.reshape(m, N_POSE)
        return (pix - obs).ravel(), jac

    result = levenberg_marquardt(fun, x0)
    np.linalg.inv(result.normal)            # its covariance, as the refinement gives one
    k = intrinsics_from_vector(result.x[:N_INTRINSIC], start)
    return Estimate(k.fx, k.fy, k.cx, k.cy, np.sqrt(2 * result.cost / len(obs))), result.cost


def child(pixels) -> None:
    """One process's medians (3 interleaved runs after a warm-up), ms, as JSON on stdout:
    OpenCV at its defaults and our calibrate without and with the correction."""
    views = [View(f"v{k}", p, BOARD.dot_positions()) for k, p in enumerate(pixels)]
    runs = {"opencv": lambda: opencv(pixels, (cv2.TERM_CRITERIA_COUNT
                                              + cv2.TERM_CRITERIA_EPS, 30, np.finfo(float).eps)),
            "detected": lambda: ours(views, False), "corrected": lambda: ours(views, True)}
    times = {label: [] for label in runs}
    fx = {label: run().fx for label, run in runs.items()}
    for _ in range(3):
        for label, run in runs.items():
            begin = time.process_time()
            run()
            times[label].append(time.process_time() - begin)
    print(json.dumps({label: [float(np.median(t)) * 1e3, fx[label] - TRUTH.fx]
                      for label, t in times.items()}))


def against_baseline(path: Path, baseline: Path, rounds: int) -> None:
    """Whole calibrations of an older tree and of this one, in alternating processes."""
    here = Path(__file__).resolve().parent.parent
    rows = {"baseline": [], "current": []}
    for _ in range(rounds):
        for name, tree in (("baseline", baseline), ("current", here)):
            env = dict(os.environ, PYTHONPATH=str(tree))
            out = subprocess.run([sys.executable, __file__, "--child", "--centres", str(path)],
                                 env=env, capture_output=True, text=True, check=True)
            rows[name].append(json.loads(out.stdout.strip().splitlines()[-1]))
    print(f"whole calibrate, {rounds} alternating processes of each tree (baseline "
          f"{baseline}); ms median of the processes' medians, ratio to OpenCV in the same "
          f"process, fx error px")
    for name, runs in rows.items():
        cells = []
        for label in ("opencv", "detected", "corrected"):
            ms = np.median([r[label][0] for r in runs])
            ratio = np.median([r[label][0] / r["opencv"][0] for r in runs])
            cells.append(f"{label} {ms:7.1f} ms {ratio:5.2f}x fx {runs[-1][label][1]:+.4f}")
        print(f"{name:<9} " + " | ".join(cells))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--centres", type=Path, default=None)
    parser.add_argument("--baseline", type=Path, default=None,
                        help="a folder holding an older olp_compensate package (git archive "
                             "REV olp_compensate | tar -x -C DIR): whole calibrations of it "
                             "and of this tree in alternating processes")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    path = args.centres or (Path(tempfile.gettempdir())
                            / f"olp_camera_speed_{args.views}_{args.seed}.npz")
    pixels = centres(args.views, args.seed, path)
    if args.child:
        return child(pixels)
    if args.baseline:
        return against_baseline(path, args.baseline, args.rounds)
    side_by_side(pixels, args.rounds)


def side_by_side(pixels, rounds: int) -> None:
    """The table of the module docstring."""
    points = [BOARD.dot_positions()] * len(pixels)
    views = [View(f"v{k}", p, points[0]) for k, p in enumerate(pixels)]
    start = rac.rac_calibrate(pixels, points, TRUTH.width, TRUTH.height)
    block_cost = []

    def block():
        result = refine(pixels, points, start.intrinsics, start.camera_T_board)
        block_cost.append(sum(float(np.sum(r ** 2)) for r in result.residuals) / 2)
        return refined(result)

    dense_cost = []

    def dense():
        estimate, cost = dense_refine(pixels, points, start.intrinsics, start.camera_T_board)
        dense_cost.append(cost)
        return estimate

    contenders = [
        ("OpenCV calibrateCamera, default criteria (30, eps)",
         lambda: opencv(pixels, (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 30,
                                 np.finfo(float).eps))),
        ("OpenCV calibrateCamera, criteria (100, 1e-12)",
         lambda: opencv(pixels, (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100,
                                 1e-12))),
        ("ours: refinement alone, block normal + Schur", block),
        ("ours: refinement alone, dense J^T J (before)", dense),
        ("ours: RAC + refinement, centres as detected", lambda: ours(views, False)),
        ("ours: RAC + refinement + circle correction", lambda: ours(views, True)),
    ]
    times = {label: [] for label, _ in contenders}
    results = {}
    for label, run in contenders:           # warm-up (imports, caches)
        results[label] = run()
    for _ in range(rounds):
        for label, run in contenders:
            begin = time.process_time()
            run()
            times[label].append(time.process_time() - begin)
    peer = np.median(times[contenders[0][0]])
    print(f"{len(pixels)} views of {len(points[0])} dots, {rounds} interleaved rounds, one "
          f"core, CPU time of the process")
    print(f"truth: fx {TRUTH.fx:g} fy {TRUTH.fy:g} cx {TRUTH.cx:g} cy {TRUTH.cy:g} px")
    print(f"{'contender':<52} {'median ms':>9} {'min ms':>7} {'x OpenCV':>8} | {'dfx':>7} "
          f"{'dfy':>7} {'dcx':>7} {'dcy':>7} {'rms px':>7}")
    for label, _ in contenders:
        t, e = np.array(times[label]), results[label]
        print(f"{label:<52} {np.median(t) * 1e3:9.1f} {np.min(t) * 1e3:7.1f} "
              f"{np.median(t) / peer:8.2f} | {e.fx - TRUTH.fx:7.3f} {e.fy - TRUTH.fy:7.3f} "
              f"{e.cx - TRUTH.cx:7.3f} {e.cy - TRUTH.cy:7.3f} {e.rms:7.4f}")
    print(f"refinement cost (half the sum of squares, px^2): block {block_cost[-1]:.12g}, "
          f"dense {dense_cost[-1]:.12g} (relative difference "
          f"{abs(block_cost[-1] - dense_cost[-1]) / dense_cost[-1]:.1e})")
    print(f"of the circle correction's calibrate, in circle_centre_bias (camera/detect.py, "
          f"3 passes x {len(pixels)} views): {np.median(BIAS_SECONDS[-rounds:]) * 1e3:.1f}"
          f" ms median")
    print("rms px: RMS over all dots of the distance between projected and detected centre "
          "(OpenCV's own figure; ours for calibrate on the corrected centres when corrected)")
    bias_accuracy(views)


def bias_accuracy(views) -> None:
    """Largest error (px) of circle_centre_bias over the views, at the corrected
    calibration's intrinsics and poses, against the centroid of polygons of 4096 and 8192
    projected boundary points extrapolated (Richardson, error O(1/n^4)); next to it the
    256-point polygon's (the method before issue 32). Imported here: ``--baseline`` runs
    this script's children on older trees, which have no polygon_centre_bias."""
    from olp_compensate.camera.centres import polygon_centre_bias

    cal = calibrate(views, TRUTH.width, TRUTH.height,
                    centre_bias=lambda k, T: circle_centre_bias(k, T, BOARD))
    worst = {"quadrature": 0.0, "polygon 256": 0.0, "polygon 4096": 0.0}
    for view in cal.views:
        k, T = cal.intrinsics, view.camera_T_board
        fine = polygon_centre_bias(k, T, BOARD, 4096)
        reference = (4 * polygon_centre_bias(k, T, BOARD, 8192) - fine) / 3
        for label, value in (("quadrature", circle_centre_bias(k, T, BOARD)),
                             ("polygon 256", polygon_centre_bias(k, T, BOARD, 256)),
                             ("polygon 4096", fine)):
            worst[label] = max(worst[label], float(np.abs(value - reference).max()))
    print("circle_centre_bias against the extrapolated 4096/8192-point polygons, largest "
          "error over the views (px): " + ", ".join(f"{label} {value:.1e}"
                                                    for label, value in worst.items()))


if __name__ == "__main__":
    main()
