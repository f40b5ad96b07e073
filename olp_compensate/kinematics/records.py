"""Robot records: one compact JSON description per arm (``robots/NAME.robot.json``).

A record holds the arm's geometry in one of two kinds, the controller's axis ranges and
couplings, speeds, masses and the maker; the URDF the rest of the package reads is generated
from it (:func:`urdf_from_record`), so a robot is one file. The format is documented in
``robots/README.md``. Units in a record: metres for lengths, degrees for angles and axis
ranges, deg/s for speeds, kg, N·m.

Geometry kinds:

- ``opw``: the seven lengths of an ortho-parallel arm with a spherical wrist (a1, a2, b, c1,
  c2, c3, c4; Brandstoetter et al. 2014, the convention of opw_kinematics) with the joint
  ``offsets_deg`` and ``signs`` that turn controller axis values into model angles
  (``theta = sign * q - offset``). ``base_height`` (m) puts the robot's base frame that far
  above the OPW root (FANUC and Staubli base frames sit at the height of axis 2), and
  ``flange_rpy_deg`` turns the OPW tip frame into the maker's flange frame.
  The URDF uses the ROS-Industrial layout: every link frame parallel to the base at zero.
- ``dh``: a standard Denavit-Hartenberg table (``d``, ``a`` in m, ``alpha_deg``,
  ``offsets_deg``, ``signs``; ``theta_i = sign_i q_i + offset_i``), for arms that are not OPW
  (Universal Robots, PUMA 560). The URDF's ``link_i`` frame is DH frame i-1 turned by q_i.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ModelError

RECORD_SUFFIX = ".robot.json"
OPW_LENGTHS = ("a1", "a2", "b", "c1", "c2", "c3", "c4")
COUPLINGS = {
    "abb_parallel": ((2, 1, -1.0),),   # URDF joint_3 = q3 - q2 (ABB parallel linkage)
    "fanuc_j2_j3": ((2, 1, 1.0),),     # URDF joint_3 = J2 + J3 (FANUC J3 from the horizontal)
}
DIALECTS = {"ABB": "rapid", "KUKA": "krl", "FANUC": "fanuc_tp", "Staubli": "val3",
            "Universal Robots": "urscript", "Kawasaki": "as", "Unimation": "vplus"}
# Estimated share of the total mass per link (base, link_1..link_6) when a record gives no
# inertials: a placeholder for gravity torques, documented in robots/README.md.
MASS_SHARES = (0.30, 0.25, 0.18, 0.12, 0.08, 0.05, 0.02)


@dataclass(frozen=True)
class LinkInertial:
    """Mass (kg), centre of mass (m, link frame) and inertia about it (kg·m², link frame:
    ixx, ixy, ixz, iyy, iyz, izz) of one link."""

    mass: float
    com: tuple
    inertia: tuple


@dataclass(frozen=True)
class RobotRecord:
    """A parsed ``NAME.robot.json`` (see the module docstring for units)."""

    name: str
    maker: str
    model: str
    geometry: dict
    axis_ranges_deg: np.ndarray
    coupling: np.ndarray | None
    max_speed_deg_s: tuple | None
    effort_nm: tuple | None
    payload_kg: float | None
    mass_kg: float | None
    links: tuple | None
    reach_mm: float | None
    datasheet: dict
    sources: tuple
    source: str

    @property
    def kind(self) -> str:
        return self.geometry["kind"]

    @property
    def dialect(self) -> str | None:
        """The program language of the maker's controller (None: not supported)."""
        return DIALECTS.get(self.maker)

    @property
    def coupling_name(self) -> str | None:
        return self.geometry.get("coupling_name")


def _fail(where: str, message: str):
    raise ModelError(f"{where}: {message}")


def _numbers(doc: dict, key: str, where: str, count: int | None = None, optional=False):
    value = doc.get(key)
    if value is None:
        if optional:
            return None
        _fail(where, f"'{key}' is missing")
    flat = value if isinstance(value, list) else [value]
    if (not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in flat)
            or (count is not None and len(flat) != count)
            or not all(math.isfinite(v) for v in flat)):
        want = "a number" if count is None else f"{count} numbers"
        _fail(where, f"'{key}' must be {want}, got {value!r}")
    return value


def _coupling(doc: dict, where: str) -> np.ndarray | None:
    value = doc.get("coupling")
    if value is None:
        return None
    if isinstance(value, str):
        if value not in COUPLINGS:
            _fail(where, f"unknown coupling '{value}' (known: {', '.join(sorted(COUPLINGS))})")
        matrix = np.eye(6)
        for row, column, factor in COUPLINGS[value]:
            matrix[row, column] = factor
        return matrix
    matrix = np.array(value, dtype=float)
    if matrix.shape != (6, 6) or abs(np.linalg.det(matrix)) < 1e-9:
        _fail(where, "'coupling' must be a name or an invertible 6x6 matrix")
    return matrix


