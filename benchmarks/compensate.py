"""Throughput of the whole ``olp-fix`` command on a generated RAPID module.

Generates a module of N robtargets (default 100,000) for an ABB IRB 2400 (random reachable
joints away from singularities, a tool and a work object, confdata of the nominal
solution), calibrates a virtual robot, and times ``olp-fix`` as a user runs it (a new
process: start-up, reading calib.json, parsing, resolving, IK on the calibrated model,
splicing, writing the program and the report), by default (the module's chunks of targets
shared with a forked process where there are two cores or more) and with ``-j 1`` (one
process). Prints targets/s (target: >= 20,000/s). The IK comparison with roboticstoolbox's
``ik_LM`` is ``benchmarks/ik_peer.py`` (run it too; it uses the same IK entry point).

The command runs once untimed (so the module file is in the OS cache, lark's grammar
analysis in the user cache folder and the package's bytecode written, as after any first
run of an installed tool: pip compiles bytecode on install, so the runs may write it, to a
temporary folder, even where PYTHONDONTWRITEBYTECODE is set), then ``--repeat`` times;
the best and the median run are printed (this machine's speed drifts by a third within
minutes). Then the time of each stage of olp-fix's column path (programs/rapid/
module_columns.py), in this process (:func:`lane_stages`; it takes any RAPID module, a
realistic one included, as olp-fix does).

In the same run, interleaved with olp-fix's runs, the floor: a plain Python rewrite of the
same module in a new process (read the file, replace the position of every robtarget
literal with that of a fixed 0.1 mm shift by one regular expression, write the file);
printed with the ratio of olp-fix to it (target: at most 8x; the 3x of an earlier issue was withdrawn). And olp-fix's peak memory
above the interpreter's: ``ru_maxrss`` of ``getrusage(RUSAGE_CHILDREN)`` in a new process
that ran ``olp-fix -j 1``, minus that of one that ran ``python -c "import numpy"``, per
target (target: at most 1 KB per target); for the default run, whose second process
``ru_maxrss`` would not add, the peak of the processes' proportional set sizes summed
(a page they share counts once), sampled every 10 ms.

With ``--realistic``, the CPU time and peak memory per target of ``olp-fix -j 1`` on the plain
module next to one shaped as real modules are (:func:`generate_realistic_module`: Offs and
RelTool moves, routine-local targets, several tools and work objects, 5 % of the targets
outside the axis ranges and 1 % out of reach), and on that module with every target
reachable next to every target failing, runs interleaved.

Run: ``python benchmarks/compensate.py [--targets N] [--repeat K] [--realistic]``. Exit code 0.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.compensation.pose import Compensator
from olp_compensate.kinematics.conventions import MM, invert_pose, quat_wxyz_from_matrix
from olp_compensate.calibration.identify import IdentificationOptions, identify
from olp_compensate.io.calibration_file import write_calibration
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.calibration.simulate import make_virtual_robot, random_joints

sys.path.insert(0, str(Path(__file__).resolve().parent))
from installed import installed_env  # noqa: E402

TOOL = "[TRUE,[[120.5,0,210],[0.92388,0,0.382683,0]],[2.5,[0,0,80],[1,0,0,0],0,0,0]]"
WOBJ = "[FALSE,TRUE,\"\",[[700,-300,300],[1,0,0,0]],[[0,0,0],[1,0,0,0]]]"


def generate_module(n: int, seed: int = 1, joints: np.ndarray | None = None) -> str:
    """A RAPID module with n robtargets (half in a work object) and a MoveL to each;
    ``joints``: the IRB 2400's controller joints (n, 6), rad, of the targets (default:
    random, away from singularities)."""
    robot = load_robot("abb_irb2400")
    comp = Compensator(nominal_calibration(robot))
    if joints is not None:
        q = robot.joints_from_controller(np.asarray(joints, dtype=float))
    else:
        rng = np.random.default_rng(seed)
        q = robot.joints_from_controller(random_joints(robot, 3 * n, rng, margin=0.3))
        # a program's targets are away from singularities: wrist (axis 5 near zero) and
        # elbow (stretched arm); the smallest singular value of the Jacobian above 2 cm/rad
        q = q[np.abs(np.sin(q[:, 4])) > 0.2]
        _, jac = comp.real_flange_and_jacobian(q)
        q = q[np.linalg.svd(jac, compute_uv=False)[:, -1] > 0.02]
    while len(q) < n:
        q = np.concatenate([q, q])
    q = q[:n]
    tool = np.eye(4)
    tool[:3, :3] = np.array([[0.70710678, 0, 0.70710678], [0, 1, 0], [-0.70710678, 0, 0.70710678]])
    tool[:3, 3] = np.array([120.5, 0, 210]) * MM
    wobj = np.eye(4)
    wobj[:3, 3] = np.array([700, -300, 300]) * MM
    tcp = comp.nominal_flange(q) @ tool
    in_wobj = np.arange(n) % 2 == 1
    tcp[in_wobj] = invert_pose(wobj) @ tcp[in_wobj]
    pos = tcp[:, :3, 3] / MM
    quat = quat_wxyz_from_matrix(tcp[:, :3, :3])
    conf = comp.confdata(q)
    lines = ["MODULE Big", f"  PERS tooldata tGun:={TOOL};", f"  PERS wobjdata wTable:={WOBJ};"]
    for k in range(n):
        p, o, c = pos[k], quat[k], conf[k]
        lines.append(f"  CONST robtarget p{k}:=[[{p[0]:.2f},{p[1]:.2f},{p[2]:.2f}],"
                     f"[{o[0]:.6f},{o[1]:.6f},{o[2]:.6f},{o[3]:.6f}],"
                     f"[{c[0]},{c[1]},{c[2]},{c[3]}],[9E9,9E9,9E9,9E9,9E9,9E9]];")
    lines.append("  PROC main()")
    for k in range(n):
        wobj_arg = "\\WObj:=wTable" if in_wobj[k] else ""
        lines.append(f"    MoveL p{k},v500,z10,tGun{wobj_arg};")
    lines += ["  ENDPROC", "ENDMODULE", ""]
    return "\r\n".join(lines)


TOOLS = {"tGun": ([120.5, 0, 210], [0.92388, 0, 0.382683, 0]),
         "tGrip": ([0, 0, 180], [1, 0, 0, 0]),
         "tPen": ([35, -20, 95], [0.965926, 0, 0, 0.258819])}
WOBJS = {"": [0, 0, 0], "wTable": [700, -300, 300], "wFixture": [900, 400, 150]}


def _pose(xyz_mm, quat_wxyz) -> np.ndarray:
    from olp_compensate.kinematics.conventions import matrix_from_quat_wxyz

    pose = np.eye(4)
    pose[:3, :3] = matrix_from_quat_wxyz(np.asarray(quat_wxyz, dtype=float))
    pose[:3, 3] = np.asarray(xyz_mm, dtype=float) * MM
    return pose


def _away_from_singularities(comp, q: np.ndarray) -> np.ndarray:
    """The rows of URDF joints ``q (m, 6)`` rad whose Jacobian's smallest singular value
    is above 2 cm/rad (the elbow not stretched), as :func:`generate_module` keeps them."""
    _, jac = comp.real_flange_and_jacobian(q)
    return q[np.linalg.svd(jac, compute_uv=False)[:, -1] > 0.02]


def _realistic_joints(robot, n: int, rng, failing: float) -> tuple[np.ndarray, np.ndarray]:
    """URDF joints (n, 6), rad, and a mask of the targets made unreachable: about
    ``failing`` of them outside an axis range (inside the URDF limits), a fifth as many out
    of reach (their position moved 2.5x away from the base), the rest in range; all away
    from singularities as :func:`generate_module`'s (without that filter 3.5 % more of
    the targets failed: stretched elbows the calibrated arm no longer reaches)."""
    comp = Compensator(nominal_calibration(robot))
    n_out = int(round(n * failing * 5 / 6))
    n_far = int(round(n * failing / 6))
    good = robot.joints_from_controller(random_joints(robot, 3 * n, rng, margin=0.3))
    good = _away_from_singularities(comp, good[np.abs(np.sin(good[:, 4])) > 0.2])
    out = random_joints(robot, 20 * max(n_out, 1), rng, margin=0.05, within_ranges=False)
    out = out[robot.outside_ranges(out).any(axis=1) & (np.abs(np.sin(out[:, 4])) > 0.2)]
    out = _away_from_singularities(comp, robot.joints_from_controller(out))
    while len(good) < n:
        good = np.concatenate([good, good])
    while len(out) < n_out:
        out = np.concatenate([out, out])
    q = np.concatenate([out[:n_out], good[:n - n_out]])
    far = np.zeros(n, bool)
    far[n_out:n_out + n_far] = True
    order = rng.permutation(n)
    return q[order], far[order]


def generate_realistic_module(n: int, seed: int = 1, failing: float = 0.06) -> str:
    """A RAPID module of n robtargets as real modules are: three tools and two work objects
    (and the base frame), one target in ten declared inside its routine, routines of 500
    moves, every fifth target approached by ``Offs(p, 0, 0, 50)`` and every seventh left by
    ``RelTool(p, 0, 0, -20)`` (both solved at run time: reported ``runtime``), about
    ``failing`` of the targets outside the axis ranges (5/6) or out of reach (1/6);
    ``failing=1``: every target fails. IRB 2400; the confdata of the nominal solution."""
    robot = load_robot("abb_irb2400")
    comp = Compensator(nominal_calibration(robot))
    rng = np.random.default_rng(seed)
    q, far = _realistic_joints(robot, n, rng, failing)
    tool_names, wobj_names = list(TOOLS), list(WOBJS)
    tool_of = [tool_names[k % 3] for k in range(n)]
    wobj_of = [wobj_names[(k // 3) % 3] for k in range(n)]
    flange = comp.nominal_flange(q)
    conf = comp.confdata(q)
    lines = ["MODULE Real"]
    for name, (xyz, quat) in TOOLS.items():
        lines.append(f"  PERS tooldata {name}:=[TRUE,[[{xyz[0]},{xyz[1]},{xyz[2]}],"
                     f"[{','.join(map(str, quat))}]],[2.5,[0,0,80],[1,0,0,0],0,0,0]];")
    for name, xyz in WOBJS.items():
        if name:
            lines.append(f"  PERS wobjdata {name}:=[FALSE,TRUE,\"\",[[{xyz[0]},{xyz[1]},"
                         f"{xyz[2]}],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];")

    def literal(k: int) -> str:
        tcp = flange[k] @ _pose(*TOOLS[tool_of[k]])
        if far[k]:
            tcp[:3, 3] *= 2.5
        target = invert_pose(_pose(WOBJS[wobj_of[k]], [1, 0, 0, 0])) @ tcp
        p, o, c = target[:3, 3] / MM, quat_wxyz_from_matrix(target[:3, :3]), conf[k]
        return (f"[[{p[0]:.2f},{p[1]:.2f},{p[2]:.2f}],[{o[0]:.6f},{o[1]:.6f},{o[2]:.6f},"
                f"{o[3]:.6f}],[{c[0]},{c[1]},{c[2]},{c[3]}],[9E9,9E9,9E9,9E9,9E9,9E9]]")

    local = [k % 10 == 9 for k in range(n)]
    lines += [f"  CONST robtarget p{k}:={literal(k)};" for k in range(n) if not local[k]]
    routines = []
    for start in range(0, n, 500):
        block = range(start, min(start + 500, n))
        routines.append(f"r{start // 500}")
        lines.append(f"  PROC r{start // 500}()")
        lines += [f"    VAR robtarget p{k}:={literal(k)};" for k in block if local[k]]
        for k in block:
            args = f"v500,z10,{tool_of[k]}" + (f"\\WObj:={wobj_of[k]}" if wobj_of[k] else "")
            if k % 5 == 0:
                lines.append(f"    MoveJ Offs(p{k},0,0,50),{args};")
            lines.append(f"    MoveL p{k},{args};")
            if k % 7 == 0:
                lines.append(f"    MoveL RelTool(p{k},0,0,-20),{args};")
        lines.append("  ENDPROC")
    lines += ["  PROC main()", *[f"    {r};" for r in routines], "  ENDPROC", "ENDMODULE", ""]
    return "\r\n".join(lines)


FLOOR = r"""
import re, sys
NUMBER = rb"([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)"
ANY = rb"[-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?"
LITERAL = re.compile(rb"\[\[" + NUMBER + rb"," + NUMBER + rb"," + NUMBER + rb"\],(\[" +
                     rb",".join([ANY] * 4) + rb"\],\[" + rb",".join([rb"-?[0-9]+"] * 4) +
                     rb"\],\[)")
