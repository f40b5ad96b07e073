"""olp-fix over a corpus of real programs: what parses, what comes back byte for byte, and
whether every target literal is accounted for, per dialect.

Files under the folders given are sorted by dialect from their extension, as the library
does (:func:`olp_compensate.programs.languages.extensions`, any case): RAPID (.mod .modx
.prg .sys), V+/AS (.pg .v2 .lc .loc .as), KUKA KRL (.src and .dat; a .src and the .dat of
the same stem in one folder are one program, counted once), FANUC TP (.ls), Stäubli VAL3
(.dtx), URScript (.script). Hidden files and names starting with ``$`` (KRL system data
lists such as ``$config.dat``) are skipped, as ``olp-fix`` skips them in a folder.

Each program is run as ``olp-fix`` runs it, with the NOMINAL calibration of a robot of its
maker (so a correct run changes no byte): RAPID an ABB IRB 2400 (``--robot``), V+/AS the
same default, KRL a KUKA KR 16-2, FANUC an R-2000iC/165F, VAL3 a Stäubli TX2-60, URScript
a UR10e. For each dialect present it prints:

- files (programs; a KRL pair is one), and the parse rate, each failure on one line as
  ``file:line:col message``;
- the byte-identical rate of the parsed programs (every output file == its input);
- the status counts of all report rows;
- target literals found by an independent scan (a regular expression per dialect, outside
  comments and strings, not the parser) against those the report accounts for at the same
  place (file, line, column). The places: RAPID as before (a literal that is the whole
  value of a scalar declaration at its name); V+/AS a location line at its name; KRL an
  aggregate with X, Y, Z, A, B, C (or A1..A6) at its ``{``; FANUC a ``/POS`` record at its
  ``X`` number (a joint record at its ``P[``); VAL3 a ``pointRx``/``jointRx`` value at its
  first pose attribute's value (else at its ``<``); URScript a ``p[...]`` or six-number
  list written in a motion, or the whole value of an assignment to a name a motion moves
  to, at its first number.
  A literal written inside a motion that is reported as a whole (a run-time target, an
  instruction that could not be read) counts as accounted by that row (same line, at the
  motion);
- the time.

With ``--robot auto`` each program runs on the robot it was written for: the one its text
names, else the one ``--robot-map FILE`` gives its path (lines ``GLOB,ROBOT``), else the
robot of the dialect's maker that reaches the most of its targets inside the axis ranges
with the nominal model (the heuristic and its ties: :mod:`corpus_robots`). Each program's
line says which robot it got and why (header / map / targets / default); a table per robot
model closes the run: programs, target uses (report rows), the share ``ok`` and the other
statuses, next to the share ``ok`` of the same programs on the dialect's fixed default
robot (the one above; RAPID's IRB 2400), so that the gain of the right robot shows.

Run: ``python benchmarks/corpus.py DIR [DIR ...] [--robot NAME|auto] [--robot-map FILE]
[-v]``. Exit code 0 (2 for a bad ``--robot-map``).
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

from olp_compensate.programs.languages import extensions
from olp_compensate.compensation.files import ProgramFiles, compensate_files
from olp_compensate.programs.object_model.task import compensate_program
from olp_compensate.errors import OlpError, ParseError
from olp_compensate.programs import load

import corpus_robots  # beside this script

EXTENSIONS = {".mod", ".modx", ".prg", ".sys"}
"""RAPID's extensions (kept for callers of the RAPID-only version)."""
ORDER = ("rapid", "vplus", "krl", "fanuc", "val3", "urscript")
MAKER_ROBOT = {"krl": "kuka_kr16_2", "fanuc": "fanuc_r2000ic_165f", "val3": "staubli_tx2_60",
               "urscript": "ur10e"}
NAMES = {"rapid": "RAPID", "vplus": "V+/AS", "krl": "KUKA KRL", "fanuc": "FANUC TP",
         "val3": "Staubli VAL3", "urscript": "URScript"}
