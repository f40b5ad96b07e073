"""Stäubli VAL3 configuration rules: ``shoulder``, ``elbow``, ``wrist`` of a ``pointRx``.

Conventions and their sources:

- ``x, y, z`` mm; ``rx, ry, rz`` deg, about x, then the new y, then the new z:
  ``R = Rx(rx) Ry(ry) Rz(rz)`` (VAL3 ``trsf``; RoboDK's VAL3 post writes its poses with
  ``Pose_2_TxyzRxyz``, ``transl(x, y, z) rotx(rx) roty(ry) rotz(rz)``).
- ``config`` (VAL3 type ``config``, Beckhoff/CODESYS uniVAL enumerations that mirror it):
  shoulder ``righty | lefty | ssame | sfree``, elbow ``epositive | enegative | esame |
  efree``, wrist ``wpositive | wnegative | wsame | wfree``. ``epositive``: axis 3 >= 0;
  ``wpositive``: axis 5 >= 0 (VAL3 axis values; zero = stretched arm for the TX2 arms, so
  axis 3 positive is the elbow-up arm, as RoboDK's post writes ``epositive`` for elbow up).
  ``righty``: the arm plane is offset to the right of the line from axis 1 to the wrist
  centre, seen from above, as a human right arm (the PUMA/V+ lineage of the word); for the
  TX2-60, whose forearm sits 20 mm to the left when it reaches forward, the front arm is
  ``lefty`` and the back arm ``righty``, as RoboDK's post writes them (front -> lefty).
  Without a shoulder offset, ``lefty`` is taken as the wrist centre in front of axis 1.
- ``ssame``/``esame``/``wsame`` (keep the current) and ``*free`` (any) do not constrain the
  branch: the one nearest the previous joints is taken, and they are written back as is.
"""

from __future__ import annotations

import numpy as np

from ...compensation.dialect_rules import ArmGeometry, DialectRules
from ...kinematics.conventions import euler_xyz_from_matrix, matrix_from_euler_xyz
from ..emit import format_like
from ..pose_dialects import PoseConvention, PoseTarget
from ..targets import Edit

_SHOULDER = ("righty", "lefty")
_ELBOW = ("epositive", "enegative")
_WRIST = ("wpositive", "wnegative")
_FIELDS = ("x", "y", "z", "rx", "ry", "rz")


def _is_righty(geometry: ArmGeometry, q: np.ndarray) -> bool:
    frames = geometry._frames(q)
    w = geometry.wrist_point_frames(frames)
    o1, z1, z2 = frames[0][:3, 3], frames[0][:3, 2], frames[1][:3, 2]
    d = w - o1
    lateral = (d @ z2) * z2
    reach = d - lateral - (d @ z1) * z1
    if np.linalg.norm(lateral) < 1e-6 or np.linalg.norm(reach) < 1e-9:
        return geometry.in_front_of_axis1(q) < 0
    return float(np.cross(reach, lateral) @ z1) < 0


def val3_config(geometry: ArmGeometry, q: np.ndarray) -> tuple[str, str, str]:
    """(shoulder, elbow, wrist) words of controller axes ``q`` (rad)."""
    return ("righty" if _is_righty(geometry, q) else "lefty",
            "epositive" if q[2] >= 0 else "enegative",
            "wpositive" if q[4] >= 0 else "wnegative")


def val3_written(target: PoseTarget) -> tuple[str, ...]:
    """The configuration words as written (as many as the point writes)."""
    return tuple(n.text for n in target.config)


def _slot(word: str) -> int | None:
    for k, words in enumerate((_SHOULDER, _ELBOW, _WRIST)):
        if word in words:
            return k
    return None


def val3_config_values(geometry: ArmGeometry, q: np.ndarray, target: PoseTarget) -> tuple:
    """The written words with each constraining one replaced by that of ``q``."""
    mine = val3_config(geometry, q)
    return tuple(mine[_slot(w)] if _slot(w) is not None else w for w in val3_written(target))


def val3_choose(geometry: ArmGeometry, target: PoseTarget, branches: np.ndarray, previous):
    wanted = [(slot, w) for w in val3_written(target) if (slot := _slot(w)) is not None]
    candidates = []
    for q in branches:
        if not np.all(np.isfinite(q)):
            continue
        mine = val3_config(geometry, q)
        if all(mine[slot] == w for slot, w in wanted):
            candidates.append(q.copy())
    if not candidates:
        words = " ".join(val3_written(target))
        return None, (f"no solution of the nominal arm has the configuration {words}"
                      if wanted else "the nominal arm does not reach the target")
    reference = np.zeros(len(candidates[0])) if previous is None else previous
    return min(candidates, key=lambda q: float(np.sum((q - reference) ** 2))), None


def val3_config_edits(target: PoseTarget, values: tuple) -> list[Edit]:
    return [Edit(n.start, n.end, v) for n, v in zip(target.config, values) if n.text != v]


def _format(number, value: float, decimals: int, k: int) -> str:
    if number.start == number.end:                  # left out of the file: insert it
        return f' {_FIELDS[k]}="{format_like("0.000", value, decimals)}"'
    return format_like(number.text, value, decimals)


VAL3 = DialectRules(
    name="val3",
    convention=PoseConvention(
        position_scale=1e-3,
        rotation=lambda rxyz: matrix_from_euler_xyz(*np.radians(rxyz)),
        angles=lambda rotation, ref: np.degrees(euler_xyz_from_matrix(rotation,
                                                                     np.radians(ref))),
        position_decimals=3, angle_decimals=3),
    choose=val3_choose, config=val3_config_values, written=val3_written,
    config_edits=val3_config_edits, config_words=lambda values: " ".join(values),
    is_identity=lambda key: key in ("world[0]", "flange[0]", "world", "flange"),
    format_number=_format,
    full_words=lambda geometry, q: " ".join(val3_config(geometry, q)))
