"""Is a significant effect separated from the geometry? The acceptance rule that weighs
an effect's fitted size against what it explains (issue 28, weaknesses seen on real data).

A candidate effect with Jacobian columns B fitted beside the other unknowns (the geometry
and the effects already named, columns A) moves the measured points by d = B v. Of that
motion only the part outside the span of A, ``P d`` (P the projector orthogonal to A), is
what the data attribute to the effect: the rest the co-fitted geometry cancels, and adding
the effect lowers the in-sample sum of squares by |P d|^2, not |d|^2. Its
**separability** is

    s = |P d| / |d|     (0: a combination of the geometry; 1: orthogonal to it).

The fitted size |d| is the explained part |P d| amplified 1/s: an unmodelled error of the
effect's distinct shape, or a misfit of the noise, enters the named size 1/s times larger.
An effect is named only when ``s >= MIN_SEPARABILITY``; below, the diagnosis says so
("not named: not separable from the geometry over these poses", with s and the sizes) and
never names it silently.

Naming is a label, not a model choice. A term the held-out test keeps stays in the
extended model whatever its separability (what it predicts is real: its held-out gain was
measured); only its name and size are withheld when it is not separable, or when the data
cannot tell it from a significant candidate that is not (a proxy). Such a term is a
"predictive term, not named" (d.json ``predictive_not_named``); a significant term the
model does not keep, with the same reasons, goes to ``not_named``.

The threshold, measured on virtual robots with the truth known (``benchmarks/diagnose.py``
and ``benchmarks/cyclic.py`` cases, true effects 3-6x the noise): true effects named have
s = 0.40-0.99 (gravity compliance of joint 2 over random poses the lowest, 0.40; bands
0.97-0.99), but a 3x-noise compliance of joint 3 over 80 poses inside the controller's
ranges (tests/test_diagnose.py's CLI case) has 0.17; on real data the effects named without
a physical cause had s = 0.07 (a 3.9 mm compliance of joint 3 on a joint-by-joint sweep)
and 0.09-0.13 (a gear harmonic and a 0.71 mm band of joint 3 on an IRB 120 that explain
0.01 mm). 0.15 lies between (0.2 refused the 0.17 case and a band of its joint stood in).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg

MIN_SEPARABILITY = 0.15
"""Least share |P d| / |d| of an effect's motion distinct from the other unknowns."""


def separability_from_gram(gram: np.ndarray, others: np.ndarray, own: np.ndarray,
                           values: np.ndarray) -> tuple[float, float]:
    """(s, |d|^2) for the effect of columns ``own`` at ``values`` beside the columns
    ``others``, from the Gram matrix ``gram`` = A'A of all the columns (cheap: no pass
    over the rows). |P d|^2 = |d|^2 - (A_o'd)' (A_o'A_o)^-1 (A_o'd)."""
    dd = float(values @ gram[np.ix_(own, own)] @ values)
    if dd <= 0:
        return float("nan"), 0.0
    cross = gram[np.ix_(others, own)] @ values
    g = gram[np.ix_(others, others)]
    g = g + np.eye(len(others)) * 1e-12 * max(float(np.trace(g)) / max(len(others), 1), 1e-300)
    try:
        explained = float(cross @ linalg.cho_solve(linalg.cho_factor(g), cross))
    except linalg.LinAlgError:
        explained = float(cross @ np.linalg.lstsq(g, cross, rcond=1e-12)[0])
    return float(np.sqrt(max(dd - explained, 0.0) / dd)), dd


def separability(basis_q: np.ndarray, motion: np.ndarray) -> float:
    """s of the motion ``motion`` (3m,) beside the columns whose orthonormal basis is
    ``basis_q`` (3m, k)."""
    norm = float(np.linalg.norm(motion))
    if norm == 0:
        return float("nan")
    distinct = motion - basis_q @ (basis_q.T @ motion)
    return float(np.linalg.norm(distinct) / norm)


def separable(s: float) -> bool:
    """True when the separability ``s`` lets the effect be named (nan: not computed)."""
    return not s < MIN_SEPARABILITY


