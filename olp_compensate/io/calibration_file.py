"""calib.json, version 1: read, validate against the published schema, write atomically.

The file embeds the robot's URDF and its kinematic fingerprint, so a calibration is
self-contained and is never applied to another robot model. Non-geometric effects are a
list of ``{"kind", "joint" (1-based controller axis, null for arm-wide), "parameters",
"std", "unit"}`` (SI; see :mod:`olp_compensate.calibration.effects`), plus ``"order"`` for a gear
harmonic and ``"reference_temperature_c"`` for thermal expansion; files whose list is empty
(every file written before effects existed) read as before.

A tool identified from full-pose rows also has ``"quat_wxyz"`` (its frame in the flange frame)
and ``"rot_std_deg"`` (standard deviation of a small rotation about the tool's own axes); the
validation then has ``orientation_rms_deg``, ``orientation_max_deg`` and their held-out
counterparts. These keys are optional: files without them read as before.

A tool calibrated for programs (``olp-cal tool``) has ``"for_programs": true``: only such a
tool replaces a program's tool of its name in olp-fix. A tool without the key (every point
of an identification, and every file written before the key existed) is a measured point,
never a program's tool.

A tool point's or the device frame's component that the poses cannot separate from the rest
(``olp-cal identify``: held at its start value, not fitted) is named in the tool's, or in
``device_T_base``'s, ``"held"``: ``{component: why}``, components ``x y z rx ry rz`` of a
tool and ``tx ty tz rx ry rz`` of the device frame. Such a component's std in ``std_mm`` or
``rot_std_deg`` is 0, which is not an uncertainty: the data did not determine it. Files
without the key hold nothing; they read as before.

A calibration with local models per region (``olp-cal identify --per-region``) also has
``"regions"``: a list of ``{"name", "volume": {"min_mm", "max_mm", "margin_mm"} (an
axis-aligned box in the base frame of the global calibration), "model", "device_T_base",
"tools", "effects", "validation"}`` (each as the global calibration stores it, of the same
robot) plus ``"global_heldout_rms_mm"`` and ``"global_heldout_max_mm"`` (the global model's
held-out errors on the region's rows). Files without the key have no regions.

A diagnosis's extended model (``olp-cal diagnose -o``) also has ``"geometric_fallback"``
(the geometric model of the same rows: ``model``, ``device_T_base``, ``tools``,
``effects`` (empty), ``validation``), and each effect its ``"fitted_range"``
(:mod:`olp_compensate.calibration.effect_ranges`): rows outside an effect's range are
predicted and compensated by the fallback. Files without them use the effects everywhere.

A fit written although its own statistics rejected it (``--force``) carries ``"warnings"``:
a list of one-line verdicts (:mod:`olp_compensate.calibration.fit_check`); files without
the key have none.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..calibration.calibration import (Calibration, RegionBox, RegionCalibration, ToolPoint,
                                       Validation)
from ..calibration.unknowns import REGISTRATION_NAMES
from ..kinematics.conventions import matrix_from_quat_wxyz, quat_wxyz_from_matrix
from ..errors import DataError, ModelError
from ..kinematics.model import build_model
from ..kinematics.robot import (Robot, bundled_robot_names, load_robot, ranges_from_edge_units,
                     robot_from_urdf_text)
from .atomic import check_finite_json, write_text_atomic
from .kept_numbers import keep_numbers
from .schemas import schema, schema_bytes, schema_error, validator
from .user_cache import cache_folder

if TYPE_CHECKING:
    from ..calibration.remainder import ResidualMap

LENGTH_OR_ANGLE_LIMIT = 1e6
"""Largest plausible size of a length (mm) or angle (deg) in calib.json (1 km)."""
_MODEL_PATHS = ("model/parameters/*/value", "model/parameters/*/nominal",
                "device_T_base/xyz_mm/*", "tools/*/xyz_mm/*")
PLAUSIBLE_PATHS = (_MODEL_PATHS + ("robot/axis_ranges_deg/*/*", "regions/*/volume/min_mm/*",
                                   "regions/*/volume/max_mm/*")
                   + tuple("regions/*/" + path for path in _MODEL_PATHS))
"""JSON paths (``*``: any key or index) whose numbers are lengths or angles."""

TOOL_COMPONENTS = ("x", "y", "z", "rx", "ry", "rz")
"""A tool's components that can be held (``tool.NAME.x`` ... among a calibration's frozen)."""
DEVICE_COMPONENTS = tuple(name.split(".", 1)[1] for name in REGISTRATION_NAMES)
"""The device frame's components that can be held (``base.tx`` ... ``base.rz``)."""

