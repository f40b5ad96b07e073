"""Accuracy of the camera as a measuring device, from views taken at known displacements
(seed section 9).

The camera (or the board) is moved by a coordinate measuring machine or a linear stage by
known *pure translations* ``d_i`` (stage frame), one view per position; each view is measured
(:func:`.measure.measure_pose`): the optical centre ``p_i`` in the board frame, and
``camera_R_board``. Three figures, each per view and as statistics:

- **travel** (the seed's first method): ``|p_i - p_0| - |d_i - d_0|``, the error of the
  distance travelled from the first view, mm. Blind to the direction of the error, it is the
  figure the seed tuned fx on.
- **rotation spread** (the seed's second method): over a pure translation the rotation is
  the same in every view, so each ``p_i = -R_i^T T_i`` is compared to ``-R^T T_i`` with the
  average rotation ``R`` of all views (the chordal mean); every error of the view shows up
  through its rotation, apart from errors of the board itself.
- **registered**: the known displacements placed in the board frame by the best rigid fit
  (Kabsch: rotation stage -> board and p_0), and each ``p_i`` against its fitted position:
  the 3-D error against the stage, mm.

Every error is also given as a fraction of the view's distance (optical centre to the
board's centre): "1:N" with N = distance / error, the way the seed states its figure (a
median of 1:3,000).
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..calibration.registration import kabsch
from ..errors import DataError
from ..io.measurements import read_csv_text
from ..kinematics.conventions import rotation_angle_between

MOVED = ("camera", "board")
MOVE_COLUMNS = ("image", "dx_mm", "dy_mm", "dz_mm")
MAX_MOVE_MM = 1e5
"""Largest accepted stage coordinate, mm (100 m: no stage or CMM travels further)."""


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of per-view errors (mm) and of their ratio to the view's distance.

    mean_mm, median_mm, std_mm, max_mm : of the absolute errors. median_ratio, worst_ratio :
    N of "1:N" (distance / error) for the median and the largest error-to-distance ratio
    (inf when the error is zero)."""

    mean_mm: float
    median_mm: float
    std_mm: float
    max_mm: float
    median_ratio: float
    worst_ratio: float

    @classmethod
    def of(cls, errors_mm: np.ndarray, distances_mm: np.ndarray) -> "ErrorStats":
        """Statistics of ``errors_mm`` (k,) at view distances ``distances_mm`` (k,)."""
        e = np.abs(np.asarray(errors_mm, dtype=float))
        if e.size == 0:
            nan = float("nan")
            return cls(nan, nan, nan, nan, nan, nan)
        fraction = e / np.asarray(distances_mm, dtype=float)

        def one_in(f):
            return float("inf") if f == 0 else float(1.0 / f)

        return cls(mean_mm=float(np.mean(e)), median_mm=float(np.median(e)),
                   std_mm=float(np.std(e, ddof=1)) if e.size > 1 else 0.0,
                   max_mm=float(np.max(e)), median_ratio=one_in(float(np.median(fraction))),
                   worst_ratio=one_in(float(np.max(fraction))))


@dataclass(frozen=True)
class MoveAssessment:
    """Result of :func:`assess_moves`; per view (k,), in the order given, view 0 the
    reference.

    distance_mm : optical centre to the board's centre. known_mm, measured_mm : distance
    travelled from view 0, by the stage and by the camera. travel_error_mm : measured minus
    known (0 for view 0). spread_error_mm : the seed's rotation-spread error (3-D).
    spread_deg : angle of each view's rotation from the average. registered_error_mm : 3-D
    error against the fitted stage motion. board_R_stage : (3, 3) the stage's axes in the
    board frame, from the fit. travel, spread, registered :
    :class:`ErrorStats` (travel over views 1..k-1, the others over all views).
    """

    names: tuple[str, ...]
    moved: str
    distance_mm: np.ndarray
    known_mm: np.ndarray
    measured_mm: np.ndarray
    travel_error_mm: np.ndarray
    spread_error_mm: np.ndarray
    spread_deg: np.ndarray
    registered_error_mm: np.ndarray
    board_R_stage: np.ndarray
    travel: ErrorStats
    spread: ErrorStats
    registered: ErrorStats


