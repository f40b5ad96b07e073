"""What ``olp-fix PATH...`` works on: the program files under each path, grouped into the
units compensated together, and where each output goes.

- A file is one unit (a KRL ``.src`` or ``.dat`` brings its partner of the same stem); the
  RAPID modules named on the command line together form one task, and so do those of a
  folder's task: the modules under a ``TASKn`` folder of a backup (``PROGMOD``, ``SYSMOD``),
  or the modules side by side in one folder. A task's modules resolve each other's
  declarations (system modules first).
- A folder (a task folder, a controller backup) is searched recursively for program files
  of every dialect (:func:`~olp_compensate.programs.languages.extensions`, any case);
  outputs of an earlier run (``*_compensated.*``), hidden files and KRL system data lists
  (``$config.dat``, ``$machine.dat``...: frame data is given with ``--config``) are skipped.
- Only regular files are read (through links): a FIFO, a device (a link to ``/dev/zero``), a
  socket or a broken link found in a folder is skipped with a warning; named as a program
  it is refused (a pipe such as ``<(cat x.mod)`` is not read: save the program to a file).
- Outputs: without ``-o`` a file given is written beside its input as
  ``NAME_compensated.EXT``, and a folder ``F`` goes to the sibling folder
  ``F_compensated/`` that mirrors it (never into the folder: a RAPID task folder would hold
  two modules of one name); with one file given, ``-o`` names its output (a KRL pair:
  ``OUT.src`` and ``OUT.dat``); with several files or a folder, ``-o`` names a folder whose
  tree mirrors the input's (relative to the folder given, or to the files' common parent),
  outside every folder given. Folders named ``*_compensated`` are outputs of an earlier run
  and are not searched.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass
from pathlib import Path

from ..errors import DataError
from ..programs.languages import language_named

SUFFIX = "_compensated"


@dataclass(frozen=True)
class Unit:
    """Files compensated together, with the dialect, the report's names and the outputs."""

    dialect: str
    paths: tuple[Path, ...]
    names: tuple[str, ...]
    outputs: tuple[Path, ...]
    mirrored: bool = False
    """Whether the outputs go into a folder mirroring the input tree (made as needed)."""


def _is_program(path: Path, extensions: dict[str, str]) -> bool:
    name = path.name
    return (path.suffix.lower() in extensions and not name.startswith((".", "$"))
            and not path.stem.endswith(SUFFIX))


