"""What every command shares: error handling, signals, threads, the rule that no output
overwrites an input, logging, units in printed numbers.

Kept free of numpy and the package's heavy modules: ``olp-cal --help`` and
``olp-fix --version`` import this and no more.
"""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import sys
import warnings
from pathlib import Path
from typing import Callable, NoReturn

from ..errors import DataError, OlpError
from ..io.atomic import forget_written, remove_live_temps, written_files

EXIT_OK, EXIT_BAD_INPUT = 0, 1
EXIT_INTERRUPTED = 130
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
THREADS_HELP = ("BLAS and OpenMP run on one thread (measured fastest for these small "
                "matrices: identify on 1,000 poses 7x, diagnose 2x faster than on every "
                "core); set OMP_NUM_THREADS to choose otherwise")


class Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an exception so that temporary files are removed."""


def _raise_terminated(signum, frame) -> None:
    raise Terminated()


def limit_threads() -> contextlib.AbstractContextManager:
    """One BLAS/OpenMP thread for the run, unless the user set a thread variable.

    Before numpy is imported the environment does it for free; when numpy is already
    loaded (commands called in-process) threadpoolctl limits the loaded libraries and
    restores them when the context ends."""
    if any(v in os.environ for v in THREAD_VARIABLES):
        return contextlib.nullcontext()
    if "numpy" not in sys.modules:
        for variable in THREAD_VARIABLES:
            os.environ[variable] = "1"
        return contextlib.nullcontext()
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return contextlib.nullcontext()
    return threadpool_limits(1)


@contextlib.contextmanager
def _signals_as_exceptions():
    """SIGTERM raises :class:`Terminated` (and SIGINT KeyboardInterrupt) for the run;
    the previous handlers come back after it. Only in the main thread (elsewhere
    ``signal.signal`` refuses, and the handlers stay as they are)."""
    try:
        previous = signal.signal(signal.SIGTERM, _raise_terminated)
    except ValueError:   # not the main thread
        previous = ValueError
    if previous is ValueError:   # (the run's own errors outside the handler above)
        yield
        return
    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)


class _StdoutGuard:
    """``sys.stdout`` for a run whose reader may leave early (``olp-cal ... | head -2``):
    a write or flush that finds the pipe closed sends the rest to the null device and the
    command goes on (its files are written, its exit code is its own)."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            silence_stdout()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            silence_stdout()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