def mean_rotation(rotations: np.ndarray) -> np.ndarray:
    """The chordal L2 mean (3, 3) of rotations (k, 3, 3): the rotation nearest their sum."""
    u, _, vt = np.linalg.svd(np.sum(rotations, axis=0))
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def assess_moves(board_T_camera: np.ndarray, moves_m: np.ndarray, board_centre_m: np.ndarray,
                 names=None, moved: str = "camera") -> MoveAssessment:
    """Assess measured camera poses against known pure translations.

    board_T_camera : (k, 4, 4) measured camera frames in the board frame, m. moves_m : (k, 3)
    known positions of the stage, m, stage frame (displacements from any origin; view 0 is
    the reference). board_centre_m : (3,) the board point the distance is taken to, board
    frame, m. moved : "camera" (the camera rode the stage) or "board".
    """
    T = np.asarray(board_T_camera, dtype=float)
    d = np.asarray(moves_m, dtype=float)
    k = len(T)
    if moved not in MOVED:
        raise DataError(f"assess: moved must be one of {', '.join(MOVED)}, got {moved!r}")
    if T.shape != (k, 4, 4) or d.shape != (k, 3):
        raise DataError(f"assess: expected poses (k, 4, 4) and moves (k, 3), got {T.shape} "
                        f"and {d.shape}")
    if k < 3:
        raise DataError(f"assess: {k} views; at least 3 positions are needed (the seed used 25)")
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(d))):
        raise DataError("assess: poses and moves must be finite numbers")
    names = tuple(names) if names is not None else tuple(f"view {i + 1}" for i in range(k))
    p = T[:, :3, 3]
    R = T[:, :3, :3]                      # board_R_camera
    d = d - d[0]
    known = np.linalg.norm(d, axis=1)
    measured = np.linalg.norm(p - p[0], axis=1)
    distance = np.linalg.norm(p - np.asarray(board_centre_m, dtype=float), axis=1)

    # the seed's second method, in the seed's terms: camera_T_board = (Rc, Tc), p = -Rc^T Tc
    camera_R_board = np.swapaxes(R, 1, 2)
    Tc = -np.einsum("kij,kj->ki", camera_R_board, p)
    average = mean_rotation(camera_R_board)
    p_average = -Tc @ average           # -average^T Tc, row by row
    spread_error = np.linalg.norm(p - p_average, axis=1)
    spread_deg = np.degrees(rotation_angle_between(camera_R_board, average[None]))

    sign = 1.0 if moved == "camera" else -1.0
    if np.linalg.matrix_rank(d - d.mean(axis=0), tol=1e-9) == 0:
        raise DataError("assess: the known moves are all the same; move the stage")
    fit = kabsch(sign * d, p)
    fitted = sign * d @ fit[:3, :3].T + fit[:3, 3]
    registered = np.linalg.norm(p - fitted, axis=1)
    mm = 1e3
    return MoveAssessment(
        names=names, moved=moved, distance_mm=distance * mm, known_mm=known * mm,
        measured_mm=measured * mm, travel_error_mm=(measured - known) * mm,
        spread_error_mm=spread_error * mm, spread_deg=spread_deg,
        registered_error_mm=registered * mm, board_R_stage=fit[:3, :3],
        travel=ErrorStats.of((measured - known)[1:] * mm, distance[1:] * mm),
        spread=ErrorStats.of(spread_error * mm, distance * mm),
        registered=ErrorStats.of(registered * mm, distance * mm))


