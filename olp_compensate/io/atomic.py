"""Atomic output: write beside the target, then rename, so no file is ever half-written.

Temporary files are named ``.NAME.olp-PID-XXXXXXXX.tmp`` in the target's folder. They are
removed on every exit path that Python sees (errors, Ctrl-C, and SIGTERM once the command
line has turned it into an exception, see :mod:`olp_compensate.cli.common`). A SIGKILL
cannot be caught: the temporary file of a killed run stays, and the next write of the same
NAME removes every such file whose process (PID in the name) no longer runs. (O_TMPFILE
with linkat would avoid the name altogether, but only on Linux and some file systems, and
linkat cannot replace an existing file, so a named step would remain.)

The module also keeps the list of files written so far in this process
(:func:`written_files`), so that an interrupted command can say what it wrote.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable
from pathlib import Path

from ..errors import DataError, OlpError

TEMP_MARK = ".olp-"
_live_temps: set[str] = set()
_written: list[Path] = []


def temp_name(path: Path, pid: int | None = None) -> Path:
    """The temporary file for ``path``: ``.NAME.olp-PID-RANDOM.tmp`` in the same folder."""
    pid = os.getpid() if pid is None else pid
    return path.with_name(f".{path.name}{TEMP_MARK}{pid}-{os.urandom(4).hex()}.tmp")


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True   # another user's process (or unknown): keep its file
    return True


def remove_stale_temps(path: Path) -> list[Path]:
    """Remove the temporary files of ``path`` left by killed runs (their PID is gone)."""
    folder = path.parent if str(path.parent) else Path(".")
    pattern = re.compile(re.escape(f".{path.name}{TEMP_MARK}") + r"(\d+)-[0-9a-f]{8}\.tmp")
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        found = pattern.fullmatch(entry.name)
        if found and not _pid_alive(int(found.group(1))):
            try:
                os.unlink(entry.path)
                removed.append(Path(entry.path))
            except OSError:
                pass
    return removed


def remove_live_temps() -> None:
    """Remove this process's unfinished temporary files (called on interruption)."""
    for name in list(_live_temps):
        try:
            os.unlink(name)
        except OSError:
            pass
        _live_temps.discard(name)


def track_temp(tmp: Path) -> None:
    """Remove ``tmp`` on interruption until :func:`untrack_temp` (writers of their own)."""
    _live_temps.add(str(tmp))


def untrack_temp(tmp: Path, remove: bool = False, written: Path | None = None) -> None:
    """Stop tracking ``tmp``; ``remove`` it, or note that it became the file ``written``."""
    _live_temps.discard(str(tmp))
    if remove:
        Path(tmp).unlink(missing_ok=True)
    if written is not None:
        _written.append(Path(written))


def written_files() -> list[Path]:
    """Files this process wrote completely so far, in order."""
    return list(_written)


def forget_written() -> None:
    """Start a new list of written files (at the start of each command)."""
    _written.clear()


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename."""
    path = Path(path)
    remove_stale_temps(path)
    tmp = temp_name(path)
    _live_temps.add(str(tmp))
    renamed = False
    try:
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except OSError as exc:
            raise OlpError(f"{path}: cannot write ({exc.strerror})") from None
        try:
            # give the file the mode a plain open() would (umask applies), or the mode of
            # the file it replaces
            mode = path.stat().st_mode & 0o777 if path.exists() else 0o666 & ~_umask()
            os.chmod(tmp, mode)
            with os.fdopen(fd, "wb") as handle:
                handle.write(data)
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(tmp, path)
            renamed = True
        except OSError as exc:
            raise OlpError(f"{path}: cannot write ({exc.strerror})") from None
        _written.append(path)
    finally:
        _live_temps.discard(str(tmp))
        if not renamed:
            Path(tmp).unlink(missing_ok=True)


def write_files_atomic(files: list[tuple[Path, bytes | Iterable[bytes]]]) -> None:
    """Write several files that belong together (a program and its report): every
    temporary file first, then the renames back to back with SIGINT and SIGTERM held
    off, so that an interruption leaves all the new files or none of them (only a
    SIGKILL between two renames, microseconds apart, can split them). A file's data is
    bytes, or an iterable of bytes pieces written one after the other (a big report is
    never held whole)."""
    import signal

    temps = []
    try:
        for path, data in files:
            path = Path(path)
            remove_stale_temps(path)
            tmp = temp_name(path)
            _live_temps.add(str(tmp))
            temps.append((path, tmp))
            try:
                mode = path.stat().st_mode & 0o777 if path.exists() else 0o666 & ~_umask()
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
                with os.fdopen(fd, "wb") as handle:
                    if isinstance(data, (bytes, bytearray, memoryview)):
                        handle.write(data)
                    else:
                        for piece in data:
                            handle.write(piece)
                    handle.flush()
                    os.fsync(handle.fileno())
                os.chmod(tmp, mode)
            except OSError as exc:
                raise OlpError(f"{path}: cannot write ({exc.strerror})") from None
        held = {signal.SIGINT, signal.SIGTERM}
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, held)
        try:
            for path, tmp in temps:
                try:
                    os.replace(tmp, path)
                except OSError as exc:
                    raise OlpError(f"{path}: cannot write ({exc.strerror})") from None
                _live_temps.discard(str(tmp))
                _written.append(path)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    finally:
        for _, tmp in temps:
            if str(tmp) in _live_temps:
                _live_temps.discard(str(tmp))
                Path(tmp).unlink(missing_ok=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text_atomic(path: str | Path, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` atomically (see :func:`write_bytes_atomic`)."""
    write_bytes_atomic(path, text.encode(encoding))


def check_finite_json(value, what: str, where: str = "") -> None:
    """:class:`DataError` when a JSON document to write holds NaN or an infinity (JSON
    has no such numbers; ``where`` is the path into the document, for the message)."""
    if isinstance(value, float):
        if not math.isfinite(value):
            raise DataError(f"{what}: refusing to write {value} at {where or '(top level)'} "
                            f"(not a finite number)")
    elif isinstance(value, dict):
        for key, item in value.items():
            check_finite_json(item, what, f"{where}/{key}" if where else str(key))
    elif isinstance(value, (list, tuple)):
        for k, item in enumerate(value):
            check_finite_json(item, what, f"{where}/{k}" if where else str(k))