def _geometry(doc: dict, where: str) -> dict:
    geometry = doc.get("geometry")
    if not isinstance(geometry, dict) or geometry.get("kind") not in ("opw", "dh"):
        _fail(where, "'geometry' must be an object with \"kind\": \"opw\" or \"dh\"")
    here = f"{where}: geometry"
    out = {"kind": geometry["kind"], "source": geometry.get("source", "")}
    if geometry["kind"] == "opw":
        for key in OPW_LENGTHS:
            out[key] = float(_numbers(geometry, key, here))
        out["base_height"] = float(_numbers(geometry, "base_height", here, optional=True) or 0.0)
        out["flange_rpy_deg"] = tuple(_numbers(geometry, "flange_rpy_deg", here, 3, True)
                                      or (0.0, 0.0, 0.0))
    else:
        for key in ("d", "a", "alpha_deg"):
            out[key] = tuple(float(v) for v in _numbers(geometry, key, here, 6))
    out["offsets_deg"] = tuple(float(v) for v in _numbers(geometry, "offsets_deg", here, 6, True)
                               or (0.0,) * 6)
    signs = _numbers(geometry, "signs", here, 6, True) or (1,) * 6
    if any(s not in (1, -1) for s in signs):
        _fail(here, f"'signs' must be six values of 1 or -1, got {signs!r}")
    out["signs"] = tuple(int(s) for s in signs)
    return out


def _links(doc: dict, where: str) -> tuple | None:
    links = doc.get("links")
    if links is None:
        return None
    if not isinstance(links, list) or len(links) != 7:
        _fail(where, "'links' must list 7 inertials (base_link, link_1 ... link_6)")
    out = []
    for k, link in enumerate(links):
        here = f"{where}: links/{k}"
        if not isinstance(link, dict):
            _fail(here, "expected an object with mass_kg, com_m, inertia_kgm2")
        out.append(LinkInertial(float(_numbers(link, "mass_kg", here)),
                                tuple(_numbers(link, "com_m", here, 3)),
                                tuple(_numbers(link, "inertia_kgm2", here, 6))))
    return tuple(out)


def record_from_dict(doc: dict, where: str) -> RobotRecord:
    """Validate a record document; :class:`ModelError` naming ``where`` and the key."""
    if not isinstance(doc, dict):
        _fail(where, "a robot record must be a JSON object")
    for key in ("name", "maker", "model"):
        if not isinstance(doc.get(key), str) or not doc[key]:
            _fail(where, f"'{key}' must be a non-empty string")
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.+\-]*", doc["name"]):
        _fail(where, f"'name' must be letters, digits, '_', '.', '+' or '-', got {doc['name']!r}")
    try:
        ranges = np.array(doc.get("axis_ranges_deg"), dtype=float)
    except (TypeError, ValueError):
        ranges = np.empty(0)
    if (ranges.shape != (6, 2) or not np.all(np.isfinite(ranges))
            or np.any(ranges[:, 0] > ranges[:, 1])):
        _fail(where, "'axis_ranges_deg' must be six [lower, upper] pairs, lower <= upper")
    speeds = _numbers(doc, "max_speed_deg_s", where, 6, optional=True)
    efforts = _numbers(doc, "effort_nm", where, 6, optional=True)
    datasheet = doc.get("datasheet") or {}
    if not isinstance(datasheet, dict):
        _fail(where, "'datasheet' must be an object")
    sources = doc.get("sources") or []
    geometry = _geometry(doc, where)
    coupling = doc.get("coupling")
    geometry["coupling_name"] = coupling if isinstance(coupling, str) else None
    return RobotRecord(
        name=doc["name"], maker=doc["maker"], model=doc["model"], geometry=geometry,
        axis_ranges_deg=ranges, coupling=_coupling(doc, where),
        max_speed_deg_s=None if speeds is None else tuple(speeds),
        effort_nm=None if efforts is None else tuple(efforts),
        payload_kg=_numbers(doc, "payload_kg", where, optional=True),
        mass_kg=_numbers(doc, "mass_kg", where, optional=True),
        links=_links(doc, where), reach_mm=_numbers(doc, "reach_mm", where, optional=True),
        datasheet=datasheet, sources=tuple(sources), source=where)


def read_record(path: Path | str, where: str | None = None) -> RobotRecord:
    """Read and validate ``NAME.robot.json``; :class:`ModelError` for any defect."""
    where = where or str(path)
    try:
        text = Path(path).read_text(encoding="utf-8") if isinstance(path, (str, Path)) \
            else path.read_text(encoding="utf-8")
        doc = json.loads(text)
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"{where}: cannot read the robot record ({exc})") from None
    except json.JSONDecodeError as exc:
        raise ModelError(f"{where}:{exc.lineno}:{exc.colno}: not valid JSON ({exc.msg})") from None
    return record_from_dict(doc, where)
