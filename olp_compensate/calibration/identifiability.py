"""Identifiability (Motta 2006, section 5; Schroer): what the poses can and cannot separate.

Parameters redundant by construction are frozen with the reason (:func:`structural_freeze`:
the first joint's zero and height define the base frame; the last joint's zero turns
everything after its axis, which the unknown tool points and tool rotations absorb). Then
the SVD of the column-scaled Jacobian over the actual poses finds combinations the data
cannot separate (singular values below ``RANK_TOLERANCE``); which parameters to freeze for
them is chosen from that null space by :func:`~.freeze_choice.choose_frozen` (largest part
in it first; near ties, within ``TIE_MARGIN``, by the fixed order: the model's parameters in
its order, then the tool points, then the device frame), and the report names the
combination and any tie (:func:`analyse_identifiability`). Effects come after the geometry:
an effect whose columns the kept geometry (and the effects before it) nearly spans
(relative singular value of its projected columns below ``EFFECT_SEPARATION``) is reported
and not fitted (:func:`effect_separation`), so an effect never displaces geometry.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError
from ..kinematics.model import KinematicModel
from .device_motions import DeviceMotion, held_motions
from .factorizations import pivoted_cholesky_diagonal, pivoted_qr_r
from .freeze_choice import TIE_MARGIN, choose_frozen
from .measurements import Measurements
from .problem import IdentificationProblem

RANK_TOLERANCE = 1e-8
"""Singular values below this fraction of the largest mark an inseparable combination."""
WEAK_TOLERANCE = 1e-4
"""Singular values below this fraction of the largest mark a barely observable combination."""
EFFECT_SEPARATION = 0.05
"""An effect whose unit-scaled columns keep less than this fraction (smallest singular value)
outside the span of the geometry is reported as inseparable, not fitted."""
CERTAIN_RANK = 1e-5
"""A pivoted Cholesky diagonal of the scaled J^T J above this fraction of the largest proves
full rank without the pivoted QR (J^T J resolves relative singular values down to ~1e-8,
the same order as RANK_TOLERANCE, so nearer cases go to the QR)."""


@dataclass(frozen=True)
class Identifiability:
    """What the poses can and cannot tell apart.

    ``frozen``: parameter name -> reason; ``weak``: descriptions of barely observable
    combinations; ``condition_number`` of the unit-column-scaled Jacobian of the unknowns.
    ``frozen`` also holds effects (by label) that the data cannot separate from the geometry.
    """

    condition_number: float
    frozen: dict[str, str]
    weak: list[str]
    singular_values: np.ndarray
    motions: dict[str, DeviceMotion] = field(default_factory=dict)
    """Held device-frame unknown -> the rigid motion of the device frame it leaves
    undetermined (:mod:`.device_motions`); its reason in ``frozen`` is that motion's text."""



def structural_freeze(model: KinematicModel, meas: Measurements, tool_names: list[str],
                      user_freeze: tuple[str, ...], rotated_tools=(),
                      option: str = "IdentificationOptions.freeze") -> dict[str, str]:
    """Parameters redundant by construction, and the user's, name -> reason; ``option``
    names where ``user_freeze`` came from, for the message when a name is unknown.

    The last joint's zero ``Rz(q_n + theta_n)`` turns everything after axis n, which is only
    the tools: turning every tool point (and, with orientation rows, every tool rotation)
    about that axis gives the same measurements, however many points per pose are measured,
    so it is held at nominal and the tools are found in the flange frame of the nominal zero
    (it is observable only against a tool known beforehand, which identification does not
    assume)."""
    frozen = {}
    for name in ("j1.theta", "j1.d"):
        if name in model.names:
            frozen[name] = ("redundant with the device registration (the base frame is defined "
                            "by axis 1: its zero and height)")
    last = model.n_joints
    if model.joint_kinds[-1] == "revolute":
        what = "tool points and tool rotations" if rotated_tools else "tool points"
        frozen[f"j{last}.theta"] = (
            f"redundant with the tools: the last joint's zero turns them about axis {last}, "
            f"which their unknown {what} absorb (held at nominal; the tools are found in the "
            f"flange frame of the nominal zero)")
    for name in user_freeze:
        if name not in model.names:
            raise DataError(f"{option}: no parameter named '{name}' (known: "
                            f"{', '.join(model.names)})")
        frozen[name] = "held at nominal on request"
    return frozen


def describe_combination(vector: np.ndarray, names: list[str]) -> str:
    order = np.argsort(-np.abs(vector))
    parts = [names[k] for k in order[:4] if abs(vector[k]) > 0.15 * abs(vector[order[0]])]
    return " + ".join(parts)


def unit_columns(jac: np.ndarray, columns: np.ndarray, norms: np.ndarray) -> np.ndarray:
    """``jac[:, columns] / norms[columns]``, a new Fortran-ordered array (LAPACK's order:
    its QR then works in place)."""
    out = np.empty((len(jac), len(columns)), order="F")
    if len(columns) == jac.shape[1]:  # all of them, in order: no intermediate copy
        return np.divide(jac, norms, out=out)
    return np.divide(jac[:, columns], norms[columns], out=out)


