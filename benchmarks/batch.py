"""``olp-fix FOLDER -j 2`` against ``-j 1`` on a 20-program backup, measured in one run.

Writes, in a temporary folder, two controller-backup-like trees of 20 programs each, every
target made from random in-range joints of the robot the tree is for (so each is reachable,
away from the wrist singularity):

- ``irb2400``: an ABB IRB 2400 cell, 12 RAPID modules in two tasks (each module's
  targets named its own) and 8 V+ ``.pg`` files;
- ``kr16``: a KUKA KR 16-2 cell, 20 KRL ``.src``/``.dat`` pairs (``$config.dat`` given with
  ``--config``);

with ``--targets`` targets per program (default 300), and a calibration of a virtual robot
of that model. Then times the whole command ``olp-fix TREE --model calib.json -o OUT -q``
with ``-j 1`` and ``-j 2``, each run a new process, the two interleaved (alternating which
goes first) after one untimed run of each, ``--pairs`` times (default 7); prints the
minimum and median of each and the ratio -j 2 / -j 1 (target: below 0.6 on a 2-core
machine), and checks that both write the same bytes (every output file and the report).

Also prints the CPU time of each command (user + system, its workers included: -j 2 should
add little to -j 1's) and the load average (this machine is shared: with other processes
on the second core no wall-time gain is possible), then where the time goes, measured in
this process with the functions the command runs (``olp_compensate.cli.fix_batch``): the
start-up of a new olp-fix process (on a one-target module, against ``python -c "import
numpy"``), the per-process set-up (reading calib.json, fitting the closed form: once in
-j 1, once per worker in -j 2), the programs' work (its sum and the best split on two
workers) and the pickling of the workers' results (bytes and report objects).

With ``--plant N`` (for example 1000) it measures instead a plant's backup of N RAPID programs
of 50-500 targets each, one robot folder each: CPU per target and peak memory of
``olp-fix PLANT -j 1`` next to the plant's first 100 programs and its largest program alone.

Run: ``python benchmarks/batch.py [--pairs 7] [--targets 300] [--only irb2400|kr16]
[--plant N]``.
Exit code 0, 1 when the two runs write different bytes or a run fails.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
import filecmp
import math
import os
import pickle
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints
from olp_compensate.compensation.dialect_rules import ArmGeometry
from olp_compensate.programs.krl.rules import krl_status, krl_turn
from olp_compensate.compensation.pose import Compensator
from olp_compensate.io.calibration_file import write_calibration
from olp_compensate.kinematics.conventions import MM, euler_zyx_from_matrix, euler_zyz_from_matrix
from olp_compensate.kinematics.robot import load_robot

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compensate import generate_module  # noqa: E402  (the RAPID module of compensate.py)
from installed import installed_env  # noqa: E402

KRL_TOOL_MM = (12.0, -5.0, 180.0, 0.0, 0.0, 0.0)
CONFIG_DAT = (f"DEFDAT  $CONFIG\r\n;FOLD TOOL DATA\r\nDECL FRAME TOOL_DATA[16]\r\n"
              f"TOOL_DATA[1]={{X {KRL_TOOL_MM[0]},Y {KRL_TOOL_MM[1]},Z {KRL_TOOL_MM[2]},"
              f"A 0.0,B 0.0,C 0.0}}\r\n;ENDFOLD\r\nENDDAT\r\n")
VPLUS_TOOL_MM = (0.0, 0.0, 145.0)


def _joints(robot, comp: Compensator, n: int, seed: int) -> np.ndarray:
    """n controller joint vectors (n, 6), rad, in range and away from singularities and
    from the edge of the reach, as taught targets are: axis 5 away from zero, the smallest
    singular value of the Jacobian above 2 cm/rad (as ``compensate.generate_module``), the
    elbow at least 15 deg from the stretched or folded arm (a target within a few mm of
    the data-sheet arm's reach may lie beyond the real arm's: ``unreachable``) and the
    wrist point at least 10 cm from axis 1."""
    q = random_joints(robot, 8 * n, np.random.default_rng(seed), margin=0.3)
    q = q[np.abs(np.sin(q[:, 4])) > 0.2]
    _, jac = comp.real_flange_and_jacobian(robot.joints_from_controller(q))
    q = q[np.linalg.svd(jac, compute_uv=False)[:, -1] > 0.02]
    geometry = ArmGeometry(robot)
    q = q[:2 * n]
    q = q[[abs(math.sin(geometry.elbow_angle(row))) > math.sin(math.radians(15))
           and abs(geometry.in_front_of_axis1(row)) > 0.1 for row in q]]
    if len(q) < n:
        raise ValueError(f"{robot.name}: only {len(q)} of {n} joint draws away from "
                         f"singularities; draw more")
    return q[:n]


def vplus_program(robot, n: int, seed: int) -> str:
    """A V+ disk file: .PROGRAM moving to loc1..locn with TOOL gripper, and .LOCATIONS."""
    comp = Compensator(nominal_calibration(robot))
    q = robot.joints_from_controller(_joints(robot, comp, n, seed))
    tool = np.eye(4)
    tool[:3, 3] = np.array(VPLUS_TOOL_MM) * MM
    tcp = comp.nominal_flange(q) @ tool
    lines = [f"; olp-robot: {robot.name}", f".PROGRAM cell{seed}()", "    TOOL gripper"]
    lines += [f"    MOVE{'S' if k % 2 else ''} loc{k}" for k in range(1, n + 1)]
    lines += [".END", ".LOCATIONS", "",
              "gripper " + " ".join(f"{v:10.3f}" for v in (*VPLUS_TOOL_MM, 0, 0, 0))]
    for k, pose in enumerate(tcp, 1):
        ypr = np.degrees(euler_zyz_from_matrix(pose[:3, :3]))
        lines.append(f"loc{k:<6d}" + " ".join(f"{v:10.3f}" for v in (*pose[:3, 3] / MM, *ypr)))
    lines += [".END", ""]
    return "\n".join(lines)


def krl_pair(robot, n: int, seed: int) -> tuple[str, str]:
    """(.src, .dat) of a KRL program: XP1..XPn moved to with PTP/LIN inline-form folds,
    TOOL_DATA[1] in BASE_DATA[0]; S and T of the joints the targets come from."""
    comp = Compensator(nominal_calibration(robot))
    geometry = ArmGeometry(robot)
    q_ctrl = _joints(robot, comp, n, seed)
    tool = np.eye(4)
    tool[:3, 3] = np.array(KRL_TOOL_MM[:3]) * MM
    tcp = comp.nominal_flange(robot.joints_from_controller(q_ctrl)) @ tool
    name = f"CELL{seed}"
    dat = ["&ACCESS RVP", "&REL 1", f"DEFDAT  {name}", ";FOLD EXTERNAL DECLARATIONS",
           ";ENDFOLD (EXTERNAL DECLARATIONS)"]
    src = ["&ACCESS RVP", "&REL 1", f"DEF {name}( )", ";FOLD INI", ";ENDFOLD (INI)"]
    for k, (pose, q) in enumerate(zip(tcp, q_ctrl), 1):
        x, y, z = pose[:3, 3] / MM
        a, b, c = np.degrees(euler_zyx_from_matrix(pose[:3, :3]))
        dat.append(f"DECL E6POS XP{k}={{X {x:.3f},Y {y:.3f},Z {z:.3f},A {a:.4f},B {b:.4f},"
                   f"C {c:.4f},S {krl_status(geometry, q)},T {krl_turn(q)},E1 0.0,E2 0.0,"
                   f"E3 0.0,E4 0.0,E5 0.0,E6 0.0}}")
        dat.append(f"DECL FDAT FP{k}={{TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE,POINT2[] \" \"}}")
        move = "PTP" if k % 2 else "LIN"
        src += [f";FOLD {move} P{k} Vel=100 % PDAT{k} Tool[1] Base[0];%{{PE}}",
                "$BWDSTART=FALSE", f"FDAT_ACT=FP{k}",
                f"BAS(#{'PTP' if k % 2 else 'CP'}_PARAMS,100)", f"{move} XP{k} ", ";ENDFOLD"]
    dat.append("ENDDAT")
    src.append("END")
    return "\r\n".join(src) + "\r\n", "\r\n".join(dat) + "\r\n"


def write_backup(kind: str, folder: Path, n_targets: int) -> tuple[str, Path | None]:
    """The 20-program tree of ``kind`` under ``folder / 'BACKUP'``; (robot, $config.dat)."""
    tree = folder / "BACKUP"
    if kind == "irb2400":
        robot = load_robot("abb_irb2400")
        comp = Compensator(nominal_calibration(robot))
        for k in range(12):
            path = tree / "RAPID" / f"TASK{k % 2 + 1}" / "PROGMOD" / f"cell{k}.mod"
            path.parent.mkdir(parents=True, exist_ok=True)
            joints = _joints(robot, comp, n_targets, 10 + k)
            # the modules of a task declare their targets under names of their own (a
            # controller refuses one global CONST declared in two modules); the tool and
            # work object are PERS, one variable of the task
            module = re.sub(r"\bp(\d+)\b", rf"c{k}p\1", generate_module(n_targets, joints=joints))
            path.write_bytes(module.replace("MODULE Big", f"MODULE Cell{k}").encode("latin-1"))
        for k in range(8):
            path = tree / "VPLUS" / f"cell{k}.pg"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(vplus_program(robot, n_targets, 30 + k).encode("latin-1"))
        return robot.name, None
    robot = load_robot("kuka_kr16_2")
    for k in range(20):
        src, dat = krl_pair(robot, n_targets, 50 + k)
        path = tree / "KRC" / "R1" / "Program" / f"Cell{k}.src"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(src.encode("latin-1"))
        path.with_suffix(".dat").write_bytes(dat.encode("latin-1"))
    config = folder / "$config.dat"
    config.write_bytes(CONFIG_DAT.encode("latin-1"))
    return robot.name, config


def write_model(robot_name: str, path: Path) -> None:
    """A calibration of a virtual robot of that model (60 poses, 0.02 mm noise)."""
    robot = load_robot(robot_name)
    virtual = make_virtual_robot(robot, seed=2, n_points=3)
    rng = np.random.default_rng(2)
    meas = virtual.measure(random_joints(robot, 60, rng), 0.02e-3, rng)
    write_calibration(path, identify(robot, meas, IdentificationOptions(folds=0)).calibration)


def same_bytes(a: Path, b: Path) -> list[str]:
    """Relative paths of the files that differ or are missing between trees a and b."""
    files_a = {p.relative_to(a) for p in a.rglob("*") if p.is_file()}
    files_b = {p.relative_to(b) for p in b.rglob("*") if p.is_file()}
    bad = sorted(str(p) for p in files_a ^ files_b)
    bad += [str(p) for p in sorted(files_a & files_b)
            if not filecmp.cmp(a / p, b / p, shallow=False)]
    return bad


_ENV: dict[str, str] | None = None
"""The commands' environment (installed.py), set by main() once its folder exists."""


