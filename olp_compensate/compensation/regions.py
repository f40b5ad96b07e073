"""Compensation with local models per region: each target solved on the model of the
region whose volume holds it, the global model elsewhere (seed section 10).

:class:`RegionalCompensator` is a :class:`~olp_compensate.compensation.pose.Compensator`
of the global calibration whose :meth:`~RegionalCompensator.compensate_flanges` splits the
rows by region, solves each group on its region's model and merges the results in the
input order; everything else (nominal controller, confdata, closed-form family) is the
nominal arm's and the same for every model. So it goes wherever a Compensator goes
(:func:`~olp_compensate.compensation.pose.compensate_poses`, ``compensate_program``).

Frames. A target is given in the base frame of the global calibration. A region's model
has its own base frame (defined from its own identified axes) and its own device frame;
both device frames are the one physical measuring device, so a flange pose in the global
base frame is ``region_base_T_base = inv(region.device_T_base) @ global.device_T_base``
times it in the region's. A region's tool of the same name as the calibrated tool a target
was aimed with replaces its point (the orientation stays the one the target used).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..calibration.calibration import GLOBAL_MODEL, Calibration
from ..errors import DataError
from ..kinematics.conventions import invert_pose
from .failures import FailureReport
from .failures import explain_failures as explain_on
from .ik import IKSolution
from .pose import Compensator

__all__ = ["RegionalCompensator", "RegionalSolution", "GLOBAL_MODEL", "explain_failures"]


@dataclass(frozen=True)
class RegionalSolution:
    """Which model solved each row: ``regions`` (m,) names (:data:`GLOBAL_MODEL` for the
    global one), ``desired`` (m, 4, 4) the flange poses each model solved for, in that
    model's base frame, m (for explaining failures on the same model)."""

    regions: np.ndarray
    desired: np.ndarray


