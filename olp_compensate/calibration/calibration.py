"""A calibrated robot: the model, its identified values, the device frame and the tools;
optionally local models of the regions where the robot works (seed section 10)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..kinematics.conventions import matrix_from_quat_wxyz
from ..errors import DataError
from ..kinematics.model import KinematicModel, build_model, forward
from ..kinematics.robot import Robot

if TYPE_CHECKING:  # a field's type only: identify never makes one (2-4 ms of its start)
    from .remainder import ResidualMap
# The effects' module loads when a calibration has effects: a geometric one (what identify
# makes by default) needs none of it (5-9 ms of a command's start, issue 32).
if TYPE_CHECKING:
    from .effects import Conditions, Effect, EffectInputs


@dataclass(frozen=True)
class ToolPoint:
    """A calibrated tool point in the flange frame: ``xyz_m`` (3,), its standard deviation
    (3,) or None, and the tool orientation as a quaternion (w, x, y, z) when known (the
    rotation of the tool's frame in the flange frame), with ``rot_std_rad`` (3,), the
    standard deviation of a small rotation about the tool frame's own axes, when identified.

    ``for_programs``: a tool calibrated for programs (``olp-cal tool``), which replaces a
    program's tool of the same name; False for a point measured for the identification
    (a tracker target, ``tcp`` by default), which is never a program's tool."""

    xyz_m: np.ndarray
    std_m: np.ndarray | None = None
    quat_wxyz: np.ndarray | None = None
    rot_std_rad: np.ndarray | None = None
    for_programs: bool = False


@dataclass(frozen=True)
class Validation:
    """How good a calibration is, in mm: residuals of the fit and of held-out folds; with
    orientation rows also the angle between measured and predicted tool frames, deg."""

    method: str
    poses: int
    residual_rms_mm: float
    residual_max_mm: float
    heldout_rms_mm: float | None
    heldout_max_mm: float | None
    condition_number: float
    orientation_rms_deg: float | None = None
    orientation_max_deg: float | None = None
    heldout_orientation_rms_deg: float | None = None
    heldout_orientation_max_deg: float | None = None


GLOBAL_MODEL = "global"
"""Name of the global model where regions are named (reserved: no region takes it)."""


@dataclass(frozen=True)
class RegionBox:
    """An axis-aligned box in the base frame: corners ``min_m`` and ``max_m`` (3,), m;
    ``margin_m``: how far it was grown beyond the measured points that define it."""

    min_m: np.ndarray
    max_m: np.ndarray
    margin_m: float = 0.0

    def __post_init__(self):
        low, high = (np.asarray(v, dtype=float) for v in (self.min_m, self.max_m))
        if low.shape != (3,) or high.shape != (3,):
            raise DataError(f"region box: expected 3 coordinates per corner, got "
                            f"{low.shape} and {high.shape}")
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(low <= high)):
            raise DataError(f"region box: expected finite corners with min <= max, got min "
                            f"{low.tolist()} and max {high.tolist()} m")
        object.__setattr__(self, "min_m", low)
        object.__setattr__(self, "max_m", high)

    @property
    def centre_m(self) -> np.ndarray:
        """(3,) the box's centre, base frame, m."""
        return 0.5 * (self.min_m + self.max_m)

    def contains(self, points_base_m: np.ndarray) -> np.ndarray:
        """(m,) bool: which points (m, 3), base frame, m, lie inside (faces included)."""
        points = np.asarray(points_base_m, dtype=float).reshape(-1, 3)
        return np.all((points >= self.min_m) & (points <= self.max_m), axis=1)


@dataclass(frozen=True)
class RegionCalibration:
    """A local model of the region ``name``: identified from that region's measurements
    alone, used for targets inside ``box`` (base frame of the global calibration).

    ``calibration`` holds the region's parameters, device frame, tools and validation
    figures (its ``regions`` empty); ``global_heldout_rms_mm`` / ``global_heldout_max_mm``:
    the global model's held-out errors on the same rows, mm (None without folds), so the
    two can be compared. It is also a calibration volume of
    :func:`olp_compensate.calibration.validation.validate` (``name``, ``centre_m``,
    ``contains``)."""

    name: str
    box: RegionBox
    calibration: "Calibration"
    global_heldout_rms_mm: float | None = None
    global_heldout_max_mm: float | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.strip():
            raise DataError(f"region name: expected a non-empty text, got {self.name!r}")
        if self.name == GLOBAL_MODEL:
            raise DataError(f"region name: '{GLOBAL_MODEL}' names the global model; rename "
                            f"the region")
        if self.calibration.regions:
            raise DataError(f"region {self.name}: a region's calibration has no regions")

    @property
    def centre_m(self) -> np.ndarray:
        """(3,) the centre of the region's box, base frame, m."""
        return self.box.centre_m

    def contains(self, points_base_m: np.ndarray) -> np.ndarray:
        """(m,) bool: which points (m, 3), base frame, m, lie in the region's box."""
        return self.box.contains(points_base_m)


