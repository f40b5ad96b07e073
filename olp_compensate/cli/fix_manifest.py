"""``olp-fix --manifest plant.csv [--changed-only]``: every robot of a plant in one run.

The manifest is a CSV with the header ``robot, calibration, controller, input, output``
(spaces after commas allowed; lines starting with ``#`` are comments): one row per program
(a file, a task folder or a controller backup, as olp-fix takes them), compensated with its
own calibration and written to its output. Relative paths are taken from the manifest's
folder. ``robot`` names the robot in the report (any text); ``controller`` may be empty.

The report (``--report``, default ``<manifest>_report.csv`` beside it) has olp-fix's
columns for every target of every program, preceded by ``robot``, ``input``,
``input_sha256``, ``calibration``, ``calibration_sha256`` and ``olp_compensate_version``.
The state of each program (those hashes, the version, the exit code) is kept in
``--state`` (default ``<manifest>.state.json``); with ``--changed-only`` a program whose
input, calibration and olp-compensate version are unchanged since a run that completed it
(and whose output is still there) is skipped, and the summary says how many were.

Exit codes: 0 every target of every program compensated; 2 some targets were not (see the
report); 1 a row or program could not be processed (the others still are).
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import io
import json
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from .. import __version__
from ..errors import DataError, OlpError
from .common import run_guarded

COLUMNS = ("robot", "calibration", "controller", "input", "output")
PREFIX = ("robot", "input", "input_sha256", "calibration", "calibration_sha256",
          "olp_compensate_version")
STATE_VERSION = 1


@dataclass(frozen=True)
class Entry:
    """One manifest row: paths resolved from the manifest's folder; ``line`` 1-based."""

    line: int
    robot: str
    calibration: Path
    controller: Path | None
    input: Path
    output: Path

    @property
    def key(self) -> str:
        return f"{self.robot}\0{self.input}\0{self.output}"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="olp-fix --manifest", description=__doc__.splitlines()[0])
    p.add_argument("--manifest", required=True, metavar="PLANT.csv",
                   help="CSV: robot, calibration, controller, input, output")
    p.add_argument("--changed-only", action="store_true",
                   help="skip programs whose input, calibration and olp-compensate version "
                        "are unchanged since the last run")
    p.add_argument("--report", help="the plant's report CSV (default: "
                                    "<manifest>_report.csv beside the manifest)")
    p.add_argument("--state", help="the run's bookkeeping (default: <manifest>.state.json)")
    p.add_argument("-q", "--quiet", action="store_true", help="no summary on the terminal")
    p.add_argument("--version", action="version", version=f"olp-fix {__version__}")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="more logging; -v also shows tracebacks")
    return p


def read_manifest(path: Path) -> list[Entry]:
    """The rows of manifest ``path``; DataError with file:line for a bad one."""
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read the manifest ({exc})") from None
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), 1)
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise DataError(f"{path}: empty manifest; expected the header "
                        f"{', '.join(COLUMNS)}")
    rows = list(csv.reader(io.StringIO("\n".join(ln for _, ln in lines)),
                           skipinitialspace=True))
    header = [h.strip().lower() for h in rows[0]]
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise DataError(f"{path}:{lines[0][0]}: manifest header lacks "
                        f"{', '.join(missing)} (expected {', '.join(COLUMNS)})")
    folder = path.parent
    entries = []
    for (number, _), row in zip(lines[1:], rows[1:]):
        if len(row) != len(header):
            raise DataError(f"{path}:{number}: {len(row)} fields, the header has "
                            f"{len(header)}")
        cell = {h: v.strip() for h, v in zip(header, row)}
        for column in ("robot", "calibration", "input", "output"):
            if not cell[column]:
                raise DataError(f"{path}:{number}: {column}: empty")
        entries.append(Entry(line=number, robot=cell["robot"],
                             calibration=folder / cell["calibration"],
                             controller=folder / cell["controller"] if cell["controller"]
                             else None,
                             input=folder / cell["input"], output=folder / cell["output"]))
    return entries


def sha256_of(path: Path) -> str:
    """SHA-256 of a file's bytes; of a folder, of each file's relative path and SHA-256
    (sorted), so a backup folder has one hash."""
    if path.is_dir():
        digest = hashlib.sha256()
        for file in sorted(p for p in path.rglob("*") if p.is_file()):
            digest.update(f"{file.relative_to(path).as_posix()}\0{sha256_of(file)}\n".encode())
        return digest.hexdigest()
    try:
        with open(path, "rb") as stream:
            return hashlib.file_digest(stream, "sha256").hexdigest()
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from None


