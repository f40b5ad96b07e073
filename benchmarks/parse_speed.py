"""Speed of the program layer: parse and emit a large generated RAPID module.

Generates a module with N robtarget declarations (default 100,000) and a PROC moving to
each of them (MoveL p<k>, v1000, z10, tGun\\WObj:=wobj0), then reports targets/s for:

- parse   : bytes -> Program (lark grammar + fast paths + literal reading)
- emit    : edits for every target (new position and orientation) + splice -> text
- total   : parse + emit, the figure the design asks to be well over 20,000 targets/s

Options: --targets N, --no-moves (declarations only), --inline (RoboDK style: the targets
written inline in MoveL instructions, no declarations), --vplus (a V+ .LOCATIONS list),
--repeat R (best and median of R runs are printed; this machine's timings vary by 20 %).

    python benchmarks/parse_speed.py [--targets 100000] [--no-moves | --inline | --vplus]
"""

from __future__ import annotations

import argparse
import gc
import random
import statistics
import time

import numpy as np

from olp_compensate import programs
from olp_compensate.programs.grammar import parser


def rapid_module(n: int, moves: bool = True, inline: bool = False, seed: int = 0) -> str:
    rng = random.Random(seed)
    tool = ("PERS tooldata tGun:=[TRUE,[[120.5,0,210],[0.92388,0,0.382683,0]],"
            "[2.5,[0,0,80],[1,0,0,0],0,0,0]];")
    lines = ["MODULE Big", "  " + tool]
    literals = []
    for _ in range(n):
        x, y, z = rng.uniform(700, 1200), rng.uniform(-500, 500), rng.uniform(300, 1200)
        cf1 = -1 if y < 0 else 0
        literals.append(f"[[{x:.2f},{y:.2f},{z:.2f}],[0.0436194,0,0.999048,0],"
                        f"[{cf1},0,{cf1},0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]]")
    if not inline:
        lines += [f"  CONST robtarget p{k}:={lit};" for k, lit in enumerate(literals)]
    lines.append("  PROC main()")
    if inline:
        lines += [f"    MoveL {lit},v1000,z10,tGun\\WObj:=wobj0;" for lit in literals]
    elif moves:
        lines += [f"    MoveL p{k}, v1000, z10, tGun\\WObj:=wobj0;" for k in range(n)]
    lines += ["  ENDPROC", "ENDMODULE", ""]
    return "\r\n".join(lines)


def vplus_locations(n: int, seed: int = 0) -> str:
    rng = random.Random(seed)
    lines = [".LOCATIONS", ""]
    for k in range(n):
        x, y, z = rng.uniform(300, 600), rng.uniform(-300, 300), rng.uniform(-200, 300)
        lines.append(f"loc{k:<8d} {x:10.3f} {y:10.3f} {z:10.3f}     0.000   180.000     0.000")
    lines += [".END", ""]
    return "\n".join(lines)


def edits_for_all(program):
    """Every target moved by 0.1234 mm and turned slightly, the new values computed in one
    numpy batch as a compensation would: position and orientation edits."""
    targets = program.targets
    k = 7 if program.dialect == "rapid" else 6
    values = np.array([[float(v) for v in t.texts[:k]] for t in targets])
    values[:, :3] += 0.1234
    values[:, 4] += 1e-4 if program.dialect == "rapid" else 0.01
    return programs.edits_for_targets(program, position_mm=values[:, :3],
                                      orientation=values[:, 3:])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--no-moves", action="store_true")
    group.add_argument("--inline", action="store_true")
    group.add_argument("--vplus", action="store_true")
    args = ap.parse_args(argv)
    n = args.targets
    if args.vplus:
        text, dialect, what = vplus_locations(n), "vplus", "V+ location list"
    else:
        text = rapid_module(n, moves=not args.no_moves, inline=args.inline)
        dialect = "rapid"
        what = ("RAPID, inline MoveL targets" if args.inline else
                "RAPID, declarations only" if args.no_moves else
                "RAPID, declarations + one MoveL each")
    data = text.encode("latin-1")
    # build the cached parsers first: a one-off cost (~0.3 s), not per file
    parser("rapid.lark" if dialect == "rapid" else "vplus.lark",
           programs.rapid.Callbacks if dialect == "rapid" else programs.vplus.Callbacks,
           ("start", "call") if dialect == "rapid" else ("start",))
    runs = []
    for _ in range(max(args.repeat, 1)):
        t0 = time.perf_counter()
        program = programs.loads(data, dialect, "bench")
        t1 = time.perf_counter()
        edits = edits_for_all(program)
        out = programs.dumps(program, edits).encode("latin-1")
        t2 = time.perf_counter()
        count = len(program.targets)
        assert count == n, (count, n)
        assert len(out) > len(data)
        runs.append((t2 - t0, t1 - t0, t2 - t1))
        del program, edits, out
        gc.collect()
    runs.sort()
    print(f"{what}: {n} targets, {len(data) / 1e6:.1f} MB, every target edited "
          f"(position and orientation); best and median of {len(runs)} runs")
    for k, label in ((1, "parse"), (2, "emit "), (0, "total")):
        best = min(r[k] for r in runs)
        med = statistics.median(r[k] for r in runs)
        print(f"  {label}  {n / best:9,.0f} targets/s  ({best:5.2f} s; median "
              f"{n / med:9,.0f} targets/s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
