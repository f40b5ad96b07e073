"""Numbers written "like" the original: the style rules of the splice emitter.

A new number keeps the original's style (plain decimal or exponent, exponent letter case
and sign, a leading ``+``, a missing leading zero) with at least ``MM_DECIMALS`` decimals
for millimetres, ``QUAT_DECIMALS`` for quaternion components and ``DEG_DECIMALS`` for
degrees (about 1 micrometre and 1 microradian), or more when the original had more.
Orientations are written as the representation nearest the written one (quaternion sign,
Z-Y-Z branch), so an unchanged orientation keeps its numbers.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import DataError
from ..kinematics.conventions import euler_zyz_from_matrix, matrix_from_euler_zyz

MM_DECIMALS = 3
QUAT_DECIMALS = 6
DEG_DECIMALS = 4


def format_like(original: str, value: float, decimals: int) -> str:
    """``value`` written in the style of ``original`` with at least ``decimals`` decimals
    (plain style) or resolution 10**-decimals (exponent style)."""
    value = float(value)
    if not math.isfinite(value):
        raise DataError(f"cannot write {value} into a program (replacing {original!r})")
    return format_finite(original, value, decimals)


def format_finite(original: str, value: float, decimals: int) -> str:
    """:func:`format_like` for a finite float (the hot path)."""
    if "e" in original or "E" in original:
        return _format_exp(original, value, decimals)
    dot = original.find(".")
    d = len(original) - dot - 1 if dot >= 0 else 0
    s = "%.*f" % (d if d > decimals else decimals, value)
    if s[0] == "-" and not s.strip("-0."):
        s = s[1:]  # no "-0.000"
    c = original[0]
    if c == "+":
        if s[0] != "-":
            s = "+" + s
        c = original[1:2]
    elif c == "-":
        c = original[1:2]
    if c == "." and "0." in s[:3]:
        s = s.replace("0.", ".", 1)  # the original wrote ".5", not "0.5"
    return s


def _format_exp(original: str, value: float, decimals: int) -> str:
    mant_o, _, exp_o = original.replace("E", "e").partition("e")
    letter = "E" if "E" in original else "e"
    dot = mant_o.find(".")
    d0 = len(mant_o) - dot - 1 if dot >= 0 else 0
    k = math.floor(math.log10(abs(value))) if value != 0 else 0
    d = max(d0, decimals + k, 0)
    mant, _, ex = ("%.*e" % (d, value)).partition("e")
    exn = int(ex)
    if mant[0] == "-" and not mant.strip("-0."):
        mant = mant[1:]
    digits = exp_o.lstrip("+-")
    sign = "-" if exn < 0 else ("+" if exp_o[:1] == "+" else "")
    if original[:1] == "+" and mant[0] != "-":
        mant = "+" + mant
    return f"{mant}{letter}{sign}{str(abs(exn)).zfill(len(digits))}"


def format_int_like(original: str, value: int) -> str:
    """An integer (confdata) in the style of ``original`` (keeps a leading ``+``)."""
    s = str(int(value))
    return "+" + s if original[:1] == "+" and value >= 0 else s


def finite_floats(name: str, values) -> list[float]:
    """``values`` as a list of finite floats, or DataError naming ``name``."""
    try:
        vals = [float(v) for v in (values.tolist() if hasattr(values, "tolist")
                                   else values)]
    except (TypeError, ValueError):
        raise DataError(f"{name}: expected numbers, got {values!r}") from None
    if not all(map(math.isfinite, vals)):
        raise DataError(f"{name}: values must be finite, got {vals}")
    return vals


def check_values(name: str, values, count: int) -> list[float]:
    """``values`` as a list of ``count`` finite floats, or DataError naming ``name``."""
    vals = finite_floats(name, values)
    if len(vals) != count:
        raise DataError(f"{name}: expected {count} values, got {len(vals)}")
    return vals


def aligned_quaternion(quat_wxyz, reference_wxyz) -> list[float]:
    """Unit quaternion ``quat_wxyz`` with the sign (q or -q) nearest ``reference_wxyz``."""
    q = check_values("orientation", quat_wxyz, 4)
    norm = math.sqrt(sum(c * c for c in q))
    if norm < 1e-12:
        raise DataError("orientation: a zero quaternion is no rotation")
    dot = sum(a * float(b) for a, b in zip(q, reference_wxyz))
    scale = (-1.0 if dot < 0 else 1.0) / norm
    return [c * scale for c in q]


def nearest_euler_zyz_deg(rotation, reference_deg) -> np.ndarray:
    """V+ (yaw, pitch, roll) in degrees for ``rotation`` (3, 3), choosing among the
    equivalent triples (the two Z-Y-Z branches, multiples of 360) the one nearest
    ``reference_deg``, so an unchanged orientation keeps its numbers."""
    ref = np.asarray(reference_deg, dtype=float)
    yaw, pitch, roll = np.rad2deg(euler_zyz_from_matrix(np.asarray(rotation, dtype=float)))
    best = None
    for cand in (np.array([yaw, pitch, roll]), np.array([yaw + 180.0, -pitch, roll + 180.0])):
        cand = ref + (cand - ref + 180.0) % 360.0 - 180.0
        if abs(cand[1]) < 1e-9 or abs(abs(cand[1]) - 180.0) < 1e-9:
            # gimbal lock: only yaw + roll (pitch 0) or yaw - roll (pitch 180) is defined
            total = cand[0] + cand[2] if abs(cand[1]) < 90 else cand[0] - cand[2]
            sgn = 1.0 if abs(cand[1]) < 90 else -1.0
            r0 = ref[2] + ((total - ref[0] - sgn * ref[2]) / 2.0)
            cand = np.array([total - sgn * r0, cand[1], r0])
        err = np.abs(cand - ref).sum()
        if best is None or err < best[0]:
            best = (err, cand)
    out = best[1]
    check = matrix_from_euler_zyz(*np.deg2rad(out))
    if not np.allclose(check, rotation, atol=1e-9):
        raise DataError("orientation: could not express the rotation as Z-Y-Z angles")
    return out
