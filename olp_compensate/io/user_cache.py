"""The user's cache folder for olp-compensate: what a run may keep for the next one.

``olp-compensate`` in ``$XDG_CACHE_HOME`` (``~/.cache``; ``%LOCALAPPDATA%`` on Windows).
Everything kept there is a speed-up only: a missing, unreadable or unwritable folder makes
the run do the work again, never fail.
"""

from __future__ import annotations

import os


def cache_folder() -> str | None:
    """The folder (created if needed), or None when there is none to use."""
    if os.name == "nt":
        base = os.environ.get("LOCALAPPDATA", "")
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"),
                                                                ".cache")
    if not os.path.isabs(base):
        return None
    folder = os.path.join(base, "olp-compensate")
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError:
        return None
    return folder