_N = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_NUM = r"\s*" + _N + r"\s*"
LITERAL = re.compile(r"\[\s*" + r"\s*,\s*".join(
    r"\[" + ",".join([_NUM] * n) + r"\]" for n in (3, 4, 4, 6)) + r"\s*\]")
DECLARED = re.compile(r"(?:CONST|PERS|VAR)\s+[A-Za-z_]\w*\s+([A-Za-z_]\w*)\s*:=\s*$", re.I)


# ---------------------------------------------------------------- RAPID (as before)

def blank_comments_and_strings(text: str) -> str:
    """``text`` with comments and strings replaced by spaces (offsets kept)."""
    return _blank(text, "!")


def _blank(text: str, marker: str, keep_quotes: bool = False) -> str:
    """``text`` with ``marker`` comments and ``"..."`` strings replaced by spaces, line by
    line (offsets kept; with ``keep_quotes`` the quotes stay)."""
    out = []
    for line in text.split("\n"):
        chars, quoted = list(line), False
        for k, c in enumerate(line):
            if c == '"':
                quoted = not quoted
                if not keep_quotes:
                    chars[k] = " "
            elif quoted:
                chars[k] = " "
            elif line.startswith(marker, k):
                chars[k:] = " " * (len(line) - k)
                break
        out.append("".join(chars))
    return "\n".join(out)


def _place(clean: str, at: int) -> tuple[int, int]:
    """1-based (line, column) of offset ``at`` (lines end at LF; a CR is a character)."""
    return clean.count("\n", 0, at) + 1, at - clean.rfind("\n", 0, at)


def literal_places(text: str) -> list[tuple[int, int]]:
    """(line, column) where each robtarget literal should be reported."""
    clean = blank_comments_and_strings(text)
    places = []
    for m in LITERAL.finditer(clean):
        at = m.start()
        declared = DECLARED.search(clean, max(at - 200, 0), at)
        if declared is not None:
            at = declared.start(1)
        places.append(_place(clean, at))
    return places


# ---------------------------------------------------------------- the other dialects

_VPLUS_SECTION = re.compile(r"^\s*\.(LOCATIONS|TRANS|JOINTS|POINTS)\b(.*?)^\s*\.END\b",
                            re.I | re.M | re.S)
_VPLUS_LINE = re.compile(r"^[ \t]*(#?[A-Za-z_][\w.]*(?:\[[^\]\n]*\])?)(?:[ \t,]+" + _N + r"){4,}",
                         re.M)


def vplus_places(text: str) -> list[tuple[int, int]]:
    """V+/AS: a line ``name x y z ...`` inside ``.LOCATIONS``/``.TRANS``/``.JOINTS``/
    ``.POINTS`` ... ``.END``, at its name; not the names the file sets as ``TOOL name`` or
    ``BASE name`` (frames, not targets)."""
    clean = _blank(text, ";")
    frames = {n.lower() for n in re.findall(r"\b(?:TOOL|BASE)[ \t]+([A-Za-z_][\w.]*)", clean,
                                            re.I)}
    places = []
    for section in _VPLUS_SECTION.finditer(clean):
        for m in _VPLUS_LINE.finditer(clean, section.start(2), section.end(2)):
            if m.group(1).lower() not in frames:
                places.append(_place(clean, m.start(1)))
    return places


_KRL_AGGREGATE = re.compile(r"\{[^{}]*\}")
_KRL_KEY = re.compile(r"(?:^|[{,])\s*([A-Za-z]\w*)\s+" + _N)


