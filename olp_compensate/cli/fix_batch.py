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
    from .fix_unit import make_compensator
    from ..io.calibration_file import read_calibration
    from ..kinematics.robot import load_robot

    from .fix_models import read_controller

    calibration = read_calibration(model, load_robot(robot) if robot else None)
    teacher = None if taught_on is None else read_calibration(taught_on, calibration.robot)
    controller = read_controller(options["args"], calibration)
    _STATE.update(compensator=make_compensator(calibration, options["region"], controller),
                  teacher=teacher, options=options, controller=controller,
                  calibration=calibration, model=model, loaded={})


def _compensator_for(dialect: str, paths, names):
    """The worker's compensator, or one under the load this program states (or the
    override) when the calibration holds load-dependent effects; and the load's notes."""
    from .fix_unit import make_compensator
    from .fix_models import unit_load

    args = _STATE["options"]["args"]
    load, notes = unit_load(args, _STATE["calibration"], dialect, paths, names)
    if load is None:
        return _STATE["compensator"], load, notes
    key = (load.kg, tuple(load.cog_m), load.source)
    if key not in _STATE["loaded"]:
        _STATE["loaded"][key] = make_compensator(_STATE["calibration"],
                                                 _STATE["options"]["region"],
                                                 _STATE["controller"], load)
    return _STATE["loaded"][key], load, notes


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
    from .fix_unit import check_not_cut_short, check_robot
    from .fix_models import load_sensitive, with_load_notes

    started = time.perf_counter()
    options = _STATE["options"]
    try:
        for path in paths:
            check_robot(Path(path), _STATE["calibration"], _STATE["model"])
        compensator, load, notes = _compensator_for(dialect, paths, names)
        result = compensate_files(ProgramFiles(dialect=dialect, paths=tuple(map(Path, paths)),
                                               names=names),
                                  compensator, emit=options["emit"],
                                  unused=options["unused"], taught_on=_STATE["teacher"],
                                  frames_path=options["config"])
        if not result.report.rows:
            check_not_cut_short(dialect, paths, names)
        report = with_load_notes(result.report, load, notes,
                                 load_sensitive(_STATE["calibration"]))
    except OlpError as exc:
        return UnitOutcome(index=index, error=str(exc).splitlines()[0],
                           seconds=time.perf_counter() - started)
    return UnitOutcome(index=index, data=result.data, report=report,
                       seconds=time.perf_counter() - started)


def _outcomes(args, units):
    """Yield the :class:`UnitOutcome` of every unit as it completes."""
    options = {"emit": args.emit, "unused": args.unused, "config": args.config,
               "region": args.region, "args": _model_args(args)}
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


def _model_args(args):
    """The options the controller model and the load read, as a picklable namespace."""
    from argparse import Namespace

    return Namespace(model=args.model, controller=args.controller, config=args.config,
                     payload_kg=args.payload_kg, payload_cog_mm=args.payload_cog_mm)


def _size(unit) -> int:
    """Bytes of a unit's files (its work, roughly)."""
    return sum(p.stat().st_size for p in unit.paths if p.exists())


def _warm(units, init) -> None:
    """Load in this process what every worker needs before the pool forks: the
    calibration and closed form, and each dialect's parser (a grammar loads once)."""
    _start_worker(*init)
    from ..programs.languages import language_named

    for dialect in {u.dialect for u in units}:
        warm_up = language_named(dialect).warm_up
        try:
            if warm_up is not None:
                warm_up()
        except OlpError:
            pass
    from importlib import import_module

    for module in ("files", "dialect_program"):   # imported to be inherited
        import_module(f"..compensation.{module}", __package__)


@dataclass(frozen=True)
class UnitSummary:
    """What the table and the exit code need of one finished unit, once its outputs are
    written and its rows spooled (the bytes and the rows themselves are not kept)."""

    n_rows: int
    n_fine: int
    counts: dict
    exit_code: int
    problems: tuple = ()
    error: str | None = None


class ReportSpool:
    """The rows of a folder run's report, kept on disk as each unit finishes (one CSV piece
    per unit in a temporary folder) and joined in the units' input order at the end, so a
    backup's report costs no more memory than its largest program's."""

    def __init__(self, n_joints: int):
        import tempfile

        self._folder = tempfile.TemporaryDirectory(prefix="olp-fix-report-")
        self.n_joints = n_joints
        self._header: str | None = None
        self._indices: list[int] = []

    def add(self, index: int, report) -> None:
        """Spool ``report``'s rows, in the run's joint columns (the calibration's axes)."""
        import dataclasses

        chunks = dataclasses.replace(report, n_joints=self.n_joints).csv_chunks()
        header = next(chunks)
        self._header = self._header or header
        with open(Path(self._folder.name) / f"{index}.csv", "w", encoding="utf-8",
                  newline="") as f:
            f.writelines(chunks)
        self._indices.append(index)

    def pieces(self):
        """The report's bytes in pieces: the header, then each unit's rows in input order."""
        from ..compensation.report import CompensationReport

        header = self._header or next(CompensationReport(file="", rows=(),
                                                         n_joints=self.n_joints).csv_chunks())
        yield header.encode("utf-8")
        for index in sorted(self._indices):
            with open(Path(self._folder.name) / f"{index}.csv", "rb") as f:
                while block := f.read(1 << 20):
                    yield block

    def close(self) -> None:
        self._folder.cleanup()


