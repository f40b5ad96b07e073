"""Non-geometric effects: small terms on the joint angles or on the link geometry.

Each effect is a frozen dataclass that knows its ``kind``, the joint it acts on, the data
columns it needs, its parameters with units, how it changes the joints or the geometry,
and its analytic derivatives. Effects are linear in their parameters: an effect is a basis
(one column per parameter) times its ``values``.

Joint effects act on the *controller axes* (the drive axes that carry the gearboxes; for
arms without a parallel linkage these are the URDF joints): the axis really turns to
``q_j + dq_j`` when commanded ``q_j`` (rad), with

==================  =====================================================  =============
kind                dq_j                                                   parameters
==================  =====================================================  =============
joint_compliance    ``c * tau_j``                                          c, rad/N.m
gear_harmonic       ``a sin(k q_j) + b cos(k q_j)``, order k = 1, 2, 3     a, b, rad
backlash            ``(w / 2) * sign(tau_j)``, or ``-(w / 2) * d_j`` where  w, rad
                    the approach direction ``d_j`` (+1/-1) is given
joint_scale         ``s * q_j``                                            s, rad/rad
cyclic_error        ``sum_k a_k sin(k q_j) + b_k cos(k q_j)``, k = K0..K,  a<k>, b<k>, rad
                    inside the fitted range of q_j only (zero outside)
==================  =====================================================  =============

``tau_j`` is the *gravity load torque* about axis j (N.m, see :mod:`olp_compensate.calibration.gravity`):
the torque gravity exerts, ``-g(q)`` with pinocchio's ``g``, from the URDF inertials plus
``payload_kg`` at the measured point. With this sign a real joint has ``c > 0`` (it sags the
way gravity pulls) and a real gap ``w > 0``: gravity closes the gap in its own direction
(the issue's ``-(w/2) sign(g)``); a joint approached moving in + lags behind by ``w/2``.

``thermal_expansion`` acts on the geometry: every link translation of the arm (joint
origins and the flange offset) is scaled by ``1 + alpha (T - T0)``; for a serial chain this
scales the flange position in the base frame by the same factor. ``alpha`` is in 1/K, ``T``
the ``temperature_c`` column and ``T0`` the calibration's reference temperature (the mean
of the measurements; the geometry is identified at T0). Tool points are not scaled.

At compensation time no payload, temperature or direction is known: the defaults are no
payload, the reference temperature and the gravity-closed backlash (:class:`Conditions`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import DataError, ModelError
from .effect_inputs import Conditions, EffectInputs, effect_inputs


TORQUE_SIGN_TOLERANCE = 1e-6
"""Load torques below this (N.m) count as zero for the sign in the backlash term."""


@dataclass(frozen=True)
class Effect:
    """Base of all effects. ``joint``: 0-based controller axis (None for arm-wide effects);
    ``values`` and ``std``: one per parameter, in ``units`` (std NaN when unknown)."""

    kind: ClassVar[str] = ""
    parameter_names: ClassVar[tuple[str, ...]] = ()
    units: ClassVar[tuple[str, ...]] = ()
    required_columns: ClassVar[tuple[str, ...]] = ()
    optional_columns: ClassVar[tuple[str, ...]] = ()
    acts_on_joint: ClassVar[bool] = True
    needs_torque: ClassVar[bool] = False
    description: ClassVar[str] = ""

    joint: int | None = None
    values: tuple[float, ...] = ()
    std: tuple[float, ...] = ()
    fitted_range: tuple[tuple[int, float, float], ...] = ()
    """(axis 0-based, low, high) of each controller axis the effect depends on, over the
    rows it was fitted on (rad or m); empty: unknown (files before issue 28), used
    everywhere. See :mod:`.effect_ranges`."""

    def __post_init__(self):
        p = len(self.parameter_names)
        if not self.values:
            object.__setattr__(self, "values", (0.0,) * p)
        if not self.std:
            object.__setattr__(self, "std", (float("nan"),) * p)
        for name in ("values", "std"):
            object.__setattr__(self, name, tuple(float(v) for v in getattr(self, name)))
        if len(self.values) != p or len(self.std) != p:
            raise ValueError(f"{self.kind}: expected {p} values and std, got "
                             f"{len(self.values)} and {len(self.std)}")

    n_parameters = property(lambda self: len(self.parameter_names))

    @property
    def label(self) -> str:
        """Short human name, joints 1-based: ``joint_compliance j2``."""
        return self.kind if self.joint is None else f"{self.kind} j{self.joint + 1}"

    @property
    def key(self) -> tuple:
        """What identifies the term apart from its values (kind, joint, order...)."""
        return (self.kind, self.joint)

    def with_values(self, values, std=None) -> "Effect":
        """The same term with other parameter values (and standard deviations)."""
        return dataclasses.replace(self, values=tuple(values),
                                   std=tuple(std) if std is not None else ())

    def basis(self, inputs: EffectInputs) -> np.ndarray:
        """(m, p): d(dq_j)/d(parameter) for joint effects, d(scale)/d(parameter) for the
        geometry effect."""
        raise NotImplementedError

    def basis_dq(self, inputs: EffectInputs) -> np.ndarray:
        """(m, p, n): derivative of :meth:`basis` with respect to the controller axes."""
        m, n = inputs.q.shape
        return np.zeros((m, self.n_parameters, n))

    def evaluate(self, inputs: EffectInputs) -> np.ndarray:
        """(m,): the joint deflection dq_j (rad), or the scale change (1) of thermal expansion."""
        return self.basis(inputs) @ np.array(self.values)

    def evaluate_dq(self, inputs: EffectInputs) -> np.ndarray:
        """(m, n): derivative of :meth:`evaluate` with respect to the controller axes."""
        return np.einsum("mpn,p->mn", self.basis_dq(inputs), np.array(self.values))

    def headline(self) -> tuple[float, float, str]:
        """(value, std, unit) that names the effect's size in one number."""
        return self.values[0], self.std[0], self.units[0]

    def to_dict(self) -> dict:
        """The calib.json entry (SI units, joint 1-based or null); ``fitted_range`` (a list
        of ``{"joint" (1-based), "min", "max"}``, rad or m) only when known."""
        doc = {"kind": self.kind, "joint": None if self.joint is None else self.joint + 1,
               "parameters": dict(zip(self.parameter_names, self.values)),
               "std": {k: (None if not np.isfinite(v) else v)
                       for k, v in zip(self.parameter_names, self.std)},
               "unit": dict(zip(self.parameter_names, self.units))}
        if self.fitted_range:
            doc["fitted_range"] = [{"joint": j + 1, "min": lo, "max": hi}
                                   for j, lo, hi in self.fitted_range]
        return doc


