"""Measurements: measured points (and orientations) of a robot at known joint values.

The type every calibration stage takes; :mod:`olp_compensate.io.measurements` reads and
writes it as the measurement CSV, :mod:`olp_compensate.io.session` from MCAP sessions.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


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
        return len(np.unique(self.pose_ids))

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
