"""The poses a robot controller reports, as a CSV: what ``olp-cal controller`` fits.

One row per reading: ``q1_deg`` ... ``qN_deg`` (the controller's axes; mm for a prismatic
axis), ``x_mm, y_mm, z_mm`` and ``qw, qx, qy, qz`` (the flange's, or a named tool's, pose in
the robot base frame as the controller computes it: pendant, RAPID ``CRobT``/``CJointT``,
KUKA ``$POS_ACT``/``$AXIS_ACT``, UR waypoints). The columns are those of the measurement CSV
(:mod:`olp_compensate.io.measurements`), so the same reader checks them; here every row needs
its orientation. The written decimals tell how precisely the rows state the controller's
model (:class:`ReportedPoses`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DataError
from ..kinematics.conventions import matrix_from_quat_wxyz
from ..kinematics.robot import Robot
from .measurements import ORIENTATION_COLUMNS, open_table, parse_measurements, read_csv_text

POSITION_COLUMNS = ("x_mm", "y_mm", "z_mm")


@dataclass(frozen=True)
class ReportedPoses:
    """Rows of a controller's report: ``q_ctrl`` (m, n) controller axes, rad/m;
    ``base_T_tool`` (m, 4, 4), base frame, m; ``lines`` (m,) 1-based; ``precision_m`` and
    ``precision_rad``: how far from the controller's exact numbers the written decimals
    (positions, quaternions and joints, the coarsest of each) may put a row."""

    q_ctrl: np.ndarray
    base_T_tool: np.ndarray
    lines: np.ndarray
    precision_m: float
    precision_rad: float
    source: str


def _decimals(cell: str) -> int:
    mantissa = cell.strip().lower().split("e")[0].replace(",", ".")
    exponent = cell.strip().lower().split("e")[1] if "e" in cell.lower() else "0"
    places = len(mantissa) - mantissa.find(".") - 1 if "." in mantissa else 0
    try:
        return places - int(exponent)
    except ValueError:
        return places


def _coarsest(text: str, source: str, columns) -> dict[str, int]:
    """The fewest decimals written in each of ``columns``."""
    table = open_table(text, source, "columns q1_deg, ..., x_mm, y_mm, z_mm, qw, qx, qy, qz")
    index = {h: k for k, h in enumerate(table.header)}
    out = {c: 99 for c in columns if c in index}
    for _, record in table.records:
        for c in out:
            cell = record[index[c]]
            if cell.strip():
                out[c] = min(out[c], _decimals(cell))
    return out


def parse_reported_poses(text: str, robot: Robot, source: str = "<poses>") -> ReportedPoses:
    """Parse the CSV text of a controller's reported poses for ``robot``."""
    units = [j.unit for j in robot.joints]
    meas = parse_measurements(text, units, source)
    if meas.orientation is None:
        raise DataError(f"{source}: the controller's poses need the orientation columns qw, "
                        f"qx, qy, qz")
    missing = ~np.all(np.isfinite(meas.orientation), axis=1)
    if np.any(missing):
        line = int(meas.rows[np.flatnonzero(missing)[0]])
        raise DataError(f"{source}:{line}: no orientation on this row (qw, qx, qy, qz are "
                        f"needed on every row)")
    joint_columns = [f"q{k + 1}_{u}" for k, u in enumerate(units)]
    decimals = _coarsest(text, source, [*joint_columns, *POSITION_COLUMNS,
                                        *ORIENTATION_COLUMNS])
    half = {c: 0.5 * 10.0 ** -d for c, d in decimals.items()}
    position_m = math.sqrt(3) * max(half[c] for c in POSITION_COLUMNS) * 1e-3
    joint_rad = math.sqrt(len(units)) * max(
        half[c] * (math.pi / 180 if c.endswith("_deg") else 1e-3) for c in joint_columns)
    reach = float(np.max(np.linalg.norm(meas.points, axis=1)))
    quat_rad = 4.0 * max(half[c] for c in ORIENTATION_COLUMNS)
    poses = np.repeat(np.eye(4)[None], meas.n_rows, axis=0)
    poses[:, :3, :3] = matrix_from_quat_wxyz(meas.orientation)
    poses[:, :3, 3] = meas.points
    return ReportedPoses(q_ctrl=meas.joints, base_T_tool=poses, lines=meas.rows,
                         precision_m=position_m + reach * joint_rad,
                         precision_rad=quat_rad + joint_rad, source=source)


def read_reported_poses(path: str | Path, robot: Robot) -> ReportedPoses:
    """Read a CSV of a controller's reported poses (module docstring)."""
    text = read_csv_text(path, "a CSV of the controller's reported poses")
    return parse_reported_poses(text, robot, str(path))
