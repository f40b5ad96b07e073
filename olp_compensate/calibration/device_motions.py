"""What a held device-frame component leaves undetermined, said as the rigid motion it is.

When the poses cannot separate a device-registration unknown (``base.tx`` ... ``base.rz``),
the identification holds it at its start value (:mod:`.identifiability`). Which motion of
the device frame that leaves open is a fact of the data: for each held unknown k, the null
vector of the unit-scaled Jacobian that is 1 at k and 0 at every other held unknown (the
null basis ``N`` times the inverse of its held rows: a canonical choice, independent of
the basis an SVD returns) is the change that freezing k forbids. When that vector moves no
model parameter (its geometric part below ``GEOMETRY_SHARE``), it is a rigid motion of the
device frame, alone or with tool points (or frames) that move to match; its registration part, a
small change ``(rho, phi)`` of ``device_T_base = (R0 Exp(phi), t0 + R0 rho)`` at the start
``phi = 0``, moves a point p of the device frame by ``w x p + v`` with ``w = R0 phi`` and
``v = R0 rho - w x t0`` (device frame, rad and m): a screw of axis direction ``w / |w|``
through ``w x v / |w|^2``, pitch ``w.v / |w|^2`` (m/rad), or a translation along ``v`` when
``w`` is nil. A device-only rotation whose axis runs through the measured points is the
line those points lie on (points on one line let the device frame turn about it unseen);
points in a plane leave no device-only motion (a rigid motion fixing three non-collinear
points is the identity). The null space is the start's, where the identification decides
what to hold: a controller's straight line is straight in its nominal model, so the start's
predicted points lie on it exactly while the real arm's are off it by its errors (the ASTL
LINE session's by 0.3 mm, given in the sentence).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GEOMETRY_SHARE = 1e-2
"""A held direction whose model-parameter part (unit-scaled) is below this fraction of it
moves the device frame (and tool points) only: a rigid motion."""
TOOL_SHARE = 1e-2
"""A tool point whose part of the held direction is below this fraction of it stays."""
ROTATION_SHARE = 1e-3
"""A motion whose rotation moves the measured points (RMS distance from their centroid times
the angle) by less than this fraction of its translation is a translation."""
PITCH_SHARE = 1e-2
"""A rotation whose translation along its axis, per radian, is below this fraction of the
measured points' RMS distance from their centroid is a pure rotation."""


@dataclass(frozen=True)
class DeviceMotion:
    """A rigid motion of the device frame that the poses do not determine, held by freezing
    ``component`` (``base.ty``...). ``kind``: 'rotation', 'screw' or 'translation';
    ``direction``: unit axis (rotation, screw) or translation direction, device frame;
    ``point_mm``: the point of the axis nearest the measured points' centroid, device frame,
    mm (None for a translation); ``pitch_mm_per_deg`` (screw; 0 otherwise); ``tools``: the
    tool points (``NAME``) and tool frames (``NAME's frame``) that move with it;
    ``farthest_mm``: the largest distance of a measured point from the axis, mm (None for a
    translation); ``text``: the sentence the report and calib.json give."""

    component: str
    kind: str
    direction: np.ndarray
    point_mm: np.ndarray | None
    pitch_mm_per_deg: float
    tools: tuple[str, ...]
    farthest_mm: float | None
    text: str


def _signed(unit: np.ndarray) -> np.ndarray:
    """``unit`` with its largest component positive (a direction has no sign)."""
    return unit if unit[np.argmax(np.abs(unit))] >= 0 else -unit


def _triple(values: np.ndarray, digits: int) -> str:
    """``(x, y, z)`` to ``digits`` decimals, a zero without its sign."""
    texts = [f"{v:.{digits}f}" for v in values]
    return "(" + ", ".join(t.lstrip("-") if float(t) == 0.0 else t for t in texts) + ")"


