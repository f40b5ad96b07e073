"""``olp-fix`` over several programs (folders, backups): in parallel processes, one summary
table and one report; a program that fails is reported and the others go on."""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
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


def run_batch(args, units) -> int:
    """Compensate ``units`` (:class:`~olp_compensate.cli.fix_inputs.Unit`); write each
    unit's outputs as it completes and the one report at the end; print the table."""
    from ..compensation.report import CompensationReport
    from ..io.atomic import write_files_atomic, write_text_atomic
    from .fix import load_calibrations, loadable_outputs

    started = time.perf_counter()
    calibration, _ = load_calibrations(args)      # refuse bad calibrations before the work
    outcomes: list[UnitOutcome | None] = [None] * len(units)
    for outcome in _outcomes(args, units):
        outcomes[outcome.index] = outcome
        if outcome.error is None:
            outputs = units[outcome.index].outputs
            if units[outcome.index].mirrored:   # -o OUTDIR (or F_compensated) mirrors F
                for out in outputs:
                    out.parent.mkdir(parents=True, exist_ok=True)
            write_files_atomic(list(zip(outputs, loadable_outputs(units[outcome.index],
                                                                  list(outcome.data)))))
    rows = [r for o in outcomes if o.report is not None for r in o.report.rows]
    n_joints = calibration.robot.n_joints
    report = CompensationReport(file="(several)", rows=tuple(rows), n_joints=n_joints,
                                warnings=tuple(w for o in outcomes if o.report is not None
                                               for w in o.report.warnings))
    if args.report:
        write_text_atomic(args.report, report.to_csv())
    failed = [o for o in outcomes if o.error is not None]
    if not args.quiet:
        _table(units, outcomes, report, calibration, args, time.perf_counter() - started)
    for o in failed:
        print(f"olp-fix: {o.error}", file=sys.stderr)
    if failed:
        return 1
    return report.exit_code


def _table(units, outcomes, report, calibration, args, seconds: float) -> None:
    from ..compensation.program import KEPT

    print(f"olp-fix: {len(units)} programs, {len(report.rows)} target uses in "
          f"{seconds:.2f} s")
    print(f"  robot {calibration.robot.name} (calibration {args.model})")
    width = max(len(" + ".join(u.names)) for u in units)
    print(f"  {'program':<{width}}  {'uses':>6}  {'ok':>6}  {'not':>6}  status")
    for unit, outcome in zip(units, outcomes):
        name = " + ".join(unit.names)
        if outcome.error is not None:
            print(f"  {name:<{width}}  {'':>6}  {'':>6}  {'':>6}  failed: {outcome.error}")
            continue
        rows = outcome.report.rows
        fine = sum(1 for r in rows if r.status in KEPT or r.compensated)
        print(f"  {name:<{width}}  {len(rows):>6}  {fine:>6}  {len(rows) - fine:>6}  "
              f"exit {outcome.report.exit_code}")
    counts = report.counts()
    print("  statuses: " + ", ".join(f"{v} {k}" for k, v in sorted(counts.items())))
    problems = [r for r in report.rows if not (r.status in KEPT or r.compensated)]
    for r in problems[:SHOWN_PROBLEMS]:
        print(f"  {r.file}:{r.line}:{r.column}: {r.target}: {r.status}"
              + (f" ({r.note})" if r.note else ""))
    if len(problems) > SHOWN_PROBLEMS:
        print(f"  ... and {len(problems) - SHOWN_PROBLEMS} more (see --report)")
    written = sum(len(u.outputs) for u, o in zip(units, outcomes) if o.error is None)
    print(f"  wrote {written} programs" + (f" and {args.report}" if args.report else ""))
