"""What remains after the named effects: how much of it a flexible model of the joints
predicts, and the noise floor that no model of the joints predicts.

The flexible model (:class:`ResidualMap`) is ridge regression on random Fourier features
(Rahimi & Recht 2007) and on the products of pairs of the inputs (a trigonometric
polynomial: gravity torques and their coupling through the arm are of this kind). The
inputs: sin and cos of every revolute controller axis (a prismatic axis: its value over
its span), plus, for the predictability estimate only,
temperature and time scaled to [-1, 1] when the measurements carry them. Features
``sqrt(2 / D) cos(x W / ell + b)`` (W standard normal, b uniform, fixed seed) approximate
a Gaussian kernel of length ``ell``; the inputs also enter linearly. The length and the
penalty are chosen by nested cross-validation on the diagnosis's folds (inner folds within
each outer training set), so the held-out figure is honest; the stored map takes the pair
that ordinary k-fold cross-validation over all rows chooses. Everything works from per-fold
Gram matrices and one eigen-decomposition per training set and length.

A second, local model checks the first: the mean of the k nearest training rows in the
same inputs, k chosen by the same nested cross-validation. The predictable remainder (and
so the noise floor) is the better of the two held-out figures: on a real arm's path data
(a tracker following a curve) the smooth kernel found nothing while the nearest neighbours
predicted half of the residual, and a noise floor above what some model of the joints
reaches would call structure noise. The stored map is the kernel model's (it needs no
training rows); its own figures are in its ``validation``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations_with_replacement

import numpy as np

FEATURES = 150
"""Random Fourier features D."""
POLY_DEGREE = 2
"""Highest degree of the products of the inputs."""
LENGTHS = (0.5, 1.0, 2.0)
"""Kernel lengths tried, in units of the inputs (sin/cos lie in [-1, 1])."""
PENALTIES = np.logspace(-5, 2, 8)
"""Ridge penalties tried, relative to the number of training rows."""
SEED = 28
NEIGHBOURS = (1, 2, 4, 8, 16, 32)
"""k tried by the nearest-neighbour check."""


@dataclass(frozen=True)
class ResidualMap:
    """A cross-validated map from the controller axes to the residual left by the model
    (measured minus predicted, device frame, m). ``kinds`` per axis: 'revolute' (sin, cos)
    or 'prismatic' (value scaled by ``span``); ``q_range`` (n, 2) controller axis span it
    was fitted on (rad/m): outside it the map is refused; ``validation``: held-out figures,
    mm."""

    kinds: tuple[str, ...]
    center: np.ndarray
    span: np.ndarray
    frequencies: np.ndarray
    phases: np.ndarray
    weights: np.ndarray
    length: float
    penalty: float
    q_range: np.ndarray
    validation: dict = field(default_factory=dict)

    def features(self, q_ctrl: np.ndarray) -> np.ndarray:
        return _design(_inputs(q_ctrl, self.kinds, self.center, self.span), self.frequencies,
                       self.phases, self.length)

    def inside(self, q_ctrl: np.ndarray) -> np.ndarray:
        """(m,) True for the rows whose every axis lies in the fitted span."""
        q = np.atleast_2d(q_ctrl)
        return np.all((q >= self.q_range[:, 0]) & (q <= self.q_range[:, 1]), axis=1)

    def predict(self, q_ctrl: np.ndarray) -> np.ndarray:
        """(m, 3) predicted residual, device frame, m; zero on rows outside the span."""
        q = np.atleast_2d(np.asarray(q_ctrl, float))
        return (self.features(q) @ self.weights) * self.inside(q)[:, None]

    def to_dict(self) -> dict:
        return {"kind": "random_fourier_ridge", "inputs": [
                    f"{'sin/cos' if k == 'revolute' else 'value'} of axis {j + 1}"
                    for j, k in enumerate(self.kinds)],
                "axis_kinds": list(self.kinds), "center": self.center.tolist(),
                "span": self.span.tolist(), "length": self.length, "penalty": self.penalty,
                "frequencies": self.frequencies.tolist(), "phases": self.phases.tolist(),
                "weights_m": self.weights.tolist(), "q_range": self.q_range.tolist(),
                "output": "measured minus predicted position, device frame, m",
                "validation": self.validation}

    @classmethod
    def from_dict(cls, doc: dict) -> "ResidualMap":
        return cls(kinds=tuple(doc["axis_kinds"]), center=np.array(doc["center"], float),
                   span=np.array(doc["span"], float),
                   frequencies=np.array(doc["frequencies"], float),
                   phases=np.array(doc["phases"], float),
                   weights=np.array(doc["weights_m"], float), length=float(doc["length"]),
                   penalty=float(doc["penalty"]), q_range=np.array(doc["q_range"], float),
                   validation=dict(doc.get("validation") or {}))


def _inputs(q: np.ndarray, kinds, center, span, extra: np.ndarray | None = None) -> np.ndarray:
    cols = []
    for j, kind in enumerate(kinds):
        if kind == "revolute":
            cols += [np.sin(q[:, j]), np.cos(q[:, j])]
        else:
            cols.append((q[:, j] - center[j]) / span[j])
    x = np.column_stack(cols)
    return x if extra is None else np.hstack([x, extra])


def _monomials(x: np.ndarray, degree: int) -> np.ndarray:
    """Every product of 2..``degree`` of the columns of x (with repetition)."""
    cols = [np.prod(x[:, list(c)], axis=1) for d in range(2, degree + 1)
            for c in combinations_with_replacement(range(x.shape[1]), d)]
    return np.column_stack(cols) if cols else np.zeros((len(x), 0))


def _design(x: np.ndarray, frequencies, phases, length: float) -> np.ndarray:
    """Random Fourier features, the products of up to POLY_DEGREE of the sin/cos inputs
    (gravity and coupling terms are of this kind), the inputs and a constant."""
    d = frequencies.shape[1]
    z = np.sqrt(2.0 / d) * np.cos(x @ frequencies / length + phases)
    return np.hstack([z, _monomials(x, POLY_DEGREE), x, np.ones((len(x), 1))])


@dataclass(frozen=True)
class Predictability:
    """``heldout`` (m, 3): the ``target`` minus the flexible model's nested-CV prediction;
    ``rms_before``/``rms_after``: 3-D RMS of the target and of ``heldout``, m; ``joints``:
    0-based axes the map depends on most; ``map``: the map on the joints alone."""

    heldout: np.ndarray
    target: np.ndarray
    rms_before: float
    rms_after: float
    joints: list[int]
    map: ResidualMap | None
    model: str = "random Fourier ridge"
    """Which flexible model reached ``rms_after`` (or 'k-nearest neighbours')."""


class _Fold:
    """Per-fold Gram matrices of one design and one target; the eigen-decompositions of
    the training sets' Gram matrices are cached and shared with :meth:`retarget`."""

    def __init__(self, phi: np.ndarray, y: np.ndarray, folds, eig: dict | None = None):
        self.phi, self.folds = phi, folds
        self.grams = [phi[f].T @ phi[f] for f in folds] if eig is None else None
        self.rhs = [phi[f].T @ y[f] for f in folds]
        self.yy = [float(np.sum(y[f] ** 2)) for f in folds]
        self.rows = [int(f.sum()) for f in folds]
        self._eig: dict = {} if eig is None else eig
        self._cache: dict = {}

    def retarget(self, y: np.ndarray) -> "_Fold":
        """The same design with another target (no Gram matrix or decomposition again)."""
        other = _Fold(self.phi, y, self.folds, eig=self._eig)
        other.grams = self.grams
        return other

    def solutions(self, train: list[int]):
        """Weights for every penalty of the grid, fitted on the folds ``train`` (cached:
        the nested folds share their training sets)."""
        key = frozenset(train)
        if key not in self._cache:
            if key not in self._eig:
                d, v = np.linalg.eigh(sum(self.grams[f] for f in train))
                self._eig[key] = (np.clip(d, 0.0, None), v)
            d, v = self._eig[key]
            vr = v.T @ sum(self.rhs[f] for f in train)
            n = sum(self.rows[f] for f in train)
            self._cache[key] = [v @ (vr / (d + lam * n)[:, None]) for lam in PENALTIES]
        return self._cache[key]

    def sse(self, fold: int, w: np.ndarray) -> float:
        return float(self.yy[fold] - 2 * np.sum(w * self.rhs[fold])
                     + np.sum(w * (self.grams[fold] @ w)))


