"""Reusable scratch arrays for the large arrays a fit fills again at every evaluation.

Fresh memory costs a page fault per 4 KiB; for the chain's derivatives and the
identification Jacobian (megabytes at a thousand poses) that takes about as long as the
arithmetic that fills them. Measured (interleaved A/B against ``np.empty``/``np.zeros``,
new processes, 9 pairs, OPENBLAS_NUM_THREADS=1, ``identify(folds=0)`` on
``olp-cal simulate --robot abb_irb2400 --poses N``; CPU time per call, min/median): 1,000
poses, repeated calls 9.8/10.3 ms against 11.0/11.7 ms, first call 14.1/14.6 ms against
14.4/15.4 ms; 10,000 poses, repeated calls 100/104 ms against 105/108 ms (first call
within the noise). A whole ``olp-cal identify`` is dominated by its imports: no difference.
"""

from __future__ import annotations

import sys

import numpy as np

try:  # threading.local is this class; importing threading for it costs 0.5-1 ms of a start
    from _thread import _local as _thread_local
except ImportError:
    from threading import local as _thread_local

_SPARES = _thread_local()
SPARE_BYTES = 16 << 20
"""Arrays up to this size are kept by :func:`reusable_array` for reuse."""


def _free_reference_count() -> int:
    """What ``sys.getrefcount`` reports, in :func:`reusable_array`'s loop, for an array that
    only its pool refers to (measured, not assumed: interpreters count loop variables and
    arguments differently)."""
    count = 0
    for spare in [np.empty(0)]:
        count = sys.getrefcount(spare)
    return count


_FREE = _free_reference_count()


def reusable_array(tag: str, shape: tuple[int, ...], slots: int = 1) -> np.ndarray:
    """An uninitialized float array of ``shape``: one of the last ``slots`` arrays handed
    out under ``tag`` in this thread, when it has that shape and nothing refers to it any
    more, not even a view (a view refers to it, so its reference count shows it), else a
    new one."""
    pool = getattr(_SPARES, tag, None)
    if pool is None:
        pool = []
        setattr(_SPARES, tag, pool)
    for spare in pool:
        if spare.shape == shape and sys.getrefcount(spare) == _FREE:
            return spare
    array = np.empty(shape)
    if array.nbytes <= SPARE_BYTES:
        pool.append(array)
        if len(pool) > slots:
            del pool[0]
    return array