@contextlib.contextmanager
def _stdout_may_close():
    """Route ``print`` through :class:`_StdoutGuard` for the run."""
    previous = sys.stdout
    sys.stdout = _StdoutGuard(previous)
    try:
        yield
    finally:
        sys.stdout = previous


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings from inside numpy or scipy: one log line, no source line."""
    _logging().getLogger("olp_compensate").info("%s: %s", category.__name__, message)


_LOG_FORMAT: list = []   # (level, format) of the run whose logging is not set up yet


def _logging():
    """The ``logging`` module, set up as :func:`run_guarded` asked (on first use: importing
    and setting it up costs a command about 5 ms, and most runs log nothing)."""
    import logging

    if _LOG_FORMAT:
        level, format = _LOG_FORMAT.pop()
        logging.basicConfig(level=level, format=format)
    return logging


def _set_up_logging(prog: str, verbosity: int) -> None:
    """Log records as ``prog: LEVEL: message`` at WARNING (INFO with -v, DEBUG with -vv):
    at once when asked for more or when ``logging`` is loaded already (another library may
    log), else on first use (:func:`_logging`; at WARNING only a library that loads
    ``logging`` during the run and warns through it would find it not set up)."""
    _LOG_FORMAT[:] = [(30 - 10 * min(verbosity, 2), f"{prog}: %(levelname)s: %(message)s")]
    if verbosity or "logging" in sys.modules:
        _logging()


def run_guarded(action: Callable[[], int], verbosity: int, prog: str) -> int:
    """Run ``action``; turn :class:`OlpError` into one line on stderr and exit code 1,
    Ctrl-C and SIGTERM into exit code 130 with the files written so far named, after
    removing unfinished temporary files. With ``-v`` the traceback is shown as well."""
    _set_up_logging(prog, verbosity)
    forget_written()
    try:
        with _signals_as_exceptions(), limit_threads(), warnings.catch_warnings(), \
                _stdout_may_close():
            warnings.showwarning = _one_line_warning
            return action()
    except OlpError as exc:
        remove_live_temps()
        if verbosity:
            _logging().exception("details")
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt as exc:
        remove_live_temps()
        how = "terminated" if isinstance(exc, Terminated) else "interrupted"
        written = written_files()
        done = (f"; written before: {', '.join(map(str, written))}" if written
                else "; no file written")
        print(f"{prog}: {how}{done}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:   # `olp-cal ... | head`: the reader left; no traceback
        remove_live_temps()
        silence_stdout()
        return EXIT_BAD_INPUT
    except Exception as exc:
        remove_live_temps()
        if type(exc).__name__ != "LinAlgError" or verbosity:
            raise
        # a numerical failure on data no check caught: one line, not a traceback
        print(f"{prog}: error: the computation failed on these data ({exc}); they may be "
              f"degenerate (identical poses, equal or huge numbers); -v shows where",
              file=sys.stderr)
        return EXIT_BAD_INPUT


def _file_key(path: str | Path) -> tuple:
    """What names one file: its device and inode where it exists (through links, ``..`` and
    case-insensitive file systems), else its resolved path."""
    try:
        st = os.stat(path)
        return ("file", st.st_dev, st.st_ino)
    except (OSError, ValueError):
        return ("path", os.path.realpath(path))


def refuse_clashes(inputs: list[tuple[str, str | Path | None]],
                   outputs: list[tuple[str, str | Path | None]]) -> None:
    """:class:`DataError` when an output is one of the inputs or another output.

    ``inputs`` and ``outputs``: (what the user calls it, e.g. ``'--model'``, path or None).
    An input that names no existing file (a bundled robot's name) is skipped. Called before
    anything is read or written; each path is resolved once, so a backup of thousands of
    programs is checked in time linear in their number."""
    sources: dict[tuple, tuple[str, str | Path]] = {}
    for label, path in inputs:
        if path is not None and os.path.isfile(path):
            sources.setdefault(_file_key(path), (label, path))
    written: dict[tuple, str] = {}
    for label, out in outputs:
        if out is None:
            continue
        key = _file_key(out)
        if key in sources:
            source_label, source = sources[key]
            raise DataError(f"{out}: {label} is an input ({source_label} {source}); "
                            f"refusing to overwrite it, choose another output file")
        if key in written:
            raise DataError(f"{out}: named for both {written[key]} and {label}; give each "
                            f"output its own file")
        written[key] = label


def robot_input(robot: str | None) -> tuple[str, str | None]:
    """The ``--robot`` argument as an input (a URDF path; a bundled name is no file)."""
    return ("--robot", robot)


def silence_stdout() -> None:
    """Send what is left for stdout to the null device, after its reader went away (so
    that the flush at exit does not fail again)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):   # not a real file (captured output)
        pass


def exit_now(code: int) -> NoReturn:
    """End the process with ``code`` once the standard streams are flushed, without the
    interpreter's teardown: a big run's millions of small objects are not freed one by one
    (0.25 s after a 100,000-target olp-fix). Only for a command's entry point: every file
    it writes must be closed already."""
    if "logging" in sys.modules:
        sys.modules["logging"].shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except BrokenPipeError:
            silence_stdout()
        except (OSError, ValueError):
            pass
    os._exit(code)


def mm(value_m: float | None, digits: int = 3) -> str:
    """A length in metres printed in mm with its unit."""
    return "n/a" if value_m is None else f"{value_m * 1e3:.{digits}f} mm"


@contextlib.contextmanager
def no_gc():
    """Pause the cyclic garbage collector for a command's run: a parse allocates millions of
    small acyclic objects, and the collector's repeated full scans would make it several
    times slower. The library never touches the collector: a calling program decides."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()