def _torque(inputs: EffectInputs, joint: int, kind: str) -> np.ndarray:
    if inputs.torque is None:
        raise ValueError(f"{kind} needs the gravity torque: build the inputs with torque=True")
    return inputs.torque[:, joint]


@dataclass(frozen=True)
class JointCompliance(Effect):
    """``dq_j = c * tau_j``: an elastic joint under the gravity load (c = 1 / stiffness)."""

    kind: ClassVar[str] = "joint_compliance"
    parameter_names: ClassVar[tuple[str, ...]] = ("c",)
    units: ClassVar[tuple[str, ...]] = ("rad/N.m",)
    optional_columns: ClassVar[tuple[str, ...]] = ("payload_kg",)
    needs_torque: ClassVar[bool] = True
    description: ClassVar[str] = "the joint bends under the gravity torque"

    def basis(self, inputs):
        return _torque(inputs, self.joint, self.kind)[:, None]

    def basis_dq(self, inputs):
        if inputs.dtorque_dq is None:
            raise ValueError("joint_compliance derivatives need dtorque_dq (derivatives=True)")
        return inputs.dtorque_dq[:, self.joint, None, :]


@dataclass(frozen=True)
class GearHarmonic(Effect):
    """``dq_j = a sin(k q_j) + b cos(k q_j)``: transmission error of order k (output side)."""

    kind: ClassVar[str] = "gear_harmonic"
    parameter_names: ClassVar[tuple[str, ...]] = ("a", "b")
    units: ClassVar[tuple[str, ...]] = ("rad", "rad")
    description: ClassVar[str] = "the gear transmission error repeats k times per turn"

    order: int = 1

    def __post_init__(self):
        super().__post_init__()
        if self.order not in (1, 2, 3):
            raise ValueError(f"gear_harmonic order must be 1, 2 or 3, got {self.order}")

    @property
    def label(self) -> str:
        return f"gear_harmonic k={self.order} j{self.joint + 1}"

    @property
    def key(self) -> tuple:
        return (self.kind, self.joint, self.order)

    def basis(self, inputs):
        angle = self.order * inputs.q[:, self.joint]
        return np.column_stack([np.sin(angle), np.cos(angle)])

    def basis_dq(self, inputs):
        m, n = inputs.q.shape
        angle = self.order * inputs.q[:, self.joint]
        out = np.zeros((m, 2, n))
        out[:, 0, self.joint] = self.order * np.cos(angle)
        out[:, 1, self.joint] = -self.order * np.sin(angle)
        return out

    def headline(self):
        """Amplitude sqrt(a^2 + b^2), rad, with its first-order standard deviation."""
        a, b = self.values
        amplitude = float(np.hypot(a, b))
        sa, sb = self.std
        if amplitude == 0:
            return 0.0, float(np.hypot(sa, sb)), "rad"
        std = float(np.hypot(a * sa, b * sb) / amplitude)
        return amplitude, std, "rad"

    @property
    def phase_rad(self) -> float:
        """Phase phi of ``A sin(k q + phi)``: a = A cos(phi), b = A sin(phi)."""
        return float(np.arctan2(self.values[1], self.values[0]))

    def to_dict(self):
        return {**super().to_dict(), "order": self.order}


