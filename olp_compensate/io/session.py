"""Measurement sessions at the robot, recorded in MCAP (openable in Foxglove).

A session file holds two JSON channels (schemas in JSON Schema):

- ``/session/info`` (one message, first): robot name, joint count, joint units, source,
  creation time, format ``olp-compensate session v1``.
- ``/robot/joints`` (one message per pose): ``pose`` (1-based index), ``time_s`` (Unix time,
  s, UTC, when the joints were read), ``controller_time_s`` (the controller's clock or null),
  ``q_deg`` and ``q_rad`` (n values each).

The measuring device (laser tracker, CMM arm) records its points separately;
:func:`merge_session` joins them with the joints, by order or by nearest time, into the
project's measurement CSV (version 1). Files are written to a temporary file in the target
folder and renamed, so none is ever half-written, and an input is never overwritten.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import replace
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..calibration.measurements import Measurements
from ..errors import DataError, OlpError
from . import atomic
from .measurements import open_table, parse_cell_number, read_measurements, write_measurements

if TYPE_CHECKING:  # annotations only: multiprocessing and sockets stay out of identify's start
    from .rtde_source import Ask, JointSource, Say

FORMAT = "olp-compensate session v1"
MCAP_MAGIC = b"\x89MCAP0\r\n"
JOINTS_TOPIC = "/robot/joints"
INFO_TOPIC = "/session/info"

JOINTS_SCHEMA = {
    "title": "olp_compensate.JointReading",
    "type": "object",
    "properties": {
        "pose": {"type": "integer", "description": "1-based pose index"},
        "time_s": {"type": "number", "description": "Unix time of the reading, s (UTC)"},
        "controller_time_s": {"type": ["number", "null"],
                              "description": "controller clock, s since it started"},
        "q_deg": {"type": "array", "items": {"type": "number"}, "description": "joints, deg"},
        "q_rad": {"type": "array", "items": {"type": "number"}, "description": "joints, rad"},
    },
    "required": ["pose", "time_s", "q_deg", "q_rad"],
}
INFO_SCHEMA = {
    "title": "olp_compensate.SessionInfo",
    "type": "object",
    "properties": {
        "format": {"type": "string"}, "robot": {"type": "string"},
        "n_joints": {"type": "integer"},
        "joint_units": {"type": "array", "items": {"type": "string"}},
        "units": {"type": "object"}, "source": {"type": "string"},
        "created_utc": {"type": "string"}, "note": {"type": "string"},
    },
    "required": ["format", "robot", "n_joints"],
}


def _check_new(path: Path, overwrite: bool) -> None:
    if path.exists() and not overwrite:
        raise DataError(f"{path}: already exists; choose another name (sessions are never "
                        f"overwritten)")


def record_session(path, joint_source: JointSource, ask: Ask, say: Say, *, robot_name: str,
                   note: str = "", max_poses: int = 10_000, overwrite: bool = False) -> int:
    """Record joints at each pose into an MCAP session file; returns the number of poses.

    At each pose the technician presses Enter (live source) or types the joints (typed
    source); ``q`` ends the session. If the source fails (lost connection...), the poses
    recorded so far are saved and the error is raised again with the file named.
    """
    path = Path(path)
    _check_new(path, overwrite)
    from mcap.writer import Writer

    fd, tmp = _open_temp(path)
    with os.fdopen(fd, "wb") as stream:
        writer = Writer(stream)
        joints_channel = _start_session(writer, joint_source, robot_name, note)
        say(f"Recording poses of {robot_name} into {path} (joints {joint_source.description}). "
            f"Type q to finish.")
        try:
            count, failure = _record_poses(writer, joints_channel, joint_source, ask, say,
                                           max_poses)
        finally:
            writer.finish()
            stream.flush()
            os.fsync(stream.fileno())
    return _keep_recorded(path, tmp, count, failure, say)


def _open_temp(path: Path) -> tuple[int, str]:
    """(file descriptor, name) of a new tracked temporary file beside ``path``."""
    atomic.remove_stale_temps(path)
    tmp = atomic.temp_name(path)
    atomic.track_temp(tmp)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except OSError as exc:
        atomic.untrack_temp(tmp)
        raise OlpError(f"{path}: cannot write ({exc.strerror})") from None
    return fd, tmp


def _start_session(writer, joint_source: JointSource, robot_name: str, note: str) -> int:
    """Start the MCAP file: both channels and the session's info message; returns the
    joints channel's id."""
    writer.start(profile="", library="olp-compensate")
    joints_channel = writer.register_channel(
        JOINTS_TOPIC, "json", writer.register_schema(
            JOINTS_SCHEMA["title"], "jsonschema", json.dumps(JOINTS_SCHEMA).encode()))
    info_channel = writer.register_channel(
        INFO_TOPIC, "json", writer.register_schema(
            INFO_SCHEMA["title"], "jsonschema", json.dumps(INFO_SCHEMA).encode()))
    now = time.time_ns()
    n = joint_source.n_joints
    info = {"format": FORMAT, "robot": robot_name, "n_joints": n,
            "joint_units": ["deg"] * n,
            "units": {"q_deg": "deg", "q_rad": "rad", "time_s": "s (Unix time, UTC)",
                      "controller_time_s": "s"},
            "source": joint_source.description,
            "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "note": note}
    writer.add_message(info_channel, now, json.dumps(info).encode(), now)
    return joints_channel


def _record_poses(writer, joints_channel: int, joint_source: JointSource, ask: Ask, say: Say,
                  max_poses: int) -> tuple[int, OlpError | KeyboardInterrupt | None]:
    """Capture and write poses until ``q`` or ``max_poses``: (poses recorded, the failure
    that ended the session or None); a failure keeps the poses recorded so far."""
    count = 0
    try:
        for pose in range(1, max_poses + 1):
            reading = joint_source.capture(
                ask, say, f"Pose {pose}: move to the pose and let the device measure", ("q",))
            if isinstance(reading, str):
                break
            q_rad = np.asarray(reading.q_rad, dtype=float)
            message = {"pose": pose, "time_s": reading.time_s,
                       "controller_time_s": reading.controller_time_s,
                       "q_deg": [float(v) for v in np.degrees(q_rad)],
                       "q_rad": [float(v) for v in q_rad]}
            stamp = int(reading.time_s * 1e9)
            writer.add_message(joints_channel, stamp, json.dumps(message).encode(), stamp,
                               sequence=pose)
            count = pose
            say(f"  pose {pose} recorded: q = ("
                + ", ".join(f"{v:.3f}" for v in message["q_deg"]) + ") deg")
    except (OlpError, KeyboardInterrupt) as exc:
        return count, exc
    return count, None


def _keep_recorded(path: Path, tmp: str, count: int,
                   failure: OlpError | KeyboardInterrupt | None, say: Say) -> int:
    """Move the finished temporary file to ``path`` when it holds a pose (else remove it),
    then raise ``failure`` again, naming the file that keeps the poses; returns ``count``."""
    if count == 0:
        atomic.untrack_temp(tmp, remove=True)
        if failure is not None:
            raise failure
        say("No pose recorded; nothing written.")
        return 0
    os.replace(tmp, path)
    atomic.untrack_temp(tmp, written=path)
    if isinstance(failure, KeyboardInterrupt):
        raise failure
    if failure is not None:
        raise type(failure)(f"{failure} (the {count} poses recorded so far are saved in "
                            f"{path})") from failure
    say(f"{count} poses saved in {path}.")
    return count


def read_session(path):
    """Read a session: ``(joints_deg (m, n), times_s (m,) Unix s, info dict)``.

    ``info`` is the ``/session/info`` message plus ``pose`` (m,) indices and
    ``controller_time_s`` (m,) (NaN where unknown).
    """
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    path = Path(path)
    info, rows = None, []
    try:
        with open(path, "rb") as stream:
            for _, channel, message in make_reader(stream).iter_messages(
                    topics=[INFO_TOPIC, JOINTS_TOPIC]):
                data = json.loads(message.data)
                if channel.topic == INFO_TOPIC:
                    info = data
                else:
                    rows.append(data)
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror})") from None
    except (McapError, ValueError, KeyError) as exc:
        raise DataError(f"{path}: not a readable MCAP session ({exc})") from None
    if info is None or info.get("format") != FORMAT:
        raise DataError(f"{path}: no '{INFO_TOPIC}' message of format '{FORMAT}'")
    if not rows:
        raise DataError(f"{path}: the session holds no poses")
    n = int(info["n_joints"])
    bad = [r.get("pose") for r in rows if len(r.get("q_deg", ())) != n]
    if bad:
        raise DataError(f"{path}: pose {bad[0]} has a joint count other than {n}")
    rows.sort(key=lambda r: r["pose"])
    info = dict(info, pose=[int(r["pose"]) for r in rows],
                controller_time_s=[math.nan if r.get("controller_time_s") is None
                                   else float(r["controller_time_s"]) for r in rows])
    return (np.array([r["q_deg"] for r in rows], dtype=float),
            np.array([r["time_s"] for r in rows], dtype=float), info)