def krl_places(text: str) -> list[tuple[int, int]]:
    """KRL: an aggregate ``{...}`` (no nested braces) whose number fields include X, Y, Z,
    A, B, C or A1..A6, at its ``{``."""
    clean = _blank(text, ";")
    places = []
    for m in _KRL_AGGREGATE.finditer(clean):
        keys = {k.group(1).upper() for k in _KRL_KEY.finditer(m.group())}
        if {"X", "Y", "Z", "A", "B", "C"} <= keys or {"A1", "A2", "A3", "A4", "A5", "A6"} <= keys:
            places.append(_place(clean, m.start()))
    return places


_FANUC_RECORD = re.compile(r"^[ \t]*P\[[^\]\n]*\][ \t]*\{(.*?)\};", re.M | re.S)
_FANUC_X = re.compile(r"(?<![\w\[])X[ \t]*=[ \t]*(" + _N + ")")
_FANUC_GP = re.compile(r"\bGP(\d+)[ \t]*:")


def fanuc_places(text: str) -> list[tuple[int, int]]:
    """FANUC: a ``P[..]{ ... };`` record after ``/POS``: at group 1's ``X`` number, or at
    the record's ``P`` for a joint record."""
    pos = re.search(r"^/POS\b", text, re.M)
    if pos is None:
        return []
    places = []
    for m in _FANUC_RECORD.finditer(text, pos.end()):
        lo, hi = m.start(1), m.end(1)
        groups = list(_FANUC_GP.finditer(text, lo, hi))
        for g, nxt in zip(groups, groups[1:] + [None]):
            if g.group(1) == "1":
                lo, hi = g.end(), nxt.start() if nxt is not None else hi
        x = _FANUC_X.search(text, lo, hi)
        start = m.start() + len(m.group()) - len(m.group().lstrip())
        places.append(_place(text, x.start(1) if x else start))
    return places


_VAL3_CONTAINER = re.compile(r"<(Data|point|joint)\b([^>]*?)(/?)>(.*?)</\1>", re.S)
_VAL3_ENTRY = re.compile(r"<(Value|valuePoint|valueJoint)\b")
_VAL3_POSE_ATTR = re.compile(r"""\b(x|y|z|rx|ry|rz)\s*=\s*"([^"]*)\"""")


def val3_places(text: str) -> list[tuple[int, int]]:
    """VAL3: each value of a ``pointRx`` or ``jointRx`` container (either layout), at its
    first pose attribute's value (a point) or at its ``<`` (a joint, a point without
    attributes)."""
    clean = re.sub(r"<!--.*?-->", lambda m: " " * len(m.group()), text, flags=re.S)
    places = []
    for c in _VAL3_CONTAINER.finditer(clean):
        kind, attrs = c.group(1), c.group(2)
        typ = re.search(r'(?<![:\w])type\s*=\s*"([^"]*)"', attrs)
        typ = typ.group(1) if kind == "Data" and typ else {"point": "pointRx",
                                                          "joint": "jointRx"}.get(kind)
        if typ not in ("pointRx", "jointRx"):
            continue
        entries = list(_VAL3_ENTRY.finditer(clean, c.start(4), c.end(4)))
        for e, nxt in zip(entries, entries[1:] + [None]):
            hi = nxt.start() if nxt is not None else c.end(4)
            attr = _VAL3_POSE_ATTR.search(clean, e.start(), hi) if typ == "pointRx" else None
            places.append(_place(clean, attr.start(2) if attr else e.start()))
    return places


_UR_LITERAL = re.compile(r"(p?)\[\s*(" + _N + r")(?:\s*,\s*" + _N + r"){5}\s*\]")
_UR_MOTION = re.compile(r"\b(movej|movel|movep|movec)\s*\(")
_UR_ASSIGN = re.compile(r"^[ \t]*(?:global[ \t]+|local[ \t]+)?([A-Za-z_]\w*)[ \t]*=(?!=)[ \t]*$",
                        re.M)


