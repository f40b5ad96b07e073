"""``olp-cal identify``: the robot's real geometry from measured points."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..calibration.identify import IdentificationOptions, identify
from ..calibration.fit_check import MAX_RMS_M, FitVerdict, forced_warning, judge_residual
from ..calibration.measurements import check_spread
from ..calibration.regions import (DEFAULT_MARGIN_M, check_margin, identify_regions,
                                   least_unknowns, region_column)
from ..errors import DataError, OlpError
from ..io.calibration_file import write_calibration
from ..io.session import read_measurements_any
from ..kinematics.robot import load_robot
from .common import mm, refuse_clashes

HELP = ("identify the robot's geometry from a measurement CSV (or an MCAP session with the "
        "device's points) and write calib.json")


def add_measurement_source_arguments(p) -> None:
    """The positional measurements argument (CSV, or MCAP session) and its merge options;
    read them with :func:`read_measurement_source`."""
    p.add_argument("measurements", help="measurement CSV (version 1), or an MCAP session from "
                                        "olp-cal record with --points")
    p.add_argument("--points", metavar="CSV",
                   help="with an MCAP session: the measuring device's points (x_mm, y_mm, "
                        "z_mm [, time_s, point, pose]), joined on the fly")
    p.add_argument("--by", choices=("order", "time"), default="order",
                   help="with --points: join by order (or the 'pose' column) or by time")
    p.add_argument("--tolerance-s", type=float, default=0.5,
                   help="with --points --by time: largest gap between a point and its pose, s")
    p.add_argument("--time-offset-s", type=float, default=0.0,
                   help="with --points --by time: added to the device's time_s to get Unix "
                        "time, s")


def read_measurement_source(args, joint_units: list[str]):
    """The measurements named by :func:`add_measurement_source_arguments` options."""
    from ..io.session import is_mcap

    if args.points is not None and not is_mcap(args.measurements):
        raise DataError(f"{args.measurements}: device points (--points) go with an MCAP "
                        f"session, and this is not one; a measurement CSV already holds its "
                        f"points")
    if args.points is None and is_mcap(args.measurements):
        raise DataError(f"{args.measurements}: an MCAP session holds the joints only; give the "
                        f"measuring device's points with --points points.csv (or merge them "
                        f"first with olp-cal merge)")
    return read_measurements_any(args.measurements, joint_units, points=args.points,
                                 by=args.by, tolerance_s=args.tolerance_s,
                                 time_offset_s=args.time_offset_s)


def _unverified_scale(metadata) -> bool:
    """:func:`~olp_compensate.camera.scale.unverified_rows` of a measurement CSV's
    metadata lines, the camera package imported only where a line says ``unverified``
    (rows from the camera path; others need none of it)."""
    if not any("unverified" in line for line in metadata):
        return False
    from ..camera.scale import unverified_rows

    return unverified_rows(metadata)


def check_freeze_names(robot, convention: str, names) -> None:
    """``--freeze`` names that are no parameter of the model, in the command's words."""
    if not names:  # nothing to check: no model to build
        return
    from ..kinematics.model import build_model

    known = build_model(robot, convention).names
    for name in names:
        if name not in known:
            raise DataError(f"--freeze: no parameter named '{name}' (known: "
                            f"{', '.join(known)})")