def _run(argv: list[str], cpu: list[float] | None = None) -> float:
    """Wall time of a new process, s; its CPU time (user + system, its workers included)
    appended to ``cpu``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, env=_ENV)
    seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 2):
        raise SystemExit(f"{' '.join(argv)} exited {done.returncode}:\n{done.stderr}")
    if cpu is not None:
        cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return seconds


def _min_median(times: list[float]) -> str:
    return f"min {min(times):6.3f} s  median {statistics.median(times):6.3f} s"


def time_pairs(folder: Path, tree: Path, model: Path, config: Path | None,
               pairs: int) -> tuple[dict[str, list[float]], dict[str, list[float]]]:
    """(wall times, CPU times) of ``pairs`` interleaved -j 1 / -j 2 runs (new processes)
    after one untimed run of each; the outputs go to folder/out-j1, out-j2."""
    olp_fix = str(Path(sys.executable).parent / "olp-fix")
    argv = {}
    for jobs in ("1", "2"):
        argv[jobs] = [olp_fix, str(tree), "--model", str(model), "-o",
                      str(folder / f"out-j{jobs}"), "--report",
                      str(folder / f"out-j{jobs}" / "report.csv"), "-j", jobs, "-q"]
        if config is not None:
            argv[jobs] += ["--config", str(config)]
    times: dict[str, list[float]] = {"1": [], "2": []}
    cpu: dict[str, list[float]] = {"1": [], "2": []}
    for run in range(pairs + 1):
        for jobs in (("1", "2") if run % 2 else ("2", "1")):
            shutil.rmtree(folder / f"out-j{jobs}", ignore_errors=True)
            (folder / f"out-j{jobs}").mkdir()
            used: list[float] = []
            seconds = _run(argv[jobs], used)
            if run:           # run 0: untimed (OS cache, bytecode, grammar cache)
                times[jobs].append(seconds)
                cpu[jobs] += used
    return times, cpu


def where_time_goes(tree: Path, model: Path, config: Path | None, seconds_j1: float) -> None:
    """In-process: the set-up of a worker, the programs' work, the pickling of results."""
    from olp_compensate.cli import fix_batch
    from olp_compensate.cli.common import no_gc
    from olp_compensate.programs.languages import extensions
    from olp_compensate.cli.fix_inputs import plan_units

    units = plan_units([str(tree)], None, "/nonexistent-out", extensions())
    # the command's options; any other (added since) at its default, None
    options = defaultdict(lambda: None, emit="pose", unused="skip",
                          config=None if config is None else str(config))
    setups = []
    for _ in range(3):
        t0 = time.perf_counter()
        fix_batch._start_worker(str(model), None, None, options)
        setups.append(time.perf_counter() - t0)
    setup = min(setups)
    with no_gc():             # as the command runs; the first pass loads modules, grammars
        for _ in range(2):
            outcomes = [fix_batch._work(k, u.dialect, tuple(map(str, u.paths)), u.names)
                        for k, u in enumerate(units)]
    if any(o.error for o in outcomes):
        print("    a unit failed in-process: " + "; ".join(o.error for o in outcomes if o.error))
    work = [o.seconds for o in outcomes]
    t0 = time.perf_counter()
    blobs = [pickle.dumps(o, pickle.HIGHEST_PROTOCOL) for o in outcomes]
    dump = time.perf_counter() - t0
    t0 = time.perf_counter()
    for blob in blobs:
        pickle.loads(blob)
    load = time.perf_counter() - t0
    report_bytes = sum(len(pickle.dumps(o.report, pickle.HIGHEST_PROTOCOL)) for o in outcomes)
    data_bytes = sum(len(d) for o in outcomes for d in o.data)
    # best split of the units on two workers (longest first, each to the least loaded)
    loads = [0.0, 0.0]
    for s in sorted(work, reverse=True):
        loads[loads.index(min(loads))] += s
    rows = sum(len(o.report.rows) for o in outcomes)
    print(f"    in-process: set-up per process (read calib.json, fit closed form) "
          f"{setup:.3f} s; work of the {len(units)} programs {sum(work):.3f} s "
          f"({rows} target uses, {rows / sum(work):,.0f}/s), on 2 workers at best "
          f"{max(loads):.3f} s")
    print(f"    pickling the results back: {len(blobs)} outcomes, "
          f"{sum(map(len, blobs)) / 1e6:.1f} MB ({data_bytes / 1e6:.1f} MB program bytes, "
          f"{report_bytes / 1e6:.1f} MB report objects), dumps {dump:.3f} s + loads "
          f"{load:.3f} s")
    rest = max(seconds_j1 - setup - sum(work), 0.0)
    floor = rest + setup + max(loads)
    print(f"    -j 1 (min {seconds_j1:.3f} s) = set-up {setup:.3f} + work {sum(work):.3f} + "
          f"the rest {rest:.3f} s (start-up, imports, finding files, writing); -j 2 at best "
          f"(the rest + one set-up + the best split) {floor:.3f} s = "
          f"{floor / seconds_j1:.2f}x of -j 1")