@dataclass(frozen=True)
class Backlash(Effect):
    """``dq_j = (w/2) sign(tau_j)`` (gap closed by gravity), or ``-(w/2) d_j`` on rows whose
    approach direction ``d_j`` is known; w is the full gap, rad."""

    kind: ClassVar[str] = "backlash"
    parameter_names: ClassVar[tuple[str, ...]] = ("w",)
    units: ClassVar[tuple[str, ...]] = ("rad",)
    optional_columns: ClassVar[tuple[str, ...]] = ("direction_K", "payload_kg")
    needs_torque: ClassVar[bool] = True
    description: ClassVar[str] = "the gear gap is closed by gravity (or by the approach direction)"

    def basis(self, inputs):
        tau = _torque(inputs, self.joint, self.kind)
        side = np.where(np.abs(tau) > TORQUE_SIGN_TOLERANCE, np.sign(tau), 0.0)
        if inputs.directions is not None:
            d = inputs.directions[:, self.joint]
            side = np.where(d != 0, -np.sign(d), side)
        return 0.5 * side[:, None]


@dataclass(frozen=True)
class JointScale(Effect):
    """``dq_j = s * q_j``: a transmission ratio that is off by the factor 1 + s."""

    kind: ClassVar[str] = "joint_scale"
    parameter_names: ClassVar[tuple[str, ...]] = ("s",)
    units: ClassVar[tuple[str, ...]] = ("rad/rad",)
    description: ClassVar[str] = "the transmission ratio is off"

    def basis(self, inputs):
        return inputs.q[:, self.joint, None].copy()

    def basis_dq(self, inputs):
        m, n = inputs.q.shape
        out = np.zeros((m, 1, n))
        out[:, 0, self.joint] = 1.0
        return out


@dataclass(frozen=True)
class ThermalExpansion(Effect):
    """Link translations scaled by ``1 + alpha (T - T0)``; alpha in 1/K, T0 in deg C."""

    kind: ClassVar[str] = "thermal_expansion"
    parameter_names: ClassVar[tuple[str, ...]] = ("alpha",)
    units: ClassVar[tuple[str, ...]] = ("1/K",)
    required_columns: ClassVar[tuple[str, ...]] = ("temperature_c",)
    acts_on_joint: ClassVar[bool] = False
    description: ClassVar[str] = "the links grow with temperature"

    reference_temperature_c: float | None = None
    """T0, deg C; None until identification sets it to the mean of the measurements."""

    def basis(self, inputs):
        if inputs.temperature_c is None:  # at the reference temperature: no change
            return np.zeros((inputs.n_rows, 1))
        if self.reference_temperature_c is None:
            raise ValueError("thermal_expansion: the reference temperature is not set")
        return (np.asarray(inputs.temperature_c, float) - self.reference_temperature_c)[:, None]

    def to_dict(self):
        return {**super().to_dict(), "reference_temperature_c": self.reference_temperature_c}