@dataclass(frozen=True)
class Calibration:
    """Everything needed to predict where the real robot goes.

    ``values`` and ``std`` are (P,) in SI (std is NaN for frozen parameters, whose reasons
    are in ``frozen``); ``device_T_base`` places the robot base in the measuring device's
    frame (4, 4), m; ``tools`` maps point names to :class:`ToolPoint`; ``effects`` are the
    fitted non-geometric terms (:mod:`olp_compensate.calibration.effects`); ``regions``
    local models (:class:`RegionCalibration`) of the same robot, chosen by
    :meth:`region_for` for points inside their boxes (the global model elsewhere).
    ``warnings``: verdicts the fit's own statistics gave and the user overrode (``--force``),
    kept in calib.json's ``"warnings"`` list.
    """

    robot: Robot
    model: KinematicModel
    values: np.ndarray
    std: np.ndarray
    device_T_base: np.ndarray = field(default_factory=lambda: np.eye(4))
    frozen: dict[str, str] = field(default_factory=dict)
    tools: dict[str, ToolPoint] = field(default_factory=dict)
    effects: tuple[Effect, ...] = ()
    validation: Validation | None = None
    regions: tuple[RegionCalibration, ...] = ()
    warnings: tuple[str, ...] = ()
    residual_map: ResidualMap | None = None
    """Optional cross-validated map of what the model leaves (``olp-cal diagnose
    --residual-map``): applied on request, inside its joint region only."""
    geometric_fallback: Calibration | None = None
    """The geometric model fitted on the same rows as the effects (``olp-cal diagnose``):
    it predicts the rows where an effect is outside its ``fitted_range``
    (:mod:`.effect_ranges`); None: the effects are used everywhere."""
    as_read: object = field(default=None, compare=False, repr=False)
    """The calib.json document this calibration was read from (None: not read from one),
    kept through ``dataclasses.replace`` so that writing it again keeps every number whose
    value did not change as it was read, digit for digit
    (:mod:`olp_compensate.io.calibration_file`)."""

    def __post_init__(self):
        object.__setattr__(self, "warnings", tuple(self.warnings))
        if not self.regions:
            return
        object.__setattr__(self, "regions", tuple(self.regions))
        names = [r.name for r in self.regions]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise DataError(f"regions: the name {', '.join(twice)} is used more than once")
        other = [r.name for r in self.regions
                 if r.calibration.robot.fingerprint != self.robot.fingerprint]
        if other:
            raise DataError(f"region {other[0]}: its calibration is of another robot model "
                            f"than {self.robot.name}")

    def region(self, name: str) -> RegionCalibration:
        """The region called ``name``; :class:`DataError` listing the known ones."""
        for r in self.regions:
            if r.name == name:
                return r
        known = ", ".join(r.name for r in self.regions) or "none"
        raise DataError(f"no region named {name!r} in this calibration (known: {known})")

    def region_for(self, points_base_m: np.ndarray) -> np.ndarray:
        """(m,) object array: for each point (m, 3), base frame, m, the name of the region
        whose box contains it, or None (the global model). Where boxes overlap the one
        whose centre is nearest wins (the first listed on a tie)."""
        points = np.asarray(points_base_m, dtype=float).reshape(-1, 3)
        out = np.full(len(points), None, dtype=object)
        if not self.regions:
            return out
        distance = np.stack([np.where(r.box.contains(points),
                                      np.linalg.norm(points - r.box.centre_m, axis=1), np.inf)
                             for r in self.regions], axis=1)
        inside = np.isfinite(distance).any(axis=1)
        nearest = np.argmin(distance, axis=1)
        names = np.array([r.name for r in self.regions], dtype=object)
        out[inside] = names[nearest[inside]]
        return out

    def actual_joints(self, q_urdf: np.ndarray, jacobian: bool = False,
                      conditions: Conditions | None = None):
        """The joint values (m, n) the arm really takes when commanded ``q_urdf`` (m, n),
        URDF axes, rad/m, after the joint-space effects in ``effects``; with ``jacobian``
        also d(actual)/d(commanded) (m, n, n), or None when there are no such effects.

        This is the single hook through which non-geometric joint effects (compliance,
        gear error, backlash, scale) reach prediction and compensation. The effects act on
        the controller axes (:mod:`olp_compensate.calibration.effects`); ``conditions`` default to no
        payload and gravity-closed backlash (what is known when compensating a program)."""
        q_urdf = np.asarray(q_urdf, dtype=float)
        if not self.effects:
            return (q_urdf, None) if jacobian else q_urdf
        from .effects import (JointCompliance, effect_inputs, joint_deflection,
                              joint_deflection_dq, joint_effects, needs_torque)

        effects = joint_effects(self.effects)
        if not effects:
            return (q_urdf, None) if jacobian else q_urdf
        q = np.atleast_2d(q_urdf)
        derivatives = jacobian and any(isinstance(e, JointCompliance) for e in effects)
        inputs = effect_inputs(self.robot, self.robot.controller_from_joints(q), conditions,
                               torque=needs_torque(effects), derivatives=derivatives)
        coupling = self.robot.urdf_from_controller
        dq = joint_deflection(effects, inputs)
        actual = q + (dq if coupling is None else dq @ coupling.T)
        actual = actual.reshape(q_urdf.shape)
        if not jacobian:
            return actual
        d = joint_deflection_dq(effects, inputs)
        if coupling is not None:
            d = coupling @ d @ np.linalg.inv(coupling)
        jac = d + np.eye(q.shape[1])
        return actual, (jac if q_urdf.ndim == 2 else jac[0])

    def length_scale(self, m: int, conditions: Conditions | None = None) -> np.ndarray:
        """Factor (m,) on the arm's link translations (thermal expansion; 1 at the reference
        temperature or without the effect)."""
        if not self.effects:
            return np.ones(m)
        from .effects import EffectInputs, geometry_effects, length_scale

        effects = geometry_effects(self.effects)
        if not effects or conditions is None or conditions.temperature_c is None:
            return np.ones(m)
        temperature = np.broadcast_to(np.asarray(conditions.temperature_c, float), (m,))
        return length_scale(effects, EffectInputs(q=np.zeros((m, self.robot.n_joints)),
                                                  temperature_c=temperature))

    def _conditions_for(self, names, conditions: Conditions | None) -> Conditions | None:
        """Put an unplaced payload at the tool point 'tcp' (else the row's own point)."""
        if conditions is None or conditions.payload_kg is None:
            return conditions
        if conditions.payload_point_m is not None or names is None or not self.tools:
            return conditions
        names = list(names)
        where = ["tcp"] * len(names) if "tcp" in self.tools else names
        return dataclasses.replace(conditions, payload_point_m=self.tool_points(where))

    def outside_fitted(self, q: np.ndarray) -> np.ndarray:
        """(m,) True for the rows of controller axis values (m, n) that the geometric
        fallback predicts (some effect outside its fitted range; never without one)."""
        q = np.atleast_2d(np.asarray(q, float))
        if self.geometric_fallback is None:
            return np.zeros(len(q), dtype=bool)
        from .effect_ranges import outside_fitted

        return outside_fitted(self.effects, q)

    def _split(self, method: str, q: np.ndarray, names, conditions, shape: tuple):
        """Call ``method`` on the rows inside the effects' ranges and the geometric
        fallback's on the others (tools: the fallback's own, this one's where it has none);
        None when every row is inside."""
        q = np.atleast_2d(np.asarray(q, float))
        outside = self.outside_fitted(q)
        if not np.any(outside):
            return None
        fallback = self.geometric_fallback
        fallback = dataclasses.replace(fallback, tools={**self.tools, **fallback.tools})
        out = np.empty((len(q),) + shape)
        for rows, cal in ((~outside, self), (outside, fallback)):
            if np.any(rows):
                args = () if names is None else (np.asarray(list(names), dtype=object)[rows],)
                kwargs = {"conditions": _rows_of(conditions, rows)}
                if cal is self:
                    kwargs["fallback"] = False
                out[rows] = getattr(cal, method)(q[rows], *args, **kwargs)
        return out

    def flange_poses(self, q: np.ndarray, conditions: Conditions | None = None,
                     fallback: bool = True) -> np.ndarray:
        """Flange poses (m, 4, 4) in the base frame for controller axis values (m, n), rad/m;
        ``conditions`` (payload, temperature...) default to none (see :meth:`actual_joints`);
        rows outside the effects' fitted ranges from the geometric fallback (``fallback``)."""
        split = self._split("flange_poses", q, None, conditions, (4, 4)) if fallback else None
        if split is not None:
            return split
        q_actual = self.actual_joints(self.robot.joints_from_controller(q), conditions=conditions)
        flange = forward(self.model, self.values, q_actual).flange
        if self.effects:
            from .effects import geometry_effects

            if geometry_effects(self.effects):
                flange[:, :3, 3] *= self.length_scale(len(flange), conditions)[:, None]
        return flange

    def tool_points(self, names) -> np.ndarray:
        """Tool points (m, 3) in the flange frame for an array of point names."""
        missing = sorted(set(names) - set(self.tools))
        if missing:
            known = ", ".join(sorted(self.tools)) or "none"
            raise DataError(f"no calibrated tool point named {', '.join(missing)} (known: {known})")
        return np.array([self.tools[name].xyz_m for name in names]).reshape(-1, 3)

    def predict_points(self, q: np.ndarray, names, conditions: Conditions | None = None,
                       fallback: bool = True) -> np.ndarray:
        """Positions (m, 3) of the named tool points in the device frame, metres, for
        controller axis values (m, n); ``conditions`` as in :meth:`flange_poses` (a payload
        without a point sits at the tool point 'tcp'), rows outside the effects' fitted
        ranges from the geometric fallback (its own device frame; ``fallback``)."""
        split = self._split("predict_points", q, names, conditions, (3,)) if fallback else None
        if split is not None:
            return split
        conditions = self._conditions_for(names, conditions)
        flange = self.flange_poses(q, conditions, fallback=False)
        local = self.tool_points(names)
        base = flange[:, :3, 3] + np.einsum("mij,mj->mi", flange[:, :3, :3], local)
        return base @ self.device_T_base[:3, :3].T + self.device_T_base[:3, 3]

    def predict_rotations(self, q: np.ndarray, names, conditions: Conditions | None = None,
                          fallback: bool = True) -> np.ndarray:
        """Rotations (m, 3, 3) of the named tools' frames in the device frame (what a
        full-pose device measures) for controller axis values (m, n); every named tool needs
        its orientation (``quat_wxyz``); rows outside the effects' fitted ranges as in
        :meth:`predict_points`."""
        split = self._split("predict_rotations", q, names, conditions, (3, 3)) if fallback \
            else None
        if split is not None:
            return split
        names = list(names)
        unknown = sorted({n for n in names if n not in self.tools or self.tools[n].quat_wxyz is None})
        if unknown:
            raise DataError(f"no calibrated tool orientation for {', '.join(unknown)}")
        conditions = self._conditions_for(names, conditions)
        flange = self.flange_poses(q, conditions, fallback=False)
        turn = np.array([matrix_from_quat_wxyz(self.tools[n].quat_wxyz) for n in names])
        return self.device_T_base[:3, :3] @ flange[:, :3, :3] @ turn.reshape(-1, 3, 3)


def _rows_of(conditions: Conditions | None, rows: np.ndarray) -> Conditions | None:
    """The conditions of the rows of a mask (per-row arrays cut, scalars kept)."""
    if conditions is None:
        return None
    from .effects import Conditions

    return Conditions(**{f.name: _cut(getattr(conditions, f.name), rows)
                         for f in dataclasses.fields(conditions)})


def _cut(value, rows: np.ndarray):
    if value is None or np.ndim(value) == 0 or np.shape(value)[0] != len(rows):
        return value
    return np.asarray(value)[rows]


def nominal_calibration(robot: Robot, convention: str = "auto") -> Calibration:
    """The calibration that is exactly the nominal robot (device frame = base frame)."""
    model = build_model(robot, convention)
    return Calibration(robot=robot, model=model, values=model.nominal,
                       std=np.full(model.n_parameters, np.nan),
                       frozen={p.name: "nominal calibration" for p in model.parameters})