def parse_moves(text: str, source: str = "<moves>") -> tuple[list[str], np.ndarray]:
    """Image names and known stage positions (k, 3), m, from moves.csv text: a header with
    ``image, dx_mm, dy_mm, dz_mm`` (other columns ignored, ``#`` lines skipped)."""
    lines = [(n, line) for n, line in enumerate(text.splitlines(), start=1)
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise DataError(f"{source}: empty; expected a header image, dx_mm, dy_mm, dz_mm")
    rows = list(csv.reader(io.StringIO("\n".join(line for _, line in lines))))
    header = [h.strip() for h in rows[0]]
    missing = [c for c in MOVE_COLUMNS if c not in header]
    if missing:
        raise DataError(f"{source}:{lines[0][0]}: missing column(s) {', '.join(missing)} "
                        f"(header has: {', '.join(header)})")
    where = [header.index(c) for c in MOVE_COLUMNS]
    names, moves, seen = [], [], set()
    for (line, _), record in zip(lines[1:], rows[1:]):
        if len(record) != len(header):
            raise DataError(f"{source}:{line}: {len(record)} fields, the header has "
                            f"{len(header)}")
        name = record[where[0]].strip()
        if name in seen:
            raise DataError(f"{source}:{line}: image '{name}' is listed twice")
        seen.add(name)
        values = []
        for column, i in zip(MOVE_COLUMNS[1:], where[1:]):
            try:
                values.append(float(record[i]))
            except ValueError:
                raise DataError(f"{source}:{line}: {column} is not a number: "
                                f"'{record[i].strip()}'") from None
        if not np.all(np.isfinite(values)):
            raise DataError(f"{source}:{line}: moves must be finite numbers")
        too_far = next((c for c, v in zip(MOVE_COLUMNS[1:], values) if abs(v) > MAX_MOVE_MM),
                       None)
        if too_far is not None:
            raise DataError(f"{source}:{line}: {too_far} = {values[MOVE_COLUMNS.index(too_far) - 1]:g} "
                            f"mm is beyond any stage (limit {MAX_MOVE_MM:g} mm)")
        names.append(name)
        moves.append(values)
    if len(names) < 3:
        raise DataError(f"{source}: {len(names)} rows; at least 3 positions are needed")
    return names, np.array(moves) * 1e-3


def read_moves(path: str | Path) -> tuple[list[str], np.ndarray]:
    """:func:`parse_moves` of the file at ``path``."""
    return parse_moves(read_csv_text(path, "a moves CSV (image, dx_mm, dy_mm, dz_mm)"),
                       str(path))


def _ratio(n: float) -> str:
    """'1:N'; an error above a tenth of the distance keeps two significant digits (a
    1e308 mm error is '1:1e-305', not '1:0')."""
    if not np.isfinite(n):
        return "1:inf"
    return f"1:{n:,.0f}" if n >= 10 else f"1:{n:.2g}"


def assessment_table(result: MoveAssessment) -> str:
    """Per-view lines and the statistics of the three figures, as printed by the CLI."""
    out = [f"{'image':<20} {'dist mm':>9} {'known mm':>9} {'travel err':>10} "
           f"{'spread err':>10} {'3-D err':>8} {'rot deg':>8}"]
    for i, name in enumerate(result.names):
        out.append(f"{name:<20} {result.distance_mm[i]:9.1f} {result.known_mm[i]:9.3f} "
                   f"{result.travel_error_mm[i]:10.4f} {result.spread_error_mm[i]:10.4f} "
                   f"{result.registered_error_mm[i]:8.4f} {result.spread_deg[i]:8.4f}")
    out.append(f"{'figure (mm)':<34} {'mean':>7} {'median':>7} {'std':>7} {'max':>7}  "
               f"{'median':>10} {'worst':>10}")
    for label, s in (("travelled distance (seed method 1)", result.travel),
                     ("rotation spread (seed method 2)", result.spread),
                     ("3-D against the registered stage", result.registered)):
        out.append(f"{label:<34} {s.mean_mm:7.4f} {s.median_mm:7.4f} {s.std_mm:7.4f} "
                   f"{s.max_mm:7.4f}  {_ratio(s.median_ratio):>10} {_ratio(s.worst_ratio):>10}")
    return "\n".join(out)
