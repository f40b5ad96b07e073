"""The loads a RAPID task states: the load part of each robot-held ``tooldata`` its motions
use; ``GripLoad`` changes the load at run time."""

from __future__ import annotations

import re

from ..payloads import ProgramLoads, StatedLoad, distinct, line_of

_RAPID_GRIPLOAD = re.compile(r"^\s*(GripLoad\s+[^;\n]*)", re.M | re.I)



def stated_loads(texts: dict[str, str], config=None) -> ProgramLoads:
    """The loads of the modules ``texts`` (a task: tools declared in one module, used in
    another)."""
    from .. import loads

    return loads_of([loads(text, "rapid", name) for name, text in texts.items()])


def loads_of(programs) -> ProgramLoads:
    """The load part of each robot-held ``tooldata`` the motions of ``programs`` use
    (``[mass, [cx, cy, cz], ...]``, kg and mm in the flange frame); ``GripLoad`` changes
    the load at run time."""
    found, runtime = [], []
    programs = list(programs)           # a task: tools declared in one module, used in another
    used = {m.tool.lower() for program in programs for m in program.motions if m.tool}
    for program in programs:
        for tool in program.tools:
            if tool.name is None or tool.name.lower() not in used or tool.robhold is False:
                continue
            if tool.mass is None or len(tool.cog) != 3:
                runtime.append(f"{tool.location.file}:{tool.location.line}: tooldata "
                               f"{tool.name} without a literal load")
                continue
            found.append(StatedLoad(tool.mass.value, tuple(c.value for c in tool.cog),
                                    f"tooldata {tool.name}"))
        for match in _RAPID_GRIPLOAD.finditer(program.text):
            runtime.append(f"{program.file}:{line_of(program.text, match.start())}: "
                           f"{match.group(1).strip()}")
    return ProgramLoads(distinct(found), tuple(runtime))


