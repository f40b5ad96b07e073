"""The model a Universal Robots controller runs, from the files that state it.

Three public forms, each kept in its own convention (units SI: m and rad):

- ``calibration.conf`` (the controller's factory calibration): section ``[mounting]`` with
  ``delta_theta``, ``delta_a``, ``delta_d``, ``delta_alpha``, six values each, *added* to the
  data-sheet D-H table (:data:`~olp_compensate.kinematics.dh_table.UR_NOMINAL`); other keys
  (``calibration_status``, ``joint_checksum``...) are kept as text and written back.
- a ``.urp`` program (gzip XML): its first ``<kinematics>`` element holds ``deltaTheta``
  (added to the nominal zero offsets, which are 0) and the *absolute* ``a``, ``d``,
  ``alpha``, each a ``value="v1, ..., v6"`` attribute; UR "linearises" nearly parallel axes,
  so ``d`` may reach hundreds of metres with opposite signs on joints 2-4 (exact, not a
  fault).
- the YAML of ROS's UR calibration tools: ``kinematics:`` with ``shoulder``,
  ``upper_arm``, ``forearm``, ``wrist_1``, ``wrist_2``, ``wrist_3``, each the origin of its
  joint in the previous frame: ``x, y, z`` (m) then ``roll, pitch, yaw`` (rad, URDF's fixed
  axes: ``Rz(yaw) Ry(pitch) Rx(roll)``); the joint turns about the new z. The flange is the
  frame after ``wrist_3``'s joint (UR's D-H frame 6).

Every reader returns a :class:`UrKinematics`; :func:`dumps_ur` writes one back in the same
form (read, write, read gives the same numbers).
"""

from __future__ import annotations

import gzip
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataError, ParseError
from ..kinematics.conventions import matrix_from_euler_zyx
from ..kinematics.dh_table import DHTable
from ..kinematics.fixed_chain import FixedChain

CONF_KEYS = ("delta_theta", "delta_a", "delta_d", "delta_alpha")
URP_KEYS = ("deltaTheta", "a", "d", "alpha")
YAML_SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
YAML_KEYS = ("x", "y", "z", "roll", "pitch", "yaw")
FORMS = ("conf", "urp", "yaml")


@dataclass(frozen=True)
class UrKinematics:
    """A UR controller's model as one file states it.

    ``form``: 'conf' (``deltas`` is the D-H delta table), 'urp' (``table`` absolute, its
    ``theta`` UR's deltaTheta) or 'yaml' (``segments`` (6, 6): x, y, z, roll, pitch, yaw per
    joint); ``extra``: the file's other keys, as text (written back); ``status``: the
    .urp kinematics status attribute."""

    form: str
    deltas: DHTable | None = None
    table: DHTable | None = None
    segments: np.ndarray | None = None
    extra: dict[str, str] = field(default_factory=dict)
    status: str = ""
    notes: tuple[str, ...] = ()
    """What the file says about its own values (a .urp saved uncalibrated, waypoints that
    carry other kinematics)."""

    def chain(self, nominal: DHTable | None = None) -> FixedChain:
        """The controller's chain (base = UR base frame, flange = UR tool flange); the
        'conf' form needs the data-sheet ``nominal`` table its deltas are added to."""
        if self.form == "conf":
            if nominal is None:
                raise DataError("calibration.conf holds deltas: the robot's nominal D-H "
                                "table is needed")
            d = self.deltas
            return nominal.plus(d.theta, d.d, d.a, d.alpha).chain()
        if self.form == "urp":
            return self.table.chain()
        origins = np.array([segment_pose(row) for row in self.segments])
        return FixedChain(first=origins[0], links=np.concatenate([origins[1:], np.eye(4)[None]]))


def segment_pose(row) -> np.ndarray:
    """(4, 4) the origin ``Trans(x, y, z) Rz(yaw) Ry(pitch) Rx(roll)`` of a YAML row."""
    x, y, z, roll, pitch, yaw = (float(v) for v in row)
    pose = np.eye(4)
    pose[:3, :3] = matrix_from_euler_zyx(yaw, pitch, roll)
    pose[:3, 3] = (x, y, z)
    return pose