def startup(folder: Path, runs: int) -> dict[str, float]:
    """Median wall time of new processes: numpy import, olp-fix on a one-target module."""
    bin_dir = Path(sys.executable).parent
    robot = load_robot("abb_irb2400")
    joints = _joints(robot, Compensator(nominal_calibration(robot)), 1, 0)
    (folder / "one.mod").write_text(generate_module(1, joints=joints))
    write_calibration(folder / "nominal.json", nominal_calibration(robot))
    cases = {"python -c 'import numpy'": [sys.executable, "-c", "import numpy"],
             "olp-fix one.mod (1 target)": [str(bin_dir / "olp-fix"), str(folder / "one.mod"),
                                            "--model", str(folder / "nominal.json"), "-q"]}
    out = {}
    for name, argv in cases.items():
        subprocess.run(argv, capture_output=True, env=_ENV)
        out[name] = statistics.median(_run(argv) for _ in range(runs))
    return out


def write_plant(folder: Path, n_programs: int, pool: np.ndarray, seed: int = 7) -> list[int]:
    """A plant's backup: ``n_programs`` RAPID modules of 50-500 targets each (drawn from
    ``pool``, controller joints (m, 6), rad, of an IRB 2400), one per robot folder
    ``folder/robotNNNN/cell.mod``; returns the number of targets of each."""
    rng = np.random.default_rng(seed)
    counts = [int(c) for c in rng.integers(50, 501, n_programs)]
    for k, count in enumerate(counts):
        path = folder / f"robot{k:04d}" / "cell.mod"
        path.parent.mkdir(parents=True)
        joints = pool[rng.choice(len(pool), count, replace=False)]
        path.write_bytes(generate_module(count, joints=joints).encode("latin-1"))
    return counts