FORMAT = "olp-compensate calibration"
VERSION = 1


SCHEMA = "calibration-v1.json"


def calibration_schema() -> dict:
    """The JSON schema of calib.json version 1."""
    return schema(SCHEMA)


def _validator():
    """A validator of calib.json documents."""
    return validator(SCHEMA)


def _num(value) -> float | None:
    return None if value is None or not np.isfinite(value) else float(value)


def _model_to_dict(cal: Calibration) -> dict:
    """The parts of calib.json that a region repeats: model, device frame, tools, effects,
    validation (mm and degrees)."""
    params = []
    for k, p in enumerate(cal.model.parameters):
        entry = {"name": p.name, "unit": p.display_unit, "nominal": p.nominal * p.display_scale,
                 "value": float(cal.values[k]) * p.display_scale,
                 "std": _num(cal.std[k] * p.display_scale),
                 "status": "frozen" if p.name in cal.frozen else "identified"}
        if p.name in cal.frozen:
            entry["why"] = cal.frozen[p.name]
        params.append(entry)
    tools = {name: {"xyz_mm": (t.xyz_m * 1e3).tolist(),
                    "std_mm": None if t.std_m is None else (np.asarray(t.std_m) * 1e3).tolist(),
                    "quat_wxyz": None if t.quat_wxyz is None else np.asarray(t.quat_wxyz).tolist()}
             for name, t in cal.tools.items()}
    for name, t in cal.tools.items():
        if t.rot_std_rad is not None:
            tools[name]["rot_std_deg"] = np.degrees(np.asarray(t.rot_std_rad)).tolist()
        if t.for_programs:  # (a tool of `olp-cal tool` in place of a held point holds none)
            tools[name]["for_programs"] = True
        else:
            _put_held(tools[name], cal.frozen, f"tool.{name}.", TOOL_COMPONENTS)
    validation = None
    if cal.validation is not None:
        v = cal.validation
        validation = {"method": v.method, "poses": v.poses, "residual_rms_mm": v.residual_rms_mm,
                      "residual_max_mm": v.residual_max_mm, "heldout_rms_mm": v.heldout_rms_mm,
                      "heldout_max_mm": v.heldout_max_mm, "condition_number": v.condition_number}
        if v.orientation_rms_deg is not None:
            validation.update(orientation_rms_deg=v.orientation_rms_deg,
                              orientation_max_deg=v.orientation_max_deg,
                              heldout_orientation_rms_deg=v.heldout_orientation_rms_deg,
                              heldout_orientation_max_deg=v.heldout_orientation_max_deg)
    device = {"xyz_mm": (cal.device_T_base[:3, 3] * 1e3).tolist(),
              "quat_wxyz": quat_wxyz_from_matrix(cal.device_T_base[:3, :3]).tolist()}
    _put_held(device, cal.frozen, "base.", DEVICE_COMPONENTS)
    return {
        "model": {"convention": cal.model.convention,
                  "links": list(cal.model.conventions), "parameters": params},
        "device_T_base": device,
        "tools": tools,
        "effects": [effect.to_dict() for effect in cal.effects],
        "validation": validation,
    }


