"""What a real robot gets wrong (issue 28): the diagnosis on measured data of real arms.

Run: python benchmarks/real_data.py PATH[@ROBOT] ... [--robot NAME_OR_URDF] [--folds 5]
     [--range-joint 2 [--bootstrap 8]] [--sigma-rule quadrature|none|stated|median-floor]

Each PATH is a measurement CSV (version 1; ``olp-cal import`` turns instrument tables
into one); ROBOT (after ``@``, else ``--robot``) the bundled robot or URDF it was measured
on. The data stay outside the repository (see the README's "Real data" section for the
public sets and how they were imported). For each it prints the 5-fold held-out RMS by
pose of: the nominal model (registered to the device), the geometric model, the named
effects, the predictable remainder (the flexible model of :mod:`.remainder`), an
independent peer of it (k-nearest neighbours in the joints' sin/cos, k by the same
folds; it shares no code with the flexible model) and the noise floor, with its source.
With ``--range-joint J`` it also holds out the top fifth of joint J's range, fits the
geometric model and the diagnosis on the rest, and prints both models' RMS on the rows
held out (outside the effects' fitted ranges the extended model falls back to the
geometric one, as olp-cal diagnose -o writes it: it must not be worse there); with
``--bootstrap N`` it refits the geometric model on N resamples of those rows (poses drawn
with replacement) and prints the spread of its error on the held-out range and of its
predictions there against the fitted range: a held-out range the data do not determine
shows a wide spread, and one figure from it says nothing about a rule or a model.
Each report ends with the geometric model's residual by quartile of the distance from
the device and of the stated ``sigma_mm``: flat, they carry no information for weights.
``--sigma-rule`` compares the per-row sigma rules (``sigma_mm`` column): ``quadrature``
(the library's, :func:`row_sigma_scales`), ``none`` (no weights), ``stated`` (weights
1/sigma^2 as stated), ``median-floor`` (the rule before it: each floored at the median).
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import olp_compensate.calibration.identify as identify_module  # noqa: E402
from olp_compensate.calibration.cross_validation import pose_folds  # noqa: E402
from olp_compensate.calibration.diagnose import DiagnoseOptions, diagnose  # noqa: E402
from olp_compensate.calibration.effect_ranges import with_geometric_fallback  # noqa: E402
from olp_compensate.calibration.identify import IdentificationOptions, identify  # noqa: E402
from olp_compensate.calibration.measurements import row_sigma_scales  # noqa: E402
from olp_compensate.io.measurements import read_measurements  # noqa: E402
from olp_compensate.kinematics.model import build_model  # noqa: E402
from olp_compensate.kinematics.robot import load_robot  # noqa: E402


def _stated_sigma_m(meas, position_sigma_m: float) -> np.ndarray:
    """(m,) the ``sigma_mm`` column in m, the default where a cell is empty."""
    cells = [str(c).strip() for c in meas.extra["sigma_mm"]]
    return np.array([float(c) * 1e-3 if c else position_sigma_m for c in cells])


def _rule(name: str):
    """A replacement for :func:`row_sigma_scales` (position weights only; ASTL-like tables
    carry no orientation) following the rule ``name``."""
    def scales(meas, position_sigma_m, rotation_sigma_rad):
        if name == "quadrature":
            return row_sigma_scales(meas, position_sigma_m, rotation_sigma_rad)
        if name == "none" or "sigma_mm" not in meas.extra:
            return None
        sigma = _stated_sigma_m(meas, position_sigma_m)
        if name == "median-floor":
            sigma = np.maximum(sigma, np.median(sigma))
        return position_sigma_m / sigma, np.ones(meas.n_rows)
    return scales


SIGMA_RULES = ("quadrature", "none", "stated", "median-floor")


def nominal_heldout(robot, meas, folds: int) -> float:
    """Held-out RMS of the nominal geometry, only the device frame and tools fitted, m."""
    names = tuple(p.name for p in build_model(robot, "auto").parameters)
    return identify(robot, meas, IdentificationOptions(folds=folds, freeze=names)).heldout_rms


def knn_peer(q: np.ndarray, target: np.ndarray, folds, ks=(1, 2, 4, 8, 16, 32)) -> float:
    """3-D RMS of ``target`` minus its k-nearest-neighbour prediction (mean of the k
    nearest training rows in sin/cos of the joints), k chosen on the held-out folds."""
    x = np.hstack([np.sin(q), np.cos(q)])
    best = np.inf
    for k in ks:
        out = np.empty_like(target)
        for test in folds:
            train = np.flatnonzero(~test)
            d = ((x[test][:, None, :] - x[train][None, :, :]) ** 2).sum(axis=2)
            near = np.argsort(d, axis=1)[:, :k]
            out[test] = target[test] - target[train][near].mean(axis=1)
        best = min(best, float(np.sqrt(np.mean(np.sum(out**2, axis=1)))))
    return best


def rms_on(robot, calibration, meas) -> float:
    """3-D RMS of measured minus predicted by ``calibration`` on ``meas`` (as olp-cal
    predict does: rows outside the effects' fitted ranges by its geometric fallback), m."""
    predicted = calibration.predict_points(meas.joints, meas.point_names)
    return float(np.sqrt(np.mean(np.sum((meas.points - predicted) ** 2, axis=1))))


def _bootstrap(robot, train, test, n: int) -> None:
    """Refit the geometric model on ``n`` resamples of ``train``'s poses; print the spread
    of its RMS on ``test`` and of its predictions on both (m -> mm)."""
    rng = np.random.default_rng(0)
    poses = np.unique(train.pose_ids)
    errors, predicted = [], []
    for _ in range(n):
        pick = rng.choice(poses, len(poses))
        rows = np.concatenate([np.flatnonzero(train.pose_ids == p) for p in pick])
        sample = dataclasses.replace(train.subset(rows), pose_ids=np.array(
            [f"b{k}" for k in range(len(rows))], dtype=object))
        cal = identify(robot, sample, IdentificationOptions(folds=0)).calibration
        errors.append(rms_on(robot, cal, test))
        predicted.append((cal.predict_points(train.joints, train.point_names),
                          cal.predict_points(test.joints, test.point_names)))
    spread = [float(np.sqrt(np.mean(np.sum(np.std(np.stack(p), axis=0) ** 2, axis=1))))
              for p in zip(*predicted)]
    print(f"    bootstrap ({n} resamples of the fitted poses): geometric on the held-out "
          f"range {min(errors) * 1e3:.4f}-{max(errors) * 1e3:.4f} mm (median "
          f"{np.median(errors) * 1e3:.4f}); its predictions vary {spread[0] * 1e3:.4f} mm RMS "
          f"on the fitted range, {spread[1] * 1e3:.4f} mm on the held-out one")


def range_check(robot, meas, joint: int, folds: int, bootstrap: int = 0) -> None:
    """Hold out the top fifth of ``joint``'s (0-based) range; print both models' RMS there."""
    q = meas.joints[:, joint]
    cut = np.quantile(q, 0.8)
    test = q > cut
    train = meas.subset(~test)
    geometric = identify(robot, train, IdentificationOptions(folds=0)).calibration
    d = diagnose(robot, train, DiagnoseOptions(folds=folds))
    extended = with_geometric_fallback(d.extended.calibration, d.geometric.calibration,
                                       train.joints)
    print(f"  joint {joint + 1} above {np.degrees(cut):.1f} deg held out ({int(test.sum())} "
          f"rows, outside the fitted range): geometric "
          f"{rms_on(robot, geometric, meas.subset(test)) * 1e3:.4f} mm, named effects "
          f"{rms_on(robot, extended, meas.subset(test)) * 1e3:.4f} mm ("
          + (", ".join(k.effect.label for k in d.effects) or "none")
          + (f"; {len(d.predictive)} predictive term(s) not named" if d.predictive else "")
          + ")")
    if bootstrap:
        _bootstrap(robot, train, meas.subset(test), bootstrap)


def _by_quartile(values: np.ndarray, residual: np.ndarray) -> str:
    """RMS of ``residual`` (m) in each quartile of ``values``, mm, as 'a / b / c / d'."""
    edges = np.quantile(values, [0.25, 0.5, 0.75])
    group = np.searchsorted(edges, values)
    return " / ".join(f"{np.sqrt(np.mean(residual[group == g] ** 2)) * 1e3:.4f}"
                      for g in range(4))


def sigma_check(meas, calibration) -> None:
    """Do the stated sigmas (and the distance from the device) tell which rows are poor?
    The geometric model's residual by quartile of each: flat means they do not."""
    residual = np.linalg.norm(meas.points - calibration.predict_points(
        meas.joints, meas.point_names), axis=1)
    distance = np.linalg.norm(meas.points, axis=1)
    print(f"  geometric residual by quartile of the distance from the device "
          f"({distance.min():.2f}-{distance.max():.2f} m): "
          f"{_by_quartile(distance, residual)} mm")
    if "sigma_mm" in meas.extra:
        stated = _stated_sigma_m(meas, np.nan)
        ok = np.isfinite(stated)
        print(f"  ... by quartile of the stated sigma_mm ({np.nanmin(stated) * 1e3:.4g}-"
              f"{np.nanmax(stated) * 1e3:.4g} mm): {_by_quartile(stated[ok], residual[ok])} mm")


def report(path: str, robot, folds: int) -> None:
    meas = read_measurements(path, robot)
    start = time.perf_counter()
    d = diagnose(robot, meas, DiagnoseOptions(folds=folds))
    seconds = time.perf_counter() - start
    rem = d.remainder
    peer = knn_peer(meas.joints, rem.target, pose_folds(meas.pose_ids, folds))
    print(f"{path} ({robot.name}, {meas.n_poses} poses, {meas.n_rows} points, "
          f"{seconds:.0f} s)")
    print(f"  nominal (registered)      {nominal_heldout(robot, meas, folds) * 1e3:8.4f} mm")
    print(f"  geometric                 {d.geometric.heldout_rms * 1e3:8.4f} mm")
    print(f"  named effects             {d.extended.heldout_rms * 1e3:8.4f} mm: "
          + (", ".join(k.effect.label for k in d.effects) or "none")
          + (f"; with {len(d.predictive)} predictive term{'s' if len(d.predictive) > 1 else ''} "
             f"not named (hints: "
             + ", ".join(f"{t.unnamed.label} s = {t.unnamed.separability:.3f}"
                         for t in d.predictive) + ")" if d.predictive else ""))
    print(f"  predictable remainder     {rem.rms_after * 1e3:8.4f} mm (from joints "
          f"{', '.join(str(j + 1) for j in rem.joints) or 'none'}; {rem.model}); independent peer "
          f"(k-nearest neighbours) {min(peer, rem.rms_before) * 1e3:.4f} mm")
    print(f"  noise floor               {d.noise.sigma_m * 1e3:8.4f} mm per axis "
          f"({d.noise.sigma_m * np.sqrt(3) * 1e3:.4f} mm 3-D), from {d.noise.source}")
    for k in d.effects:
        print(f"    {k.effect.label}: moves the point {k.point_rms_m * 1e3:.3f} mm RMS")
    sigma_check(meas, d.geometric.calibration)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", help="measurement CSV[@robot]")
    parser.add_argument("--robot", help="bundled robot name or URDF (default for every path)")
    parser.add_argument("--folds", type=int, default=5)
    parser.add_argument("--range-joint", type=int, help="1-based joint for the range check")
    parser.add_argument("--bootstrap", type=int, default=0,
                        help="with --range-joint: resamples for the held-out range's spread")
    parser.add_argument("--sigma-rule", choices=SIGMA_RULES, default="quadrature",
                        help="per-row sigma rule (sigma_mm column) to compare")
    args = parser.parse_args()
    identify_module.row_sigma_scales = _rule(args.sigma_rule)
    print(f"per-row sigma rule: {args.sigma_rule}")
    for item in args.paths:
        path, _, name = item.partition("@")
        if not (name or args.robot):
            parser.error(f"{item}: give the robot as PATH@ROBOT or --robot")
        robot = load_robot(name or args.robot)
        report(path, robot, args.folds)
        if args.range_joint:
            range_check(robot, read_measurements(path, robot), args.range_joint - 1, args.folds,
                        args.bootstrap)


if __name__ == "__main__":
    main()