def shifted(match):
    x, y, z = (float(v) + 0.1 for v in match.groups()[:3])
    return b"[[%.2f,%.2f,%.2f]," % (x, y, z) + match.group(4)
with open(sys.argv[1], "rb") as f:
    text = f.read()
text, n = LITERAL.subn(shifted, text)
with open(sys.argv[2], "wb") as f:
    f.write(text)
print(n)
"""
"""The floor: every robtarget literal's position (``[[x,y,z],[q1..q4],[cf1,cf4,cf6,cfx],[``)
moved by 0.1 mm along x, y and z (written with two decimals), the rest of the bytes kept;
prints the number of literals rewritten."""

PEAK_RSS = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=False, "
            "stdout=subprocess.DEVNULL); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")
"""Runs its arguments as a child and prints the child's peak resident memory, KB (Linux)."""


def peak_rss_kb(command: list[str], env: dict | None = None) -> int:
    """Peak resident memory (KB) of ``command`` run as the only child of a new process."""
    done = subprocess.run([sys.executable, "-c", PEAK_RSS, *command], capture_output=True,
                          text=True, env=env, check=True)
    return int(done.stdout.split()[-1])


def tree_peak_kb(command: list[str], env: dict | None = None) -> int:
    """Peak of the summed resident memory (KB) of ``command`` and its child processes,
    sampled every 10 ms from /proc (Linux): their proportional set sizes (a page two
    processes share counts half in each)."""
    process = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    peak = 0
    while process.poll() is None:
        peak = max(peak, sum(_pss_kb(pid) for pid in _tree(process.pid)))
        time.sleep(0.01)
    return peak