@dataclass(frozen=True)
class Refusal:
    """A significant effect the rule refused: its label, kind, 0-based joint (None for
    thermal expansion), where (``stage``: 'effect scan', 'cyclic bands', 'effect scan
    after the bands'), its p-value, separability and how far it would move the measured
    points (RMS per point, m; ``distinct_m`` the part not cancelled by the geometry)."""

    label: str
    kind: str
    joint: int | None
    stage: str
    p_value: float
    separability: float
    moves_m: float
    confounded_with: str = ""
    """When set: the effect is separable, but the data cannot tell it from this one, which
    is significant and not separable (the design points at an effect it cannot separate;
    naming the separable one would name a proxy)."""
    gain: float = float("nan")
    """Share of the held-out sum of squares the term removed where it was tested."""
    gain_m: float = float("nan")
    """How much the held-out RMS (3-D, per point, m; weighted as the fit) fell when the
    term was added: the reference model's held-out RMS minus the model's with it."""

    @property
    def distinct_m(self) -> float:
        return self.moves_m * self.separability

    @property
    def kept_reason(self) -> str:
        """Why a term kept in the model is not named (no size: it is not determined)."""
        if self.confounded_with:
            return (f"the data cannot tell it from {self.confounded_with}, which is significant "
                    f"but not separable from the geometry over these poses")
        return (f"not separable from the geometry over these poses (separability "
                f"{self.separability:.3f} < {MIN_SEPARABILITY}): what it predicts is measured "
                f"held-out, its size is not determined by these data")

    @property
    def reason(self) -> str:
        if self.confounded_with:
            own = (f"separability {self.separability:.3f} of its own; "
                   if np.isfinite(self.separability) else "")
            return (f"the data cannot tell it from {self.confounded_with}, which is significant "
                    f"but not separable from the geometry over these poses ({own}this design "
                    f"cannot say which)")
        return (f"not separable from the geometry over these poses: "
                f"{self.distinct_m * 1e3:.3g} mm of the {self.moves_m * 1e3:.3g} mm RMS it "
                f"moves the measured points is distinct from the geometry and the named "
                f"effects (separability {self.separability:.3f} < {MIN_SEPARABILITY})")


def refusal_entries(refusals: list[Refusal]) -> list[dict]:
    """The d.json key ``not_named``."""
    def num(value: float) -> float | None:
        return float(value) if np.isfinite(value) else None

    return [{"effect": r.label, "kind": r.kind,
             "joint": None if r.joint is None else r.joint + 1, "stage": r.stage,
             "p_value": num(r.p_value), "separability": num(r.separability),
             "min_separability": MIN_SEPARABILITY, "moves_mm": num(r.moves_m * 1e3),
             "distinct_mm": num(r.distinct_m * 1e3), "confounded_with": r.confounded_with or None,
             "reason": r.reason} for r in refusals]


def predictive_entries(terms: list[Refusal]) -> list[dict]:
    """The d.json key ``predictive_not_named``: the terms kept in the extended model but not
    named; ``kind`` and ``joint`` (1-based) are the candidate's, a hint only."""
    def num(value: float) -> float | None:
        return float(value) if np.isfinite(value) else None

    return [{"hint_kind": r.kind, "hint_joint": None if r.joint is None else r.joint + 1,
             "stage": r.stage, "p_value": num(r.p_value),
             "separability": num(r.separability), "min_separability": MIN_SEPARABILITY,
             "heldout_gain": num(r.gain), "heldout_gain_mm": num(r.gain_m * 1e3),
             "confounded_with": r.confounded_with or None, "reason": r.kept_reason}
            for r in terms]


def predictive_gain_m(terms: list[Refusal]) -> float:
    """The held-out RMS the ``terms`` removed when they were added, summed, m."""
    return float(sum(r.gain_m for r in terms if np.isfinite(r.gain_m)))


def predictive_lines(terms: list[Refusal]) -> list[str]:
    """The text summary's lines for the terms kept in the model but not named."""
    if not terms:
        return []
    n = len(terms)
    why = ("not separable from the geometry over these poses" if not any(
        r.confounded_with for r in terms) else "not separable from the geometry over these "
        "poses, or not distinguishable from a term that is not")
    lines = [f"predictable, not named: {n} term{'s' if n > 1 else ''}, gain "
             f"{predictive_gain_m(terms) * 1e3:.4f} mm held-out (3-D RMS, summed as they were "
             f"added); {why}: kept in the extended model, names and sizes withheld"]
    for r in terms:
        lines.append(f"  term ({r.stage}, p = {r.p_value:.1e}, held-out gain "
                     f"{r.gain_m * 1e3:.4f} mm; a hint only: {r.label}): {r.kept_reason}")
    return lines


def refusal_lines(refusals: list[Refusal]) -> list[str]:
    """The text summary's lines: one per effect significant but not named."""
    seen, lines = set(), []
    for r in refusals:
        if (r.label, r.stage) in seen:
            continue
        seen.add((r.label, r.stage))
        lines.append(f"not named: {r.label} ({r.stage}, p = {r.p_value:.1e}): {r.reason}")
    return lines