def urscript_places(text: str) -> list[tuple[int, int, int | None]]:
    """URScript: a ``p[six numbers]`` or ``[six numbers]`` inside a motion call's
    parentheses, or as the whole value of an assignment to a name a motion moves to
    (``movel(name, ...)``, ``movej(get_inverse_kin(name, ...))``), at its first number;
    with the column of the enclosing motion, if any."""
    clean = _blank(text, "#", keep_quotes=True)
    moved_to = set(re.findall(r"\b(?:movej|movel|movep|movec)\s*\(\s*(?:get_inverse_kin\s*\(\s*)?"
                              r"([A-Za-z_]\w*)\s*[,)]", clean))
    moved_to |= set(re.findall(r"\bmovec\s*\([^,()]*,\s*([A-Za-z_]\w*)\s*[,)]", clean))
    open_calls = _open_motions(clean)
    places = []
    for m in _UR_LITERAL.finditer(clean):
        if m.start() > 0 and not m.group(1) and (clean[m.start() - 1].isalnum()
                                                 or clean[m.start() - 1] in "_]"):
            continue                                  # an index such as a[1, ...]
        motion = next((s for s, e in open_calls if s < m.start() < e), None)
        line_start = clean.rfind("\n", 0, m.start()) + 1
        assigned = _UR_ASSIGN.match(clean[line_start:m.start()])
        end_of_line = clean.find("\n", m.end())
        rest = clean[m.end():end_of_line if end_of_line >= 0 else len(clean)].strip()
        whole_value = assigned is not None and rest == "" and assigned.group(1) in moved_to
        if motion is None and not whole_value:
            continue
        line, column = _place(clean, m.start(2))
        places.append((line, column, _place(clean, motion)[1] if motion is not None else None))
    return places


def _open_motions(clean: str) -> list[tuple[int, int]]:
    """(start, end) of each motion call: from its name to its closing parenthesis (or the
    end of the text when it is never closed)."""
    spans = []
    for m in _UR_MOTION.finditer(clean):
        depth, end = 0, len(clean)
        for k in range(m.end() - 1, len(clean)):
            c = clean[k]
            if c in "([{":
                depth += 1
            elif c in ")]}":
                depth -= 1
                if depth == 0:
                    end = k
                    break
        spans.append((m.start(), end))
    return spans


PLACES = {"vplus": vplus_places, "krl": krl_places, "fanuc": fanuc_places,
          "val3": val3_places}


# ---------------------------------------------------------------- files and units

def programs_in(folders: list[str]) -> list[Path]:
    """RAPID files under ``folders`` (the RAPID-only interface, kept)."""
    return [p for d, units in units_in(folders).items() if d == "rapid"
            for unit in units for p in unit]


def units_in(folders: list[str]) -> dict[str, list[list[Path]]]:
    """dialect -> programs (each a list of files: a KRL pair is one program)."""
    found = []
    for folder in folders:
        root = Path(folder)
        paths = [root] if root.is_file() else root.rglob("*")
        found += [p for p in paths if p.is_file() and p.suffix.lower() in extensions()
                  and not p.name.startswith((".", "$"))]
    units: dict[str, list[list[Path]]] = defaultdict(list)
    krl: dict[tuple[Path, str], list[Path]] = defaultdict(list)
    for path in sorted(set(found)):
        dialect = extensions()[path.suffix.lower()]
        if dialect == "krl":
            krl[(path.parent, path.stem.lower())].append(path)
        else:
            units[dialect].append([path])
    for members in krl.values():
        members.sort(key=lambda p: (p.suffix.lower() != ".src", p.name))
        by_ext: dict[str, Path] = {}
        for p in members:                    # one .src and one .dat per stem
            by_ext.setdefault(p.suffix.lower(), p)
        units["krl"].append(list(by_ext.values()))
    if "krl" in units:
        units["krl"].sort()
    return dict(units)


def _failure(exc: OlpError, path: Path) -> str:
    if isinstance(exc, ParseError) and exc.line:
        return f"{exc.file}:{exc.line}:{exc.column} {exc.message}"
    return f"{path}: {' '.join(str(exc).split())}"


