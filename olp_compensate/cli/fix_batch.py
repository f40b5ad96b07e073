"""``olp-fix`` over several programs (folders, backups): in parallel processes, one summary
table and one report; a program that fails is reported and the others go on."""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import OlpError

SHOWN_PROBLEMS = 20

_STATE: dict = {}
"""The calibrations and options of a worker process (set once by :func:`_start_worker`)."""


@dataclass(frozen=True)
class UnitOutcome:
    """What became of one unit: its new bytes and report, or the one-line error."""

    index: int
    data: tuple[bytes, ...] = ()
    report: object = None
    error: str | None = None
    seconds: float = 0.0


def _start_worker(model: str, robot: str | None, taught_on: str | None, options: dict) -> None:
    from .fix import make_compensator
    from ..io.calibration_file import read_calibration
    from ..kinematics.robot import load_robot

    calibration = read_calibration(model, load_robot(robot) if robot else None)
    teacher = None if taught_on is None else read_calibration(taught_on, calibration.robot)
    _STATE.update(compensator=make_compensator(calibration, options["region"]),
                  teacher=teacher, options=options,
                  calibration=calibration, model=model)


def _start_pool_worker(parent: int, *init) -> None:
    """A pool worker's start: it dies with ``parent`` (this olp-fix), then
    :func:`_start_worker`."""
    _end_with(parent)
    _start_worker(*init)


def _end_with(parent: int) -> None:
    """Have the kernel kill this worker when its parent ``parent`` dies, even by SIGKILL
    (Linux ``prctl(PR_SET_PDEATHSIG)``): a killed olp-fix leaves no worker reading on."""
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)   # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):   # no prctl (not Linux): the pool ends its workers
        return
    if os.getppid() != parent:          # the parent died before prctl took effect
        os._exit(1)


def _work(index: int, dialect: str, paths: tuple, names: tuple) -> UnitOutcome:
    """Compensate one unit in this process (see :func:`_start_worker`)."""
    from ..compensation.files import ProgramFiles, compensate_files
    from .fix import check_not_cut_short, check_robot

    started = time.perf_counter()
    options = _STATE["options"]
    try:
        for path in paths:
            check_robot(Path(path), _STATE["calibration"], _STATE["model"])
        result = compensate_files(ProgramFiles(dialect=dialect, paths=tuple(map(Path, paths)),
                                               names=names),
                                  _STATE["compensator"], emit=options["emit"],
                                  unused=options["unused"], taught_on=_STATE["teacher"],
                                  frames_path=options["config"])
        if not result.report.rows:
            check_not_cut_short(dialect, paths, names)
    except OlpError as exc:
        return UnitOutcome(index=index, error=str(exc).splitlines()[0],
                           seconds=time.perf_counter() - started)
    return UnitOutcome(index=index, data=result.data, report=result.report,
                       seconds=time.perf_counter() - started)


def _outcomes(args, units):
    """Yield the :class:`UnitOutcome` of every unit as it completes."""
    options = {"emit": args.emit, "unused": args.unused, "config": args.config,
               "region": args.region}
    init = (args.model, args.robot, args.taught_on, options)
    jobs = min(args.jobs or os.cpu_count() or 1, len(units))
    if jobs == 1:
        _start_worker(*init)
        for k, u in enumerate(units):
            yield _work(k, u.dialect, tuple(map(str, u.paths)), u.names)
        return
    _warm(units, init)       # forked workers inherit the imports, the parsers, the model
    order = sorted(range(len(units)), key=lambda k: -_size(units[k]))   # largest first
    with ProcessPoolExecutor(max_workers=jobs, initializer=_start_pool_worker,
                             initargs=(os.getpid(), *init)) as pool:
        futures = [pool.submit(_work, k, units[k].dialect, tuple(map(str, units[k].paths)),
                               units[k].names) for k in order]
        for future in as_completed(futures):
            yield future.result()


def _size(unit) -> int:
    """Bytes of a unit's files (its work, roughly)."""
    return sum(p.stat().st_size for p in unit.paths if p.exists())


def _warm(units, init) -> None:
    """Load in this process what every worker needs before the pool forks: the
    calibration and closed form, and each dialect's parser (a grammar loads once)."""
    _start_worker(*init)
    from ..programs import loads

    samples = {"rapid": "MODULE Warm\nENDMODULE\n", "vplus": ".PROGRAM warm()\n.END\n"}
    for dialect in {u.dialect for u in units} & set(samples):
        try:
            loads(samples[dialect], dialect, "<warm-up>")
        except OlpError:
            pass
    from importlib import import_module

    for module in ("files", "task", "dialect_program"):   # imported to be inherited
        import_module(f"..compensation.{module}", __package__)


@dataclass
class UnitSummary:
    """What the table keeps of a unit once its outputs and report rows are written: its
    counts, its first problem rows, its exit code (or its error)."""

    error: str | None = None
    uses: int = 0
    fine: int = 0
    counts: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)
    more_problems: int = 0
    exit_code: int = 0


