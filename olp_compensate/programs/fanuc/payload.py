"""The loads a FANUC TP program states: ``PAYLOAD[n]`` picks a payload schedule of the
controller's system variables, so it is stated as set at run time."""

from __future__ import annotations

import re

from ..payloads import ProgramLoads, line_of

_FANUC_PAYLOAD = re.compile(r"^\s*\d+:\s*(PAYLOAD\s*\[[^\]]*\])", re.M | re.I)


def stated_loads(texts: dict[str, str], config=None) -> ProgramLoads:
    """Each ``PAYLOAD[n]`` as a load set at run time."""
    runtime = [f"{name}:{line_of(text, m.start())}: {m.group(1)} (a payload schedule of the "
               f"controller's system variables)"
               for name, text in texts.items() for m in _FANUC_PAYLOAD.finditer(text)]
    return ProgramLoads((), tuple(runtime))