def _read_device_csv(path: Path):
    """Device points: rows of x_mm, y_mm, z_mm [, time_s, point, pose] (``#`` lines skipped)."""
    try:
        text = path.read_bytes().decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read ({getattr(exc, 'strerror', None) or exc})") \
            from None
    table = open_table(text, str(path), "x_mm, y_mm, z_mm")
    index = table.require(("x_mm", "y_mm", "z_mm"), str(path))
    rows = []
    for line, record in table.records:
        cell = {h: record[k].strip() for h, k in index.items()}

        def number(column):
            return parse_cell_number(cell[column], str(path), line, column, table.decimal_comma)
        rows.append({"line": line, "xyz": [number(c) for c in ("x_mm", "y_mm", "z_mm")],
                     "time_s": number("time_s") if "time_s" in index else None,
                     "point": cell.get("point") or "tcp", "pose": cell.get("pose") or None})
    if not rows:
        raise DataError(f"{path}: no data rows after the header")
    return rows


def merged_measurements(session_path, device_csv, by: str = "order",
                        tolerance_s: float = 0.5, time_offset_s: float = 0.0):
    """Join device points with recorded joints: ``(Measurements, metadata lines)``.

    ``by='order'``: the k-th device row goes with the k-th pose (or by the device's ``pose``
    column, 1-based). ``by='time'``: each device row goes with the pose read nearest in time
    (device ``time_s`` + ``time_offset_s`` in Unix s), within ``tolerance_s``. Joints in rad,
    points in m (device frame), ``time_s`` in s since the first pose; ``rows`` are the
    device file's line numbers (messages name that file).
    """
    session_path, device_csv = Path(session_path), Path(device_csv)
    if by not in ("order", "time"):
        raise DataError(f"by: expected 'order' or 'time', got {by!r}")
    joints_deg, times, info = read_session(session_path)
    poses = info["pose"]
    device = _read_device_csv(device_csv)
    match = []
    if by == "order" and all(r["pose"] is not None for r in device):
        lookup = {str(p): k for k, p in enumerate(poses)}
        for r in device:
            if r["pose"] not in lookup:
                raise DataError(f"{device_csv}:{r['line']}: column 'pose': the session has no "
                                f"pose {r['pose']} (it has 1..{poses[-1]})")
            match.append(lookup[r["pose"]])
    elif by == "order":
        if len(device) != len(poses):
            raise DataError(f"{device_csv} has {len(device)} points but {session_path} has "
                            f"{len(poses)} poses: add a 'pose' column, or merge by time")
        match = list(range(len(poses)))
    else:
        if device[0]["time_s"] is None:
            raise DataError(f"{device_csv}: merging by time needs a 'time_s' column")
        for r in device:
            gap = np.abs(times - (r["time_s"] + time_offset_s))
            k = int(np.argmin(gap))
            if gap[k] > tolerance_s:
                raise DataError(f"{device_csv}:{r['line']}: no pose within {tolerance_s:g} s of "
                                f"time_s {r['time_s']} (nearest: pose {poses[k]}, "
                                f"{gap[k]:.3f} s away)")
            close = np.flatnonzero(gap <= tolerance_s)
            if len(close) > 1:
                raise DataError(f"{device_csv}:{r['line']}: time_s {r['time_s']} is within "
                                f"{tolerance_s:g} s of poses {poses[close[0]]} and "
                                f"{poses[close[1]]}; lower tolerance_s or merge by order")
            match.append(k)
    match = np.array(match)
    rel_times = np.array([(r["time_s"] + time_offset_s if r["time_s"] is not None
                           else times[k]) - times[0] for r, k in zip(device, match)])
    meas = Measurements(
        joints=np.radians(joints_deg[match]),
        points=np.array([r["xyz"] for r in device]) * 1e-3,
        pose_ids=np.array([str(poses[k]) for k in match], dtype=object),
        point_names=np.array([r["point"] for r in device], dtype=object),
        time_s=rel_times, rows=np.array([r["line"] for r in device]),
        source=str(device_csv))
    metadata = [f"# robot: {info['robot']}", f"# session: {session_path.name}",
                f"# device: {device_csv.name}", f"# merged: by {by}",
                f"# time_zero_unix_s: {times[0]:.3f}"]
    return meas, metadata