class RegionalCompensator(Compensator):
    """A compensator that picks, per target, the local model of the region holding it.

    ``force``: a region name to use for every target (or :data:`GLOBAL_MODEL`), None to
    choose by volume. Rows are dispatched by the position of their tool point in the base
    frame of the global calibration: callers that know the target's TCP pass ``regions``
    (:meth:`regions_for`); otherwise the point is ``dispatch_point_m`` in the flange frame
    (default: the calibration's tool 'tcp', the measured point, else the flange origin).
    """

    def __init__(self, calibration: Calibration, force: str | None = None,
                 dispatch_point_m: np.ndarray | None = None, controller=None, load=None):
        super().__init__(calibration, controller, load)
        known = [r.name for r in calibration.regions]
        if force is not None and force != GLOBAL_MODEL and force not in known:
            listed = ", ".join(known) or "none"
            raise DataError(f"region {force!r}: not in this calibration (regions: {listed}; "
                            f"'{GLOBAL_MODEL}' is the global model)")
        self.force = force
        if dispatch_point_m is None:
            tcp = calibration.tools.get("tcp")
            dispatch_point_m = np.zeros(3) if tcp is None else tcp.xyz_m
        self.dispatch_point_m = np.asarray(dispatch_point_m, dtype=float).reshape(3)
        self._compensators: dict[str, Compensator] = {}

    @property
    def region_names(self) -> tuple[str, ...]:
        """The names of the calibration's regions, in its order."""
        return tuple(r.name for r in self.calibration.regions)

    def calibration_for(self, name: str) -> Calibration:
        """The calibration of region ``name`` (the global one for :data:`GLOBAL_MODEL`)."""
        if name == GLOBAL_MODEL:
            return self.calibration
        return self.calibration.region(name).calibration

    def compensator_for(self, name: str) -> Compensator:
        """The :class:`Compensator` of region ``name`` (built on first use; this one for
        :data:`GLOBAL_MODEL`, whose own ``compensate_flanges`` then still dispatches)."""
        if name == GLOBAL_MODEL:
            return self
        if name not in self._compensators:
            self._compensators[name] = Compensator(self.calibration_for(name),
                                                   self.controller, self.load)
        return self._compensators[name]

    def region_base_T_base(self, name: str) -> np.ndarray:
        """(4, 4) the global base frame in region ``name``'s base frame (identity for the
        global model), m."""
        if name == GLOBAL_MODEL:
            return np.eye(4)
        region = self.calibration_for(name)
        return invert_pose(region.device_T_base) @ self.calibration.device_T_base

    def regions_for(self, base_T_tcp: np.ndarray) -> np.ndarray:
        """(m,) object array of region names, :data:`GLOBAL_MODEL` outside every region,
        for TCP poses (m, 4, 4) or points (m, 3) in the global base frame, m (``force``
        wins when set)."""
        a = np.asarray(base_T_tcp, dtype=float)
        points = a[..., :3, 3] if a.shape[-2:] == (4, 4) else a
        points = points.reshape(-1, 3)
        if self.force is not None:
            return np.full(len(points), self.force, dtype=object)
        names = self.calibration.region_for(points)
        names[np.equal(names, None)] = GLOBAL_MODEL
        return names

    def _dispatch(self, desired: np.ndarray) -> np.ndarray:
        """Regions of flange poses (m, 4, 4) by their :attr:`dispatch_point_m`."""
        point = desired[:, :3, :3] @ self.dispatch_point_m + desired[:, :3, 3]
        return self.regions_for(point)

    def _checked_regions(self, regions, m: int) -> np.ndarray:
        names = np.asarray(regions, dtype=object).reshape(-1)
        if len(names) != m:
            raise DataError(f"regions: expected {m} names, got {len(names)}")
        unknown = sorted(set(names.tolist()) - set(self.region_names) - {GLOBAL_MODEL},
                         key=str)
        if unknown:
            raise DataError(f"regions: unknown {', '.join(map(repr, unknown))} (regions: "
                            f"{', '.join(self.region_names) or 'none'})")
        return names

    def region_desired(self, name: str, desired: np.ndarray, tools=None) -> np.ndarray:
        """Flange poses (k, 4, 4) in the global base frame, aimed with the global
        calibration's tools ``tools`` (k,) (names, or None/'' for none), as region
        ``name``'s model must reach them: in its base frame, the point of its own tool of
        that name in place of the global one."""
        out = self.region_base_T_base(name) @ desired
        if name == GLOBAL_MODEL or tools is None:
            return out
        local, glob = self.calibration_for(name).tools, self.calibration.tools
        tools = np.asarray(tools, dtype=object).reshape(-1)
        for tool in set(tools.tolist()) - {None, ""}:
            if tool in local and tool in glob:
                rows = tools == tool
                shift = glob[tool].xyz_m - local[tool].xyz_m      # flange frame, m
                out[rows, :3, 3] += out[rows, :3, :3] @ shift
        return out

    def compensate_flanges(self, desired_real_flange: np.ndarray,
                           requested_flange: np.ndarray | None = None,
                           confdata: np.ndarray | None = None, *, regions=None, tools=None):
        """As :meth:`Compensator.compensate_flanges`, each row on the model of its region:
        ``regions`` (m,) names from :meth:`regions_for` (default: by
        :attr:`dispatch_point_m`, or ``force``), ``tools`` (m,) the calibrated tool each
        desired flange was aimed with (see :meth:`region_desired`). Returns (joints URDF
        (m, n), nominal flange at them (m, 4, 4), IKSolution, nominal joints of
        ``requested_flange`` or None), rows in the input order."""
        return self.solve_regions(desired_real_flange, requested_flange, confdata,
                                  regions=regions, tools=tools)[:4]

    def solve_regions(self, desired_real_flange: np.ndarray,
                      requested_flange: np.ndarray | None = None,
                      confdata: np.ndarray | None = None, *, regions=None, tools=None):
        """:meth:`compensate_flanges` and, fifth, the :class:`RegionalSolution` (which
        model solved each row), for reports and :func:`explain_failures`."""
        desired = np.asarray(desired_real_flange, dtype=float).reshape(-1, 4, 4)
        m = len(desired)
        names = (self._dispatch(desired) if regions is None
                 else self._checked_regions(regions, m))
        if m == 0:
            return (*Compensator.compensate_flanges(self, desired, requested_flange, confdata),
                    RegionalSolution(regions=names, desired=desired))
        tools = None if tools is None else np.asarray(tools, dtype=object).reshape(-1)
        local_desired = desired.copy()
        parts, order = [], []
        for name in dict.fromkeys(names.tolist()):
            rows = np.flatnonzero(names == name)
            target = self.region_desired(name, desired[rows],
                                         None if tools is None else tools[rows])
            local_desired[rows] = target
            requested = None if requested_flange is None else requested_flange[rows]
            conf = None if confdata is None else np.asarray(confdata)[rows]
            if name == GLOBAL_MODEL:
                part = Compensator.compensate_flanges(self, target, requested, conf)
            else:
                part = self.compensator_for(name).compensate_flanges(target, requested, conf)
            parts.append(part)
            order.append(rows)
        q, flange, solution, nominal = _merge(parts, np.concatenate(order), m,
                                              requested_flange is not None)
        return q, flange, solution, nominal, RegionalSolution(regions=names,
                                                              desired=local_desired)

    def explain_failures(self, solution: IKSolution, regional: RegionalSolution,
                         confdata: np.ndarray | None) -> list[FailureReport | None]:
        """:func:`~olp_compensate.compensation.failures.explain_failures` of each failed row
        on the model that solved it (``regional`` from :meth:`solve_regions`)."""
        out: list[FailureReport | None] = [None] * len(solution.success)
        for name in dict.fromkeys(regional.regions.tolist()):
            rows = np.flatnonzero(regional.regions == name)
            if np.all(solution.success[rows]):
                continue
            comp = self.compensator_for(name)
            conf = None if confdata is None else np.asarray(confdata)[rows]
            reports = explain_on(comp, _take(solution, rows), regional.desired[rows], conf)
            for row, report in zip(rows.tolist(), reports):
                out[row] = report
        return out


