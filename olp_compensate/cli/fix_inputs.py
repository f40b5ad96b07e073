"""What ``olp-fix PATH...`` works on: the program files under each path, grouped into the
units compensated together, and where each output goes.

- A file is one unit (a KRL ``.src`` or ``.dat`` brings its partner of the same stem); the
  RAPID modules named on the command line together form one task, and so do those of a
  folder's task: the modules under a ``TASKn`` folder of a backup (``PROGMOD``, ``SYSMOD``),
  or the modules side by side in one folder. A task's modules resolve each other's
  declarations (system modules first).
- A folder (a task folder, a controller backup) is searched recursively for program files
  of every dialect (:data:`~olp_compensate.compensation.files.EXTENSIONS`, any case);
  outputs of an earlier run (``*_compensated.*``), hidden files and KRL system data lists
  (``$config.dat``, ``$machine.dat``...: frame data is given with ``--config``) are skipped.
- Outputs: without ``-o`` each file is written beside its input as ``NAME_compensated.EXT``;
  with one file given, ``-o`` names its output (a KRL pair: ``OUT.src`` and ``OUT.dat``);
  with several files or a folder, ``-o`` names a folder whose tree mirrors the input's
  (relative to the folder given, or to the files' common parent).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import DataError

SUFFIX = "_compensated"


@dataclass(frozen=True)
class Unit:
    """Files compensated together, with the dialect, the report's names and the outputs."""

    dialect: str
    paths: tuple[Path, ...]
    names: tuple[str, ...]
    outputs: tuple[Path, ...]


def _is_program(path: Path, extensions: dict[str, str]) -> bool:
    name = path.name
    return (path.suffix.lower() in extensions and not name.startswith((".", "$"))
            and not path.stem.endswith(SUFFIX))


def _files_under(folder: Path, extensions: dict[str, str]) -> list[Path]:
    found = []
    for root, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        found += [Path(root) / f for f in sorted(files) if _is_program(Path(root) / f, extensions)]
    return found


def _task_root(path: Path, given_alone: bool) -> Path | None:
    """The folder whose RAPID modules form one task with ``path``: the ``TASKn`` folder of
    a backup, else the module's folder; None for modules named on the command line (they
    form one task together)."""
    if given_alone:
        return None
    for parent in path.parents:
        if re.fullmatch(r"TASK\d+", parent.name, re.IGNORECASE):
            return parent
    return path.parent


def _group(files: list[tuple[Path, str]], dialect: str | None, extensions,
           alone: set[Path]) -> list[tuple]:
    """(dialect, [(path, name), ...]) units: KRL .src/.dat of one stem together, a RAPID
    task's modules together (system modules first)."""
    units = []
    krl: dict[tuple[Path, str], list[tuple[Path, str]]] = {}
    tasks: dict[Path | None, list[tuple[Path, str]]] = {}
    for path, name in files:
        d = dialect or extensions[path.suffix.lower()]
        if d == "krl":
            krl.setdefault((path.parent, path.stem.lower()), []).append((path, name))
        elif d == "rapid":
            tasks.setdefault(_task_root(path, path in alone), []).append((path, name))
        else:
            units.append((d, [(path, name)]))
    for members in krl.values():
        members.sort(key=lambda m: m[0].suffix.lower() != ".src")     # .src first
        units.append(("krl", members))
    for members in tasks.values():
        members.sort(key=lambda m: (m[0].suffix.lower() != ".sys", m[1].lower()))
        units.append(("rapid", members))
    units.sort(key=lambda u: str(u[1][0][0]))
    return units


def plan_units(paths: list[str], dialect: str | None, output: str | None,
               extensions: dict[str, str]) -> list[Unit]:
    """The units of ``paths`` (see the module docstring)."""
    entries: list[tuple[Path, str, Path | None]] = []    # (file, report name, root)
    single_file = len(paths) == 1 and Path(paths[0]).is_file()
    for given in paths:
        path = Path(given)
        if path.is_dir():
            found = _files_under(path, extensions)
            if not found:
                raise DataError(f"{given}: no program files in this folder (extensions: "
                                f"{', '.join(sorted(extensions))})")
            entries += [(f, f.relative_to(path).as_posix(), path) for f in found]
        elif path.is_file() or not path.exists():
            if not path.exists():
                raise DataError(f"{given}: no such file or folder")
            if dialect is None and path.suffix.lower() not in extensions:
                raise DataError(f"{given}: unknown program extension "
                                f"{path.suffix or '(none)'!r}; expected one of "
                                f"{', '.join(sorted(extensions))}, or give --dialect")
            entries.append((path, given, None))
            partner = _krl_partner(path) if (dialect or extensions.get(
                path.suffix.lower())) == "krl" else None
            if partner is not None and all(partner != e[0] for e in entries):
                entries.append((partner, str(Path(given).with_name(partner.name)), None))
    files = [(p, name) for p, name, _ in entries]
    root_of = {p: root for p, _, root in entries}
    loose = [p for p, _, root in entries if root is None]
    common = Path(os.path.commonpath([p.resolve().parent for p in loose])) if loose else None
    units = []
    alone = {p for p, _, root in entries if root is None}
    for d, members in _group(files, dialect, extensions, alone):
        outs = tuple(_output(p, root_of[p], common, output, single_file, Path(paths[0]))
                     for p, _ in members)
        units.append(Unit(dialect=d, paths=tuple(p for p, _ in members),
                          names=tuple(n for _, n in members), outputs=outs))
    return units


def _krl_partner(path: Path) -> Path | None:
    """The ``.dat`` of a ``.src`` (or the reverse), same stem, any case, if it exists."""
    want = ".dat" if path.suffix.lower() == ".src" else ".src"
    for candidate in path.parent.glob(f"{path.stem}.*"):
        if candidate.suffix.lower() == want and candidate.stem == path.stem:
            return candidate
    return None


def _output(path: Path, root: Path | None, common: Path | None, output: str | None,
            single_file: bool, given: Path) -> Path:
    if output is None:
        return path.with_name(f"{path.stem}{SUFFIX}{path.suffix}")
    out = Path(output)
    if single_file:                      # -o names the given file's output; a KRL
        return out if path == given else out.with_name(out.stem + path.suffix)   # partner beside it
    relative = (path.relative_to(root) if root is not None
                else path.resolve().relative_to(common))
    return out / relative
