"""``olp-cal export``: a calibration in a maker's format. Nothing is sent to a controller.

- ``--format ur-calibration``: a UR ``calibration.conf`` (``[mounting]`` deltas added to the
  data-sheet D-H, rad and m) fitted to the identified arm over its joint ranges;
- ``--format dh-table``: a CSV of the standard D-H table, the modified (Craig) table beside
  it, units in the column names.
Each prints what the table cannot hold: the distance between its flange and the calibrated
arm's at random poses within the axis ranges, mm.
"""

from __future__ import annotations

import math

from .common import refuse_clashes

HELP = ("write a calibration in a maker's format: UR calibration.conf deltas "
        "(ur-calibration) or a D-H/MDH table CSV (dh-table)")
FORMATS = ("ur-calibration", "dh-table")
POSES = 1000


def add_arguments(p) -> None:
    p.add_argument("--model", required=True, help="calib.json (olp-cal identify/diagnose)")
    p.add_argument("--format", required=True, choices=FORMATS,
                   help="ur-calibration: UR calibration.conf; dh-table: D-H/MDH table CSV")
    p.add_argument("-o", "--output", required=True, help="file to write")


def run(args) -> int:
    from ..calibration.dh_export import export_dh
    from ..io.atomic import write_text_atomic
    from ..io.calibration_file import read_calibration
    from ..kinematics.dh_table import UR_NOMINAL, ur_nominal

    refuse_clashes([("--model", args.model)], [("-o", args.output)])
    cal = read_calibration(args.model)
    name = cal.robot.name.lower()
    if args.format == "ur-calibration":
        nominal = ur_nominal(name)
        result = export_dh(cal, nominal, POSES)
        text = _conf_text(result.table, nominal)
    else:
        result = export_dh(cal, UR_NOMINAL.get(name), POSES)
        text = dh_table_csv(result.table, cal.robot.name, args.model,
                            cal.robot.urdf_from_controller is not None)
    write_text_atomic(args.output, text)
    how = ("fitted to the calibrated arm's effects" if result.fitted
           else "the identified geometry, exact")
    print(f"olp-cal export: {args.format} of {cal.robot.name} ({how}) written to {args.output}")
    print(f"  what the table cannot hold, at {result.poses} random poses within the axis "
          f"ranges: {result.rms_mm:.4f} mm RMS, {result.max_mm:.4f} mm max, "
          f"{result.max_deg:.5f} deg max")
    if result.exact.flange_offset_m > 1e-7 or result.exact.flange_tilt_rad > 1e-7:
        print(f"  the flange sits {result.exact.flange_offset_m * 1e3:.4f} mm and "
              f"{math.degrees(result.exact.flange_tilt_rad):.5f} deg off what a D-H row "
              f"allows")
    return 0


def _conf_text(table, nominal) -> str:
    from ..io.ur_kinematics import UrKinematics, dumps_conf

    return dumps_conf(UrKinematics(form="conf", deltas=table.minus(nominal)))


def dh_table_csv(table, robot: str, source: str, coupled: bool) -> str:
    """The D-H and modified D-H rows of ``table`` as CSV text (mm, deg)."""
    from ..kinematics.dh_table import mdh_rows

    mdh, _ = mdh_rows(table)
    lines = [f"# D-H table of {robot} from {source} (olp-compensate); joints are the URDF "
             f"joints{' (the controller couples some: see robots/README.md)' if coupled else ''}",
             "# standard D-H: link i = Rz(q_i + theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i); base = "
             "frame 0, flange = frame 6",
             "# modified D-H (Craig): link i = Rx(alpha_i-1) Tx(a_i-1) Rz(q_i + theta_i) "
             "Tz(d_i); the row 'flange' is Tx(a_6) Rx(alpha_6) after joint 6",
             "joint,theta_deg,d_mm,a_mm,alpha_deg,mdh_alpha_prev_deg,mdh_a_prev_mm,"
             "mdh_theta_deg,mdh_d_mm"]
    for i in range(table.n_joints):
        values = (math.degrees(table.theta[i]), table.d[i] * 1e3, table.a[i] * 1e3,
                  math.degrees(table.alpha[i]), math.degrees(mdh[i, 0]), mdh[i, 1] * 1e3,
                  math.degrees(mdh[i, 2]), mdh[i, 3] * 1e3)
        lines.append(f"{i + 1}," + ",".join(f"{v:.9f}" for v in values))
    lines.append(f"flange,,,,,{math.degrees(table.alpha[-1]):.9f},{table.a[-1] * 1e3:.9f},,")
    return "\n".join(lines) + "\n"
