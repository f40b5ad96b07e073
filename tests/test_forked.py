"""ForkedItems (compensation/forked.py): items made in a forked child, read back in
order in the parent, the child's error raised in the parent, and no child left behind."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from olp_compensate.compensation.forked import ForkedItems, can_fork
from olp_compensate.errors import DataError

pytestmark = pytest.mark.skipif(not can_fork(), reason="this platform cannot fork")

_INHERITED = {"rows": np.arange(10.0)}


def _shares(rows: slice):
    """What the parent had before the fork, read in the child: each row, then the pid."""
    yield from _INHERITED["rows"][rows].tolist()
    yield np.full(100_000, 7.0)    # bigger than a pipe holds
    yield os.getpid()


def _fail_after_one():
    yield 1
    raise DataError("big.mod:7:3: the child's message")


def _vanish():
    yield 1
    os._exit(3)


def _sleep():
    time.sleep(60)
    yield 1


def test_the_child_reads_the_parents_memory_and_its_items_come_back_in_order():
    with ForkedItems(_shares, slice(5, None)) as child:
        mine = _INHERITED["rows"][:5].sum()
        *rows, big, pid = child.items()
    assert mine == 10.0 and rows == [5.0, 6.0, 7.0, 8.0, 9.0]
    assert big.shape == (100_000,) and np.all(big == 7.0) and pid != os.getpid()


def test_the_childs_error_is_raised_in_the_parent_with_its_type_and_message():
    got = []
    with pytest.raises(DataError, match="big.mod:7:3: the child's message"):
        with ForkedItems(_fail_after_one) as child:
            got += child.items()
    assert got == [1]


def test_a_child_that_dies_before_it_is_done_is_an_error_not_a_hang():
    with pytest.raises(RuntimeError, match="exit code 3"):
        with ForkedItems(_vanish) as child:
            list(child.items())


def test_leaving_the_block_early_ends_the_child():
    started = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        with ForkedItems(_sleep) as child:
            raise KeyboardInterrupt   # the parent interrupted while the child works
    assert not child._process.is_alive()
    assert time.perf_counter() - started < 30


def test_a_child_does_not_outlive_a_parent_killed_by_sigkill(tmp_path):
    """The parent killed with SIGKILL (no Python cleanup) takes its forked child along."""
    import signal
    import subprocess
    import sys

    script = tmp_path / "parent.py"
    script.write_text(
        "import os, signal, sys, time\n"
        "from olp_compensate.compensation.forked import ForkedItems\n"
        "def work():\n"
        "    time.sleep(60)\n"
        "    yield 1\n"
        "child = ForkedItems(work)\n"
        "print(child._process.pid, flush=True)\n"
        "time.sleep(0.5)\n"
        "os.kill(os.getpid(), signal.SIGKILL)\n")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=30)
    assert done.returncode == -signal.SIGKILL
    pid = int(done.stdout.split()[0])
    for _ in range(100):     # the kernel delivers the child's SIGKILL at once; allow 5 s
        if not _running(pid):
            break
        time.sleep(0.05)
    assert not _running(pid)


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False