def add_arguments(p) -> None:
    add_measurement_source_arguments(p)
    p.add_argument("--robot", required=True, help="bundled robot name or path to a URDF")
    p.add_argument("-o", "--output", help="calib.json to write")
    p.add_argument("--folds", type=int, default=5, help="cross-validation folds (0: none)")
    p.add_argument("--robust", action="store_true",
                   help="reject rows beyond the 99.9%% noise quantile, refit, list them")
    p.add_argument("--solver", choices=("lm", "trf"), default="lm",
                   help="lm: Levenberg-Marquardt (Marquardt schedule); trf: scipy trust region")
    p.add_argument("--convention", choices=("auto", "dh"), default="auto",
                   help="auto: D-H or Hayati per link (singularity-free); dh: D-H everywhere")
    p.add_argument("--freeze", action="append", default=[], metavar="PARAM",
                   help="hold a parameter at nominal (repeatable), e.g. j3.beta")
    p.add_argument("--position-sigma-mm", type=float, default=0.05,
                   help="with orientation columns: the device's position noise per axis, mm")
    p.add_argument("--orientation-sigma-deg", type=float, default=0.01,
                   help="with orientation columns: the device's orientation noise per axis, "
                        "deg (orientation residuals are weighted by the ratio of the sigmas)")
    p.add_argument("--per-region", action="store_true",
                   help="also fit one model per region named in the measurements' 'region' "
                        "column, on its rows alone; olp-fix uses a region's model for "
                        "targets inside its volume (the global model elsewhere)")
    p.add_argument("--force", action="store_true",
                   help="write the calibration even when its RMS residual is above the "
                        f"{MAX_RMS_M * 1e3:g} mm limit (the file then carries the warning)")
    p.add_argument("--region-margin-mm", type=float, default=DEFAULT_MARGIN_M * 1e3,
                   help="with --per-region: a region's volume is the bounding box of its "
                        "measured points (base frame) grown by this much on every side, mm")


def report(result) -> str:
    """The identification report, as printed."""
    cal = result.calibration
    ident = result.identifiability
    n_tool = (sum(n.startswith("tool.") and n not in cal.frozen for n in result.unknown_names)
              if result.unknown_names else 3 * len(cal.tools))
    n_frame = 6 - sum(n.startswith("base.") and n in cal.frozen for n in result.unknown_names)
    orientations = (f" ({result.n_orientation_rows} rows with orientation)"
                    if result.n_orientation_rows else "")
    lines = [
        f"robot {cal.robot.name}: {result.n_poses} poses, {result.n_equations} equations"
        f"{orientations}, {result.n_unknowns} unknowns ({n_frame} device registration + "
        f"{result.n_unknowns - n_frame - n_tool} geometric + {n_tool} tool)",
        "links: " + ", ".join(f"{k + 1}-{k + 2} {c}" for k, c in enumerate(cal.model.conventions)),
        f"solver: {result.message} after {result.iterations} iterations",
        f"condition number (unit-scaled Jacobian): {ident.condition_number:.1f}",
        "",
        f"{'parameter':<12}{'nominal':>14}{'identified':>14}{'change':>12}{'std':>10}  unit",
    ]
    for k, p in enumerate(cal.model.parameters):
        s = p.display_scale
        if p.name in cal.frozen:
            lines.append(f"{p.name:<12}{p.nominal * s:>14.4f}{'(frozen)':>14}{'':>12}{'':>10}  {p.display_unit}")
            continue
        lines.append(f"{p.name:<12}{p.nominal * s:>14.4f}{cal.values[k] * s:>14.4f}"
                     f"{(cal.values[k] - p.nominal) * s:>12.4f}{cal.std[k] * s:>10.4f}  {p.display_unit}")
    for name, tool in cal.tools.items():
        xyz = ", ".join(_unsigned_zero(f"{v:.3f}") for v in tool.xyz_m * 1e3)
        std = ", ".join("frozen" if f"tool.{name}.{a}" in cal.frozen else f"{v:.3f}"
                        for a, v in zip("xyz", tool.std_m * 1e3))
        lines.append(f"tool {name}: ({xyz}) mm in the flange frame, std ({std}) mm")
        if tool.quat_wxyz is not None and tool.rot_std_rad is not None:
            quat = ", ".join(f"{v:.6f}" for v in tool.quat_wxyz)
            rot_std = ", ".join("frozen" if f"tool.{name}.r{a}" in cal.frozen else f"{v:.4f}"
                                for a, v in zip("xyz", np.degrees(tool.rot_std_rad)))
            lines.append(f"tool {name} frame: quaternion (w, x, y, z) ({quat}) in the flange "
                         f"frame, std ({rot_std}) deg about its axes")
    lines.append("")
    if cal.frozen:
        lines.append("frozen (not identified):")
        lines += [f"  {name}: {why}" for name, why in cal.frozen.items()]
    lines += [f"WARNING: {motion.text}" for motion in ident.motions.values()]
    if ident.weak:
        lines.append("WARNING: barely observable with these poses (the residual can look "
                     "perfect while these stay wrong; add poses that move them):")
        lines += [f"  {w}" for w in ident.weak]
    if result.outlier_rows:
        lines.append(f"outliers rejected (file lines): {', '.join(map(str, result.outlier_rows))}")
    lines.append(f"residual: RMS {mm(result.residual_rms)}, max {mm(result.residual_max)}")
    if result.orientation_rms is not None:
        lines.append(f"orientation residual: RMS {np.degrees(result.orientation_rms):.4f} deg, "
                     f"max {np.degrees(result.orientation_max):.4f} deg")
    if result.heldout_rms is not None:
        lines.append(f"held-out ({cal.validation.method}): RMS {mm(result.heldout_rms)}, "
                     f"max {mm(result.heldout_max)}")
        if result.heldout_orientation_rms is not None:
            lines.append(f"held-out orientation: RMS "
                         f"{np.degrees(result.heldout_orientation_rms):.4f} deg, max "
                         f"{np.degrees(result.heldout_orientation_max):.4f} deg")
    else:
        lines.append("held-out: not computed (too few poses or --folds 0)")
    return "\n".join(lines)


