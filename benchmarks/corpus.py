"""olp-fix over a corpus of real programs: what parses, what comes back byte for byte, and
whether every robtarget literal is accounted for.

For every RAPID file (.mod .modx .prg .sys, any case) under the folders given, runs the
library as ``olp-fix`` does with the NOMINAL calibration of an ABB IRB 2400 (so a correct
run changes no byte) and prints:

- files, and the parse rate (the others: each ParseError, one line);
- the byte-identical rate of the parsed files (output == input with the nominal model);
- the status counts of all report rows;
- robtarget literals found by an independent scan (a regular expression for the
  ``[[x,y,z],[q1..q4],[cf1,cf4,cf6,cfx],[eax_a..eax_f]]`` shape outside comments and
  strings, not the parser) against those the report accounts for at the same place (a
  literal that is the whole value of a scalar declaration is reported at its name);
- the time.

Run: ``python benchmarks/corpus.py DIR [DIR ...] [--robot NAME] [-v]``. Exit code 0.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from collections import Counter
from pathlib import Path

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.compensation.pose import Compensator
from olp_compensate.compensation.program import compensate_program
from olp_compensate.errors import OlpError
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import load

EXTENSIONS = {".mod", ".modx", ".prg", ".sys"}
_NUM = r"\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*"
LITERAL = re.compile(r"\[\s*" + r"\s*,\s*".join(
    r"\[" + ",".join([_NUM] * n) + r"\]" for n in (3, 4, 4, 6)) + r"\s*\]")
DECLARED = re.compile(r"(?:CONST|PERS|VAR)\s+[A-Za-z_]\w*\s+([A-Za-z_]\w*)\s*:=\s*$", re.I)


def blank_comments_and_strings(text: str) -> str:
    """``text`` with comments and strings replaced by spaces (offsets kept)."""
    out = []
    for line in text.split("\n"):
        chars, quoted = list(line), False
        for k, c in enumerate(line):
            if c == '"':
                quoted = not quoted
                chars[k] = " "
            elif quoted:
                chars[k] = " "
            elif c == "!":
                chars[k:] = " " * (len(line) - k)
                break
        out.append("".join(chars))
    return "\n".join(out)


def literal_places(text: str) -> list[tuple[int, int]]:
    """(line, column) where each robtarget literal should be reported."""
    clean = blank_comments_and_strings(text)
    places = []
    for m in LITERAL.finditer(clean):
        at = m.start()
        declared = DECLARED.search(clean, max(at - 200, 0), at)
        if declared is not None:
            at = declared.start(1)
        places.append((clean.count("\n", 0, at) + 1, at - clean.rfind("\n", 0, at)))
    return places


def programs_in(folders: list[str]) -> list[Path]:
    found = []
    for folder in folders:
        root = Path(folder)
        paths = [root] if root.is_file() else root.rglob("*")
        found += [p for p in paths if p.is_file() and p.suffix.lower() in EXTENSIONS]
    return sorted(found)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+")
    parser.add_argument("--robot", default="abb_irb2400")
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="list the files that differ and the literals not accounted for")
    args = parser.parse_args()
    comp = Compensator(nominal_calibration(load_robot(args.robot)))
    files = programs_in(args.folders)
    started = time.perf_counter()
    parsed = identical = literals = accounted = 0
    statuses: Counter[str] = Counter()
    for path in files:
        text = path.read_bytes().decode("latin-1")
        places = literal_places(text)
        try:
            program = load(path, "rapid")
            out, report = compensate_program(program, None, comp)
        except OlpError as exc:
            print(f"  failed: {exc}")
            continue
        parsed += 1
        literals += len(places)
        identical += out == program.text
        if out != program.text and args.verbose:
            print(f"  differs: {path}")
        statuses.update(r.status for r in report.rows)
        reported = {(r.line, r.column) for r in report.rows}
        missing = [p for p in places if p not in reported]
        accounted += len(places) - len(missing)
        if missing and args.verbose:
            print(f"  not accounted for: {path}: {missing[:5]}")
    seconds = time.perf_counter() - started
    n = max(len(files), 1)
    print(f"files: {len(files)}; parsed: {parsed} ({100 * parsed / n:.1f} %); "
          f"byte-identical with the nominal model: {identical} "
          f"({100 * identical / max(parsed, 1):.1f} % of parsed)")
    print("statuses: " + ", ".join(f"{k} {v}" for k, v in sorted(statuses.items())))
    print(f"robtarget literals in the parsed files (independent scan): {literals}; "
          f"accounted for in the reports: {accounted}")
    print(f"time: {seconds:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