@dataclass(frozen=True)
class CyclicError(Effect):
    """``dq_j = sum_k a_k sin(k q_j) + b_k cos(k q_j)``, k = ``min_order``..``max_order``
    (rad): cyclic angle error (gear stages, encoder), fitted with the ridge penalty ``ridge``
    (m^2/rad^2, :mod:`.cyclic_scan`); zero outside ``q_range`` (rad, the span it was fitted
    on). Lower orders complete no period over the span: the geometry takes them."""

    kind: ClassVar[str] = "cyclic_error"
    description: ClassVar[str] = "the joint's angle error repeats with the orders named"

    max_order: int = 1
    q_range: tuple[float, float] = (-np.inf, np.inf)
    ridge: float = 0.0
    min_order: int = 1

    orders = property(lambda self: np.arange(self.min_order, self.max_order + 1))
    parameter_names = property(lambda self: tuple(
        f"{ab}{k}" for k in range(self.min_order, self.max_order + 1) for ab in "ab"))
    units = property(lambda self: ("rad",) * (2 * len(self.orders)))
    label = property(lambda self: f"cyclic_error j{self.joint + 1}")

    def inside(self, q: np.ndarray) -> np.ndarray:
        """(m,) True where the axis values (m, n) lie in the fitted range."""
        return (q[:, self.joint] >= self.q_range[0]) & (q[:, self.joint] <= self.q_range[1])

    def basis(self, inputs):
        angle = np.outer(inputs.q[:, self.joint], self.orders)
        return (np.stack([np.sin(angle), np.cos(angle)], axis=2).reshape(len(angle), -1)
                * self.inside(inputs.q)[:, None])

    def basis_dq(self, inputs):
        m, n = inputs.q.shape
        k = self.orders
        angle = np.outer(inputs.q[:, self.joint], k)
        d = np.stack([k * np.cos(angle), -k * np.sin(angle)], axis=2).reshape(m, -1)
        out = np.zeros((m, 2 * len(k), n))
        out[:, :, self.joint] = d * self.inside(inputs.q)[:, None]
        return out

    def amplitudes(self) -> np.ndarray:
        """Amplitude sqrt(a_k^2 + b_k^2) of each order of :attr:`orders`, rad."""
        return np.hypot(*np.array(self.values).reshape(-1, 2).T)

    def headline(self):
        """Peak-equivalent amplitude sqrt(2) x RMS of dq over a turn, rad (std unknown)."""
        return float(np.sqrt(np.sum(self.amplitudes() ** 2))), float("nan"), "rad"

    def to_dict(self):
        return {**super().to_dict(), "max_order": self.max_order, "min_order": self.min_order,
                "q_range": [float(v) for v in self.q_range], "ridge": self.ridge}


EFFECT_KINDS: dict[str, type[Effect]] = {
    cls.kind: cls for cls in (JointCompliance, GearHarmonic, Backlash, ThermalExpansion, JointScale,
                           CyclicError)
}


