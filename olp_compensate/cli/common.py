"""What every command shares: error handling, logging, units in printed numbers."""

from __future__ import annotations

import logging
import os
import sys
from typing import Callable, NoReturn

from ..errors import OlpError

EXIT_OK, EXIT_BAD_INPUT = 0, 1


def run_guarded(action: Callable[[], int], verbosity: int, prog: str) -> int:
    """Run ``action``; turn :class:`OlpError` into one line on stderr and exit code 1.
    With ``-v`` the traceback is shown as well."""
    logging.basicConfig(level=logging.WARNING - 10 * min(verbosity, 2),
                        format=f"{prog}: %(levelname)s: %(message)s")
    try:
        return action()
    except OlpError as exc:
        if verbosity:
            logging.exception("details")
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:   # `olp-cal ... | head`: the reader left; no traceback
        silence_stdout()
        return EXIT_BAD_INPUT


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
    logging.shutdown()
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
