"""Dot detection speed and accuracy on rendered 1280 x 960 views, on one core.

Run: python benchmarks/detect_speed.py [--count 30] [--seed 1] [--runs 5]
         [--baseline OLD_DETECT.py] [--images CACHE.npz]

The views (board, camera and lighting of benchmarks/camera.py) are rendered once and saved
to ``--images`` (default in the temporary folder, keyed by count and seed), with the truth
of every dot: its projected centre plus :func:`circle_centre_bias` (the centroid of the
area of its image, what the detector measures). Two sets of ``--count`` views each:

- noisy: blur 0.8 px, noise 2 grey levels, light gradient 0.3, vignetting 0.15, clutter
  around the sheet (the speed target is measured on these);
- clean: no blur, no noise, even light, plain background.

Every run is a new process (one core: OMP/OPENBLAS threads 1, ``cv2.setNumThreads(1)``)
that loads the saved images, detects one view to warm up and then all views of both sets,
and reports the CPU time (``time.process_time``) per view of each set and the RMS error
(px) of all dots against the truth. With ``--baseline FILE`` (a copy of an older
``olp_compensate/camera/detect.py``, e.g. from ``git show REV:olp_compensate/camera/detect.py``)
runs alternate baseline, current, baseline, current ... so that load from other processes
falls on both alike; the table gives min and median over the runs.

Target: 20+ noisy views per second (50 ms CPU per view) with accuracy no worse than before.
"""

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from olp_compensate.camera.board import Board  # noqa: E402
from olp_compensate.camera.model import CameraIntrinsics, project_points  # noqa: E402

TRUTH = CameraIntrinsics(fx=1500.0, mu=1.0, cx=645.5, cy=477.0, k1=0.12, k2=-0.05,
                         width=1280, height=960)
BOARD = Board(rows=9, cols=9, pitch_m=0.025, dot_diameter_m=0.006, marker_diameter_m=0.01)
DISTANCE_M, TILT_DEG = (0.35, 0.8), (20.0, 50.0)
SETS = ("noisy", "clean")


def _render_options():
    from olp_compensate.camera.render import RenderOptions

    noisy = RenderOptions(supersample=8, noise_sigma=2.0, blur_sigma_px=0.8, gradient=0.3,
                          vignetting=0.15, clutter=True)
    return {"noisy": noisy, "clean": RenderOptions(supersample=8)}


def render_cache(path: Path, count: int, seed: int) -> None:
    """Render both sets of ``count`` views and save images and truth to ``path`` (.npz)."""
    from olp_compensate.camera.detect import circle_centre_bias
    from olp_compensate.camera.render import random_views, render_board

    rng = np.random.default_rng(seed)
    arrays = {}
    for k, (label, options) in enumerate(_render_options().items()):
        poses = random_views(BOARD, TRUTH, count, rng, DISTANCE_M, TILT_DEG, margin_px=15.0)
        arrays[f"{label}_images"] = np.stack([
            render_board(BOARD, TRUTH, T, replace(options, seed=1000 * seed + 100 * k + j))
            for j, T in enumerate(poses)])
        arrays[f"{label}_truth"] = np.stack([
            project_points(TRUTH, T, BOARD.dot_positions()) + circle_centre_bias(TRUTH, T, BOARD)
            for T in poses])
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    tmp.replace(path)


def _load_detector(module_file: str | None):
    """``detect_dots`` of the package, or of a copy of detect.py at ``module_file`` (loaded
    inside the package so that its relative imports resolve)."""
    if module_file is None:
        from olp_compensate.camera.detect import detect_dots
        return detect_dots
    import olp_compensate.camera  # noqa: F401  (the parent package of the copy)

    spec = importlib.util.spec_from_file_location("olp_compensate.camera._detect_baseline",
                                                  module_file)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module.detect_dots


def measure(images_path: Path, module_file: str | None) -> dict:
    """One run in this process: CPU s per view and RMS px per set, failures."""
    import cv2

    cv2.setNumThreads(1)
    detect_dots = _load_detector(module_file)
    data = np.load(images_path)
    detect_dots(data["noisy_images"][0], BOARD)  # warm up: imports, caches
    out = {}
    for label in SETS:
        images, truth = data[f"{label}_images"], data[f"{label}_truth"]
        start = time.process_time()
        found = [detect_dots(image, BOARD) for image in images]
        seconds = time.process_time() - start
        errors = [f.pixels - t for f, t in zip(found, truth) if f.ok]
        rms = (float(np.sqrt(np.mean(np.sum(np.concatenate(errors) ** 2, axis=1))))
               if errors else float("nan"))
        out[label] = {"cpu_s_per_view": seconds / len(images), "rms_px": rms,
                      "failed": sum(not f.ok for f in found)}
    return out


def _child(images_path: Path, module_file: str | None) -> dict:
    command = [sys.executable, __file__, "--images", str(images_path), "--child"]
    if module_file:
        command += ["--module", module_file]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"benchmark run failed:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _summary(label: str, runs: list[dict]) -> None:
    for name in SETS:
        cpu = np.array([r[name]["cpu_s_per_view"] for r in runs]) * 1e3
        first = runs[0][name]
        print(f"{label:<10} {name:<6} {cpu.min():8.1f} {np.median(cpu):8.1f} "
              f"{1e3 / cpu.min():8.1f} {1e3 / np.median(cpu):8.1f} "
              f"{first['rms_px']:9.4f} {first['failed']:6d}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=30, help="views per set")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--runs", type=int, default=5, help="processes per detector")
    parser.add_argument("--baseline", help="a copy of an older detect.py to compare with")
    parser.add_argument("--images", type=Path, help="rendered views (.npz), made if absent")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--module", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    images = args.images or (Path(tempfile.gettempdir())
                             / f"olp_detect_speed_{args.count}_{args.seed}.npz")
    if args.child:
        print(json.dumps(measure(images, args.module)))
        return 0
    if not images.exists():
        start = time.perf_counter()
        render_cache(images, args.count, args.seed)
        print(f"rendered 2 x {args.count} views to {images} in "
              f"{time.perf_counter() - start:.0f} s")
    detectors = ([("baseline", args.baseline)] if args.baseline else []) + [("current", None)]
    runs = {label: [] for label, _ in detectors}
    for _ in range(args.runs):  # interleaved: A B A B ...
        for label, module_file in detectors:
            runs[label].append(_child(images, module_file))
    print(f"{args.count} views per set, {TRUTH.width} x {TRUTH.height} px, one core, "
          f"{args.runs} runs each{' interleaved' if args.baseline else ''}; "
          "truth = projected centre + circle_centre_bias")
    print(f"{'detector':<10} {'set':<6} {'ms min':>8} {'ms med':>8} {'/s max':>8} "
          f"{'/s med':>8} {'RMS px':>9} {'failed':>6}")
    for label, _ in detectors:
        _summary(label, runs[label])
    return 0


if __name__ == "__main__":
    sys.exit(main())