def segments_from_table(table: DHTable) -> np.ndarray:
    """(6, 6) YAML rows of a D-H table: joint 1's origin ``Tz(d1) Rz(theta1)``, joint i+1's
    ``Tx(a_i) Rx(alpha_i) Tz(d_i+1) Rz(theta_i+1)``; the table's last ``a`` and ``alpha``
    (0 on UR arms) have no place in the YAML (:class:`DataError` if not 0)."""
    if abs(table.a[-1]) > 1e-12 or abs(table.alpha[-1]) > 1e-12:
        raise DataError("the YAML form has no place for a non-zero last a or alpha")
    rows = []
    for i in range(6):
        pose = np.eye(4)
        if i:
            pose[0, 3] = table.a[i - 1]
            pose[:3, :3] = _rx(table.alpha[i - 1])
        step = np.eye(4)
        step[:3, :3] = _rz(table.theta[i])
        step[2, 3] = table.d[i]
        pose = pose @ step
        rows.append([*pose[:3, 3], *_rpy(pose[:3, :3])])
    return np.array(rows)


def _rx(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _rz(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rpy(rotation: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    pitch = math.asin(max(-1.0, min(1.0, -float(rotation[2, 0]))))
    roll = math.atan2(float(rotation[2, 1]), float(rotation[2, 2]))
    yaw = math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))
    return roll, pitch, yaw


# -- calibration.conf -------------------------------------------------------------------

_CONF_LINE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.*?)\s*$")


def _numbers(text: str, count: int, source: str, line: int, column: int, what: str):
    """``count`` numbers of a list ``[a, b, ...]`` or ``a, b, ...``."""
    body = text.strip()
    if body.startswith("["):
        if not body.endswith("]"):
            raise ParseError(f"{what}: expected a list closed by ']', got {text!r}", source,
                             line, column)
        body = body[1:-1]
    cells = [c.strip() for c in body.split(",")]
    values = []
    for cell in cells:
        try:
            value = float(cell)
        except ValueError:
            raise ParseError(f"{what}: expected {count} numbers, got {cell!r}", source, line,
                             column) from None
        if not math.isfinite(value):
            raise ParseError(f"{what}: {cell!r} is not a finite number", source, line, column)
        values.append(value)
    if len(values) != count:
        raise ParseError(f"{what}: expected {count} numbers, got {len(values)}", source, line,
                         column)
    return np.array(values)


def loads_conf(text: str, source: str = "<calibration.conf>") -> UrKinematics:
    """Read a UR ``calibration.conf`` (module docstring)."""
    section, found, extra, seen = None, {}, {}, False
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].split(";", 1)[0] if not raw.lstrip().startswith("[") else raw
        if not line.strip():
            continue
        stripped = line.strip()
        if stripped.startswith("["):
            if not stripped.endswith("]"):
                raise ParseError(f"expected a section header [name], got {stripped!r}", source,
                                 number, raw.index("[") + 1)
            section = stripped[1:-1].strip()
            seen = seen or section == "mounting"
            continue
        match = _CONF_LINE.match(line)
        if match is None:
            raise ParseError(f"expected 'key = value', got {stripped!r}", source, number,
                             len(raw) - len(raw.lstrip()) + 1)
        if section != "mounting":
            continue
        key, value = match.group(1), match.group(2)
        if key in CONF_KEYS:
            found[key] = _numbers(value, 6, source, number, match.start(2) + 1, key)
        else:
            extra[key] = value
    if not seen:
        raise ParseError("no [mounting] section: not a UR calibration.conf", source, 1, 1)
    missing = [k for k in CONF_KEYS if k not in found]
    if missing:
        raise ParseError(f"[mounting] lacks {', '.join(missing)}", source, None)
    deltas = DHTable(found["delta_theta"], found["delta_d"], found["delta_a"],
                     found["delta_alpha"])
    return UrKinematics(form="conf", deltas=deltas, extra=extra)


def _list(values) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def dumps_conf(kin: UrKinematics) -> str:
    """calibration.conf text of deltas (every value with 17 significant digits)."""
    d = kin.deltas
    lines = ["[mounting]"]
    for key, values in zip(CONF_KEYS, (d.theta, d.a, d.d, d.alpha)):
        lines.append(f"{key} = {_list(values)}")
    lines += [f"{key} = {value}" for key, value in kin.extra.items()]
    return "\n".join(lines) + "\n"


