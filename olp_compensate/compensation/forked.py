"""Items made in a forked child process while this process goes on with other work.

A big module's chunks are compensated on two cores this way: the child inherits the
parsed module, the plan and the compensator by ``fork`` (nothing is sent to it), makes
its share chunk by chunk and writes each chunk's results, pickled, to an unlinked
temporary file as soon as they are made; the parent reads them back one at a time when
its own share is done. Neither process ever holds the child's results twice (a pipe
would block the child until the parent reads, and one message of everything would be
held pickled and unpickled at once). Linux only: see :func:`can_fork`.

The child ignores SIGINT (Ctrl-C in a terminal reaches the whole process group: the parent
handles it and ends the child), dies on SIGTERM without a traceback, and is killed by the
kernel if the parent dies first, even by SIGKILL. An exception in the
child is raised again in the parent by :meth:`ForkedItems.items`.
"""

from __future__ import annotations

import os
import pickle
import signal
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator

__all__ = ["ForkedItems", "can_fork"]

_DONE = "done"
_ITEM = "item"
_ERROR = "error"


def can_fork() -> bool:
    """Whether this process can fork a child that inherits its memory: Linux (macOS
    forks too, but its system libraries, Accelerate's BLAS among them, are not safe in a
    child forked without exec) and not a daemonic process (a multiprocessing.Pool worker
    may not have children; one has imported multiprocessing, which olp-fix does not: its
    import, 10-20 ms, is left to those who use it)."""
    pool = sys.modules.get("multiprocessing")
    return (sys.platform.startswith("linux") and hasattr(os, "fork")
            and not (pool is not None and pool.current_process().daemon))


class ForkedItems:
    """The items of ``function(*args)`` (an iterable) made in a forked child;
    :meth:`items` waits for the child and gives them in order. As a context manager, the
    child is ended on leaving the block if it still runs (an error or interruption in
    the parent)."""

    def __init__(self, function: Callable[..., Iterable], *args):
        self._file = tempfile.TemporaryFile()
        for stream in (sys.stdout, sys.stderr):   # else the child holds their buffers too
            if stream is not None:
                stream.flush()
        try:
            pid = os.fork()
        except BaseException:   # no process to be had (OSError: a limit, memory)
            self._file.close()
            raise
        if pid == 0:            # the child: never returns into the parent's code
            code = 1
            try:
                _child(self._file, function, args)
                code = 0
            finally:
                os._exit(code)
        self._process = _Process(pid)

    def items(self) -> Iterator:
        """The function's items in order, read one at a time once the child has ended
        (raises what the function raised, or RuntimeError when the child died before it
        was done)."""
        self._process.join()
        self._file.seek(0)
        while True:
            try:
                kind, value = pickle.load(self._file)
            except (EOFError, pickle.UnpicklingError):   # ended in the middle of an item
                raise RuntimeError(f"a worker process ended before its work was done "
                                   f"(exit code {self._process.exitcode})") from None
            if kind == _DONE:
                return
            if kind == _ERROR:
                raise value
            yield value

    def __enter__(self) -> ForkedItems:
        return self

    def __exit__(self, *exc) -> None:
        if self._process.is_alive():
            self._process.kill()
        self._process.join()
        self._file.close()


class _Process:
    """The forked child (what multiprocessing.Process says of one): ``pid``,
    ``exitcode`` (None while it runs; -N: ended by signal N)."""

    def __init__(self, pid: int):
        self.pid, self.exitcode = pid, None

    def join(self) -> None:
        if self.exitcode is None:
            self._ended(os.waitpid(self.pid, 0)[1])

    def is_alive(self) -> bool:
        if self.exitcode is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self._ended(status)
        return self.exitcode is None

    def kill(self) -> None:
        try:
            os.kill(self.pid, signal.SIGKILL)
        except ProcessLookupError:   # already reaped
            pass

    def _ended(self, status: int) -> None:
        self.exitcode = os.waitstatus_to_exitcode(status)


def _child(file, function, args) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _end_with_parent()
    try:
        for item in function(*args):
            file.write(pickle.dumps((_ITEM, item), pickle.HIGHEST_PROTOCOL))
        file.write(pickle.dumps((_DONE, None)))
    except BaseException as exc:   # noqa: BLE001 - every failure goes back to the parent
        try:
            answer = pickle.dumps((_ERROR, exc), pickle.HIGHEST_PROTOCOL)
        except Exception as failure:   # an exception that cannot be pickled
            answer = pickle.dumps((_ERROR, RuntimeError(f"a worker process failed: {exc!r} "
                                                        f"({failure})")))
        file.write(answer)
    file.flush()


def _end_with_parent() -> None:
    """Have the kernel kill this (child) process when its parent dies, even by SIGKILL
    (Linux ``prctl(PR_SET_PDEATHSIG)``): a killed olp-fix leaves nothing running."""
    import ctypes

    PR_SET_PDEATHSIG = 1
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):   # no prctl: the child ends when its work does
        return
    if os.getppid() == 1:               # the parent died before prctl took effect
        os._exit(1)