def _select(designs: list[_Fold], outer: set[int]) -> tuple[int, int]:
    """(length index, penalty index) of least inner-CV error over the folds not in outer."""
    k = len(designs[0].folds)
    if k - len(outer) < 2:  # no inner folds left (2-fold diagnosis): a middle choice
        return 1, len(PENALTIES) // 2
    best, arg = np.inf, (0, 0)
    for li, design in enumerate(designs):
        sse = np.zeros(len(PENALTIES))
        for inner in range(k):
            if inner in outer:
                continue
            train = [f for f in range(k) if f != inner and f not in outer]
            sse += [design.sse(inner, w) for w in design.solutions(train)]
        if sse.min() < best:
            best, arg = float(sse.min()), (li, int(np.argmin(sse)))
    return arg


def _random_features(n_in: int):
    rng = np.random.default_rng(SEED)
    return rng.standard_normal((n_in, FEATURES)), rng.uniform(0, 2 * np.pi, FEATURES)


def _scaled(values: np.ndarray) -> np.ndarray:
    span = max(float(np.ptp(values)), 1e-12)
    return (2 * (values - values.min()) / span - 1.0)[:, None]


def predictability(q_ctrl: np.ndarray, kinds: tuple[str, ...], target: np.ndarray,
                   folds: list[np.ndarray], temperature=None, time=None,
                   map_target: np.ndarray | None = None) -> Predictability:
    """How much of ``target`` (m, 3; a model's held-out residuals) the flexible model of
    the joints (and temperature and time where given) predicts, by nested CV over
    ``folds`` (row masks); and the map on the joints alone fitted on all rows of
    ``map_target`` (default ``target``; the final model's measured minus predicted)."""
    center = q_ctrl.mean(axis=0)
    span = np.maximum(np.ptp(q_ctrl, axis=0), 1e-12)
    extra = [_scaled(np.asarray(v, float)) for v in (temperature, time)
             if v is not None and np.ptp(v) > 0]
    x = _inputs(q_ctrl, kinds, center, span, np.hstack(extra) if extra else None)
    w_rff, b_rff = _random_features(x.shape[1])
    designs = [_Fold(_design(x, w_rff, b_rff, ell), target, folds) for ell in LENGTHS]
    k = len(folds)
    heldout = np.empty_like(target)
    for f in range(k):
        li, pi = _select(designs, {f})
        w = designs[li].solutions([g for g in range(k) if g != f])[pi]
        heldout[folds[f]] = target[folds[f]] - designs[li].phi[folds[f]] @ w
    before = float(np.sqrt(np.mean(np.sum(target**2, axis=1))))
    after = float(np.sqrt(np.mean(np.sum(heldout**2, axis=1))))
    kernel_after, model = after, "random Fourier ridge"
    local = target - _knn_heldout(x, target, folds)
    local_after = float(np.sqrt(np.mean(np.sum(local**2, axis=1))))
    if local_after < after:
        heldout, after, model = local, local_after, "k-nearest neighbours"
    if after >= before:  # nothing predictable: the flexible models only add noise
        heldout, after = target.copy(), before
    x_joints = _inputs(q_ctrl, kinds, center, span)
    w_j, b_j = _random_features(x_joints.shape[1])
    fitted = target if map_target is None else map_target
    joint_designs = ([_Fold(_design(x_joints, w_j, b_j, ell), fitted, folds) for ell in LENGTHS]
                     if extra else [design.retarget(fitted) for design in designs])
    li, pi = _select(joint_designs, set())
    weights = joint_designs[li].solutions(list(range(k)))[pi]
    q_range = np.column_stack([q_ctrl.min(axis=0), q_ctrl.max(axis=0)])
    rmap = ResidualMap(kinds=kinds, center=center, span=span, frequencies=w_j, phases=b_j,
                       weights=weights, length=LENGTHS[li], penalty=float(PENALTIES[pi]),
                       q_range=q_range, validation={
                           "method": f"{k}-fold cross-validation by pose, nested",
                           "heldout_rms_mm_without": before * 1e3,
                           "heldout_rms_mm_with": min(kernel_after, before) * 1e3})
    return Predictability(heldout=heldout, target=target, rms_before=before, rms_after=after,
                          joints=_important_joints(rmap, q_ctrl) if after < before else [],
                          map=rmap, model=model)


