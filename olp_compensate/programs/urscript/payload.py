"""The loads a URScript states: ``set_payload(m, [cx, cy, cz])`` (kg, m in the flange frame)
and ``set_target_payload``; one whose numbers are not literal is set at run time."""

from __future__ import annotations

import re

from ..payloads import NUMBER, ProgramLoads, StatedLoad, distinct, line_of

_UR_PAYLOAD = re.compile(r"^\s*(set_payload|set_target_payload)\s*\(([^\n]*)\)", re.M)
_UR_ARGS = re.compile(rf"^\s*({NUMBER})\s*(?:,\s*\[\s*({NUMBER})\s*,\s*({NUMBER})\s*,\s*"
                      rf"({NUMBER})\s*\])?")


def stated_loads(texts: dict[str, str], config=None) -> ProgramLoads:
    """The loads of ``set_payload``/``set_target_payload`` calls (see :mod:`..payloads`)."""
    found, runtime = [], []
    for name, text in texts.items():
        for match in _UR_PAYLOAD.finditer(text):
            where = f"{name}:{line_of(text, match.start())}"
            args = _UR_ARGS.match(match.group(2))
            if args is None:
                runtime.append(f"{where}: {match.group(0).strip()}")
                continue
            cog = tuple(float(v) * 1e3 if v is not None else 0.0 for v in args.groups()[1:])
            found.append(StatedLoad(float(args.group(1)), cog, f"{match.group(1)} at {where}"))
    return ProgramLoads(distinct(found), tuple(runtime))


