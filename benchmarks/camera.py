"""The camera against its peer, and a robot identified from camera views.

Run: python benchmarks/camera.py [--seed S] [--skip-robot] [--renderings 2:0.8,6:0.8,...]
         [--noise G --blur PX]   (one core: set below)

Part 1, on rendered views (1280 x 960 px, uneven light, the camera 350-800 mm from the
board and tilted 20-50 degrees, a 9 x 9 board of 25 mm pitch), once per rendering of
``--renderings`` (noise grey levels : blur px; default noise 2, 6, 2, 6 with blur 0.8, 0.8,
1.5, 1.5; ``--noise``/``--blur`` give one): 20 views calibrate, 20 other views are
measured. Side by side:

- ours: the seed's RAC then the full refinement, with the circle-centre correction (the
  default of ``olp-cal camera calibrate``), on our default centres (edge-weighted,
  ``detect_dots``); the same on the darkness-weighted centroids (``method="darkness"``,
  the default before issue 33); without that correction; RAC only;
- OpenCV: ``cv2.calibrateCamera`` (Zhang, 5 distortion coefficients) then ``cv2.solvePnP``
  on our centres; and OpenCV's whole pipeline: the same on its own centres
  (``cv2.findCirclesGrid`` with ``SimpleBlobDetector``), views it does not find left out.

Paired on the new views both find: OpenCV's pipeline's position error over ours, median,
and on how many views ours is the more accurate; a last table puts the renderings side by
side.

Errors against the truth: focal lengths and centre (px); the distortion, whose models
differ (ours distorted -> undistorted, OpenCV's undistorted -> distorted), compared through
the truth's distortion field: rays of a 33 x 25 pixel grid of the true camera are projected
by each estimate, px RMS and max; the pose of each new view (position mm, rotation deg, and
"1:N" = distance to the board's centre / position error, as the seed's section 9 states its
figure: median and worst). Times: calibration from 20 views, detection in views per second.

Part 2: a virtual IRB 2400 with the camera on its flange, identified from 40 camera views
(calibrate the camera from 20 views; 40 random poses that see the board well; render,
detect, measure, identify with full-pose rows; ``--candidates-per-pose K``: the 40 the pose
planner picks among 40 K):
the camera centre predicted at 1,000 new poses over the workspace against the truth, RMS and
max, beside the nominal model (only the board's place and the camera mount identified).

Targets: our median better than 1:20,000 of the distance and every view better than
1:3,000; at least as accurate as OpenCV; calibration from 20 views under 2 s; detection 20+
views per second; the camera centre within 0.05 mm RMS where the nominal model misses by
millimetres.
"""

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass, replace  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from olp_compensate.calibration.identify import IdentificationOptions, identify  # noqa: E402
from olp_compensate.calibration.measurements import Measurements  # noqa: E402
from olp_compensate.calibration.simulate import random_joints  # noqa: E402
from olp_compensate.camera.board import Board  # noqa: E402
from olp_compensate.camera.calibrate import View, calibrate  # noqa: E402
from olp_compensate.camera.campaign import (CAMERA_TOOL, board_centre,  # noqa: E402
                                            make_camera_robot, plan_campaign, render_view)
from olp_compensate.camera.detect import circle_centre_bias, detect_dots  # noqa: E402
from olp_compensate.camera.measure import measure_pose  # noqa: E402
from olp_compensate.camera.model import CameraIntrinsics  # noqa: E402
from olp_compensate.camera.render import RenderOptions, random_views, render_board  # noqa: E402
from olp_compensate.kinematics.conventions import (invert_pose,  # noqa: E402
                                                   rotation_angle_between,
                                                   rotation_from_rotvec)
from olp_compensate.kinematics.robot import load_robot  # noqa: E402

cv2.setNumThreads(1)

TRUTH = CameraIntrinsics(fx=1500.0, mu=1.0, cx=645.5, cy=477.0, k1=0.12, k2=-0.05,
                         width=1280, height=960)
BOARD = Board(rows=9, cols=9, pitch_m=0.025, dot_diameter_m=0.006, marker_diameter_m=0.01)
RENDER = RenderOptions(supersample=8, noise_sigma=2.0, blur_sigma_px=0.8, gradient=0.3,
                       vignetting=0.15)