def _put_held(entry: dict, frozen: dict[str, str], prefix: str, components) -> None:
    """``entry["held"]``: ``{component: why}`` of the frozen ``prefix + component`` names, in
    the order of ``components``; no key when none is held (files stay as they were)."""
    held = {c: frozen[prefix + c] for c in components if prefix + c in frozen}
    if held:
        entry["held"] = held


def _held(entry: dict, prefix: str, components, where: str) -> dict[str, str]:
    """The frozen names (``prefix + component``: why) of ``entry``'s ``"held"``;
    :class:`ModelError` when it is not ``{component: why}``."""
    held = entry.get("held")
    if held is None:
        return {}
    if not isinstance(held, dict) or any(
            c not in components or not isinstance(why, str) for c, why in held.items()):
        raise ModelError(f"{where}/held: expected {{component: reason}} with components among "
                         f"{', '.join(components)}")
    return {prefix + c: why for c, why in held.items()}


def _region_to_dict(region: RegionCalibration) -> dict:
    """One entry of ``regions`` (mm)."""
    box = region.box
    return {"name": region.name,
            "volume": {"min_mm": (box.min_m * 1e3).tolist(), "max_mm": (box.max_m * 1e3).tolist(),
                       "margin_mm": box.margin_m * 1e3},
            **_model_to_dict(region.calibration),
            "global_heldout_rms_mm": region.global_heldout_rms_mm,
            "global_heldout_max_mm": region.global_heldout_max_mm}


def calibration_to_dict(cal: Calibration) -> dict:
    """The JSON document of a calibration (mm and degrees); ``regions`` only when it has
    some (so a calibration without regions writes what it always wrote)."""
    doc = {
        "format": FORMAT, "version": VERSION,
        "robot": {"name": cal.robot.name, "fingerprint": cal.robot.fingerprint,
                  "joints": cal.robot.n_joints, "urdf": cal.robot.urdf_text,
                  "urdf_from_controller": None if cal.robot.urdf_from_controller is None
                  else cal.robot.urdf_from_controller.tolist(),
                  **({} if cal.robot.axis_ranges is None else {
                      "axis_ranges_deg": cal.robot.to_degrees_or_mm(
                          cal.robot.axis_ranges.T).T.tolist()})},
        **_model_to_dict(cal),
    }
    if cal.regions:
        doc["regions"] = [_region_to_dict(r) for r in cal.regions]
    if cal.warnings:
        doc["warnings"] = list(cal.warnings)
    if cal.residual_map is not None:
        doc["residual_map"] = cal.residual_map.to_dict()
    if cal.geometric_fallback is not None:
        doc["geometric_fallback"] = _model_to_dict(cal.geometric_fallback)
    return doc


@dataclasses.dataclass
class _AsRead:
    """The calib.json document a calibration was read from (``Calibration.as_read``) and
    the robot it was read for; ``again()``: what the calibration as read writes."""

    doc: dict
    robot: Robot | None
    _again: dict | None = None

    def again(self) -> dict:
        if self._again is None:
            self._again = calibration_to_dict(calibration_from_dict(
                self.doc, robot=self.robot, valid=True))
        return self._again


def dumps_calibration(cal: Calibration, source: str = "calibration") -> str:
    """calib.json text; :class:`DataError` when a number is not finite (never written).
    A calibration read from a file writes each number whose value did not change as it
    was read (:mod:`.kept_numbers`): read then written, a file comes back byte for byte."""
    doc = calibration_to_dict(cal)
    if isinstance(cal.as_read, _AsRead):
        doc = keep_numbers(doc, cal.as_read.again(), cal.as_read.doc)
    check_finite_json(doc, source)
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def write_calibration(path: str | Path, cal: Calibration) -> None:
    """Write calib.json atomically."""
    write_text_atomic(path, dumps_calibration(cal, str(path)))


