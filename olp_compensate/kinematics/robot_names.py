"""Which robot a program says it was written for.

A program may name its robot model (a bundled robot's name, ``olp-compensate``'s names as
``olp-cal robots`` lists them) in one of these forms, case-insensitive in the key:

- a comment line of any dialect: ``! olp-robot: abb_irb1200_7_70`` (RAPID, FANUC TP),
  ``; olp-robot: kuka_kr16_2`` (KRL, V+/AS), ``// olp-robot: ...`` (VAL3),
  ``# olp-robot: ...`` (URScript), ``-- olp-robot: ...``;
- a KRL header line ``&PARAM OLP_ROBOT = kuka_kr16_2`` (KRL's own ``&PARAM`` lines hold
  editor settings; the robot model is not among them, so this key is ours);
- the comment of a FANUC TP ``/ATTR`` section: ``COMMENT = "olp-robot: fanuc_m20ia";``.

The check that the named robot is the calibration's belongs to the caller (olp-fix).
"""

from __future__ import annotations

import re

from ..errors import DataError

_NAME = r"([A-Za-z0-9][A-Za-z0-9_.+\-]*)"
_PATTERNS = (
    re.compile(r"^[ \t]*(?:!|;|//|#|--)[ \t]*olp-robot[ \t]*:[ \t]*" + _NAME, re.I | re.M),
    re.compile(r"^[ \t]*&PARAM[ \t]+OLP[_-]ROBOT[ \t]*=[ \t]*" + _NAME, re.I | re.M),
    re.compile(r"^[ \t]*COMMENT[ \t]*=[ \t]*\"[ \t]*olp-robot[ \t]*:[ \t]*" + _NAME, re.I | re.M),
)


def robot_named_in(text: str) -> str | None:
    """The robot name a program's text declares, or None when it declares none.

    Raises :class:`DataError` when the text names two different robots (line numbers in the
    message, counted from 1).
    """
    named = robot_named_at(text)
    return None if named is None else named[0]


def robot_named_at(text: str) -> tuple[str, int] | None:
    """(robot name, 1-based line) the program's text declares, or None; as
    :func:`robot_named_in`."""
    found: dict[str, int] = {}
    for pattern in _PATTERNS:
        for match in pattern.finditer(text):
            found.setdefault(match.group(1), text.count("\n", 0, match.start(1)) + 1)
    if len(found) > 1:
        where = ", ".join(f"'{name}' (line {line})" for name, line in
                          sorted(found.items(), key=lambda item: item[1]))
        raise DataError(f"the program names more than one robot: {where}")
    return next(iter(found.items()), None)
