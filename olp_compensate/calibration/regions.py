"""Local calibration per region: one model per region where the robot works, beside the
global one (seed section 10: the robot "recalibrated in each Region").

A region is named by the measurements' ``region`` column (kept by the reader as an extra
text column; an empty cell means the row belongs to no region). The global model is fitted
on every row, as without regions; each region's model on that region's rows alone, with the
same options, so it takes up what the global model cannot (joint compliance, gear error) as
it is *there*. Each region's volume is the bounding box of its measured points in the base
frame of the global calibration, grown by a margin (default :data:`DEFAULT_MARGIN_M`);
compensation uses a region's model for targets inside its box
(:mod:`olp_compensate.compensation.regions`).

A region's model is kept only when its held-out error (cross-validation on the region's
rows) is not larger than the global model's held-out error on the same rows: a local model
that predicts worse than the global one where it was measured is left out of the
calibration (:func:`region_verdict`), and the figures say why.

A region's base frame is defined from its own identified axes, as every calibration's is;
its device frame is the same physical device (one measurement file), which is how the
compensation relates the two base frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import DataError
from ..kinematics.robot import Robot
from .calibration import GLOBAL_MODEL, RegionBox, RegionCalibration
from .identify import IdentificationOptions, IdentificationResult, identify
from .measurements import Measurements, check_spread

REGION_COLUMN = "region"
DEFAULT_MARGIN_M = 0.05
"""How far a region's box is grown beyond its measured points, m (50 mm): targets just
outside the measured cube still use the local model."""


@dataclass(frozen=True)
class RegionalIdentification:
    """The outcome of :func:`identify_regions`: ``result`` the global identification, its
    ``calibration`` carrying the regions; ``regions`` (name, identification of that region's
    rows) in the order the regions first appear in the measurements."""

    result: IdentificationResult
    regions: tuple[tuple[str, IdentificationResult], ...]
    candidates: tuple[RegionCalibration, ...] = ()
    """Every region fitted, kept or not (same order as ``regions``)."""
    left_out: dict[str, str] = field(default_factory=dict)
    """Regions kept out of the calibration: name -> why (held-out figures, mm)."""


def region_column(meas: Measurements) -> np.ndarray:
    """(m,) object array of each row's region name ('' for none) from the ``region`` column;
    :class:`DataError` when there is no such column or no row names a region."""
    column = meas.extra.get(REGION_COLUMN)
    if column is None:
        raise DataError(f"{meas.source}: no '{REGION_COLUMN}' column: name the region of each "
                        f"row to fit one model per region")
    labels = np.array([str(v).strip() for v in column], dtype=object)
    if not any(labels):
        raise DataError(f"{meas.source}: column '{REGION_COLUMN}': every cell is empty")
    if GLOBAL_MODEL in set(labels):
        row = int(np.flatnonzero(labels == GLOBAL_MODEL)[0])
        line = meas.rows[row] if meas.rows is not None else row + 1
        raise DataError(f"{meas.source}:{line}: column '{REGION_COLUMN}': '{GLOBAL_MODEL}' "
                        f"names the global model; give the region another name")
    return labels


def points_in_base(meas: Measurements, device_T_base: np.ndarray) -> np.ndarray:
    """The measured points (m, 3) in the base frame of ``device_T_base`` (4, 4), m."""
    return (np.asarray(meas.points, dtype=float) - device_T_base[:3, 3]) @ device_T_base[:3, :3]


def check_margin(margin_m: float) -> None:
    """:class:`DataError` unless ``margin_m`` is a finite length >= 0, m."""
    if not (margin_m >= 0 and math.isfinite(margin_m)):
        raise DataError(f"region margin: expected a length >= 0, got {margin_m * 1e3:g} mm")


def region_box(points_base_m: np.ndarray, margin_m: float = DEFAULT_MARGIN_M) -> RegionBox:
    """The bounding box of points (k, 3), base frame, m, grown by ``margin_m`` on every
    side."""
    check_margin(margin_m)
    points = np.asarray(points_base_m, dtype=float).reshape(-1, 3)
    if not len(points):
        raise DataError("region box: no points")
    return RegionBox(min_m=points.min(axis=0) - margin_m, max_m=points.max(axis=0) + margin_m,
                     margin_m=float(margin_m))


def least_unknowns(robot: Robot, meas: Measurements) -> int:
    """A floor on a fit's unknowns: the device registration (6), one geometric parameter
    per joint, the tool points (3 each). identify() knows the exact count."""
    return 6 + robot.n_joints + 3 * len(set(meas.point_names))


def _heldout(result: IdentificationResult, mask: np.ndarray) -> tuple[float | None, float | None]:
    """The global fit's held-out RMS and max error on the rows ``mask``, mm (None without)."""
    if result.heldout_errors is None:
        return None, None
    errors = np.asarray(result.heldout_errors)[mask]
    errors = errors[np.isfinite(errors)]
    if not len(errors):
        return None, None
    return float(np.sqrt(np.mean(errors ** 2)) * 1e3), float(np.max(errors) * 1e3)


