"""Program tools and measured points: two namespaces of calib.json's ``tools``.

A calibration holds the points measured for its identification (a tracker target, named
``tcp`` by default in every measurement CSV) and the tools calibrated for programs
(``olp-cal tool``, marked ``for_programs``). Only the latter replace a program's tool, and
only by an explicit name match (case-insensitive): a URScript ``set_tcp`` is named ``tcp``
too, and taking the tracker target's offset as its real tool moved every target.
"""

from __future__ import annotations

from ..calibration.calibration import Calibration, ToolPoint

__all__ = ["program_tool", "program_tool_note"]


def program_tool(calibration: Calibration, names) -> tuple[str, ToolPoint] | None:
    """(calibration's name, tool) of the tool calibrated for programs whose name is one of
    ``names`` (a program's names for its tool, tried in order), or None."""
    for name in names:
        low = name.lower()
        for key, tool in calibration.tools.items():
            if tool.for_programs and key.lower() == low:
                return key, tool
    return None


def program_tool_note(program_name: str, key: str) -> str:
    """The report note of a target whose tool was replaced by a calibrated one."""
    return f"real TCP of {program_name} from the calibration (tool '{key}', olp-cal tool)"
