"""Measurements: measured points (and orientations) of a robot at known joint values.

The type every calibration stage takes; :mod:`olp_compensate.io.measurements` reads and
writes it as the measurement CSV, :mod:`olp_compensate.io.session` from MCAP sessions.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError


@dataclass(frozen=True)
class Measurements:
    """Measured points, one row each, in the units of the file converted to SI.

    ``joints``: (m, n) rad (m for prismatic); ``points``: (m, 3) device frame, m;
    ``pose_ids`` and ``point_names``: (m,) strings; ``orientation``: (m, 4) unit quaternion
    (w, x, y, z) of the measured point's frame in the device frame (module docstring), NaN
    on position-only rows, or None; optional per-row columns (m,) or None; ``extra``: unknown columns,
    kept as text; ``rows``: (m,) 1-based line numbers in the file (for messages).
    """

    joints: np.ndarray
    points: np.ndarray
    pose_ids: np.ndarray
    point_names: np.ndarray
    orientation: np.ndarray | None = None
    payload_kg: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    time_s: np.ndarray | None = None
    directions: np.ndarray | None = None
    extra: dict[str, list[str]] = field(default_factory=dict)
    metadata: list[str] = field(default_factory=list)
    rows: np.ndarray | None = None
    source: str = "<measurements>"

    @property
    def n_rows(self) -> int:
        return len(self.points)

    @property
    def n_poses(self) -> int:
        return len(set(self.pose_ids))

    def subset(self, mask: np.ndarray) -> "Measurements":
        """The rows selected by a boolean mask or index array."""
        def pick(a):
            return None if a is None else a[mask]
        return Measurements(
            joints=self.joints[mask], points=self.points[mask], pose_ids=self.pose_ids[mask],
            point_names=self.point_names[mask], orientation=pick(self.orientation),
            payload_kg=pick(self.payload_kg), temperature_c=pick(self.temperature_c),
            time_s=pick(self.time_s), directions=pick(self.directions),
            extra={k: list(np.asarray(v, dtype=object)[mask]) for k, v in self.extra.items()},
            metadata=self.metadata, rows=pick(self.rows), source=self.source)


SAME_POSE_RAD = 1e-6
"""Two rows whose joints differ by less than this (rad or m) in every joint are one pose."""
SAME_POINT_M = 1e-6
"""Measured points closer than this (m) in every coordinate are one point."""


def distinct_poses(meas: Measurements) -> int:
    """How many different joint vectors the rows hold (repeated poses count once)."""
    if meas.n_rows == 0:
        return 0
    keys = np.round(np.asarray(meas.joints, dtype=float) / SAME_POSE_RAD) + 0.0  # no -0.0
    # a set, not np.unique: that imports numpy.ma (10-25 ms of olp-cal identify's start)
    return len(set(map(tuple, keys.tolist())))


def check_finite(meas: Measurements) -> None:
    """:class:`DataError` naming the first row holding a non-finite joint or point (the
    readers refuse them already; this guards measurements built in code)."""
    for name, values in (("joints", meas.joints), ("points", meas.points)):
        bad = ~np.isfinite(np.asarray(values, dtype=float))
        if np.any(bad):
            row = int(np.argwhere(bad)[0][0])
            line = meas.rows[row] if meas.rows is not None else row + 1
            raise DataError(f"{meas.source}:{line}: {name} hold a non-finite number")


def minimum_poses(n_unknowns: int, equations_per_pose: int) -> int:
    """Fewest distinct poses that give at least one equation per unknown, plus one pose
    of redundancy for the noise estimate."""
    return -(-n_unknowns // max(equations_per_pose, 1)) + 1


def check_spread(meas: Measurements, n_unknowns: int) -> None:
    """:class:`DataError` saying what to add when the data cannot determine ``n_unknowns``
    parameters: non-finite numbers, every measured point the same (the device did not see
    the robot move), or fewer distinct poses than the unknowns need (repeated rows of one
    pose add no information about the geometry).

    ``n_unknowns``: the fit's unknowns (device registration, geometry, tool points)."""
    check_finite(meas)
    if meas.n_rows == 0:
        raise DataError(f"{meas.source}: no measured rows")
    poses = distinct_poses(meas)
    points_per_pose = max(1, len(set(meas.point_names)))
    equations = 3 * points_per_pose
    if meas.orientation is not None and np.any(np.isfinite(meas.orientation)):
        equations += 3
    needed = minimum_poses(n_unknowns, equations)
    if poses < needed:
        rows = f"{meas.n_rows} row{'s' if meas.n_rows != 1 else ''}"
        verb = "holds" if meas.n_rows == 1 else "hold"
        raise DataError(f"{meas.source}: {rows} {verb} only {poses} distinct "
                        f"pose{'s' if poses != 1 else ''}, and {n_unknowns} unknowns need at "
                        f"least {needed}; measure {needed - poses} or more poses that differ "
                        f"in every joint (repeating a pose only measures the noise)")
    points = np.asarray(meas.points, dtype=float)
    span = points.max(axis=0) - points.min(axis=0)
    if np.all(span < SAME_POINT_M):
        where = ", ".join(f"{v * 1e3:.6g}" for v in points[0])
        raise DataError(f"{meas.source}: every measured point is the same ({where}) mm: the "
                        f"device did not see the robot move; check the x_mm, y_mm, z_mm "
                        f"columns")


