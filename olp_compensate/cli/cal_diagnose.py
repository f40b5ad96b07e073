"""``olp-cal diagnose``: what the geometric model gets wrong, its cause, the extended model
and the gain on held-out data (see :mod:`olp_compensate.calibration.diagnose`)."""

from __future__ import annotations

import dataclasses
import json

from ..calibration.diagnose import DiagnoseOptions, diagnose, diagnosis_to_dict, summary
from ..calibration.effect_ranges import with_geometric_fallback
from ..calibration.effects import EFFECT_KINDS
from ..errors import DataError
from ..io.atomic import write_text_atomic
from ..io.calibration_file import write_calibration
from ..io.measurement_import import SESSION_GAP_S, sessions
from ..io.measurements import read_measurements
from ..kinematics.robot import load_robot
from ..calibration.measurements import check_spread
from .cal_identify import least_unknowns
from .common import refuse_clashes

HELP = ("name the non-geometric effects (compliance, gear error, backlash, heat, scale, "
        "cyclic angle errors) in the measurements, fit them and measure the gain on held-out poses")


def add_arguments(p) -> None:
    p.add_argument("measurements", help="measurement CSV (version 1)")
    p.add_argument("--robot", required=True, help="bundled robot name or path to a URDF")
    p.add_argument("--noise-mm", type=float,
                   help="measurement noise per axis, mm (default: from repeated poses, else "
                        "from the residual)")
    p.add_argument("-o", "--output", help="calib.json to write (the extended model)")
    p.add_argument("--json", help="diagnosis JSON to write")
    p.add_argument("--html", help="self-contained HTML report with figures to write")
    p.add_argument("--png-dir", help="folder to write the figures into as PNG files")
    p.add_argument("--folds", type=int, default=5, help="cross-validation folds (>= 2)")
    p.add_argument("--alpha", type=float, default=0.01,
                   help="false-alarm rate per round of the test (default 0.01)")
    p.add_argument("--residual-map", action="store_true",
                   help="store the cross-validated map of what the named effects leave in "
                        "the calib.json of -o (predict and olp-fix apply it inside its "
                        "joint region)")
    p.add_argument("--no-cyclic", action="store_true",
                   help="skip the cyclic angle error bands (orders K0..K per joint)")
    p.add_argument("--kinds", help="comma-separated effect kinds to try (default all: "
                                   + ", ".join(EFFECT_KINDS) + ")")


def _kinds(text: str | None) -> tuple[str, ...] | None:
    if text is None:
        return None
    kinds = tuple(k.strip() for k in text.split(",") if k.strip())
    unknown = [k for k in kinds if k not in EFFECT_KINDS]
    if unknown or not kinds:
        raise DataError(f"--kinds: unknown effect kind '{(unknown or [text])[0]}' (known: "
                        f"{', '.join(EFFECT_KINDS)})")
    return kinds


def _with_map(result, calibration):
    """The calibration with the residual map, when the map predicts anything."""
    remainder = result.remainder
    figures = {} if remainder is None or remainder.map is None else remainder.map.validation
    without, with_map = (figures.get("heldout_rms_mm_without"),
                         figures.get("heldout_rms_mm_with"))
    if without is None or with_map is None or with_map >= without:
        print("residual map not stored: no model of the joints predicts the remainder")
        return calibration
    print(f"residual map stored ({remainder.map.to_dict()['kind']} of the joints; held-out "
          f"{without:.4f} -> {with_map:.4f} mm; applied only inside the joint ranges it was "
          f"fitted in)")
    return dataclasses.replace(calibration, residual_map=remainder.map)


def run(args) -> int:
    refuse_clashes([("measurements", args.measurements), ("--robot", args.robot)],
                   [("-o", args.output), ("--json", args.json), ("--html", args.html),
                    ("--png-dir", args.png_dir)])
    if args.noise_mm is not None and not args.noise_mm > 0:
        raise DataError(f"--noise-mm must be positive, got {args.noise_mm}")
    if args.folds < 2:
        raise DataError(f"--folds must be at least 2 (held-out data decide), got {args.folds}")
    if args.residual_map and not args.output:
        raise DataError("--residual-map stores the map in the calib.json of -o: give -o")
    options = DiagnoseOptions(noise_m=None if args.noise_mm is None else args.noise_mm * 1e-3,
                              alpha=args.alpha, folds=args.folds, kinds=_kinds(args.kinds),
                              cyclic=not args.no_cyclic)
    robot = load_robot(args.robot)
    meas = read_measurements(args.measurements, [j.unit for j in robot.joints])
    check_spread(meas, least_unknowns(robot, meas))
    runs = sessions(meas.time_s) if meas.time_s is not None else []
    if len(runs) > 1:
        print(f"WARNING: the rows form {len(runs)} sessions (time_s gaps over "
              f"{SESSION_GAP_S / 3600:g} h, from rows {', '.join(str(a + 1) for a, _ in runs[:6])}"
              f"): one device frame is fitted to all; if the device moved between them, "
              f"diagnose each alone")
    result = diagnose(robot, meas, options)
    print(summary(result))
    if args.output:
        calibration = with_geometric_fallback(result.extended.calibration,
                                              result.geometric.calibration, meas.joints)
        if args.residual_map:
            calibration = _with_map(result, calibration)
        write_calibration(args.output, calibration)
        print(f"wrote the {'extended' if result.extends else 'geometric'} model to {args.output}")
    if args.json:
        write_text_atomic(args.json, json.dumps(diagnosis_to_dict(result), indent=2) + "\n")
        print(f"wrote {args.json}")
    if args.html or args.png_dir:
        from ..report.html import write_html, write_pngs

        if args.html:
            write_html(result, args.html)
            print(f"wrote {args.html}")
        if args.png_dir:
            names = write_pngs(result, args.png_dir)
            print(f"wrote {len(names)} figures to {args.png_dir}")
    return 0
