"""Logging of the commands (cli/common.py): set up on first use, with the same output as
when it was set up before every run. Each case runs in a new process, where ``logging``
is not loaded yet (pytest's own process has it loaded, which takes the eager path)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import sys, warnings
    from olp_compensate.cli.common import run_guarded
    from olp_compensate.errors import DataError

    kind, verbosity = sys.argv[1], int(sys.argv[2])

    def action():
        if kind == "warn":
            warnings.warn("the sky fell", RuntimeWarning)
        elif kind == "error":
            raise DataError("bad.csv: no rows")
        print("logging loaded" if "logging" in sys.modules else "logging not loaded")
        return 0

    sys.exit(run_guarded(action, verbosity, "olp-x"))
""")


def run(kind: str, verbosity: int) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", SCRIPT, kind, str(verbosity)],
                          capture_output=True, text=True, timeout=60)


def test_a_quiet_run_that_logs_nothing_does_not_load_logging():
    done = run("plain", 0)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "logging not loaded"
    assert done.stderr == ""


@pytest.mark.parametrize("verbosity, shown", [(0, False), (1, True), (2, True)])
def test_a_warning_is_one_log_line_from_minus_v_on(verbosity, shown):
    done = run("warn", verbosity)
    assert done.returncode == 0, done.stderr
    line = "olp-x: INFO: RuntimeWarning: the sky fell\n"
    assert done.stderr == (line if shown else "")


def test_an_error_is_one_line_and_minus_v_adds_the_traceback_as_a_log_record():
    quiet, verbose = run("error", 0), run("error", 1)
    assert (quiet.returncode, verbose.returncode) == (1, 1)
    assert quiet.stderr == "olp-x: error: bad.csv: no rows\n"
    lines = verbose.stderr.splitlines()
    assert lines[0] == "olp-x: ERROR: details"
    assert "Traceback (most recent call last):" in lines
    assert lines[-1] == "olp-x: error: bad.csv: no rows"


def test_a_run_in_another_thread_leaves_the_signal_handlers_alone():
    import signal
    import threading

    from olp_compensate.cli.common import run_guarded
    from olp_compensate.errors import DataError

    before = signal.getsignal(signal.SIGTERM)
    seen: dict = {}

    def action():
        seen["handler"] = signal.getsignal(signal.SIGTERM)
        raise DataError("bad.csv: no rows")

    thread = threading.Thread(target=lambda: seen.setdefault(
        "code", run_guarded(action, 0, "olp-x")))
    thread.start()
    thread.join(60)
    assert seen["code"] == 1
    assert seen["handler"] is before and signal.getsignal(signal.SIGTERM) is before
