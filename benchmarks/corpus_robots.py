"""Which robot each program of ``benchmarks/corpus.py --robot auto`` runs on, and the tally
per robot model.

A program's robot is, in this order:

1. ``header``: the robot its text names (:func:`robot_named_in`: ``! olp-robot: NAME``,
   KRL ``&PARAM OLP_ROBOT = NAME``, FANUC ``/ATTR`` ``COMMENT = "olp-robot: NAME"``), when
   the library has it;
2. ``map``: the first line ``GLOB,ROBOT`` of the ``--robot-map`` file whose GLOB matches
   the program's path (``fnmatch``, case-sensitive, ``*`` also crosses folders; for a
   repository whose README names its arm);
3. ``targets``: among the library's robots of the dialect's maker (:data:`MAKERS`), the
   one on which the most of the program's Cartesian targets (those moved to, with a known
   tool and work object) are reached inside the axis ranges with the nominal model
   (status ``ok`` or ``singular``); ties go to more ``branch_changed`` targets (reached in
   the ranges on another configuration branch), then to the smaller arm (data-sheet reach,
   as a program fits the arm it was taught on and also any larger one), then by name.
   RAPID and V+/AS programs are scored with the solver alone (no account of failures), the
   other dialects by a whole ``olp-fix`` run per candidate. When no candidate reaches any
   target, the program keeps the dialect's fixed default robot.
"""

from __future__ import annotations

import fnmatch
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.compensation.pose import COMPENSATED, Compensator
from olp_compensate.errors import DataError
from olp_compensate.kinematics.robot import bundled_robot_names, library_records, load_robot
from olp_compensate.kinematics.robot_names import robot_named_in
from olp_compensate.programs import load
from olp_compensate.programs.object_model.program import solve_entries
from olp_compensate.programs.semantics import resolve
from olp_compensate.programs.targets import JointTarget

MAKERS = {"rapid": ("ABB",), "vplus": ("Kawasaki", "Unimation"), "krl": ("KUKA",),
          "fanuc": ("FANUC",), "val3": ("Staubli",), "urscript": ("Universal Robots",)}
"""Benchmark dialect -> the makers whose robots are candidates for its programs."""


@dataclass(frozen=True)
class MapLine:
    """One ``GLOB,ROBOT`` line of a robot map (``line``: 1-based)."""

    pattern: str
    robot: str
    line: int


@dataclass(frozen=True)
class Choice:
    """The robot a program runs on and why: ``how`` is 'header', 'map', 'targets' or
    'default'; ``detail`` says more (the map line, the targets reached)."""

    robot: str
    how: str
    detail: str = ""


def read_robot_map(path: str | Path) -> list[MapLine]:
    """Read a robot map: lines ``GLOB,ROBOT``; blank lines and lines starting with ``#``
    are skipped. Raises :class:`DataError` naming file, line and column for a line without
    a comma or a robot the library does not have."""
    known = set(bundled_robot_names())
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read the robot map ({exc})") from None
    out = []
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        pattern, comma, robot = raw.rpartition(",")
        if not comma or not pattern.strip():
            raise DataError(f"{path}:{number}:1: expected GLOB,ROBOT, got {line!r}")
        if robot.strip() not in known:
            column = len(pattern) + 2 + (len(robot) - len(robot.lstrip()))
            raise DataError(f"{path}:{number}:{column}: unknown robot '{robot.strip()}' "
                            "(olp-cal robots lists the library)")
        out.append(MapLine(pattern.strip(), robot.strip(), number))
    return out


def robot_from_map(path: Path, lines: list[MapLine]) -> MapLine | None:
    """The first map line whose glob matches ``path`` (its POSIX form), or None."""
    text = Path(path).as_posix()
    return next((m for m in lines if fnmatch.fnmatchcase(text, m.pattern)), None)


def candidates(dialect: str) -> list[str]:
    """Names of the library's robots of the dialect's makers, smaller arms first."""
    records = [r for r in library_records() if r.maker in MAKERS.get(dialect, ())]
    records.sort(key=lambda r: (r.reach_mm if r.reach_mm is not None else np.inf, r.name))
    return [r.name for r in records]


class Compensators:
    """One nominal :class:`Compensator` per robot name, made on first use."""

    def __init__(self):
        self._made: dict[str, Compensator] = {}

    def __call__(self, name: str) -> Compensator:
        if name not in self._made:
            self._made[name] = Compensator(nominal_calibration(load_robot(name)))
        return self._made[name]


def named_robot(texts: list[str]) -> tuple[str | None, str]:
    """(robot, note): the library robot the program's texts name (None when none does;
    the note then says why, e.g. a name the library does not have). Raises DataError when
    the texts name two different robots."""
    names = {n for n in (robot_named_in(t) for t in texts) if n is not None}
    if len(names) > 1:
        raise DataError(f"the program's files name more than one robot: {', '.join(sorted(names))}")
    if not names:
        return None, ""
    name = names.pop()
    if name not in bundled_robot_names():
        return None, f"header names '{name}', not in the library"
    return name, ""


def scored_entries(program) -> tuple[object, list[int]]:
    """(resolution, job) of a parsed RAPID or V+/AS program: the entries to score, the
    Cartesian targets moved to with a known tool and work object (robot-independent)."""
    res = resolve(program)
    known = np.isfinite(res.base_T_flange[:, 0, 0])
    bad = res.bad_value if res.bad_value is not None else np.zeros(len(known), bool)
    job = [k for k, t in enumerate(res.entry_targets)
           if known[k] and not bad[k] and res.entry_uses[k] and not isinstance(t, JointTarget)]
    return res, job