# -- .urp -------------------------------------------------------------------------------

def loads_urp(data: bytes, source: str = "<program.urp>") -> UrKinematics:
    """Read the ``<kinematics>`` of a UR program (gzip XML, or plain XML)."""
    try:
        text = gzip.decompress(data) if data[:2] == b"\x1f\x8b" else data
    except (OSError, EOFError) as exc:
        raise ParseError(f"not a readable gzip file ({exc})", source, 1, 1) from None
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        line, column = exc.position
        raise ParseError(f"malformed XML ({exc.msg if hasattr(exc, 'msg') else exc})", source,
                         line, column + 1) from None
    kinematics = next((e for e in root.iter() if e.tag.lower() == "kinematics"), None)
    if kinematics is None:
        raise ParseError("no <kinematics> element: a program saved on a UR controller has "
                         "one", source, 1, 1)
    decoded = text.decode("utf-8", errors="replace")
    values = {}
    for key in URP_KEYS:
        element = kinematics.find(key)
        line = _line_of(decoded, f"<{key} ")
        if element is None or "value" not in element.attrib:
            raise ParseError(f"<kinematics> lacks <{key} value=\"...\"/>", source, line)
        values[key] = _numbers(element.attrib["value"], 6, source, line, None, key)
    table = DHTable(values["deltaTheta"], values["d"], values["a"], values["alpha"])
    extra = {e.tag: e.attrib.get("value", "") for e in kinematics if e.tag not in URP_KEYS}
    status = kinematics.attrib.get("status", "")
    return UrKinematics(form="urp", table=table, extra=extra, status=status,
                        notes=_urp_notes(root, kinematics, status))


def _urp_notes(root, kinematics, status: str) -> tuple[str, ...]:
    """Warnings about a program's kinematics: not calibrated values; waypoints whose own
    ``<Kinematics>`` differ from the program's (saved with another calibration)."""
    notes = []
    if status.upper() == "NOT_INITIALIZED":
        notes.append("kinematics status NOT_INITIALIZED: the program was not saved on a "
                     "calibrated controller; these are the data sheet's values")
    mine = [kinematics.find(k).attrib.get("value", "").replace(" ", "") for k in URP_KEYS]
    other = 0
    for element in root.iter():
        if element is kinematics or element.tag.lower() != "kinematics":
            continue
        theirs = [(element.find(k).attrib.get("value", "") if element.find(k) is not None
                   else "").replace(" ", "") for k in URP_KEYS]
        other += theirs != mine
    if other:
        notes.append(f"{other} waypoint(s) carry other kinematics than the program's (saved "
                     f"with another calibration or robot): the program's are used")
    return tuple(notes)


def _line_of(text: str, needle: str) -> int | None:
    at = text.find(needle)
    return None if at < 0 else text.count("\n", 0, at) + 1


def dumps_urp(kin: UrKinematics, name: str = "olp_compensate") -> bytes:
    """A minimal UR program (gzip XML) holding only the kinematics (mtime 0: the same
    bytes each time)."""
    t = kin.table
    rows = [f'    <{key} value="{", ".join(repr(float(v)) for v in values)}"/>'
            for key, values in zip(URP_KEYS, (t.theta, t.a, t.d, t.alpha))]
    rows += [f'    <{key} value="{value}"/>' for key, value in kin.extra.items()]
    status = kin.status or "LINEARIZED"
    xml = ('<?xml version="1.0" encoding="UTF-8"?>\n'
           f'<URProgram name="{name}">\n  <kinematics status="{status}" validChecksum="false">\n'
           + "\n".join(rows) + "\n  </kinematics>\n  <children/>\n</URProgram>\n")
    return gzip.compress(xml.encode("utf-8"), mtime=0)


# -- ROS YAML ---------------------------------------------------------------------------

