"""Pose lists: a CSV of joint vectors to move the robot to (a planned measurement campaign).

Lines starting with ``#`` are metadata or comments; then a header ``pose, q1_deg .. qN_deg``
(``qK_mm`` for a prismatic joint; controller axis values, as in the measurement CSV) and one
row per pose. Other columns are ignored, so a measurement CSV or an ``olp-cal predict``
output reads as a pose list too; rows that share a ``pose`` id and its joints (several
points measured at one pose) are one pose.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataError
from .atomic import write_text_atomic
from .measurements import joint_columns, open_table, parse_cell_number, read_csv_text

FORMAT_LINE = "# olp-compensate poses v1"


@dataclass(frozen=True)
class PoseList:
    """Poses read from a file: ``joints`` (m, n) controller values, rad (m for prismatic);
    ``pose_ids`` (m,) strings; ``rows``: (m,) 1-based line of each pose in the file."""

    joints: np.ndarray
    pose_ids: list[str]
    rows: list[int]
    metadata: list[str] = field(default_factory=list)
    source: str = "<poses>"


def format_poses(joints: np.ndarray, joint_units: list[str], pose_ids=None,
                 metadata: list[str] | None = None) -> str:
    """CSV text of joint vectors (m, n), SI, written in degrees (mm), 6 decimals."""
    joints = np.atleast_2d(joints)
    if not np.all(np.isfinite(joints)):
        raise DataError("refusing to write a pose list with non-finite joints")
    ids = [str(k + 1) for k in range(len(joints))] if pose_ids is None else list(pose_ids)
    out = io.StringIO()
    for line in [FORMAT_LINE] + list(metadata or []):
        out.write((line if line.startswith("#") else f"# {line}") + "\n")
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["pose"] + joint_columns(joint_units))
    scale = np.array([180.0 / np.pi if u == "deg" else 1e3 for u in joint_units])
    for pose, q in zip(ids, joints * scale):
        writer.writerow([pose] + [f"{v:.6f}" for v in q])
    return out.getvalue()


def write_poses(path: str | Path, joints: np.ndarray, joint_units: list[str], pose_ids=None,
                metadata: list[str] | None = None) -> None:
    """Write a pose list atomically (see :func:`format_poses`)."""
    write_text_atomic(path, format_poses(joints, joint_units, pose_ids, metadata))


def parse_poses(text: str, joint_units: list[str], source: str = "<poses>") -> PoseList:
    """Parse a pose list (or any CSV with the joint columns) for a robot whose joints read
    in ``joint_units`` ('deg' or 'mm' per joint)."""
    columns = joint_columns(joint_units)
    table = open_table(text, source, f"pose, {', '.join(columns)}")
    header, metadata = table.header, table.metadata
    present = [h for h in header if h.startswith("q") and h[1:2].isdigit()]
    if present and len(present) != len(columns):
        raise DataError(f"{source}:{table.header_line}: the file has {len(present)} joint "
                        f"columns ({', '.join(present)}) but the robot has {len(columns)} "
                        f"joints ({', '.join(columns)})")
    index = table.require(columns, source)
    scale = np.array([np.pi / 180.0 if u == "deg" else 1e-3 for u in joint_units])
    joints, ids, rows = [], [], []
    seen: dict[str, int] = {}
    for line, record in table.records:
        q = np.array([parse_cell_number(record[index[c]], source, line, c,
                                        table.decimal_comma) for c in columns]) * scale
        pose = record[index["pose"]].strip() if "pose" in index else ""
        pose = pose or str(len(ids) + 1)
        if pose in seen:
            if not np.allclose(joints[seen[pose]], q, rtol=0.0, atol=1e-9):
                raise DataError(f"{source}:{line}: pose '{pose}' again with other joints (line "
                                f"{rows[seen[pose]]}); give each pose its own id")
            continue
        seen[pose] = len(ids)
        joints.append(q)
        ids.append(pose)
        rows.append(line)
    if not joints:
        raise DataError(f"{source}: no poses after the header")
    return PoseList(joints=np.array(joints), pose_ids=ids, rows=rows, metadata=metadata,
                    source=source)


def read_poses(path: str | Path, joint_units: list[str]) -> PoseList:
    """Read a pose list file (see :func:`parse_poses`)."""
    return parse_poses(read_csv_text(path, "a CSV of joint values"), joint_units, str(path))


def check_within_limits(poses: PoseList, robot) -> None:
    """:class:`DataError` naming file and line for the first pose outside the joint limits
    of ``robot`` (limits apply to its URDF joints; ``poses.joints`` are controller axes)."""
    urdf = robot.joints_from_controller(poses.joints)
    outside = (urdf < robot.lower_limits - 1e-6) | (urdf > robot.upper_limits + 1e-6)
    if np.any(outside):
        row, joint = np.argwhere(outside)[0]
        value = robot.to_degrees_or_mm(poses.joints[row])[joint]
        raise DataError(f"{poses.source}:{poses.rows[row]}: pose '{poses.pose_ids[row]}': "
                        f"q{joint + 1} = {value:.6g} puts joint {joint + 1} outside the limits "
                        f"of {robot.name}")