def reach_score_text(res, job: list[int], vplus: bool, comp: Compensator
                     ) -> tuple[int, int, int]:
    """The ``job`` entries of a resolved RAPID or V+/AS program on ``comp``: (targets
    reached inside the axis ranges, targets reached on another branch, targets scored)."""
    if not job:
        return 0, 0, 0
    solved = solve_entries(comp, res, job, vplus, retries=False)
    reasons = Counter(solved.reason)
    return sum(reasons[r] for r in COMPENSATED), reasons["branch_changed"], len(job)


def score_of_statuses(statuses: Counter) -> tuple[int, int, int]:
    """The same score from a whole run's status counts (the pose dialects)."""
    scored = sum(v for k, v in statuses.items() if k not in ("joint_target", "unused",
                                                             "unresolved", "runtime",
                                                             "unknown_instruction",
                                                             "bad_target"))
    return sum(statuses[r] for r in COMPENSATED), statuses["branch_changed"], scored


def best_by_targets(scores: dict[str, tuple[int, int, int]], order: list[str],
                    default: str) -> Choice:
    """The 'targets' choice among ``scores`` (robot -> score), ``order`` smaller arms
    first; the ``default`` robot when no candidate reaches any target."""
    if not scores or max(s[2] for s in scores.values()) == 0:
        return Choice(default, "default", "no target moved to with a known tool and work object")
    if max(s[0] + s[1] for s in scores.values()) == 0:
        return Choice(default, "default", "no candidate of the maker reaches any target")
    rank = {name: k for k, name in enumerate(order)}
    best = min(scores, key=lambda n: (-scores[n][0], -scores[n][1], rank.get(n, len(rank)), n))
    reached, other_branch, scored = scores[best]
    detail = f"{reached} of {scored} reached"
    if default in scores and default != best:
        detail += f"; {scores[default][0]} on {default}"
    return Choice(best, "targets", detail)


def choose(dialect: str, unit: list[Path], default: str, robot_map: list[MapLine],
           comps: Compensators, run_pose) -> tuple[Choice, object]:
    """(Choice, the parsed program or None) for one program (a list of files: a KRL pair
    is one). ``run_pose(comp)``: the status counts of a whole run of the program on
    ``comp`` (None: not parsed), used to score the pose dialects. Raises OlpError when the
    program names two robots, or does not parse (RAPID, V+/AS)."""
    texts = [p.read_bytes().decode("latin-1") for p in unit]
    named, note = named_robot(texts)
    if named is not None:
        return Choice(named, "header"), None
    mapped = robot_from_map(unit[0], robot_map)
    if mapped is not None:
        return Choice(mapped.robot, "map", f"line {mapped.line}"), None
    order = candidates(dialect)
    program, scores = None, {}
    if dialect in ("rapid", "vplus"):
        program = load(unit[0], dialect)
        res, job = scored_entries(program)
        for name in order if job else ():
            scores[name] = reach_score_text(res, job, dialect == "vplus", comps(name))
    else:
        for name in order:
            statuses = run_pose(comps(name))
            if statuses is None:
                continue
            scores[name] = score_of_statuses(statuses)
            if scores[name][2] == 0:
                break                   # nothing to score: the same on every candidate
    choice = best_by_targets(scores, order, default)
    if note:
        choice = Choice(choice.robot, choice.how, f"{choice.detail}; {note}")
    return choice, program


@dataclass
class ModelTally:
    """What the programs run on one robot model gave: programs by how the robot was
    chosen, statuses on that robot and on the dialect's fixed default robot."""

    programs: Counter = field(default_factory=Counter)
    chosen: Counter = field(default_factory=Counter)
    default: Counter = field(default_factory=Counter)
    defaults: set = field(default_factory=set)


def share(statuses: Counter, status: str = "ok") -> str:
    total = sum(statuses.values())
    return f"{100 * statuses[status] / total:.1f} %" if total else "-"


def model_report(tallies: dict[tuple[str, str], ModelTally], names: dict[str, str]
                 ) -> list[str]:
    """Lines of the per-robot-model table: ``tallies`` by (dialect, robot), a total line
    per dialect (``names``: dialect -> its name in the report)."""
    lines = ["== per robot model (--robot auto): target uses, share ok on the chosen robot "
             "and on the fixed default"]
    for dialect in dict.fromkeys(d for d, _ in tallies):
        mine = {robot: t for (d, robot), t in tallies.items() if d == dialect}
        total = ModelTally()
        for name in sorted(mine, key=lambda n: (-sum(mine[n].chosen.values()), n)):
            t = mine[name]
            total.programs.update(t.programs)
            total.chosen.update(t.chosen)
            total.default.update(t.default)
            total.defaults |= t.defaults
            lines.append(_model_line(name, t))
        lines.append(_model_line(f"all {names.get(dialect, dialect)}", total))
    return lines


def _model_line(name: str, t: ModelTally) -> str:
    how = ", ".join(f"{k} {v}" for k, v in sorted(t.programs.items()))
    others = ", ".join(f"{k} {v}" for k, v in sorted(t.chosen.items()) if k != "ok")
    default = "/".join(sorted(t.defaults))
    return (f"{name}: programs {sum(t.programs.values())} ({how}); target uses "
            f"{sum(t.chosen.values())}; ok {t.chosen['ok']} ({share(t.chosen)}) vs "
            f"{t.default['ok']} ({share(t.default)}) on {default}; others: {others or '-'}")