def loads_yaml(text: str, source: str = "<calibration.yaml>") -> UrKinematics:
    """Read the ``kinematics:`` YAML of ROS's UR calibration (block mappings of scalars,
    or one ``{k: v, ...}`` flow mapping per segment)."""
    tree = _yaml_tree(text, source)
    kinematics = tree.get("kinematics")
    if not isinstance(kinematics, dict):
        raise ParseError("expected a top-level 'kinematics:' mapping", source, 1, 1)
    rows, extra = [], {}
    for name in YAML_SEGMENTS:
        entry = kinematics.get(name)
        if not isinstance(entry, dict):
            raise ParseError(f"kinematics lacks the segment '{name}'", source,
                             kinematics.get("__line__"))
        row = []
        for key in YAML_KEYS:
            if key not in entry:
                raise ParseError(f"kinematics.{name} lacks '{key}'", source,
                                 entry.get("__line__"))
            value, line = entry[key]
            row.append(_numbers(value, 1, source, line, None, f"kinematics.{name}.{key}")[0])
        rows.append(row)
    for key, value in kinematics.items():
        if key not in YAML_SEGMENTS and key != "__line__" and isinstance(value, tuple):
            extra[key] = value[0]
    return UrKinematics(form="yaml", segments=np.array(rows), extra=extra)


def _yaml_tree(text: str, source: str) -> dict:
    """Nested dicts of a small YAML subset; a scalar is (text, line); each mapping has
    ``__line__``."""
    root: dict = {"__line__": 1}
    stack: list[tuple[int, dict]] = [(-1, root)]
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].rstrip()
        if not line.strip() or line.strip() in ("---", "..."):
            continue
        indent = len(line) - len(line.lstrip(" "))
        if "\t" in line[:indent + 1]:
            raise ParseError("tabs are not allowed for YAML indentation", source, number, 1)
        key, sep, value = line.strip().partition(":")
        if not sep or not key:
            raise ParseError(f"expected 'key: value', got {line.strip()!r}", source, number,
                             indent + 1)
        while stack[-1][0] >= indent:
            stack.pop()
        parent = stack[-1][1]
        key, value = key.strip().strip("'\""), value.strip()
        if not value:
            child = {"__line__": number}
            parent[key] = child
            stack.append((indent, child))
        elif value.startswith("{"):
            if not value.endswith("}"):
                raise ParseError("a flow mapping must close on its line with '}'", source,
                                 number, len(line))
            child = {"__line__": number}
            for item in filter(None, (p.strip() for p in value[1:-1].split(","))):
                k, s, v = item.partition(":")
                if not s:
                    raise ParseError(f"expected 'key: value' in {value!r}", source, number,
                                     indent + 1)
                child[k.strip()] = (v.strip(), number)
            parent[key] = child
        else:
            parent[key] = (value.strip("'\""), number)
    return root


def dumps_yaml(kin: UrKinematics) -> str:
    """The ``kinematics:`` YAML of segments (17 significant digits)."""
    lines = ["kinematics:"]
    for name, row in zip(YAML_SEGMENTS, kin.segments):
        lines.append(f"  {name}:")
        lines += [f"    {key}: {float(v)!r}" for key, v in zip(YAML_KEYS, row)]
    lines += [f"  {key}: {value}" for key, value in kin.extra.items()]
    return "\n".join(lines) + "\n"


# -- by extension -----------------------------------------------------------------------

def form_of(path: str | Path) -> str:
    """'conf', 'urp' or 'yaml' from a file name; :class:`DataError` otherwise."""
    suffix = Path(path).suffix.lower()
    form = {".conf": "conf", ".urp": "urp", ".yaml": "yaml", ".yml": "yaml"}.get(suffix)
    if form is None:
        raise DataError(f"{path}: expected a UR calibration.conf, a .urp program or a "
                        f"calibration .yaml")
    return form


def read_ur_kinematics(path: str | Path) -> UrKinematics:
    """Read any of the three forms, chosen by the file's extension."""
    form = form_of(path)
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror})") from None
    if form == "urp":
        return loads_urp(data, str(path))
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ParseError("not UTF-8 text", str(path), data.count(b"\n", 0, exc.start) + 1) from None
    return loads_conf(text, str(path)) if form == "conf" else loads_yaml(text, str(path))


def dumps_ur(kin: UrKinematics) -> bytes:
    """The file of ``kin`` in its own form."""
    if kin.form == "conf":
        return dumps_conf(kin).encode("utf-8")
    if kin.form == "urp":
        return dumps_urp(kin)
    return dumps_yaml(kin).encode("utf-8")