def analyse_identifiability(problem: IdentificationProblem, x: np.ndarray,
                            jacobian: np.ndarray | None = None, normal: np.ndarray | None = None,
                            ) -> tuple[Identifiability, np.ndarray]:
    """SVD of the unit-column-scaled Jacobian at x (``jacobian``, and ``normal`` = J^T J,
    when the caller has them); returns the analysis and a boolean mask over the unknowns that
    are kept (inseparable ones dropped by pivoted QR; effects that the kept geometry nearly
    spans dropped by :func:`effect_separation`).

    With ``normal``, the pivoted Cholesky factorization of the scaled J^T J (the pivoted QR's
    R in exact arithmetic, n x n work) settles the usual case: when its smallest diagonal
    exceeds ``CERTAIN_RANK`` times its largest, the pivoted QR, whose threshold
    ``RANK_TOLERANCE`` is far lower, would keep every column too, and is skipped."""
    jac = problem.residuals_and_jacobian(x)[1] if jacobian is None else jacobian
    names = problem.names()
    n_geo = problem.layout.n_geometric
    if normal is None:
        norms = np.sqrt(np.einsum("ij,ij->j", jac, jac))
    else:
        norms = np.sqrt(np.diag(normal))
    frozen = {}
    keep = norms > 1e-12 * max(norms.max(), 1e-300)
    for k in np.flatnonzero(~keep[:n_geo]):
        frozen[names[k]] = "has no effect on the measured points with these poses"
    keep[n_geo:] = False  # effects join one by one below, after the geometry
    geo = np.flatnonzero(keep[:n_geo])
    rank = _geometric_rank(jac, normal, norms, geo)
    motions = {}
    if rank.rank < len(geo):
        inseparable = _inseparable(rank, geo, names, freeze_preference(problem.layout))
        held = [names.index(name) for name in inseparable]
        motions = held_motions(problem, held, rank.null, geo, rank.norms)
        frozen.update(inseparable)
        frozen.update({name: motion.text for name, motion in motions.items()})
        keep[held] = False
    for effect, cols in zip(problem.effects, problem.layout.effects):
        reason = effect_separation(jac[:, np.flatnonzero(keep)], jac[:, cols],
                                   [names[k] for k in np.flatnonzero(keep)])
        if reason is None:
            keep[cols] = True
        else:
            frozen[effect.label] = reason
    s, vt = _kept_spectrum(jac, rank, norms, keep, geo)
    kept_names = [names[k] for k in np.flatnonzero(keep)]
    weak = [f"{describe_combination(vt[k], kept_names)} (relative singular value "
            f"{s[k] / s[0]:.1e})" for k in range(len(s)) if s[k] < WEAK_TOLERANCE * s[0]]
    return Identifiability(condition_number=float(s[0] / s[-1]), frozen=frozen, weak=weak,
                           singular_values=s, motions=motions), keep


@dataclass(frozen=True)
class _Rank:
    """Rank of the unit-scaled geometric columns: ``scaled`` is their J^T J when the
    pivoted Cholesky proved full rank (else None); otherwise ``r`` and ``pivots`` are the
    pivoted QR's (R factor and column order), ``norms`` the column norms it used, ``rank``
    the number of R's singular values above ``RANK_TOLERANCE`` times the largest and
    ``null`` (k, k - rank) the right singular vectors below it (rows in the order of
    ``geo``)."""

    rank: int
    scaled: np.ndarray | None = None
    r: np.ndarray | None = None
    pivots: np.ndarray | None = None
    norms: np.ndarray | None = None
    null: np.ndarray | None = None


def _geometric_rank(jac: np.ndarray, normal: np.ndarray | None, norms: np.ndarray,
                    geo: np.ndarray) -> _Rank:
    """The rank of the unit-scaled columns ``geo`` of ``jac``: from the pivoted Cholesky of
    the scaled ``normal`` when it is clearly regular, else from the pivoted QR."""
    if normal is not None:
        scaled = normal[np.ix_(geo, geo)] / np.outer(norms[geo], norms[geo])
        diag = pivoted_cholesky_diagonal(scaled)
        if diag is not None and diag.min() > CERTAIN_RANK * diag.max():
            return _Rank(rank=len(geo), scaled=scaled)
        norms = np.sqrt(np.einsum("ij,ij->j", jac, jac))  # the QR's own (J^T J's agree)
    r, pivots = pivoted_qr_r(unit_columns(jac, geo, norms))
    # J P = Q R, so the singular values of J are R's and its right singular vectors R's
    # with rows un-pivoted. The rank counts singular values, as RANK_TOLERANCE states (R's
    # diagonal only brackets them: on a line path it sat at 1e-8 over singular values of
    # 2e-9, and noise decided the count).
    _, s, vt_r = np.linalg.svd(r)
    rank = int(np.sum(s > RANK_TOLERANCE * s[0]))
    vt = np.empty_like(vt_r)
    vt[:, pivots] = vt_r
    return _Rank(rank=rank, r=r, pivots=pivots, norms=norms, null=vt[rank:].T)


