"""Stage 1 of identification: the options, the data and the asked effects checked, each
failure a one-line :class:`~olp_compensate.errors.DataError` (file and line where one
applies)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from ..errors import DataError
from ..kinematics.robot import Robot
from .measurements import Measurements

if TYPE_CHECKING:
    from .effects import Effect


def check_options(options) -> None:
    """DataError for an option of ``options`` (:class:`.identify.IdentificationOptions`) out
    of its domain, naming the option's field."""
    if options.solver not in ("lm", "trf"):
        raise DataError(f"IdentificationOptions.solver must be 'lm' or 'trf', got "
                        f"{options.solver!r}")
    if options.convention not in ("auto", "dh"):
        raise DataError(f"IdentificationOptions.convention must be 'auto' or 'dh', got "
                        f"{options.convention!r}")
    if not (options.position_sigma_mm > 0 and options.orientation_sigma_deg > 0):
        raise DataError(f"the position and orientation sigmas must be positive, got "
                        f"{options.position_sigma_mm} mm and {options.orientation_sigma_deg} deg")


def check_data(robot: Robot, meas: Measurements) -> None:
    """DataError when the joint columns do not fit ``robot`` or a joint lies outside its
    limits (1e-6 rad or m of slack), with the file and line."""
    if meas.joints.shape[1] != robot.n_joints:
        raise DataError(f"{meas.source}: {meas.joints.shape[1]} joint columns, but "
                        f"{robot.name} has {robot.n_joints} joints")
    lower, upper = robot.lower_limits - 1e-6, robot.upper_limits + 1e-6
    outside = (meas.joints < lower) | (meas.joints > upper)
    if np.any(outside):
        row, joint = np.argwhere(outside)[0]
        line = meas.rows[row] if meas.rows is not None else row + 1
        value = robot.to_degrees_or_mm(meas.joints[row])[joint]
        raise DataError(f"{meas.source}:{line}: q{joint + 1} = {value:.3f} is outside the joint "
                        f"limits of {robot.name}; wrong robot for these measurements?")


def check_effects(robot: Robot, meas: Measurements, effects) -> tuple[Effect, ...]:
    """Validate the effects against the data; fix thermal expansion's reference temperature
    (the mean of the measurements) when it is not given."""
    if not effects:
        return ()
    from .effects import ThermalExpansion

    out = []
    for effect in effects:
        if effect.joint is not None and not 0 <= effect.joint < robot.n_joints:
            raise DataError(f"{effect.label}: {robot.name} has joints 1..{robot.n_joints}")
        if isinstance(effect, ThermalExpansion):
            if meas.temperature_c is None:
                raise DataError(f"{meas.source}: thermal_expansion needs the 'temperature_c' "
                                f"column, which the measurements do not have")
            if effect.reference_temperature_c is None:
                effect = dataclasses.replace(
                    effect, reference_temperature_c=float(np.mean(meas.temperature_c)))
        if effect.key in {e.key for e in out}:
            raise DataError(f"{effect.label} is asked for twice")
        out.append(effect)
    return tuple(out)