def _tree(pid: int) -> list[int]:
    """``pid`` and its descendants."""
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        found.append(p)
        try:
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as f:
                    todo += [int(c) for c in f.read().split()]
        except OSError:
            pass
    return found


def _pss_kb(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            for line in f:
                if line.startswith("Pss:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def cpu_seconds(command: list[str], env: dict | None = None) -> float:
    """User + system CPU time (s) of ``command`` and every process it waited for."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def compare_modules(n: int, folder: Path, model: Path, env: dict, repeat: int) -> None:
    """CPU time and peak memory per target of ``olp-fix -j 1`` on four modules of n targets,
    runs interleaved: the plain module, the realistic one (:func:`generate_realistic_module`),
    and the realistic one with every target reachable and with every target failing."""
    modules = {"plain": generate_module(n), "realistic": generate_realistic_module(n),
               "all reachable": generate_realistic_module(n, seed=3, failing=0.0),
               "all failing": generate_realistic_module(n, seed=3, failing=1.0)}
    commands = {}
    for name, text in modules.items():
        path = folder / (name.replace(" ", "_") + ".mod")
        path.write_bytes(text.encode("latin-1"))
        commands[name] = [sys.executable, "-m", "olp_compensate.cli.fix", str(path), "--model",
                          str(model), "--report", str(folder / "cmp.csv"), "-o",
                          str(folder / "cmp"), "-j", "1"]
    cpu = {name: [] for name in commands}
    for run in range(repeat):
        for name in (list(commands) if run % 2 else list(commands)[::-1]):
            cpu[name].append(cpu_seconds(commands[name], env))
    peak = {name: peak_rss_kb(command, env) for name, command in commands.items()}
    numpy_kb = peak_rss_kb([sys.executable, "-c", "import numpy"], env)
    per = {name: min(cpu[name]) / n * 1e6 for name in commands}
    middle = {name: statistics.median(cpu[name]) / n * 1e6 for name in commands}
    mem = {name: (peak[name] - numpy_kb) / n for name in commands}
    for name in commands:
        print(f"  {name:<14} olp-fix -j 1, {n:,} targets: CPU {min(cpu[name]):6.2f} s "
              f"({per[name]:5.1f} us/target, best of {repeat}; median {middle[name]:5.1f}), "
              f"peak memory above numpy {mem[name]:5.2f} KB/target")

    def ratio(a: str, b: str) -> str:
        return f"{per[a] / per[b]:.2f}x best, {middle[a] / middle[b]:.2f}x median"
    print(f"  realistic / plain: CPU {ratio('realistic', 'plain')} (target <= 1.3x), memory "
          f"{mem['realistic'] / mem['plain']:.2f}x (target <= 1.3x); all failing / all "
          f"reachable: CPU {ratio('all failing', 'all reachable')} (target <= 3x)")


def lane_stages(module: Path, cal) -> dict[str, float]:
    """Seconds of each stage of olp-fix's column path on ``module`` (in this process, the
    garbage collector off as in the command), as :func:`~olp_compensate.programs.rapid.
    module_columns.compensate_rapid_task` runs them on one module: the table rows whose
    meaning is not plain (several pairs, copies, routine arguments) made objects, the
    objects' rows apart from the table's chunks (Offs/RelTool motions of table targets are
    rows, programs/rapid/displaced.py); a module no table can hold goes whole to the
    objects."""
    import gc

    from olp_compensate.programs.rapid import module_columns as mc
    from olp_compensate.programs.rapid.column_plans import task_plans
    from olp_compensate.programs.rapid.columns import with_objects
    from olp_compensate.programs.rapid.displaced import (DisplacedMoves, RowsWithDisplaced,
                                                         with_displaced)
    from olp_compensate.programs.rapid.reader import parse_rapid_columns

    gc.disable()
    try:
        stages = {}
        t0 = time.perf_counter()
        text = module.read_bytes().decode("latin-1")
        tables = [DisplacedMoves()]   # its Offs()/RelTool() motions as rows, as olp-fix
        parsed = mc._plain_parts([parse_rapid_columns(text, str(module), tables[0])], tables)
        stages["read and parse"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        comp = Compensator(cal)
        (plan,) = task_plans([parsed[0][0]], [parsed[0][1]])
        program, columns = parsed[0]
        if plan is None:
            if tables[0] is not None:
                program, tables[0] = with_displaced(program, tables[0]), None
            program = with_objects(program, columns)
        (res,) = mc.resolve_task([program])
        stages["resolve the rest, plan the columns"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        rows, _, edits = mc.module_rows_and_edits(program, res, comp, emit="pose",
                                                  unused="skip")
        stages[f"objects: {len(rows):,} rows and their edits"] = time.perf_counter() - t0
        table = None
        if plan is not None:
            table = mc._TablePart(program, columns.targets, plan, comp, "skip", None)
            del parsed, columns
            t0 = time.perf_counter()
            table.compensate_chunks(mc.CHUNK)
            stages["chunks: values, IK, rows, edits"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            table.retry_failed()
            stages["the targets not reached at once, again"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        if table is None:
            report_rows, table_edits = sorted(rows, key=mc.LINE_COLUMN), []
        else:
            others = sorted(rows + table.others, key=mc.LINE_COLUMN)
            if tables[0] is not None and len(tables[0]):
                others = RowsWithDisplaced(others, tables[0], program.text, program.file)
            report_rows = table.rows(others)
            table_edits = table.edits
        report = mc.CompensationReport(file=str(module), rows=report_rows,
                                       n_joints=comp.robot.n_joints)
        new = sum(map(len, mc.SplicedText(text, [edits, *table_edits]).blocks("latin-1")))
        stages["splice and encode the program"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        csv_bytes = sum(len(piece.encode()) for piece in report.csv_chunks())
        stages["report CSV"] = time.perf_counter() - t0
        assert new and csv_bytes
    finally:
        gc.enable()
    return stages


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=3, help="timed runs (default 3)")
    parser.add_argument("--realistic", action="store_true",
                        help="also time realistic modules and modules whose targets all fail")
    args = parser.parse_args()
    robot = load_robot("abb_irb2400")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        t0 = time.perf_counter()
        module = folder / "big.mod"
        module.write_bytes(generate_module(args.targets).encode("latin-1"))
        virtual = make_virtual_robot(robot, seed=2, n_points=3)
        rng = np.random.default_rng(2)
        meas = virtual.measure(random_joints(robot, 60, rng), 0.02e-3, rng)
        cal = identify(robot, meas, IdentificationOptions(folds=0)).calibration
        model = folder / "calib.json"
        write_calibration(model, cal)
        print(f"generated {args.targets} targets and a calibration in "
              f"{time.perf_counter() - t0:.1f} s")

        # as a user runs it, summary on the terminal included: by default (the chunks of
        # the module on two processes where there are two cores) and with -j 1
        command = [sys.executable, "-m", "olp_compensate.cli.fix", str(module), "--model",
                   str(model), "--report", str(folder / "report.csv")]
        commands = {"olp-fix": command, "olp-fix -j 1": [*command, "-j", "1"],
                    "floor": [sys.executable, "-c", FLOOR, str(module),
                              str(folder / "floor.mod")]}
        env = installed_env(folder)
        times: dict[str, list[float]] = {name: [] for name in commands}
        for run in range(1 + args.repeat):   # the first run is the untimed warm-up
            names = list(commands) if run % 2 else list(commands)[::-1]   # interleaved
            for name in names:
                t0 = time.perf_counter()
                done = subprocess.run(commands[name], capture_output=True, text=True, env=env)
                if run:
                    times[name].append(time.perf_counter() - t0)
                if done.returncode not in (0, 2):
                    print(done.stderr)
                    return 1
                if name == "floor" and int(done.stdout) != args.targets:
                    print(f"the floor rewrote {done.stdout.strip()} literals, not "
                          f"{args.targets}")
                    return 1
        statuses = [ln.split(",")[4] for ln in (folder / "report.csv").read_text().splitlines()[1:]]
        ok = sum(s in ("ok", "singular") for s in statuses)
        floor_best, floor_median = min(times["floor"]), statistics.median(times["floor"])
        print(f"floor, plain Python re rewrite of the same module (new process, best of "
              f"{args.repeat}): {floor_best:.2f} s, median {floor_median:.2f} s")
        for name in ("olp-fix", "olp-fix -j 1"):
            best, median = min(times[name]), statistics.median(times[name])
            print(f"{name + ',':<14} whole command (new process, interleaved, best of "
                  f"{args.repeat}): {best:.2f} s, {args.targets / best:,.0f} targets/s (target "
                  f">= 20,000/s), median {median:.2f} s; / floor: {best / floor_best:.2f}x "
                  f"best, {median / floor_median:.2f}x median (target <= 8x)")
        print(f"  default / -j 1: {min(times['olp-fix']) / min(times['olp-fix -j 1']):.2f}x "
              f"best, {statistics.median(times['olp-fix']) / statistics.median(times['olp-fix -j 1']):.2f}x "
              f"median ({len(os.sched_getaffinity(0))} cores); {ok}/{len(statuses)} compensated")
        numpy_kb = min(peak_rss_kb([sys.executable, "-c", "import numpy"], env)
                       for _ in range(2))
        fix_kb = min(peak_rss_kb(commands["olp-fix -j 1"], env) for _ in range(2))
        print(f"peak memory, olp-fix -j 1 (ru_maxrss of a new process): {fix_kb / 1024:.0f} MB, "
              f"python -c 'import numpy' {numpy_kb / 1024:.0f} MB; olp-fix above it "
              f"{(fix_kb - numpy_kb) / args.targets:.2f} KB per target (target <= 1 KB)")
        tree_kb = {name: max(tree_peak_kb(commands[name], env) for _ in range(2))
                   for name in ("olp-fix", "olp-fix -j 1")}
        print(f"peak memory, proportional set sizes of the command's processes summed, sampled "
              f"every 10 ms: olp-fix {tree_kb['olp-fix'] / 1024:.0f} MB, olp-fix -j 1 "
              f"{tree_kb['olp-fix -j 1'] / 1024:.0f} MB; the second process adds "
              f"{(tree_kb['olp-fix'] - tree_kb['olp-fix -j 1']) / args.targets:.2f} KB per "
              f"target")

        if args.realistic:
            print("modules as real ones are (Offs/RelTool moves, routine-local targets, three "
                  "tools, two work objects, targets out of range and out of reach):")
            compare_modules(args.targets, folder, model, env, args.repeat)

        # where the time goes, in-process, stage by stage as olp-fix runs them
        stages = {"plain module": module}
        if args.realistic:
            stages["realistic module"] = folder / "realistic.mod"
        for title, path in stages.items():
            print(f"{title}, stage by stage (in this process):")
            for name, seconds in lane_stages(path, cal).items():
                print(f"  {name:<40} {seconds:6.2f} s  "
                      f"({args.targets / max(seconds, 1e-9):>10,.0f}/s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