def _unsigned_zero(text: str) -> str:
    """A formatted number without the sign of a zero ("-0.000" -> "0.000": a component held
    at a zero start, or one below the last digit, is printed as the zero it is)."""
    return text[1:] if text[:1] == "-" and not text.strip("-0.") else text


def _optional_mm(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f} mm"


def regions_report(regional) -> str:
    """The per-region lines, as printed: each region's volume, poses, residual and held-out
    errors beside the global model's held-out errors on the same rows, and whether it is
    kept (a local model worse held-out than the global one is left out)."""
    regions = regional.candidates or regional.result.calibration.regions
    kept = len(regions) - len(regional.left_out)
    lines = [f"local models: {kept} region{'s' if kept != 1 else ''} kept of {len(regions)} "
             f"(volumes: measured points' bounding box in the base frame, grown by "
             f"{regions[0].box.margin_m * 1e3:.1f} mm)" if regions else "local models: none"]
    for region, (_, result) in zip(regions, regional.regions):
        low = ", ".join(f"{v * 1e3:.1f}" for v in region.box.min_m)
        high = ", ".join(f"{v * 1e3:.1f}" for v in region.box.max_m)
        lines.append(f"region {region.name}: {result.n_poses} poses, volume ({low})..({high}) "
                     f"mm, condition number {result.identifiability.condition_number:.1f}")
        lines.append(f"  residual: RMS {mm(result.residual_rms)}, max {mm(result.residual_max)}")
        if result.heldout_rms is not None:
            lines.append(f"  held-out: local model RMS {mm(result.heldout_rms)}, max "
                         f"{mm(result.heldout_max)}; global model RMS "
                         f"{_optional_mm(region.global_heldout_rms_mm)}, max "
                         f"{_optional_mm(region.global_heldout_max_mm)}")
        else:
            lines.append("  held-out: not computed (too few poses or --folds 0); the local "
                         "model is kept unchecked")
        if region.name in regional.left_out:
            lines.append(f"  LEFT OUT: {regional.left_out[region.name]}")
        lines += [f"  WARNING: {motion.text}" for motion in result.identifiability.motions.values()]
        if result.identifiability.weak:
            lines.append(f"  WARNING: barely observable in this region: "
                         f"{'; '.join(result.identifiability.weak)}")
    return "\n".join(lines)


def check_fit(result) -> None:
    """:class:`DataError` when the fit's residual is not a finite number."""
    if not math.isfinite(result.residual_rms) or not math.isfinite(result.residual_max):
        raise DataError(f"the fit did not converge to finite numbers (residual RMS "
                        f"{result.residual_rms}); the data cannot determine the model; "
                        f"nothing written")