def row_sigma_scales(meas: Measurements, position_sigma_m: float, rotation_sigma_rad: float
                     ) -> tuple[np.ndarray, np.ndarray] | None:
    """Per-row weights from the optional columns ``sigma_mm`` (a row's position uncertainty,
    mm per axis) and ``sigma_deg`` (its orientation uncertainty, deg per axis), as written
    by ``olp-cal camera measure`` or a tracker: ``(position_sigma_m / s, rotation_sigma_rad
    / s)``, each (m,), with ``s = sqrt(stated^2 + default^2)``; 1 where a cell is empty;
    None without either column. :class:`DataError` (file, line, column) for a cell that is
    not a positive number.

    The defaults (``IdentificationOptions.position_sigma_mm``, ``orientation_sigma_deg``)
    are added in quadrature because a row's error holds more than the instrument states
    (the robot's repeatability, what the model leaves): a stated figure well below the
    default adds nothing, one above it down-weights its row by (default / s)^2. The ASTL
    tracker states 0.0006-0.013 mm per axis, uncorrelated with its rows' residuals (0.04 mm
    RMS in every quartile of the stated figure), and weighted as stated, or floored at
    their median, they fitted worse than no weights; on a virtual tracker whose noise grows
    with distance the quadrature keeps most of what truthful figures give (README,
    "Per-row sigmas")."""
    columns = [c for c in ("sigma_mm", "sigma_deg") if c in meas.extra]
    if not columns:
        return None
    scales = []
    for column, default, unit in (("sigma_mm", position_sigma_m, 1e-3),
                                  ("sigma_deg", rotation_sigma_rad, np.pi / 180)):
        sigma = np.full(meas.n_rows, default, dtype=float)
        for k, text in enumerate(meas.extra.get(column, [])):
            text = str(text).strip()
            if not text:
                continue
            try:
                value = float(text)
            except ValueError:
                value = float("nan")
            if not (np.isfinite(value) and value > 0):
                line = meas.rows[k] if meas.rows is not None else k + 1
                raise DataError(f"{meas.source}:{line}: column '{column}': expected a positive "
                                f"number, got '{text}'")
            sigma[k] = value * unit
        stated = np.array([bool(str(t).strip()) for t in meas.extra.get(column, [])], bool)
        if stated.any():
            sigma[stated] = np.hypot(sigma[stated], default)
        scales.append(default / sigma)
    return scales[0], scales[1]