# ---------------------------------------------------------------- one dialect

class Tally:
    def __init__(self):
        self.parsed = self.identical = self.literals = self.accounted = 0
        self.statuses: Counter[str] = Counter()
        self.failures: list[str] = []


def run_text_unit(dialect: str, path: Path, comp, tally: Tally, verbose: bool,
                  program=None) -> Counter | None:
    """RAPID and V+/AS: one file alone, as before; its status counts (None: not parsed).
    ``program``: the file already parsed, if it is."""
    text = path.read_bytes().decode("latin-1")
    places = literal_places(text) if dialect == "rapid" else vplus_places(text)
    try:
        program = program or load(path, dialect)
        out, report = compensate_program(program, None, comp)
    except OlpError as exc:
        tally.failures.append(_failure(exc, path))
        return None
    tally.parsed += 1
    tally.literals += len(places)
    tally.identical += out == program.text
    if out != program.text and verbose:
        print(f"  differs: {path}")
    statuses = Counter(r.status for r in report.rows)
    tally.statuses.update(statuses)
    reported = {(r.line, r.column) for r in report.rows}
    missing = [p for p in places if p not in reported]
    tally.accounted += len(places) - len(missing)
    if missing and verbose:
        print(f"  not accounted for: {path}: {missing[:5]}")
    return statuses


def run_pose_unit(dialect: str, paths: list[Path], comp, tally: Tally,
                  verbose: bool) -> Counter | None:
    """KRL, FANUC, VAL3, URScript: one program through ``compensate_files``; its status
    counts (None: not parsed)."""
    names = tuple(str(p) for p in paths)
    originals = [p.read_bytes() for p in paths]
    try:
        result = compensate_files(ProgramFiles(dialect, tuple(paths), names), comp)
    except OlpError as exc:
        tally.failures.append(_failure(exc, paths[0]))
        return None
    tally.parsed += 1
    same = all(new == old for new, old in zip(result.data, originals))
    tally.identical += same
    if not same and verbose:
        print(f"  differs: {', '.join(names)}")
    rows = result.report.rows
    statuses = Counter(r.status for r in rows)
    tally.statuses.update(statuses)
    exact = {(r.file, r.line, r.column) for r in rows}
    whole = {(r.file, r.line, r.column) for r in rows
             if r.status in ("runtime", "unknown_instruction")}
    missing = []
    for name, data in zip(names, originals):
        text = data.decode("latin-1")
        if dialect == "urscript":
            places = urscript_places(text)
        else:
            places = [(line, column, None) for line, column in PLACES[dialect](text)]
        for line, column, motion in places:
            tally.literals += 1
            if (name, line, column) in exact or (
                    motion is not None and (name, line, motion) in whole):
                tally.accounted += 1
            else:
                missing.append(f"{name}:{line}:{column}")
    if missing and verbose:
        print(f"  not accounted for: {missing[:5]}")
    return statuses


def run_unit(dialect: str, unit: list[Path], comp, tally: Tally, verbose: bool,
             program=None) -> Counter | None:
    if dialect in ("rapid", "vplus"):
        return run_text_unit(dialect, unit[0], comp, tally, verbose, program)
    return run_pose_unit(dialect, unit, comp, tally, verbose)


def run_text_dialect(dialect: str, units, comp, verbose: bool) -> Tally:
    """RAPID and V+/AS: each file alone, as before."""
    tally = Tally()
    for (path,) in units:
        run_text_unit(dialect, path, comp, tally, verbose)
    return tally


def run_pose_dialect(dialect: str, units, comp, verbose: bool) -> Tally:
    """KRL, FANUC, VAL3, URScript: each program through ``compensate_files``."""
    tally = Tally()
    for paths in units:
        run_pose_unit(dialect, paths, comp, tally, verbose)
    return tally


# ---------------------------------------------------------------- --robot auto