def _peak_and_cpu(argv: list[str]) -> tuple[float, float]:
    """(peak resident memory, MB; CPU time, s) of ``argv`` run as the only child of a new
    process (Linux ru_maxrss of its children)."""
    probe = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], "
             "stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL); "
             "r = resource.getrusage(resource.RUSAGE_CHILDREN); "
             "print(r.ru_maxrss, r.ru_utime + r.ru_stime)")
    done = subprocess.run([sys.executable, "-c", probe, *argv], capture_output=True,
                          text=True, env=_ENV, check=True)
    kb, cpu = done.stdout.split()
    return int(kb) / 1024, float(cpu)


def plant_scaling(folder: Path, n_programs: int) -> None:
    """CPU per target and peak memory of ``olp-fix PLANT -j 1`` on a plant of
    ``n_programs`` programs, next to its first 100 programs and to its largest program
    alone (the targets: CPU per target within 1.3x of the 100-program folder's, peak
    memory within 1.5x of the largest program's)."""
    robot = load_robot("abb_irb2400")
    comp = Compensator(nominal_calibration(robot))
    pool = _joints(robot, comp, 2000, 99)
    plant = folder / "PLANT"
    counts = write_plant(plant, n_programs, pool)
    small = folder / "PLANT100"
    for k in range(min(100, n_programs)):
        shutil.copytree(plant / f"robot{k:04d}", small / f"robot{k:04d}")
    largest = plant / f"robot{int(np.argmax(counts)):04d}" / "cell.mod"
    model = folder / "calib.json"
    write_model(robot.name, model)
    olp_fix = str(Path(sys.executable).parent / "olp-fix")

    def command(tree: Path, out: str) -> list[str]:
        return [olp_fix, str(tree), "--model", str(model), "-o", str(folder / out),
                "--report", str(folder / f"{out}.csv"), "-j", "1", "-q"]

    runs = {"largest program alone": (command(largest, "one.mod"), max(counts)),
            "first 100 programs": (command(small, "out100"), sum(counts[:100])),
            f"{n_programs} programs": (command(plant, "outall"), sum(counts))}
    figures = {}
    for name, (argv, targets) in runs.items():
        shutil.rmtree(folder / argv[5].rsplit("/", 1)[-1], ignore_errors=True)
        _run(argv)   # untimed: OS cache, bytecode
        best = min((_peak_and_cpu(argv) for _ in range(2)), key=lambda f: f[1])
        figures[name] = (best[0], best[1] / targets * 1e6, targets)
        print(f"  {name:<24} {targets:>9,} targets: CPU {best[1]:7.2f} s "
              f"({best[1] / targets * 1e6:6.1f} us/target), peak memory {best[0]:6.0f} MB")
    many, hundred, alone = (figures[k] for k in runs.__reversed__())
    print(f"  CPU per target, {n_programs} / 100 programs: {many[1] / hundred[1]:.2f}x "
          f"(target <= 1.3x); peak memory, {n_programs} programs / largest alone: "
          f"{many[0] / alone[0]:.2f}x (target <= 1.5x)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=7, help="timed -j1/-j2 pairs (>= 5)")
    parser.add_argument("--targets", type=int, default=300, help="targets per program")
    parser.add_argument("--only", choices=("irb2400", "kr16"), help="one backup only")
    parser.add_argument("--plant", type=int, default=0, metavar="N",
                        help="instead: a plant backup of N programs (e.g. 1000) against its "
                             "first 100 and its largest program alone")
    args = parser.parse_args()
    pairs = max(args.pairs, 5)
    failed = False
    global _ENV
    with tempfile.TemporaryDirectory() as tmp:
        _ENV = installed_env(tmp)
        if args.plant:
            print(f"a plant's backup of {args.plant} RAPID programs, 50-500 targets each "
                  f"(IRB 2400), olp-fix -j 1, best of 2 runs:")
            plant_scaling(Path(tmp), args.plant)
            return 0
        start = startup(Path(tmp), pairs)
        print("start-up of a new process (median): "
              + ", ".join(f"{k} {v:.3f} s" for k, v in start.items()))
        for kind in (args.only,) if args.only else ("irb2400", "kr16"):
            folder = Path(tmp) / kind
            folder.mkdir()
            t0 = time.perf_counter()
            robot, config = write_backup(kind, folder, args.targets)
            model = folder / "calib.json"
            write_model(robot, model)
            tree = folder / "BACKUP"
            n_files = sum(1 for p in tree.rglob("*") if p.is_file())
            print(f"\n{kind}: {robot}, 20 programs ({n_files} files), {args.targets} targets "
                  f"each; generated with a calibration in {time.perf_counter() - t0:.1f} s")
            load_before = os.getloadavg()[0]
            times, cpu = time_pairs(folder, tree, model, config, pairs)
            differ = same_bytes(folder / "out-j1", folder / "out-j2")
            n_out = sum(1 for p in (folder / "out-j1").rglob("*") if p.is_file())
            print(f"  olp-fix -j 1: {_min_median(times['1'])}")
            print(f"  olp-fix -j 2: {_min_median(times['2'])}")
            ratio_min = min(times["2"]) / min(times["1"])
            ratio_med = statistics.median(times["2"]) / statistics.median(times["1"])
            print(f"  -j 2 / -j 1: {ratio_min:.2f}x (min), {ratio_med:.2f}x (median) "
                  f"(target < 0.6x; {pairs} interleaved pairs, new processes)")
            print(f"  CPU time (user + system, workers included), median: -j 1 "
                  f"{statistics.median(cpu['1']):.3f} s, -j 2 {statistics.median(cpu['2']):.3f} s "
                  f"({statistics.median(cpu['2']) / statistics.median(cpu['1']):.2f}x: the work "
                  f"-j 2 adds); load average {load_before:.1f} before, "
                  f"{os.getloadavg()[0]:.1f} after on {os.cpu_count()} cores (above 1: other "
                  f"processes took the second core)")
            if differ:
                failed = True
                print(f"  DIFFERENT BYTES in {len(differ)} of {n_out} files: {differ[:5]}")
            else:
                print(f"  same bytes: all {n_out} files (programs and report) identical")
            where_time_goes(tree, model, config, min(times["1"]))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