def freeze_preference(layout) -> np.ndarray:
    """Order in which tied unknowns are frozen (lower first), over the unknowns before the
    effects: the model's parameters in the model's order, then the tool points and
    rotations, then the device frame (which every measured point is expressed in: kept
    free longest, as :func:`structural_freeze` keeps it over j1.theta and j1.d)."""
    n = layout.n_geometric
    preference = np.arange(n) + 2 * n  # the device frame: last
    preference[layout.geometry] = np.arange(n)[layout.geometry]
    tools = slice(layout.tool_points.start, layout.tool_rotations.stop)
    preference[tools] = np.arange(n)[tools] + n
    return preference


def _inseparable(rank: _Rank, geo: np.ndarray, names: list[str],
                 preference: np.ndarray) -> dict[str, str]:
    """Name -> reason for the columns frozen for the null space (:func:`choose_frozen`),
    each with the null-space combination it takes most part in and the unknowns it tied
    with (those that take part in that combination)."""
    sub_names = [names[k] for k in geo]
    frozen = {}
    for choice in choose_frozen(rank.null, preference[geo]):
        v = choice.direction
        reason = (f"cannot be separated with these poses (combination "
                  f"{describe_combination(v, sub_names)}")
        tied = [sub_names[t] for t in choice.tied if abs(v[t]) > 0.15 * np.abs(v).max()]
        if tied:
            reason += (f"; a tie within {TIE_MARGIN:.0%} with {', '.join(tied)}, decided by "
                       f"the fixed order: model parameters, tools, device frame")
        frozen[sub_names[choice.index]] = reason + ")"
    return frozen


def _kept_spectrum(jac: np.ndarray, rank: _Rank, norms: np.ndarray, keep: np.ndarray,
                   geo: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(singular values, V^T or None) of the unit-scaled kept columns, reusing the rank's
    factorization when the kept columns are its columns; V^T only when some combination is
    weak (below ``WEAK_TOLERANCE``)."""
    same = np.array_equal(np.flatnonzero(keep), geo)
    if same and rank.r is None:  # clearly regular
        # s^2 from the scaled J^T J, to a relative error below eps / CERTAIN_RANK^2
        s, vt = np.sqrt(np.maximum(np.linalg.eigvalsh(rank.scaled)[::-1], 0.0)), None
        if s[-1] < WEAK_TOLERANCE * s[0]:  # the weak combinations are wanted: vectors too
            lam, vec = np.linalg.eigh(rank.scaled)
            s, vt = np.sqrt(np.maximum(lam[::-1], 0.0)), vec[:, ::-1].T
        return s, vt
    if same:  # the pivoted QR is this one's
        s = np.linalg.svd(rank.r, compute_uv=False)
        vt = None
        if s[-1] < WEAK_TOLERANCE * s[0]:  # the weak combinations are wanted: vectors too
            _, s, vt_r = np.linalg.svd(rank.r)
            vt = np.empty_like(vt_r)
            vt[:, rank.pivots] = vt_r
        return s, vt
    if rank.norms is not None:
        norms = rank.norms
    _, s, vt = np.linalg.svd(np.linalg.qr(jac[:, keep] / norms[keep], mode="r"))
    return s, vt


def effect_separation(kept: np.ndarray, block: np.ndarray, kept_names: list[str]) -> str | None:
    """Why an effect with Jacobian columns ``block`` (3m, p) cannot be fitted beside the
    ``kept`` columns (3m, k), or None when it can. The test is on unit-scaled columns: the
    smallest singular value of the part of ``block`` outside the span of ``kept`` must
    reach ``EFFECT_SEPARATION``."""
    norms = np.linalg.norm(block, axis=0)
    reference = np.linalg.norm(kept, axis=0).max() if kept.size else 1.0
    if np.any(norms <= 1e-12 * reference):
        return "has no effect on the measured points with these data"
    unit = block / norms
    kept_unit = kept / np.linalg.norm(kept, axis=0)
    q, _ = np.linalg.qr(kept_unit)
    outside = unit - q @ (q.T @ unit)
    u, s, vt = np.linalg.svd(outside, full_matrices=False)
    if s[-1] >= EFFECT_SEPARATION:
        return None
    direction = unit @ vt[-1]
    coefficients, *_ = np.linalg.lstsq(kept_unit, direction, rcond=None)
    return (f"cannot be separated from the geometry with these poses (it looks like "
            f"{describe_combination(coefficients, kept_names)}; {s[-1]:.1e} of it is distinct)")

