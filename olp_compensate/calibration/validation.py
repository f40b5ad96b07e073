"""Validation: how well a calibration predicts measurements the fit never saw.

Seed sections 6 and 10 state accuracy as the average position error and its standard
deviation "before and after calibration" in each region and volume. Here, per measured row:

- **after**: the distance between the measured point and the calibrated model's prediction
  in its own device frame, exactly as ``olp-cal predict`` gives it (no re-fit of anything);
- **before**: the distance between the measured point and the *nominal* arm's prediction
  (the same tool points) after a rigid registration of the device frame to these same
  measurements (Kabsch): the best a user gets without calibrating the arm.

Figures of the error norms: mean, standard deviation (n - 1), median, 95th percentile
(linear interpolation between order statistics, numpy's default) and maximum; overall and
per region. Regions come from the measurements' ``region`` column, or (the hook for
calibration volumes) from cubes containing each point in the base frame
(:class:`olp_compensate.calibration.volumes.CubeVolume` or anything with ``name``,
``centre_m`` and ``contains(points_base_m)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Protocol, Sequence

import numpy as np

from ..errors import DataError
from .calibration import Calibration, nominal_calibration
from .effects import Conditions
from .measurements import Measurements
from .registration import kabsch

OUTSIDE = "outside"
"""Region label of rows that lie in none of the given volumes."""


class Volume(Protocol):
    """What validation needs of a calibration volume (base frame, metres)."""

    name: str
    centre_m: np.ndarray

    def contains(self, points_base_m: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of position-error norms, m: ``n`` rows, ``mean``, ``std`` (sample, n - 1;
    NaN for one row), ``median``, ``p95`` (linear interpolation), ``max``."""

    n: int
    mean: float
    std: float
    median: float
    p95: float
    max: float

    def to_dict_mm(self) -> dict:
        """``{"mean", "std", "median", "p95", "max"}`` in mm (None where undefined)."""
        return {key: (None if not math.isfinite(v) else v * 1e3) for key, v in
                (("mean", self.mean), ("std", self.std), ("median", self.median),
                 ("p95", self.p95), ("max", self.max))}


def error_stats(errors_m) -> ErrorStats:
    """:class:`ErrorStats` of error norms (k,), m; DataError when there are none."""
    e = np.asarray(errors_m, dtype=float).ravel()
    if e.size == 0:
        raise DataError("no errors to summarize (no rows)")
    return ErrorStats(n=int(e.size), mean=float(np.mean(e)),
                      std=float(np.std(e, ddof=1)) if e.size > 1 else math.nan,
                      median=float(np.median(e)), p95=float(np.percentile(e, 95)),
                      max=float(np.max(e)))


@dataclass(frozen=True)
class RegionFigures:
    """Before and after statistics of the rows labelled ``name``."""

    name: str
    before: ErrorStats
    after: ErrorStats


@dataclass(frozen=True)
class ValidationReport:
    """The validation of a calibration on measurements.

    ``errors_before_m``, ``errors_after_m``: (m,) position-error norm per row, m.
    ``residuals_after_m`` (m, 3): measured minus predicted, device frame. ``points_base_m``
    (m, 3): the measured points in the calibration's base frame. ``joints`` (m, n)
    controller axes, rad. ``registration``: the device_T_base (4, 4) fitted to the nominal
    arm for 'before'. ``centre_m`` (3,): base frame centre the distances are taken from,
    named by ``centre_source``. ``labels`` (m,): region of each row (None without regions).
    """

    source: str
    robot: str
    before: ErrorStats
    after: ErrorStats
    regions: tuple[RegionFigures, ...]
    errors_before_m: np.ndarray = field(repr=False)
    errors_after_m: np.ndarray = field(repr=False)
    residuals_after_m: np.ndarray = field(repr=False)
    points_base_m: np.ndarray = field(repr=False)
    joints: np.ndarray = field(repr=False)
    registration: np.ndarray = field(repr=False)
    centre_m: np.ndarray
    centre_source: str
    labels: np.ndarray | None = field(default=None, repr=False)

    @property
    def n(self) -> int:
        return self.after.n

    @property
    def distance_from_centre_m(self) -> np.ndarray:
        """(m,) distance of each measured point from ``centre_m``, base frame, m."""
        return np.linalg.norm(self.points_base_m - self.centre_m, axis=1)


def _conditions(meas: Measurements) -> Conditions | None:
    if meas.payload_kg is None and meas.temperature_c is None and meas.directions is None:
        return None
    return Conditions(payload_kg=meas.payload_kg, temperature_c=meas.temperature_c,
                      directions=meas.directions)


def nominal_registered_errors(calibration: Calibration, meas: Measurements):
    """(errors (m,), device_T_base (4, 4)): the nominal arm with the calibration's tool
    points, its device frame registered rigidly to the measured points (Kabsch)."""
    nominal = replace(nominal_calibration(calibration.robot), tools=dict(calibration.tools))
    flange = nominal.flange_poses(meas.joints)
    local = nominal.tool_points(list(meas.point_names))
    base = flange[:, :3, 3] + np.einsum("mij,mj->mi", flange[:, :3, :3], local)
    if len(base) < 3:
        raise DataError(f"{meas.source}: validation needs at least 3 measured points to "
                        f"register the nominal arm, got {len(base)}")
    device_T_base = kabsch(base, meas.points)
    predicted = base @ device_T_base[:3, :3].T + device_T_base[:3, 3]
    return np.linalg.norm(meas.points - predicted, axis=1), device_T_base