def _summary(outcome: UnitOutcome) -> UnitSummary:
    if outcome.error is not None:
        return UnitSummary(error=outcome.error)
    report = outcome.report
    problems = report.problem_rows()
    counts = report.counts()
    return UnitSummary(uses=len(report.rows), fine=len(report.rows) - len(problems),
                       counts=counts, problems=problems[:SHOWN_PROBLEMS],
                       more_problems=max(0, len(problems) - SHOWN_PROBLEMS),
                       exit_code=report.exit_code)


def _stream(args, units, n_joints: int, summaries: list):
    """The report's CSV text, in pieces: its header, then each unit's rows in the order of
    the input tree, as soon as the units before it are done. Each unit's outputs are
    written when it completes; then only its :class:`UnitSummary` is kept (memory: the
    units done out of order, not every program's rows and bytes)."""
    from ..compensation.report import CompensationReport
    from ..io.atomic import write_files_atomic
    from .fix import loadable_outputs

    yield next(CompensationReport(file="(several)", rows=(), n_joints=n_joints).csv_chunks())
    waiting: dict[int, UnitOutcome] = {}
    done = 0
    for outcome in _outcomes(args, units):
        if outcome.error is None:
            unit = units[outcome.index]
            if unit.mirrored:                     # -o OUTDIR (or F_compensated) mirrors F
                for out in unit.outputs:
                    out.parent.mkdir(parents=True, exist_ok=True)
            write_files_atomic(list(zip(unit.outputs,
                                        loadable_outputs(unit, list(outcome.data)))))
        summaries[outcome.index] = _summary(outcome)
        waiting[outcome.index] = dataclasses.replace(outcome, data=())
        while done in waiting:
            ready = waiting.pop(done)
            done += 1
            if ready.report is not None:
                chunks = dataclasses.replace(ready.report, n_joints=n_joints).csv_chunks()
                next(chunks)                      # the header, written once
                yield from chunks


def run_batch(args, units) -> int:
    """Compensate ``units`` (:class:`~olp_compensate.cli.fix_inputs.Unit`); write each
    unit's outputs as it completes and the report's rows in input order as they become
    ready (see :func:`_stream`); print the table."""
    from ..io.atomic import write_files_atomic
    from .fix import load_calibrations

    started = time.perf_counter()
    calibration, _ = load_calibrations(args)      # refuse bad calibrations before the work
    summaries: list[UnitSummary | None] = [None] * len(units)
    pieces = _stream(args, units, calibration.robot.n_joints, summaries)
    if args.report:
        write_files_atomic([(Path(args.report), (p.encode("utf-8") for p in pieces))])
    else:
        for _ in pieces:
            pass
    failed = [s for s in summaries if s.error is not None]
    if not args.quiet:
        _table(units, summaries, calibration, args, time.perf_counter() - started)
    for s in failed:
        print(f"olp-fix: {s.error}", file=sys.stderr)
    if failed:
        return 1
    return max((s.exit_code for s in summaries), default=0)


def _table(units, summaries: list[UnitSummary], calibration, args, seconds: float) -> None:
    uses = sum(s.uses for s in summaries)
    print(f"olp-fix: {len(units)} programs, {uses} target uses in {seconds:.2f} s")
    print(f"  robot {calibration.robot.name} (calibration {args.model})")
    width = max(len(" + ".join(u.names)) for u in units)
    print(f"  {'program':<{width}}  {'uses':>6}  {'ok':>6}  {'not':>6}  status")
    counts: dict[str, int] = {}
    for unit, s in zip(units, summaries):
        name = " + ".join(unit.names)
        if s.error is not None:
            print(f"  {name:<{width}}  {'':>6}  {'':>6}  {'':>6}  failed: {s.error}")
            continue
        for status, n in s.counts.items():
            counts[status] = counts.get(status, 0) + n
        print(f"  {name:<{width}}  {s.uses:>6}  {s.fine:>6}  {s.uses - s.fine:>6}  "
              f"exit {s.exit_code}")
    print("  statuses: " + ", ".join(f"{v} {k}" for k, v in sorted(counts.items())))
    problems = [r for s in summaries for r in s.problems]
    more = sum(s.more_problems for s in summaries) + max(0, len(problems) - SHOWN_PROBLEMS)
    for r in problems[:SHOWN_PROBLEMS]:
        print(f"  {r.file}:{r.line}:{r.column}: {r.target}: {r.status}"
              + (f" ({r.note})" if r.note else ""))
    if more:
        print(f"  ... and {more} more (see --report)")
    written = sum(len(u.outputs) for u, s in zip(units, summaries) if s.error is None)
    print(f"  wrote {written} programs" + (f" and {args.report}" if args.report else ""))