def held_motions(problem, held: list[int], null: np.ndarray, geo: np.ndarray,
                 norms: np.ndarray) -> dict[str, DeviceMotion]:
    """Held device-frame unknown name -> :class:`DeviceMotion`, for those of ``held`` (indices
    into ``problem.names()``) whose held direction is rigid. ``null`` (len(geo), d):
    orthonormal null basis of the unit-scaled columns ``geo`` at the start (``x[registration]
    = 0``); ``norms``: the column norms it was scaled by (over all unknowns)."""
    layout, names = problem.layout, problem.names()
    position = {int(k): i for i, k in enumerate(geo)}
    rows = [position[k] for k in held]
    try:
        canonical = np.linalg.solve(null[rows].T, null.T).T  # (len(geo), d): 1 at its own row
    except np.linalg.LinAlgError:
        return {}
    points = problem.measured
    centroid = points.mean(axis=0)
    extent = float(np.sqrt(np.mean(np.sum((points - centroid) ** 2, axis=1))))
    is_geometry = (geo >= layout.geometry.start) & (geo < layout.geometry.stop)
    out = {}
    for j, k in enumerate(held):
        if k >= layout.registration.stop:
            continue
        vec = canonical[:, j]
        size = np.linalg.norm(vec)
        if np.linalg.norm(vec[is_geometry]) > GEOMETRY_SHARE * size:
            continue
        dx = np.zeros(layout.size)
        dx[geo] = vec / norms[geo]
        groups = [*((name, layout.tool_point(t)) for t, name in enumerate(layout.tool_names)),
                  *((f"{name}'s frame", layout.tool_rotation(r))
                    for r, name in enumerate(layout.rotated_tools))]
        tools = tuple(name for name, group in groups
                      if np.linalg.norm(_scaled_part(vec, geo, group)) > TOOL_SHARE * size)
        motion = _motion(problem, dx, centroid, extent, points)
        if motion is not None:
            out[names[k]] = DeviceMotion(component=names[k], tools=tools,
                                         text=_text(*motion, tools), **dict(zip(
                                             ("kind", "direction", "point_mm",
                                              "pitch_mm_per_deg", "farthest_mm"), motion)))
    return out


def _scaled_part(vec: np.ndarray, geo: np.ndarray, group: slice) -> np.ndarray:
    """The entries of ``vec`` (over ``geo``) that belong to the unknowns of ``group``."""
    return vec[(geo >= group.start) & (geo < group.stop)]


def _motion(problem, dx: np.ndarray, centroid: np.ndarray, extent: float,
            points: np.ndarray) -> tuple | None:
    """(kind, direction, point_mm, pitch_mm_per_deg, farthest_mm) of the device-frame motion
    of the registration part of ``dx``, or None when it does not move the frame."""
    layout = problem.layout
    w = problem.r0 @ dx[layout.registration_rotation]
    v = problem.r0 @ dx[layout.registration_translation] - np.cross(w, problem.t0)
    turn, shift = np.linalg.norm(w), np.linalg.norm(v)
    if turn == 0.0 and shift == 0.0:
        return None
    if turn * extent < ROTATION_SHARE * shift:
        return "translation", _signed(v / shift), None, 0.0, None
    axis = _signed(w / turn)
    through = np.cross(w, v) / turn**2
    through = through + axis * float(axis @ (centroid - through))  # nearest the centroid
    pitch = float(w @ v) / turn**2  # m/rad
    offset = points - through
    distance = np.linalg.norm(offset - np.outer(offset @ axis, axis), axis=1)
    farthest = float(distance.max()) * 1e3
    if abs(pitch) < PITCH_SHARE * extent:
        return "rotation", axis, through * 1e3, 0.0, farthest
    return "screw", axis, through * 1e3, float(np.radians(1.0) * pitch * 1e3), farthest


def _text(kind: str, direction: np.ndarray, point_mm, pitch_mm_per_deg: float,
          farthest_mm: float | None, tools: tuple[str, ...]) -> str:
    """The sentence for one held motion (device frame, mm). A rotation of the device frame
    alone can only be unseen when the points the model predicts lie on its axis: then the
    measured points' line is named as such."""
    with_tools = ""
    if tools:
        with_tools = (f" together with tool point{'s' if len(tools) > 1 else ''} "
                      f"{', '.join(tools)} (moved to match)")
    held = "is not determined by these poses: held where the start put it"
    if kind == "translation":
        return (f"the device frame's translation along {_triple(direction, 4)}{with_tools} "
                f"{held}; measure with the flange turned more to fix it")
    whose = "" if tools else ": the measured points' line"
    line = (f"the line through {_triple(point_mm, 1)} mm along {_triple(direction, 4)} "
            f"(device frame; every measured point within {farthest_mm:.1f} mm of it{whose})")
    what = "rotation" if kind == "rotation" else (
        f"screw motion ({pitch_mm_per_deg:.3f} mm along the axis per degree)")
    fix = ("; spread the poses more to fix it" if tools
           else "; measure points off that line to fix it")
    return f"the device frame's {what} about {line}{with_tools} {held}{fix}"