def _cyclic(joint: int, values, std, extra: dict) -> "CyclicError":
    """A cyclic_error from its calib.json fields (``max_order``, ``min_order`` (1 if absent),
    ``q_range``, ``ridge``)."""
    low = int(extra.get("min_order", 1))
    high = int(extra.get("max_order", low - 1 + (len(values) // 2 or 1)))
    if low < 1 or high < low or (values and len(values) != 2 * (high - low + 1)):
        raise DataError(f"cyclic_error: orders {low}..{high} for {len(values)} parameters")
    lo, hi = extra.get("q_range") or (-np.inf, np.inf)
    return CyclicError(joint=joint, values=values, std=std, max_order=high, min_order=low,
                       q_range=(float(lo), float(hi)), ridge=float(extra.get("ridge", 0.0)))


def make_effect(kind: str, joint: int | None, n_joints: int, *, order: int = 1,
                reference_temperature_c: float | None = None, values=(), std=(),
                extra: dict | None = None) -> Effect:
    """An effect by kind, ``joint`` 0-based (None for thermal_expansion), ``extra`` the
    cyclic_error's fields; DataError names what is wrong (unknown kind, joint out of range)."""
    cls = EFFECT_KINDS.get(kind)
    if cls is None:
        raise DataError(f"unknown effect kind '{kind}' (known: {', '.join(EFFECT_KINDS)})")
    if cls is ThermalExpansion:
        if joint is not None:
            raise DataError("thermal_expansion acts on the whole arm: give no joint")
        return ThermalExpansion(values=values, std=std,
                                reference_temperature_c=None if reference_temperature_c is None
                                else float(reference_temperature_c))
    if joint is None:
        raise DataError(f"{kind} acts on one joint: give its number (1..{n_joints})")
    if not 0 <= joint < n_joints:
        raise DataError(f"{kind}: joint {joint + 1} is out of range (the robot has joints "
                        f"1..{n_joints})")
    if cls is CyclicError:
        return _cyclic(joint, values, std, extra or {})
    if cls is GearHarmonic:
        if order not in (1, 2, 3):
            raise DataError(f"gear_harmonic: order {order} is not 1, 2 or 3")
        return GearHarmonic(joint=joint, values=values, std=std, order=int(order))
    return cls(joint=joint, values=values, std=std)


def effect_from_dict(entry: dict, n_joints: int, source: str = "<calibration>") -> Effect:
    """Rebuild an effect from its calib.json entry (see :meth:`Effect.to_dict`)."""
    try:
        kind = entry["kind"]
        joint = entry.get("joint")
        cls = EFFECT_KINDS.get(kind)
        if cls is None:
            raise ModelError(f"{source}: unknown effect kind '{kind}'")
        params = entry["parameters"]
        low = int(entry.get("min_order", 1))
        names = (CyclicError(max_order=int(entry["max_order"]), min_order=low)
                 if cls is CyclicError else cls).parameter_names
        values = [float(params[name]) for name in names]
        std_doc = entry.get("std") or {}
        std = [float("nan") if std_doc.get(name) is None else float(std_doc[name])
               for name in names]
        effect = make_effect(kind, None if joint is None else int(joint) - 1, n_joints,
                             order=int(entry.get("order", 1)),
                             reference_temperature_c=entry.get("reference_temperature_c"),
                             values=values, std=std, extra=entry)
        spans = tuple((int(r["joint"]) - 1, float(r["min"]), float(r["max"]))
                      for r in entry.get("fitted_range") or ())
        if any(not 0 <= j < n_joints or not lo <= hi for j, lo, hi in spans):
            raise DataError("fitted_range: a joint out of range or min above max")
        return dataclasses.replace(effect, fitted_range=spans) if spans else effect
    except KeyError as exc:
        raise ModelError(f"{source}: effect entry of kind {entry.get('kind')!r} lacks "
                         f"{exc}") from None
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{source}: bad effect entry of kind {entry.get('kind')!r}: "
                         f"{exc}") from None
    except DataError as exc:
        raise ModelError(f"{source}: {exc}") from None


def joint_effects(effects) -> list[Effect]:
    return [e for e in effects if e.acts_on_joint]


def geometry_effects(effects) -> list[Effect]:
    return [e for e in effects if not e.acts_on_joint]


def needs_torque(effects) -> bool:
    return any(e.needs_torque for e in effects)


def joint_deflection(effects, inputs: EffectInputs) -> np.ndarray:
    """Sum of the joint effects: dq (m, n) on the controller axes, rad."""
    dq = np.zeros_like(inputs.q)
    for e in joint_effects(effects):
        dq[:, e.joint] += e.evaluate(inputs)
    return dq


def joint_deflection_dq(effects, inputs: EffectInputs) -> np.ndarray:
    """d(dq)/d(q) (m, n, n) on the controller axes (row: deflected axis)."""
    m, n = inputs.q.shape
    out = np.zeros((m, n, n))
    for e in joint_effects(effects):
        out[:, e.joint, :] += e.evaluate_dq(inputs)
    return out


def length_scale(effects, inputs: EffectInputs) -> np.ndarray:
    """Factor (m,) on the arm's link translations (1 without thermal expansion)."""
    scale = np.ones(inputs.n_rows)
    for e in geometry_effects(effects):
        scale += e.evaluate(inputs)
    return scale


__all__ = ["Conditions", "EffectInputs", "Effect", "JointCompliance", "GearHarmonic",
           "Backlash", "JointScale", "ThermalExpansion", "EFFECT_KINDS", "make_effect",
           "effect_from_dict", "effect_inputs", "joint_deflection", "joint_deflection_dq",
           "length_scale", "CyclicError"]