DISTANCE_M, TILT_DEG = (0.35, 0.8), (20.0, 50.0)


def rendered_views(count: int, rng, seed: int):
    """(images, true camera_T_board) of ``count`` random views."""
    poses = random_views(BOARD, TRUTH, count, rng, DISTANCE_M, TILT_DEG, margin_px=15.0)
    images = [render_board(BOARD, TRUTH, T, replace(RENDER, seed=seed + k))
              for k, T in enumerate(poses)]
    return images, poses


def detect_all(images, method="centroid"):
    """Detected centres of every image (all must be found), and views per second."""
    start = time.perf_counter()
    found = [detect_dots(image, BOARD, f"view{k}", method) for k, image in enumerate(images)]
    rate = len(images) / (time.perf_counter() - start)
    failed = [f for f in found if not f.ok]
    if failed:
        raise SystemExit(f"detection failed: {failed[0].name}: {failed[0].reason}")
    return [f.pixels for f in found], rate


def opencv_centres(images, ours):
    """OpenCV's own dot centres (cv2.findCirclesGrid's blob centres), put in the order of
    our detection (a square symmetric grid comes back turned by any quarter turn); None for
    a view it does not find."""
    params = cv2.SimpleBlobDetector_Params()
    params.maxArea = TRUTH.width * TRUTH.height / BOARD.count
    detector = cv2.SimpleBlobDetector_create(params)
    out = []
    for image, pixels in zip(images, ours):
        found, centres = cv2.findCirclesGrid(image, (BOARD.cols, BOARD.rows),
                                             flags=cv2.CALIB_CB_SYMMETRIC_GRID,
                                             blobDetector=detector)
        if not found:
            out.append(None)
            continue
        centres = centres.reshape(-1, 2).astype(float)
        nearest = np.argmin(np.linalg.norm(pixels[:, None] - centres[None], axis=2), axis=1)
        out.append(centres[nearest] if len(set(nearest.tolist())) == BOARD.count else None)
    return out


# -- the estimates ---------------------------------------------------------------------------

class Ours:
    """Our calibration; poses by :func:`measure_pose`."""

    def __init__(self, label, pixels, method="rac", correct=True):
        self.label = label
        self.bias = (lambda k, T: circle_centre_bias(k, T, BOARD)) if correct else None
        views = [View(f"v{k}", p, BOARD.dot_positions()) for k, p in enumerate(pixels)]
        start = time.perf_counter()
        self.intrinsics = calibrate(views, TRUTH.width, TRUTH.height, method=method,
                                    centre_bias=self.bias).intrinsics
        self.seconds = time.perf_counter() - start
        k = self.intrinsics
        self.fx, self.fy, self.cx, self.cy = k.fx, k.fy, k.cx, k.cy

    def project_rays(self, rays):
        k = self.intrinsics
        return k.pixels_from_normalized(k.distort_normalized(rays))

    def board_T_camera(self, pixels):
        return measure_pose(pixels, BOARD.dot_positions(), self.intrinsics,
                            centre_bias=self.bias).board_T_camera


