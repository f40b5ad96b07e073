"""camera.json, version 1: read, validate against the published schema, write atomically.

The file holds the calibrated intrinsics (pixels; ``k1, k2`` dimensionless, distorted to
undistorted, see :mod:`olp_compensate.camera.model`) with their standard deviations (null
where the method gives none: the RAC-only estimate), the RAC estimate beside the refined
one, the fit's reprojection figures, each view's camera pose in the board frame (mm, w-first
quaternion), the views skipped with their reasons, and the board it was calibrated on.
``"scale"`` records where the board's scale came from (``source``: "unverified", "scale
bar" or "reference"; ``factor`` printed / nominal; ``detail``; see
:mod:`olp_compensate.camera.scale`); files without it have an unverified scale. ``"start"`` says where the refinement started
("rac", or "homography" when too few views were tilted for the RAC; then
``"rac_estimate"`` holds that start) and each view's ``"stage"`` how it entered
(:data:`olp_compensate.camera.calibrate.STAGES`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..camera.calibrate import CameraCalibration, Skipped, ViewResult
from ..camera.model import CameraIntrinsics
from ..camera.scale import BoardScale
from ..errors import ModelError
from ..kinematics.conventions import (invert_pose, matrix_from_quat_wxyz,
                                      pose_from_rotation_translation, quat_wxyz_from_matrix)
from .atomic import write_text_atomic
from .schemas import schema, schema_error, validator

FORMAT = "olp-compensate camera"
VERSION = 1

_KEYS = (("fx", "fx_px"), ("mu", "mu"), ("cx", "cx_px"), ("cy", "cy_px"), ("k1", "k1"),
         ("k2", "k2"))
"""(attribute of CameraIntrinsics, key in the file)."""


def camera_schema() -> dict:
    """The JSON schema of camera.json version 1."""
    return schema("camera.schema.json")


def _num(value) -> float | None:
    return None if value is None or not np.isfinite(value) else float(value)


def _intrinsics_dict(k: CameraIntrinsics) -> dict:
    return {key: float(getattr(k, attr)) for attr, key in _KEYS}


def camera_to_dict(cal: CameraCalibration, board: dict | None = None) -> dict:
    """The JSON document of a calibration; ``board`` is the board.json mapping (mm)."""
    views = []
    for v in cal.views:
        board_T_camera = invert_pose(v.camera_T_board)
        views.append({"image": v.name, "rms_px": v.rms_px, "max_px": v.max_px,
                      "tilt_deg": v.tilt_deg, "in_rac": bool(v.in_rac), "stage": v.stage,
                      "xyz_mm": (board_T_camera[:3, 3] * 1e3).tolist(),
                      "quat_wxyz": quat_wxyz_from_matrix(board_T_camera[:3, :3]).tolist()})
    k = cal.intrinsics
    return {
        "format": FORMAT, "version": VERSION,
        "image": {"width": int(k.width), "height": int(k.height)},
        "intrinsics": _intrinsics_dict(k),
        "std": {key: _num(cal.std.get(attr)) for attr, key in _KEYS},
        "method": cal.method,
        "rac_estimate": _intrinsics_dict(cal.rac),
        "fit": {"views": len(cal.views), "rms_px": cal.rms_px, "max_px": cal.max_px,
                "sigma_px": _num(cal.sigma_px), "circle_bias_iterations": cal.bias_iterations},
        "views": views,
        "skipped": [{"image": s.name, "reason": s.reason} for s in cal.skipped],
        "rac_excluded": [{"image": s.name, "reason": s.reason} for s in cal.rac_excluded],
        "board": board,
        "scale": cal.scale.to_dict(),
        "start": cal.start,
    }


def dumps_camera(cal: CameraCalibration, board: dict | None = None) -> str:
    return json.dumps(camera_to_dict(cal, board), indent=2) + "\n"


def write_camera(path: str | Path, cal: CameraCalibration, board: dict | None = None) -> None:
    """Write camera.json atomically."""
    write_text_atomic(path, dumps_camera(cal, board))


def camera_from_dict(doc: dict, source: str = "<camera>") -> CameraCalibration:
    """Rebuild a calibration from its document (validated against the schema)."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ModelError(f"{source}: not an olp-compensate camera file")
    if doc.get("version") != VERSION:
        raise ModelError(f"{source}: camera format version {doc.get('version')!r}; this "
                         f"olp-compensate reads version {VERSION}")
    error = schema_error(doc, validator("camera.schema.json"))
    if error is not None:
        raise ModelError(f"{source}: invalid camera file at {error[0]}: {error[1]}")
    size = doc["image"]

    def intrinsics(d):
        return CameraIntrinsics(**{attr: d[key] for attr, key in _KEYS},
                                width=size["width"], height=size["height"])

    views = tuple(ViewResult(
        v["image"], invert_pose(pose_from_rotation_translation(
            matrix_from_quat_wxyz(v["quat_wxyz"]), np.array(v["xyz_mm"]) * 1e-3)),
        v["rms_px"], v["max_px"], v["tilt_deg"], v["in_rac"],
        v.get("stage", "rac" if v["in_rac"] else "rac-pose")) for v in doc["views"])
    fit = doc["fit"]
    return CameraCalibration(
        intrinsics=intrinsics(doc["intrinsics"]),
        std={attr: float("nan") if doc["std"][key] is None else doc["std"][key]
             for attr, key in _KEYS},
        rac=intrinsics(doc["rac_estimate"]), method=doc["method"], views=views,
        skipped=tuple(Skipped(s["image"], s["reason"]) for s in doc["skipped"]),
        rms_px=fit["rms_px"], max_px=fit["max_px"],
        sigma_px=float("nan") if fit["sigma_px"] is None else fit["sigma_px"],
        rac_excluded=tuple(Skipped(s["image"], s["reason"])
                           for s in doc.get("rac_excluded", [])),
        bias_iterations=fit["circle_bias_iterations"],
        scale=BoardScale.from_dict(doc.get("scale")), start=doc.get("start", "rac"))


def read_camera(path: str | Path) -> CameraCalibration:
    """Read and validate camera.json (see :func:`camera_from_dict`)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"{path}: cannot read camera file ({exc})") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelError(f"{path}:{exc.lineno}:{exc.colno}: not valid JSON ({exc.msg})") from None
    return camera_from_dict(doc, str(path))