def merge_session(session_path, device_csv, out_csv, by: str = "order",
                  tolerance_s: float = 0.5, time_offset_s: float = 0.0) -> int:
    """Join device points with recorded joints into a measurement CSV (version 1).

    Matching as in :func:`merged_measurements`. Output columns:
    ``pose, point, q1_deg..qN_deg, x_mm, y_mm, z_mm, time_s`` (time_s in s since the first
    pose). Returns the number of rows written.
    """
    session_path, device_csv, out_csv = Path(session_path), Path(device_csv), Path(out_csv)
    for source in (session_path, device_csv):
        if source.exists() and out_csv.exists() and out_csv.resolve() == source.resolve():
            raise DataError(f"{out_csv}: is an input of the merge; choose another output file")
    meas, metadata = merged_measurements(session_path, device_csv, by, tolerance_s,
                                         time_offset_s)
    meas = replace(meas, source=str(out_csv))
    write_measurements(out_csv, meas, ["deg"] * meas.joints.shape[1], metadata)
    return meas.n_rows


def is_mcap(path) -> bool:
    """Whether ``path`` starts with the MCAP magic bytes (False when unreadable)."""
    try:
        with open(path, "rb") as stream:
            return stream.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return False


def read_measurements_any(path: str | Path, joint_units: list[str], points=None,
                          by: str = "order", tolerance_s: float = 0.5,
                          time_offset_s: float = 0.0) -> Measurements:
    """Measurements from a measurement CSV, or from an MCAP session plus the device's points.

    ``path``: a measurement CSV (version 1), or an MCAP session written by ``olp-cal record``
    (recognized by its magic bytes, whatever the extension). A session holds joints only, so
    ``points`` (the device's CSV: ``x_mm, y_mm, z_mm`` [, ``time_s``, ``point``, ``pose``])
    is required with it and is joined on the fly ``by`` 'order' or 'time' (see
    :func:`olp_compensate.io.session.merged_measurements`; ``tolerance_s``, ``time_offset_s``
    in s). ``joint_units``: the robot's, 'deg' per joint for a session. Row numbers in
    messages then refer to the points file.
    """
    if not is_mcap(path):
        if points is not None:
            raise DataError(f"{path}: device points go with an MCAP session, and this is not "
                            f"one; a measurement CSV already holds its points")
        return read_measurements(path, joint_units)
    if points is None:
        raise DataError(f"{path}: an MCAP session holds the joints only; give the measuring "
                        f"device's points too (points=..., or merge them first with "
                        f"io.session.merge_session)")
    if any(u != "deg" for u in joint_units):
        raise DataError(f"{path}: sessions hold joints in degrees; this robot has joints in "
                        f"{', '.join(joint_units)}: merge to a CSV and fix the units there")
    meas, metadata = merged_measurements(path, points, by, tolerance_s, time_offset_s)
    if meas.joints.shape[1] != len(joint_units):
        raise DataError(f"{path}: the session has {meas.joints.shape[1]} joints but the robot "
                        f"has {len(joint_units)}")
    return replace(meas, metadata=metadata)