class OpenCV:
    """cv2.calibrateCamera (Zhang) and cv2.solvePnP on the same detected centres."""

    label = "OpenCV calibrateCamera + solvePnP"

    def __init__(self, pixels, label=None):
        self.label = label or self.label
        objects = [BOARD.dot_positions().astype(np.float32)] * len(pixels)
        images = [p.astype(np.float32).reshape(-1, 1, 2) for p in pixels]
        start = time.perf_counter()
        _, self.K, self.dist, _, _ = cv2.calibrateCamera(
            objects, images, (TRUTH.width, TRUTH.height), None, None,
            criteria=(cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12))
        self.seconds = time.perf_counter() - start
        self.fx, self.fy = self.K[0, 0], self.K[1, 1]
        self.cx, self.cy = self.K[0, 2], self.K[1, 2]

    def project_rays(self, rays):
        points = np.column_stack([rays, np.ones(len(rays))])
        pix, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), self.K, self.dist)
        return pix.reshape(-1, 2)

    def board_T_camera(self, pixels):
        ok, rvec, tvec = cv2.solvePnP(BOARD.dot_positions(), pixels.reshape(-1, 1, 2),
                                      self.K, self.dist, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            raise SystemExit("solvePnP failed")
        camera_T_board = np.eye(4)
        camera_T_board[:3, :3] = rotation_from_rotvec(rvec.ravel())
        camera_T_board[:3, 3] = tvec.ravel()
        return invert_pose(camera_T_board)


def distortion_field_error(estimate) -> tuple[float, float]:
    """RMS and max px: the true rays of a pixel grid projected by the estimate."""
    X, Y = np.meshgrid(np.linspace(0, TRUTH.width - 1, 33), np.linspace(0, TRUTH.height - 1, 25))
    pixels = np.column_stack([X.ravel(), Y.ravel()])
    d = np.hypot(*(estimate.project_rays(TRUTH.rays(pixels)) - pixels).T)
    return float(np.sqrt(np.mean(d ** 2))), float(np.max(d))


def pose_errors(estimate, pixels, poses):
    """Per new view: position error mm, rotation error deg, distance / position error."""
    centre = np.append(board_centre(BOARD), 1.0)
    out = []
    for p, camera_T_board in zip(pixels, poses):
        truth = invert_pose(camera_T_board)
        measured = estimate.board_T_camera(p)
        position = np.linalg.norm(measured[:3, 3] - truth[:3, 3])
        angle = math.degrees(rotation_angle_between(measured[:3, :3], truth[:3, :3]))
        distance = np.linalg.norm((camera_T_board @ centre)[:3])
        out.append((position * 1e3, angle, distance / position))
    return np.array(out)


@dataclass(frozen=True)
class Row:
    """One estimate on one rendering: per new view position error mm, rotation error deg
    and 1:N (n, 3), and the indices (n,) of those views among the 20."""

    label: str
    errors: np.ndarray
    views: np.ndarray


def camera_part(seed: int) -> dict[str, Row]:
    """Part 1 on the current RENDER; prints its table, returns the rows by label."""
    rng = np.random.default_rng(seed)
    cal_images, _ = rendered_views(20, rng, 1000 * seed)
    new_images, new_poses = rendered_views(20, rng, 1000 * seed + 500)
    cal_pixels, rate = detect_all(cal_images)
    new_pixels, rate2 = detect_all(new_images)
    cal_dark, _ = detect_all(cal_images, "darkness")
    new_dark, _ = detect_all(new_images, "darkness")
    estimates = [(Ours(OURS, cal_pixels), new_pixels),
                 (Ours(DARK, cal_dark), new_dark),
                 (Ours("ours: RAC + refinement, centres as detected", cal_pixels,
                       correct=False), new_pixels),
                 (Ours("ours: RAC only (the seed) + circle correction", cal_pixels,
                       "rac-only"), new_pixels),
                 (OpenCV(cal_pixels), new_pixels)]
    own_cal = [p for p in opencv_centres(cal_images, cal_pixels) if p is not None]
    own_new = opencv_centres(new_images, new_pixels)
    kept = np.array([k for k, p in enumerate(own_new) if p is not None])
    own = OpenCV(own_cal, f"{OWN}: {len(own_cal)}+{len(kept)} views found")
    estimates.append((own, own_new))
    print(f"rendering: noise {RENDER.noise_sigma:g} grey levels, blur {RENDER.blur_sigma_px:g} "
          f"px; truth: fx {TRUTH.fx:g} fy {TRUTH.fy:g} cx {TRUTH.cx:g} cy {TRUTH.cy:g} px, k1 "
          f"{TRUTH.k1:g} k2 {TRUTH.k2:g}; {TRUTH.width} x {TRUTH.height} px; 20 calibration "
          f"views, 20 new views, seed {seed}")
    print(f"{'estimate':<48} {'dfx':>7} {'dfy':>7} {'dcx':>7} {'dcy':>7} {'dist rms':>8} "
          f"{'max':>6} | {'pos med':>7} {'worst':>7} {'rot med':>7} {'worst':>7} "
          f"{'1:N med':>8} {'worst':>7} | {'cal s':>6}")
    print(f"{'':<48} {'px':>7} {'px':>7} {'px':>7} {'px':>7} {'px':>8} {'px':>6} | "
          f"{'mm':>7} {'mm':>7} {'deg':>7} {'deg':>7} {'':>8} {'':>7} |")
    rows = {}
    for e, pixels in estimates:
        rms, worst = distortion_field_error(e)
        views = kept if e is own else np.arange(len(new_poses))
        err = pose_errors(e, [pixels[k] for k in views], [new_poses[k] for k in views])
        rows[OWN if e is own else e.label] = Row(e.label, err, views)
        print(f"{e.label:<48} {e.fx - TRUTH.fx:7.3f} {e.fy - TRUTH.fy:7.3f} "
              f"{e.cx - TRUTH.cx:7.3f} {e.cy - TRUTH.cy:7.3f} {rms:8.3f} {worst:6.3f} | "
              f"{np.median(err[:, 0]):7.4f} {np.max(err[:, 0]):7.4f} "
              f"{np.median(err[:, 1]):7.4f} {np.max(err[:, 1]):7.4f} "
              f"{np.median(err[:, 2]):8,.0f} {np.min(err[:, 2]):7,.0f} | {e.seconds:6.2f}")
    for label in (DARK, OWN):
        ratio, better, count = paired(rows[label], rows[OURS])
        print(f"paired, {label} against ours: its position error / ours median {ratio:.2f}, "
              f"ours better on {better} of {count} views")
    print(f"detection: {rate:.1f} and {rate2:.1f} views per second at {TRUTH.width} x "
          f"{TRUTH.height} px on one core (two batches of 20)\n")
    return rows


OURS = "ours: RAC + refinement + circle correction"
DARK = "ours, darkness centroids (before issue 33)"
OWN = "OpenCV's own pipeline"


def paired(other: Row, ours: Row) -> tuple[float, int, int]:
    """On the new views both measured: median of other's position error over ours, the
    number of views where ours is smaller, and the number of views."""
    common, i, j = np.intersect1d(other.views, ours.views, return_indices=True)
    ratio = other.errors[i, 0] / ours.errors[j, 0]
    return float(np.median(ratio)), int(np.sum(ratio > 1)), len(common)


def summary(results: list[tuple[RenderOptions, dict[str, Row]]]) -> None:
    """The renderings side by side: 1:N median / worst view, and the paired figures."""
    def cell(row):
        return f"1:{np.median(row.errors[:, 2]):,.0f} / 1:{np.min(row.errors[:, 2]):,.0f}"

    print("side by side (1:N of the distance, median / worst new view; paired: OpenCV's "
          "pipeline's error / ours, median, and views where ours is better)")
    print(f"{'rendering':<22} {'ours':>22} {'ours, darkness centr.':>22} "
          f"{'OpenCV, our centres':>22} {'OpenCV own pipeline':>22} {'paired':>16}")
    for render, rows in results:
        ratio, better, count = paired(rows[OWN], rows[OURS])
        print(f"{f'noise {render.noise_sigma:g}, blur {render.blur_sigma_px:g} px':<22} "
              f"{cell(rows[OURS]):>22} {cell(rows[DARK]):>22} "
              f"{cell(rows[OpenCV.label]):>22} {cell(rows[OWN]):>22} "
              f"{f'{ratio:.2f}x, {better}/{count}':>16}")


# -- the robot -------------------------------------------------------------------------------

def robot_part(seed: int, candidates_per_pose: int = 1) -> None:
    robot = load_robot("abb_irb2400")
    rng = np.random.default_rng(100 + seed)
    cal_images, _ = rendered_views(20, rng, 7000 + seed)
    cal_pixels, _ = detect_all(cal_images)
    camera = Ours("ours", cal_pixels)
    virtual = make_camera_robot(robot, BOARD, seed=seed)
    campaign = plan_campaign(virtual, BOARD, TRUTH, 40, np.random.default_rng(200 + seed),
                             candidates_per_pose=candidates_per_pose)
    measured = []
    for k in range(40):
        found = detect_dots(render_view(campaign, k, replace(RENDER, seed=9000 + seed)), BOARD)
        if not found.ok:
            raise SystemExit(f"campaign view {k}: {found.reason}")
        measured.append(measure_pose(found.pixels, BOARD.dot_positions(), camera.intrinsics,
                                     centre_bias=camera.bias))
    n = len(measured)
    meas = Measurements(joints=campaign.joints,
                        points=np.array([m.board_T_camera[:3, 3] for m in measured]),
                        pose_ids=np.array([str(k + 1) for k in range(n)], dtype=object),
                        point_names=np.array([CAMERA_TOOL] * n, dtype=object),
                        orientation=np.array([m.quat_wxyz for m in measured]),
                        source="<camera campaign>")
    options = IdentificationOptions(
        folds=0, position_sigma_mm=float(np.median([m.sigma_mm for m in measured])),
        orientation_sigma_deg=float(np.median([m.sigma_deg for m in measured])))
    start = time.perf_counter()
    result = identify(robot, meas, options)
    seconds = time.perf_counter() - start
    nominal = identify(robot, meas, replace(options, freeze=tuple(
        result.calibration.model.names))).calibration
    test = random_joints(robot, 1000, np.random.default_rng(300 + seed))
    names = [CAMERA_TOOL] * len(test)
    truth = virtual.true_frames(test, names)
    truth_at_views = invert_pose(campaign.camera_T_board)
    view_error = np.array([np.linalg.norm(m.board_T_camera[:3, 3] - t[:3, 3])
                           for m, t in zip(measured, truth_at_views)]) * 1e3
    print(f"IRB 2400 (seed {seed}) with the camera on its flange, 40 views "
          f"{DISTANCE_M[0] * 1e3:.0f}-{DISTANCE_M[1] * 1e3:.0f} mm from the board: camera "
          f"centre measured to {np.median(view_error):.4f} mm median, "
          f"{np.max(view_error):.4f} mm max; identified in {seconds:.2f} s")
    for label, cal in (("identified", result.calibration),
                       ("nominal (board place and camera mount only)", nominal)):
        e = np.linalg.norm(cal.predict_points(test, names) - truth[:, :3, 3], axis=1) * 1e3
        a = np.degrees(rotation_angle_between(cal.predict_rotations(test, names),
                                              truth[:, :3, :3]))
        print(f"  {label:<45} camera centre at 1,000 new poses: RMS {np.sqrt(np.mean(e**2)):.4f}"
              f" mm, max {np.max(e):.4f} mm; camera axes RMS {np.sqrt(np.mean(a**2)):.4f} deg")


def main() -> None:
    global RENDER
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--skip-robot", action="store_true")
    parser.add_argument("--skip-camera", action="store_true")
    parser.add_argument("--candidates-per-pose", type=int, default=1)
    parser.add_argument("--renderings", default="2:0.8,6:0.8,2:1.5,6:1.5",
                        help="noise grey levels : blur px, comma-separated (default "
                             "2:0.8,6:0.8,2:1.5,6:1.5; the robot part uses the first)")
    parser.add_argument("--noise", type=float, help="one rendering: image noise, grey levels")
    parser.add_argument("--blur", type=float, help="one rendering: Gaussian blur, px")
    args = parser.parse_args()
    if args.noise is not None or args.blur is not None:
        renderings = [(RENDER.noise_sigma if args.noise is None else args.noise,
                       RENDER.blur_sigma_px if args.blur is None else args.blur)]
    else:
        renderings = [tuple(float(v) for v in item.split(":"))
                      for item in args.renderings.split(",")]
    base = RENDER
    results = []
    if not args.skip_camera:
        for noise, blur in renderings:
            RENDER = replace(base, noise_sigma=noise, blur_sigma_px=blur)
            results.append((RENDER, camera_part(args.seed)))
        summary(results)
    if not args.skip_robot:
        RENDER = replace(base, noise_sigma=renderings[0][0], blur_sigma_px=renderings[0][1])
        print(f"rendering: noise {RENDER.noise_sigma:g} grey levels, blur "
              f"{RENDER.blur_sigma_px:g} px")
        robot_part(args.seed, args.candidates_per_pose)


if __name__ == "__main__":
    main()