def not_regular(path: Path) -> str | None:
    """None for a regular file (links followed), else what ``path`` is, in words."""
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        return f"cannot be read ({exc.strerror or exc})"
    if stat.S_ISREG(mode):
        return None
    for test, what in ((stat.S_ISFIFO, "a pipe (FIFO)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISDIR, "a folder")):
        if test(mode):
            return what
    return "not a file"


def _files_under(folder: Path, extensions: dict[str, str], skipped: list[str]) -> list[Path]:
    """The program files under ``folder``, in sorted order; what has a program's name but
    is no regular file goes to ``skipped`` (one line each)."""
    found = []
    for root, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and not d.endswith(SUFFIX))
        for f in sorted(files):
            path = Path(root) / f
            if not _is_program(path, extensions):
                continue
            kind = not_regular(path)
            if kind is None:
                found.append(path)
            else:
                skipped.append(f"{path}: skipped: {kind}, not a regular file")
    return found


def _group(files: list[tuple[Path, str]], dialect: str | None, extensions,
           alone: set[Path]) -> list[tuple]:
    """(dialect, [(path, name), ...]) units: files of one language with the same
    ``unit_key`` together (KRL .src/.dat of one stem, a RAPID task's modules), in the
    language's ``member_order``; every other file alone."""
    units, together = [], {}
    for path, name in files:
        language = language_named(dialect or extensions[path.suffix.lower()])
        if language.unit_key is None:
            units.append((language.name, [(path, name)]))
        else:
            key = (language.name, language.unit_key(path, path in alone))
            together.setdefault(key, []).append((path, name))
    for (name, _), members in together.items():
        order = language_named(name).member_order
        if order is not None:
            members.sort(key=lambda m: order(*m))
        units.append((name, members))
    units.sort(key=lambda u: str(u[1][0][0]))
    return units


def plan_units(paths: list[str], dialect: str | None, output: str | None,
               extensions: dict[str, str], skipped: list[str] | None = None) -> list[Unit]:
    """The units of ``paths`` (see the module docstring). ``skipped`` receives one line per
    file of a folder that is not read (not a regular file)."""
    skipped = [] if skipped is None else skipped
    entries: list[tuple[Path, str, Path | None]] = []    # (file, report name, root)
    single_file = len(paths) == 1 and _given_file(paths[0])
    _check_output(paths, output, single_file)
    for given in paths:
        path = Path(given)
        if path.is_dir():
            found = _files_under(path, extensions, skipped)
            if not found:
                raise DataError(f"{given}: no program files in this folder (extensions: "
                                f"{', '.join(sorted(extensions))})")
            entries += [(f, f.relative_to(path).as_posix(), path) for f in found]
            continue
        _check_file(given, dialect, extensions)
        entries.append((path, given, None))
        find_partner = language_named(dialect or extensions[path.suffix.lower()]).partner
        partner = None if find_partner is None else find_partner(path)
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
        mirrored = (output is not None and not single_file) or any(
            root_of[p] is not None for p, _ in members)
        units.append(Unit(dialect=d, paths=tuple(p for p, _ in members),
                          names=tuple(n for _, n in members), outputs=outs,
                          mirrored=mirrored))
    return units


def _given_file(given: str) -> bool:
    """Whether a path given names an existing file (of any kind) rather than a folder."""
    return bool(given) and os.path.exists(given) and not os.path.isdir(given)


def _check_file(given: str, dialect: str | None, extensions: dict[str, str]) -> None:
    """:class:`DataError` unless ``given`` is a regular file olp-fix can read as a program."""
    path = Path(given)
    if not os.path.lexists(path):
        raise DataError(f"{given}: no such file or folder")
    kind = not_regular(path)
    if kind is not None:
        raise DataError(f"{given}: {kind}, not a regular file; olp-fix reads program files "
                        f"(save a piped program to a file first)")
    if dialect is None and path.suffix.lower() not in extensions:
        raise DataError(f"{given}: unknown program extension "
                        f"{path.suffix or '(none)'!r}; expected one of "
                        f"{', '.join(sorted(extensions))}, or give --dialect")


def _check_output(paths: list[str], output: str | None, single_file: bool) -> None:
    """:class:`DataError` for an empty path, or an ``-o`` that cannot receive the outputs:
    a folder for one program's file, a file for a folder's tree, a folder inside (or
    equal to) a folder given."""
    for given in paths:
        if not given.strip():
            raise DataError(f"{given!r}: an empty program path; name a program file or a "
                            f"folder ('.' for the current one)")
    if output is None:
        for given in paths:
            if os.path.isdir(given) and Path(given).resolve().parent == Path(given).resolve():
                raise DataError(f"{given}: a folder without a parent cannot be mirrored "
                                f"beside itself; give -o OUTDIR")
            mirror = mirror_folder(Path(given)) if os.path.isdir(given) else None
            if mirror is not None and os.path.lexists(mirror) and not mirror.is_dir():
                raise DataError(f"{mirror}: the output folder of {given} is an existing "
                                f"file; remove it or give -o OUTDIR")
        return
    if not output.strip():
        raise DataError(f"-o {output!r}: an empty output path")
    if single_file:
        if os.path.isdir(output):
            raise DataError(f"{output}: -o names a folder; with one program -o names the "
                            f"output file (e.g. {Path(output) / Path(paths[0]).name})")
        return
    if os.path.lexists(output) and not os.path.isdir(output):
        raise DataError(f"{output}: -o names an existing file; with a folder or several "
                        f"programs -o names a folder, which mirrors the input tree")
    out = Path(output).resolve()
    for given in paths:
        if os.path.isdir(given):
            folder = Path(given).resolve()
            if out == folder or folder in out.parents:
                where = "the input folder" if out == folder else "inside the input folder"
                raise DataError(f"{output}: -o is {where} {given}: the "
                                f"outputs would be mixed with the inputs (and read as inputs "
                                f"by the next run); choose a folder outside it")


def mirror_folder(folder: Path) -> Path:
    """Where a folder compensated without ``-o`` goes: ``F`` -> ``F_compensated`` beside it."""
    resolved = folder.resolve()
    return resolved.with_name(resolved.name + SUFFIX)


def _output(path: Path, root: Path | None, common: Path | None, output: str | None,
            single_file: bool, given: Path) -> Path:
    if output is None:
        if root is not None:             # a folder: its sibling mirror
            return mirror_folder(root) / path.relative_to(root)
        return path.with_name(f"{path.stem}{SUFFIX}{path.suffix}")
    out = Path(output)
    if single_file:                      # -o names the given file's output; a KRL
        return out if path == given else out.with_name(out.stem + path.suffix)   # partner beside it
    relative = (path.relative_to(root) if root is not None
                else path.resolve().relative_to(common))
    return out / relative