def region_labels(meas: Measurements, points_base_m: np.ndarray,
                  volumes: Sequence[Volume] | None = None) -> np.ndarray | None:
    """(m,) region of each row: the ``region`` column when the measurements have one, else
    the first of ``volumes`` that contains the point (base frame), else :data:`OUTSIDE`;
    None when there is neither."""
    column = meas.extra.get("region")
    if column is not None:
        labels = np.array([str(v).strip() for v in column], dtype=object)
        empty = [int(r) for r, v in zip(meas.rows if meas.rows is not None
                                        else range(1, len(labels) + 1), labels) if not v]
        if empty:
            raise DataError(f"{meas.source}:{empty[0]}: column 'region': empty (name the "
                            f"region of every row, or drop the column)")
        return labels
    if not volumes:
        return None
    labels = np.full(len(points_base_m), OUTSIDE, dtype=object)
    for volume in reversed(list(volumes)):   # the first volume wins where they overlap
        labels[np.asarray(volume.contains(points_base_m), bool)] = volume.name
    return labels


def validate(calibration: Calibration, meas: Measurements,
             volumes: Sequence[Volume] | None = None,
             centre_m: np.ndarray | None = None) -> ValidationReport:
    """Validate ``calibration`` on ``meas`` (controller joints, device-frame points).

    ``volumes``: calibration volumes (base frame) that label rows without a ``region``
    column and, when there is one, give the centre for the distance figure; ``centre_m``
    (3,), base frame, overrides it (default: the centroid of the validation points).
    """
    if meas.n_rows == 0:
        raise DataError(f"{meas.source}: no rows to validate")
    if meas.joints.shape[1] != calibration.robot.n_joints:
        raise DataError(f"{meas.source}: {meas.joints.shape[1]} joints per row, the "
                        f"calibration's robot {calibration.robot.name} has "
                        f"{calibration.robot.n_joints}")
    names = list(meas.point_names)
    predicted = calibration.predict_points(meas.joints, names, _conditions(meas))
    residuals = meas.points - predicted
    after = np.linalg.norm(residuals, axis=1)
    before, registration = nominal_registered_errors(calibration, meas)
    device = calibration.device_T_base
    points_base = (meas.points - device[:3, 3]) @ device[:3, :3]
    if centre_m is not None:
        centre, centre_source = np.asarray(centre_m, float), "the given centre"
    elif volumes and len(volumes) == 1:
        centre, centre_source = np.asarray(volumes[0].centre_m, float), \
            f"the centre of volume {volumes[0].name}"
    else:
        centre, centre_source = points_base.mean(axis=0), "the centroid of the validation points"
    labels = region_labels(meas, points_base, volumes)
    regions = ()
    if labels is not None:
        regions = tuple(RegionFigures(name=str(name), before=error_stats(before[labels == name]),
                                      after=error_stats(after[labels == name]))
                        for name in dict.fromkeys(labels))
    return ValidationReport(
        source=meas.source, robot=calibration.robot.name, before=error_stats(before),
        after=error_stats(after), regions=regions, errors_before_m=before,
        errors_after_m=after, residuals_after_m=residuals, points_base_m=points_base,
        joints=np.asarray(meas.joints), registration=registration, centre_m=centre,
        centre_source=centre_source, labels=labels)


def validation_to_dict(report: ValidationReport) -> dict:
    """The JSON document: ``n``, ``before_mm``, ``after_mm``, ``regions`` (mm, unrounded)."""
    return {
        "n": report.n, "robot": report.robot, "source": report.source,
        "before": "nominal arm, device frame registered rigidly to these measurements",
        "after": "calibrated model in its own device frame (no re-fit)",
        "before_mm": report.before.to_dict_mm(), "after_mm": report.after.to_dict_mm(),
        "regions": {r.name: {"n": r.after.n, "before_mm": r.before.to_dict_mm(),
                             "after_mm": r.after.to_dict_mm()} for r in report.regions},
        "centre_mm": (report.centre_m * 1e3).tolist(), "centre_source": report.centre_source,
    }


def _line(label: str, s: ErrorStats) -> str:
    std = "n/a" if not math.isfinite(s.std) else f"{s.std * 1e3:.3f} mm"
    return (f"  {label:<7} mean {s.mean * 1e3:.3f} mm, std {std}, median "
            f"{s.median * 1e3:.3f} mm, p95 {s.p95 * 1e3:.3f} mm, max {s.max * 1e3:.3f} mm")


def change_words(before_m: float, after_m: float) -> str:
    """How the mean error changed, in words that match the sign: 'N.Nx smaller', 'N.Nx
    LARGER' (with the figures and what it means), or 'unchanged'; m in, mm out."""
    if after_m < before_m:
        gain = f"{before_m / after_m:.1f}x" if after_m > 0 else "infinitely"
        return f"mean error {gain} smaller after calibration"
    if after_m == before_m:
        return "mean error unchanged by the calibration"
    ratio = f"{after_m / before_m:.1f}x" if before_m > 0 else "infinitely"
    return (f"WARNING: mean error {ratio} LARGER after calibration ({before_m * 1e3:.3f} mm "
            f"-> {after_m * 1e3:.3f} mm): the calibration does not describe the robot that "
            f"made these measurements (another robot, tool or cell?)")


def validation_summary(report: ValidationReport) -> list[str]:
    """Printed lines: overall and per-region figures, every number with its unit."""
    lines = [f"validation of {report.robot} on {report.source}: {report.n} measured points",
             "  before: nominal arm, device frame registered to these measurements; after: "
             "the calibrated model as it predicts (no re-fit)",
             _line("before", report.before), _line("after", report.after)]
    lines.append(f"  {change_words(report.before.mean, report.after.mean)}")
    for r in report.regions:
        lines.append(f"region {r.name}: {r.after.n} points")
        lines.extend([_line("before", r.before), _line("after", r.after)])
    return lines
