"""``olp-fix``: compensate a robot program on a calibrated model (see issue: programs)."""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    print("olp-fix: program compensation is not available in this version yet", file=sys.stderr)
    return 1