def run_auto(dialect: str, units, default: str, robot_map, comps, tallies,
             verbose: bool) -> Tally:
    """Each program on its own robot (printed with the reason), its statuses also on
    ``default`` for the per-model table."""
    tally = Tally()
    for unit in units:
        try:
            choice, program = corpus_robots.choose(
                dialect, unit, default, robot_map, comps,
                lambda comp: run_pose_unit(dialect, unit, comp, Tally(), False))
        except OlpError as exc:
            tally.failures.append(_failure(exc, unit[0]))
            continue
        print(f"  {unit[0]}: {choice.robot} ({choice.how}"
              f"{': ' + choice.detail if choice.detail else ''})")
        statuses = run_unit(dialect, unit, comps(choice.robot), tally, verbose, program)
        if statuses is None:
            continue
        on_default = statuses if choice.robot == default else run_unit(
            dialect, unit, comps(default), Tally(), False, program)
        model = tallies.setdefault((dialect, choice.robot), corpus_robots.ModelTally())
        model.programs[choice.how] += 1
        model.chosen.update(statuses)
        model.default.update(on_default or Counter())
        model.defaults.add(default)
    return tally


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+")
    parser.add_argument("--robot", default="abb_irb2400",
                        help="robot of the RAPID and V+/AS programs (default abb_irb2400), "
                             "or 'auto': each program on the robot it was written for")
    parser.add_argument("--robot-map", metavar="FILE",
                        help="with --robot auto: lines GLOB,ROBOT naming the robot of the "
                             "programs whose path matches GLOB")
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="list the files that differ and the literals not accounted for")
    args = parser.parse_args()
    auto = args.robot == "auto"
    try:
        robot_map = corpus_robots.read_robot_map(args.robot_map) if args.robot_map else []
    except OlpError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.robot_map and not auto:
        print("error: --robot-map needs --robot auto", file=sys.stderr)
        return 2
    units = units_in(args.folders)
    comps = corpus_robots.Compensators()
    tallies: dict[tuple[str, str], corpus_robots.ModelTally] = {}
    for dialect in ORDER:
        if dialect not in units and not (dialect == "rapid" and not units):
            continue
        robot = MAKER_ROBOT.get(dialect, "abb_irb2400" if auto else args.robot)
        started = time.perf_counter()
        if auto:
            print(f"== {NAMES[dialect]}: the robot of each program (fixed default {robot})")
            tally = run_auto(dialect, units.get(dialect, []), robot, robot_map, comps,
                             tallies, args.verbose)
        else:
            run = run_text_dialect if dialect in ("rapid", "vplus") else run_pose_dialect
            tally = run(dialect, units.get(dialect, []), comps(robot), args.verbose)
        seconds = time.perf_counter() - started
        report(dialect, "each program's own robot" if auto else robot,
               len(units.get(dialect, [])), tally, seconds)
    if auto:
        print("\n".join(corpus_robots.model_report(tallies, NAMES)))
    return 0


def report(dialect: str, robot: str, n_files: int, tally: Tally, seconds: float) -> None:
    print(f"== {NAMES[dialect]} (nominal {robot})")
    for line in tally.failures:
        print(f"  failed: {line}")
    n = max(n_files, 1)
    print(f"files: {n_files}; parsed: {tally.parsed} ({100 * tally.parsed / n:.1f} %); "
          f"byte-identical with the nominal model: {tally.identical} "
          f"({100 * tally.identical / max(tally.parsed, 1):.1f} % of parsed)")
    print("statuses: " + ", ".join(f"{k} {v}" for k, v in sorted(tally.statuses.items())))
    what = "robtarget literals" if dialect == "rapid" else "target literals"
    print(f"{what} in the parsed files (independent scan): {tally.literals}; "
          f"accounted for in the reports: {tally.accounted}")
    print(f"time: {seconds:.2f} s")


if __name__ == "__main__":
    sys.exit(main())