def _knn_predict(x_train, y_train, x_test, ks) -> list[np.ndarray]:
    """Mean of the k nearest training rows' y for every k of ``ks`` (ascending)."""
    d = (np.sum(x_test**2, 1)[:, None] + np.sum(x_train**2, 1)[None, :]
         - 2.0 * x_test @ x_train.T)
    kmax = min(ks[-1], len(x_train))
    near = np.argpartition(d, kmax - 1, axis=1)[:, :kmax]
    near = np.take_along_axis(near, np.argsort(np.take_along_axis(d, near, 1), 1), 1)
    cumulative = np.cumsum(y_train[near], axis=1)
    return [cumulative[:, min(k, kmax) - 1] / min(k, kmax) for k in ks]


def _knn_heldout(x: np.ndarray, y: np.ndarray, folds) -> np.ndarray:
    """Nested-CV prediction (m, 3) of y by the k nearest rows, k chosen on inner folds."""
    k_folds, out = len(folds), np.zeros_like(y)
    for f, test in enumerate(folds):
        sse = np.zeros(len(NEIGHBOURS))
        for g, inner in enumerate(folds):
            if g == f or k_folds < 3:
                continue
            train = ~(test | inner)
            sse += [np.sum((y[inner] - p) ** 2)
                    for p in _knn_predict(x[train], y[train], x[inner], NEIGHBOURS)]
        k = NEIGHBOURS[int(np.argmin(sse))] if k_folds >= 3 else 4
        out[test] = _knn_predict(x[~test], y[~test], x[test], (k,))[0]
    return out


def _important_joints(rmap: ResidualMap, q_ctrl: np.ndarray, share: float = 0.2) -> list[int]:
    """Axes whose shuffling changes the map's prediction by at least ``share`` of the
    largest such change (0-based)."""
    base = rmap.features(q_ctrl) @ rmap.weights
    rng = np.random.default_rng(SEED)
    change = []
    for j in range(q_ctrl.shape[1]):
        shuffled = q_ctrl.copy()
        shuffled[:, j] = rng.permutation(shuffled[:, j])
        change.append(float(np.mean(np.sum((rmap.features(shuffled) @ rmap.weights - base) ** 2,
                                           axis=1))))
    change = np.array(change)
    if change.max() <= 0:
        return []
    return [int(j) for j in np.flatnonzero(change >= share * change.max())]