def calibration_from_dict(doc: dict, source: str = "<calibration>",
                          robot: Robot | None = None, *, valid: bool = False) -> Calibration:
    """Rebuild a calibration; ``robot``, when given, must have the file's fingerprint.
    ``valid``: the document is known to match the schema (not checked again)."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ModelError(f"{source}: not an olp-compensate calibration file")
    if doc.get("version") != VERSION:
        raise ModelError(f"{source}: calibration format version {doc.get('version')!r}; this "
                         f"olp-compensate reads version {VERSION}")
    error = None if valid else schema_error(doc, _validator())
    if error is not None:
        raise ModelError(f"{source}: invalid calibration at {error[0]}: {error[1]}")
    _check_square(doc["robot"], "urdf_from_controller", source)
    _check_square(doc["robot"], "axis_ranges_deg", source, columns=2)
    embedded = robot_from_urdf_text(doc["robot"]["urdf"], name=doc["robot"]["name"],
                                    source=f"{source} (embedded URDF)",
                                    urdf_from_controller=doc["robot"].get("urdf_from_controller"))
    if embedded.fingerprint != doc["robot"]["fingerprint"]:
        raise ModelError(f"{source}: the embedded URDF does not match the stored fingerprint "
                         "(the file was edited by hand?)")
    if robot is not None and robot.fingerprint != embedded.fingerprint:
        raise ModelError(f"{source}: this calibration is for robot '{embedded.name}' "
                         f"({embedded.fingerprint[:19]}...), not for '{robot.name}' "
                         f"({robot.fingerprint[:19]}...)")
    embedded = _with_axis_ranges(embedded, doc["robot"].get("axis_ranges_deg"), robot, source)
    calibration = _model_from_dict(doc, embedded, source)
    if doc.get("warnings"):
        calibration = dataclasses.replace(calibration, warnings=tuple(doc["warnings"]))
    if doc.get("residual_map") is not None:
        calibration = dataclasses.replace(
            calibration, residual_map=_residual_map(doc["residual_map"], embedded, source))
    if doc.get("geometric_fallback") is not None:
        calibration = dataclasses.replace(calibration, geometric_fallback=_fallback(
            doc["geometric_fallback"], embedded, source))
    regions = tuple(_region_from_dict(entry, embedded, f"{source}: regions/{k}")
                    for k, entry in enumerate(doc.get("regions", ())))
    try:
        return dataclasses.replace(calibration, regions=regions, as_read=_AsRead(doc, robot))
    except DataError as exc:
        raise ModelError(f"{source}: {exc}") from None


def _fallback(doc: dict, robot: Robot, source: str) -> Calibration:
    """The stored geometric fallback; :class:`ModelError` when it is not a model."""
    where = f"{source}: geometric_fallback"
    try:
        return _model_from_dict(doc, robot, where)
    except (KeyError, TypeError, ValueError, AttributeError, DataError) as exc:
        raise ModelError(f"{where}: {exc!r}") from None


def _residual_map(doc: dict, robot: Robot, source: str) -> ResidualMap:
    """The stored residual map; :class:`ModelError` when its shapes do not fit the robot."""
    from ..calibration.remainder import ResidualMap  # only files that hold one need it

    try:
        rmap = ResidualMap.from_dict(doc)
        n_in = sum(2 if k == "revolute" else 1 for k in rmap.kinds)
        rmap.predict(np.zeros((1, robot.n_joints)))
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"{source}: residual_map: {exc!r}") from None
    if len(rmap.kinds) != robot.n_joints or rmap.frequencies.shape[0] != n_in:
        raise ModelError(f"{source}: residual_map: made for another number of axes")
    return rmap


def _region_from_dict(entry: dict, robot: Robot, source: str) -> RegionCalibration:
    """One entry of ``regions``; :class:`ModelError` for a box that is not one."""
    try:
        box = RegionBox(min_m=np.array(entry["volume"]["min_mm"]) * 1e-3,
                        max_m=np.array(entry["volume"]["max_mm"]) * 1e-3,
                        margin_m=entry["volume"].get("margin_mm", 0.0) * 1e-3)
        return RegionCalibration(name=entry["name"], box=box,
                                 calibration=_model_from_dict(entry, robot, source),
                                 global_heldout_rms_mm=entry.get("global_heldout_rms_mm"),
                                 global_heldout_max_mm=entry.get("global_heldout_max_mm"))
    except DataError as exc:
        raise ModelError(f"{source} ({entry['name']}): {exc}") from None


def _model_from_dict(doc: dict, embedded: Robot, source: str) -> Calibration:
    """The calibration of ``embedded`` held by the model parts of ``doc`` (the top level,
    or one region)."""
    model = build_model(embedded, doc["model"]["convention"])
    by_name = {p["name"]: p for p in doc["model"]["parameters"]}
    values = model.nominal.copy()
    std = np.full(model.n_parameters, np.nan)
    frozen = {}
    for k, p in enumerate(model.parameters):
        if p.name not in by_name:
            raise ModelError(f"{source}: parameter '{p.name}' is missing")
        entry = by_name[p.name]
        values[k] = entry["value"] / p.display_scale
        if entry["std"] is not None:
            std[k] = entry["std"] / p.display_scale
        if entry["status"] == "frozen":
            frozen[p.name] = entry.get("why", "frozen")
    pose = np.eye(4)
    pose[:3, :3] = matrix_from_quat_wxyz(doc["device_T_base"]["quat_wxyz"])
    pose[:3, 3] = np.array(doc["device_T_base"]["xyz_mm"]) * 1e-3
    tools = {}
    for name, t in doc["tools"].items():
        frozen.update(_held(t, f"tool.{name}.", TOOL_COMPONENTS, f"{source}: tools/{name}"))
        tools[name] = ToolPoint(
            xyz_m=np.array(t["xyz_mm"]) * 1e-3,
            std_m=None if t.get("std_mm") is None else np.array(t["std_mm"]) * 1e-3,
            quat_wxyz=None if t.get("quat_wxyz") is None else np.array(t["quat_wxyz"]),
            rot_std_rad=None if t.get("rot_std_deg") is None else np.radians(t["rot_std_deg"]),
            for_programs=bool(t.get("for_programs", False)))
    frozen.update(_held(doc["device_T_base"], "base.", DEVICE_COMPONENTS,
                        f"{source}: device_T_base"))
    v = doc.get("validation")
    validation = None if v is None else Validation(
        method=v["method"], poses=v["poses"], residual_rms_mm=v["residual_rms_mm"],
        residual_max_mm=v["residual_max_mm"], heldout_rms_mm=v["heldout_rms_mm"],
        heldout_max_mm=v["heldout_max_mm"], condition_number=v["condition_number"],
        orientation_rms_deg=v.get("orientation_rms_deg"),
        orientation_max_deg=v.get("orientation_max_deg"),
        heldout_orientation_rms_deg=v.get("heldout_orientation_rms_deg"),
        heldout_orientation_max_deg=v.get("heldout_orientation_max_deg"))
    effects = ()
    if doc["effects"]:  # the effects' module loads only for a calibration that has some
        from ..calibration.effects import effect_from_dict

        effects = tuple(effect_from_dict(e, embedded.n_joints, source) for e in doc["effects"])
    return Calibration(robot=embedded, model=model, values=values, std=std, device_T_base=pose,
                       frozen=frozen, tools=tools, effects=effects,
                       validation=validation)


def _check_square(robot_doc: dict, key: str, source: str, columns: int | None = None) -> None:
    """:class:`ModelError` when ``robot/KEY`` is not a table of ``joints`` rows of
    ``columns`` (default ``joints``) numbers each."""
    table = robot_doc.get(key)
    if table is None:
        return
    n = robot_doc.get("joints")
    width = n if columns is None else columns
    if (not isinstance(table, list) or len(table) != n
            or any(not isinstance(row, list) or len(row) != width for row in table)):
        raise ModelError(f"{source}: robot/{key}: expected {n} rows of {width} numbers")


def _with_axis_ranges(embedded: Robot, ranges_deg, robot: Robot | None, source: str) -> Robot:
    """The embedded robot with the controller's axis ranges: the file's, else those of the
    robot given, else those of the bundled robot of that name and fingerprint (files
    written before the ranges were stored)."""
    if ranges_deg is None:
        known = robot
        if known is None and embedded.name in bundled_robot_names():
            known = load_robot(embedded.name)
        if known is None or known.fingerprint != embedded.fingerprint or known.axis_ranges is None:
            return embedded
        ranges = known.axis_ranges
    else:
        ranges = ranges_from_edge_units(embedded, ranges_deg)
    return robot_from_urdf_text(embedded.urdf_text, name=embedded.name, source=embedded.source,
                                urdf_from_controller=embedded.urdf_from_controller,
                                axis_ranges=ranges)


def _matches(path: list, pattern: str) -> bool:
    parts = pattern.split("/")
    return len(parts) == len(path) and all(p == "*" or p == str(k) for p, k in zip(parts, path))


def _numbers(value, path: list):
    """(JSON path, number) of every number in a document."""
    if isinstance(value, bool):
        return
    if isinstance(value, (int, float)):
        yield path, value
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from _numbers(item, path + [key])
    elif isinstance(value, list):
        for k, item in enumerate(value):
            yield from _numbers(item, path + [k])


def check_numbers(doc, source: str) -> None:
    """:class:`ModelError` naming the JSON path of the first number that is not finite,
    or of a length or angle beyond :data:`LENGTH_OR_ANGLE_LIMIT` (a corrupt or hand-edited
    file; JSON itself has no NaN, but Python's reader accepts it)."""
    for path, value in _numbers(doc, []):
        where = "/".join(map(str, path))
        if path[:2] == ["model", "parameters"] and len(path) > 2:
            entry = doc["model"]["parameters"][path[2]]
            if isinstance(entry, dict) and isinstance(entry.get("name"), str):
                where += f" ({entry['name']})"
        if not np.isfinite(value):
            raise ModelError(f"{source}: {where}: {value} is not a finite number")
        if abs(value) > LENGTH_OR_ANGLE_LIMIT and any(_matches(path, p) for p in PLAUSIBLE_PATHS):
            raise ModelError(f"{source}: {where}: {value:.6g} is beyond any plausible length "
                             f"or angle (at most {LENGTH_OR_ANGLE_LIMIT:g})")


def read_calibration(path: str | Path, robot: Robot | None = None) -> Calibration:
    """Read and validate calib.json (see :func:`calibration_from_dict`).

    A file read whole and valid before (the same bytes, the same schema: a mark named by
    their SHA-256 in the user's cache folder, :mod:`.user_cache`) is not checked against
    the schema again: loading the validator took 50-70 ms of each olp-fix run, and a plant
    runs olp-fix over thousands of programs with one calib.json. Every other check is
    made at every read."""
    path = Path(path)
    try:
        data = path.read_bytes()
        text = data.decode("utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"{path}: cannot read calibration ({exc})") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelError(f"{path}:{exc.lineno}:{exc.colno}: not valid JSON ({exc.msg})") from None
    except RecursionError:
        raise ModelError(f"{path}: not a calibration (nested too deeply)") from None
    check_numbers(doc, str(path))
    mark = _valid_mark(data)
    valid = mark is not None and os.path.exists(mark)
    calibration = calibration_from_dict(doc, str(path), robot, valid=valid)
    if mark is not None and not valid:
        try:
            with open(mark, "x"):
                pass
        except OSError:   # another run made it, or the folder is read-only: no matter
            pass
    return calibration


def _valid_mark(data: bytes) -> str | None:
    """The cache file marking calib.json bytes ``data`` as valid, or None (no cache)."""
    folder = cache_folder()
    if folder is None:
        return None
    from ..kinematics.robot import sha256  # hashlib costs 2-4 ms of a command's start

    digest = sha256(schema_bytes(SCHEMA) + b"\0" + data).hexdigest()
    return os.path.join(folder, f"valid-calibration-{digest}")
