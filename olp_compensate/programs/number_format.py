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


def fixed_rows(values: np.ndarray, decimals: int) -> list[str]:
    """Each row of ``values`` (n, m) floats as ``",".join("%.{decimals}f" % v ...)``
    (the same text), the whole array written by array operations (a fifth of the time).

    Each number is the integer nearest ``|v| * 10**decimals`` (the product rounded to
    floats, its digits by integer division), with its point put in and a ``-`` where the
    sign bit is set (``%`` writes ``-0.0000`` too). Where that product lies so near a
    half-integer that its rounding could differ from the exact decimal rounding ``%``
    does (within two units in its last place), and where it is not below 2**52 (or not
    finite), the row is written by ``%`` instead."""
    v = np.asarray(values, dtype=float)
    n, m = v.shape if v.ndim == 2 else (len(v), 1)
    if not n or not m:
        return [""] * n
    v = v.reshape(n, m)
    scaled = np.abs(v) * 10.0 ** decimals
    if not scaled.max() < 2.0 ** 52:   # NaN, inf or too large for exact integers
        return [_fixed_row(row, decimals) for row in v.tolist()]
    whole = np.rint(scaled)
    unsure = np.abs(np.abs(scaled - whole) - 0.5) <= scaled * 2.0 ** -51
    top = int(whole.max())
    rest = whole.astype(np.uint32 if top < 2 ** 32 else np.uint64)
    width = max(len(str(top)), decimals + 1)   # digits of the widest
    point = 1 if decimals else 0
    # a number: sign, digits (the point among them), ',' or '\n'; 0 bytes are dropped
    chars = np.zeros((n, m, width + point + 2), np.uint8)
    np.multiply(np.signbit(v), ord("-"), out=chars[:, :, 0], dtype=np.uint8)
    tens, digit = np.empty_like(rest), np.empty_like(rest)
    column = width + point
    for k in range(width):
        if decimals and k == decimals:
            chars[:, :, column] = ord(".")
            column -= 1
        np.floor_divide(rest, 10, out=tens)
        np.subtract(rest, np.multiply(tens, 10, out=digit), out=digit)
        if k > decimals:   # a leading zero of the integer part: dropped
            np.multiply(digit + 48, rest > 0, out=digit)
        else:
            digit += 48
        chars[:, :, column] = digit
        rest, tens, column = tens, rest, column - 1
    chars[:, :, -1] = ord(",")
    chars[:, -1, -1] = ord("\n")
    out = chars.tobytes().translate(None, b"\0").decode("ascii").split("\n")
    out.pop()
    for i in np.flatnonzero(unsure.any(axis=1)).tolist():
        out[i] = _fixed_row(v[i].tolist(), decimals)
    return out


def _fixed_row(row: list[float], decimals: int) -> str:
    return ",".join(["%.*f" % (decimals, x) for x in row])


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