def _summary_of(outcome: UnitOutcome) -> UnitSummary:
    if outcome.error is not None:
        return UnitSummary(0, 0, {}, 1, error=outcome.error)
    report = outcome.report
    counts = report.counts()
    problems = report.problem_rows()   # neither compensated nor needing no compensation
    n_rows = sum(counts.values())
    return UnitSummary(n_rows, n_rows - len(problems), counts, report.exit_code,
                       tuple(problems[:SHOWN_PROBLEMS]))


def run_batch(args, units) -> int:
    """Compensate ``units`` (:class:`~olp_compensate.cli.fix_inputs.Unit`); write each
    unit's outputs and spool its report rows as it completes (memory bounded by the largest
    program, not the sum), then the one report in the input order; print the table."""
    from ..io.atomic import write_files_atomic
    from .fix_unit import load_calibrations, loadable_outputs
    from .fix_models import read_controller, warn_no_controller_model

    started = time.perf_counter()
    calibration, _ = load_calibrations(args)      # refuse bad calibrations before the work
    controller = read_controller(args, calibration)
    for dialect in dict.fromkeys(u.dialect for u in units):   # each language's warning once
        warn_no_controller_model(dialect, controller)
    summaries: list[UnitSummary | None] = [None] * len(units)
    spool = ReportSpool(calibration.robot.n_joints)
    try:
        for outcome in _outcomes(args, units):
            if outcome.error is None:
                unit = units[outcome.index]
                if unit.mirrored:                     # -o OUTDIR (or F_compensated) mirrors F
                    for out in unit.outputs:
                        out.parent.mkdir(parents=True, exist_ok=True)
                write_files_atomic(list(zip(unit.outputs,
                                            loadable_outputs(unit, list(outcome.data)))))
                if args.report:
                    spool.add(outcome.index, outcome.report)
            summaries[outcome.index] = _summary_of(outcome)
            del outcome                              # its bytes and rows are done with
        if args.report:
            write_files_atomic([(Path(args.report), spool.pieces())])
    finally:
        spool.close()
    failed = [s for s in summaries if s.error is not None]
    if not args.quiet:
        _table(units, summaries, calibration, args, time.perf_counter() - started)
    for s in failed:
        print(f"olp-fix: {s.error}", file=sys.stderr)
    if failed:
        return 1
    return 2 if any(s.exit_code for s in summaries) else 0


def _table(units, summaries, calibration, args, seconds: float) -> None:
    n_rows = sum(s.n_rows for s in summaries)
    print(f"olp-fix: {len(units)} programs, {n_rows} target uses in {seconds:.2f} s")
    print(f"  robot {calibration.robot.name} (calibration {args.model}"
          + (f"; controller model {args.controller})" if args.controller else ")"))
    width = max(len(" + ".join(u.names)) for u in units)
    print(f"  {'program':<{width}}  {'uses':>6}  {'ok':>6}  {'not':>6}  status")
    counts: dict[str, int] = {}
    for unit, summary in zip(units, summaries):
        name = " + ".join(unit.names)
        if summary.error is not None:
            print(f"  {name:<{width}}  {'':>6}  {'':>6}  {'':>6}  failed: {summary.error}")
            continue
        for status, n in summary.counts.items():
            counts[status] = counts.get(status, 0) + n
        print(f"  {name:<{width}}  {summary.n_rows:>6}  {summary.n_fine:>6}  "
              f"{summary.n_rows - summary.n_fine:>6}  exit {summary.exit_code}")
    print("  statuses: " + ", ".join(f"{v} {k}" for k, v in sorted(counts.items())))
    problems = [r for s in summaries for r in s.problems]
    n_problems = sum(s.n_rows - s.n_fine for s in summaries)
    for r in problems[:SHOWN_PROBLEMS]:
        print(f"  {r.file}:{r.line}:{r.column}: {r.target}: {r.status}"
              + (f" ({r.note})" if r.note else ""))
    if n_problems > SHOWN_PROBLEMS:
        print(f"  ... and {n_problems - SHOWN_PROBLEMS} more (see --report)")
    written = sum(len(u.outputs) for u, s in zip(units, summaries) if s.error is None)
    print(f"  wrote {written} programs" + (f" and {args.report}" if args.report else ""))