def judge_identification(result, meas, sigma_mm: float) -> FitVerdict:
    """The shared residual rule (:mod:`olp_compensate.calibration.fit_check`) on an
    identification: RMS residual above the limit, naming the file line of the worst row."""
    cal = result.calibration
    if result.residual_rms <= MAX_RMS_M:
        return FitVerdict(False)
    try:
        distances = np.linalg.norm(cal.predict_points(meas.joints, meas.point_names)
                                   - meas.points, axis=1)
    except DataError:
        distances = np.array([result.residual_max])
    lines = (meas.rows if meas.rows is not None and len(meas.rows) == len(distances)
             else np.arange(1, len(distances) + 1))
    names = [f"line {int(line)}" for line in lines]
    noise = (f"{MAX_RMS_M * 1e3 / sigma_mm:.0f} times the stated noise of {sigma_mm:g} mm "
             f"(--position-sigma-mm)")
    return judge_residual(f"{meas.source}: the measurements do not fit robot "
                          f"{cal.robot.name}", distances, names, noise=noise,
                          rms_m=result.residual_rms)


def check_robot_line(meas, robot) -> None:
    """:class:`DataError` when the CSV's ``# robot: NAME`` line names another robot than
    ``--robot`` (same name, or a bundled robot of the same kinematic fingerprint, agree)."""
    for line in meas.metadata:
        key, _, value = line.lstrip("#").partition(":")
        if key.strip().lower() != "robot" or not value.strip():
            continue
        named = value.strip()
        if named == robot.name or _same_kinematics(named, robot):
            return
        raise DataError(f"{meas.source}: its '# robot: {named}' line names another robot than "
                        f"--robot {robot.name}; identify with --robot {named}, or correct the "
                        f"line if the data were measured on {robot.name}")


def _same_kinematics(name: str, robot) -> bool:
    try:
        return load_robot(name).fingerprint == robot.fingerprint
    except OlpError:
        return False


def run(args) -> int:
    refuse_clashes([("measurements", args.measurements), ("--points", args.points),
                    ("--robot", args.robot)], [("-o", args.output)])
    robot = load_robot(args.robot)
    check_freeze_names(robot, args.convention, args.freeze)
    meas = read_measurement_source(args, [j.unit for j in robot.joints])
    check_robot_line(meas, robot)
    check_spread(meas, least_unknowns(robot, meas))
    if args.per_region:            # refuse bad region input before the global fit
        region_column(meas)
        check_margin(args.region_margin_mm * 1e-3)
    options = IdentificationOptions(convention=args.convention, solver=args.solver,
                                    robust=args.robust, folds=args.folds,
                                    freeze=tuple(args.freeze),
                                    position_sigma_mm=args.position_sigma_mm,
                                    orientation_sigma_deg=args.orientation_sigma_deg)
    result = identify(robot, meas, options)
    check_fit(result)
    print(report(result))
    if _unverified_scale(meas.metadata):
        print("WARNING: these camera rows were measured with a board of unverified scale "
              "(their '# board scale:' line): a 0.1-0.3 % print error scales the identified "
              "lengths by as much, and neither the residual nor the held-out error shows it; "
              "measure the printed scale bar and run 'camera measure --scale-bar-mm L'")
    verdict = judge_identification(result, meas, args.position_sigma_mm)
    if verdict.rejected:
        if not args.force:
            raise DataError(f"{verdict.message} Nothing written (--force writes it with this "
                            f"warning in the file)")
        print(f"WARNING: {verdict.message} Written anyway (--force), flagged in the file")
    if args.per_region:
        regional = identify_regions(robot, meas, options, args.region_margin_mm * 1e-3,
                                    global_result=result)
        result = regional.result
        print("")
        print(regions_report(regional))
    if args.output:
        calibration = result.calibration
        if verdict.rejected:
            calibration = replace(calibration, warnings=calibration.warnings
                                  + (forced_warning(verdict),))
        write_calibration(args.output, calibration)
        print(f"wrote {args.output}")
    return 0