def explain_failures(comp: Compensator, solution: IKSolution, desired_flange: np.ndarray,
                     confdata: np.ndarray | None,
                     regional: RegionalSolution | None = None) -> list[FailureReport | None]:
    """Why each failed row failed, on the model that solved it: with a
    :class:`RegionalCompensator` and the ``regional`` part of its :meth:`solve_regions`,
    per region; otherwise :func:`olp_compensate.compensation.failures.explain_failures`."""
    if isinstance(comp, RegionalCompensator) and regional is not None:
        return comp.explain_failures(solution, regional, confdata)
    return explain_on(comp, solution, desired_flange, confdata)


def _take(solution: IKSolution, rows: np.ndarray) -> IKSolution:
    """The rows ``rows`` of an IK solution."""
    return IKSolution(q=solution.q[rows], success=solution.success[rows],
                      reason=solution.reason[rows], iterations=solution.iterations[rows],
                      position_error_m=solution.position_error_m[rows],
                      rotation_error_rad=solution.rotation_error_rad[rows],
                      on_asked=None if solution.on_asked is None else solution.on_asked[rows])


def _merge(parts: list, order: np.ndarray, m: int, with_nominal: bool):
    """One (q, flange, IKSolution, nominal) from per-region parts whose rows are
    ``order`` (the parts' rows concatenated) back in the input order."""
    back = np.empty(m, dtype=int)
    back[order] = np.arange(m)

    def joined(values):
        return np.concatenate(values)[back]

    solutions = [p[2] for p in parts]
    solution = IKSolution(
        q=joined([s.q for s in solutions]), success=joined([s.success for s in solutions]),
        reason=joined([s.reason for s in solutions]),
        iterations=joined([s.iterations for s in solutions]),
        position_error_m=joined([s.position_error_m for s in solutions]),
        rotation_error_rad=joined([s.rotation_error_rad for s in solutions]),
        on_asked=(None if any(s.on_asked is None for s in solutions)
                  else joined([s.on_asked for s in solutions])))
    nominal = joined([p[3] for p in parts]) if with_nominal else None
    return joined([p[0] for p in parts]), joined([p[1] for p in parts]), solution, nominal