def region_verdict(region: RegionCalibration) -> str | None:
    """Why ``region`` must be kept out (its local model predicts its own rows worse
    held-out than the global model), or None to keep it. Without both held-out figures
    (``--folds 0``, too few poses) nothing can be compared and the region is kept."""
    local = region.calibration.validation
    local_rms = None if local is None else local.heldout_rms_mm
    global_rms = region.global_heldout_rms_mm
    if local_rms is None or global_rms is None or local_rms <= global_rms:
        return None
    return (f"local model held-out RMS {local_rms:.3f} mm > global model's {global_rms:.3f} "
            f"mm on the same rows: the global model is used there")


def identify_regions(robot: Robot, meas: Measurements,
                     options: IdentificationOptions = IdentificationOptions(),
                     margin_m: float = DEFAULT_MARGIN_M,
                     global_result: IdentificationResult | None = None
                     ) -> RegionalIdentification:
    """Identify the global model on every row (or take ``global_result``, identified on
    ``meas``) and one model per region named in the ``region`` column, each on its rows
    alone with ``options``; the global calibration returned carries them as
    :class:`RegionCalibration` (box: the region's measured points in the global base frame,
    grown by ``margin_m``, m); a region whose model is worse held-out than the global one
    (:func:`region_verdict`) is left out of it and listed in ``left_out``.
    :class:`DataError` naming a region whose rows cannot determine a model."""
    labels = region_column(meas)
    result = identify(robot, meas, options) if global_result is None else global_result
    device_T_base = result.calibration.device_T_base
    fits, regions = [], []
    for name in dict.fromkeys(v for v in labels if v):
        mask = labels == name
        subset = meas.subset(mask)
        try:
            check_spread(subset, least_unknowns(robot, subset))
            local = identify(robot, subset, options)
        except DataError as exc:
            raise DataError(f"region {name}: {exc}") from None
        if not (math.isfinite(local.residual_rms) and math.isfinite(local.residual_max)):
            raise DataError(f"region {name}: the fit did not converge to finite numbers")
        rms, worst = _heldout(result, mask)
        regions.append(RegionCalibration(
            name=name, box=region_box(points_in_base(subset, device_T_base), margin_m),
            calibration=local.calibration, global_heldout_rms_mm=rms,
            global_heldout_max_mm=worst))
        fits.append((name, local))
    left_out = {r.name: why for r in regions if (why := region_verdict(r)) is not None}
    kept = tuple(r for r in regions if r.name not in left_out)
    calibration = replace(result.calibration, regions=kept)
    return RegionalIdentification(result=replace(result, calibration=calibration),
                                  regions=tuple(fits), candidates=tuple(regions),
                                  left_out=left_out)