def _controller_option() -> bool:
    """Whether this olp-fix has a ``--controller`` option to pass the column on to."""
    from .fix_run import build_parser as fix_parser

    return any("--controller" in a.option_strings for a in fix_parser()._actions)


def _run_entry(entry: Entry, manifest: Path, folder: Path) -> tuple[int, list[dict]]:
    """Compensate one row's program; (exit code, its report rows as dicts)."""
    from .fix_run import build_parser as fix_parser, run as fix_run

    argv = [str(entry.input), "--model", str(entry.calibration), "-o", str(entry.output),
            "--report", str(folder / "report.csv"), "-q"]
    if entry.controller is not None:
        if not _controller_option():
            raise DataError(f"{manifest}:{entry.line}: controller: {entry.controller}: this "
                            f"olp-fix has no controller models (--controller); leave the "
                            f"column empty")
        argv += ["--controller", str(entry.controller)]
    code = fix_run(fix_parser().parse_args(argv))
    with open(folder / "report.csv", encoding="utf-8", newline="") as stream:
        return code, list(csv.DictReader(stream))


def run(args) -> int:
    from ..io.atomic import write_text_atomic

    manifest = Path(args.manifest)
    entries = read_manifest(manifest)
    report = Path(args.report) if args.report else manifest.with_name(
        f"{manifest.stem}_report.csv")
    state_path = Path(args.state) if args.state else manifest.with_name(
        f"{manifest.name}.state.json")
    state = _read_state(state_path)
    rows, worst, skipped, failed = [], 0, 0, 0
    for entry in entries:
        prefix = {"robot": entry.robot, "input": str(entry.input),
                  "olp_compensate_version": __version__}
        try:
            prefix["input_sha256"] = sha256_of(entry.input)
            prefix["calibration"] = str(entry.calibration)
            prefix["calibration_sha256"] = sha256_of(entry.calibration)
            before = state.get(entry.key)
            now = {"input_sha256": prefix["input_sha256"], "version": __version__,
                   "calibration_sha256": prefix["calibration_sha256"]}
            if (args.changed_only and before is not None and before.get("code") in (0, 2)
                    and all(before.get(k) == v for k, v in now.items())
                    and entry.output.exists()):
                skipped += 1
                worst = max(worst, before["code"])
                rows.append({**prefix, "status": "unchanged",
                             "note": "skipped (--changed-only): input, calibration and "
                                     "olp-compensate version as in the last run"})
                continue
            with tempfile.TemporaryDirectory(prefix="olp-manifest-") as tmp:
                code, program_rows = _run_entry(entry, manifest, Path(tmp))
            state[entry.key] = {**now, "code": code, "output": str(entry.output)}
            worst = max(worst, code)
            rows += [{**prefix, **r} for r in program_rows]
        except OlpError as exc:
            failed += 1
            state.pop(entry.key, None)
            rows.append({**prefix, "status": "error", "note": str(exc)})
            if not args.quiet:
                print(f"olp-fix: {manifest}:{entry.line}: {exc}", file=sys.stderr)
    write_text_atomic(report, _csv(rows))
    write_text_atomic(state_path, json.dumps({"version": STATE_VERSION, "programs": state},
                                             indent=1, sort_keys=True) + "\n")
    if not args.quiet:
        done = len(entries) - skipped - failed
        print(f"olp-fix: {manifest}: {len(entries)} programs: {done} compensated, {skipped} "
              f"skipped (input, calibration and olp-compensate version unchanged), "
              f"{failed} failed; report {report}")
    return 1 if failed else (2 if worst == 2 else 1 if worst == 1 else 0)


def _read_state(path: Path) -> dict:
    """The programs of a previous run's state (empty when there is none or it is stale)."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(doc, dict) or doc.get("version") != STATE_VERSION:
        return {}
    programs = doc.get("programs")
    return programs if isinstance(programs, dict) else {}


def _csv(rows: list[dict]) -> str:
    columns = [*PREFIX, "target", "file", "line", "column", "status"]
    for r in rows:
        columns += [k for k in r if k not in columns]
    if "note" in columns:                      # olp-fix's last column stays last
        columns.remove("note")
        columns.append("note")
    buf = io.StringIO()
    writer = csv.DictWriter(buf, columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    """``olp-fix --manifest ...`` as a function; returns the exit code."""
    args = build_parser().parse_args(argv)
    return run_guarded(lambda: run(args), args.verbose, "olp-fix")
