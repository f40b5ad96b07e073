"""The load a program says its robot carries, per dialect.

- RAPID: the load part of each robot-held ``tooldata`` its motions use (``[mass, [cx, cy,
  cz], ...]``, kg and mm in the flange frame); ``GripLoad`` changes the load at run time.
- URScript: ``set_payload(m, [cx, cy, cz])`` (kg, m in the flange frame) and
  ``set_target_payload(m, [cx, cy, cz], ...)``; one whose numbers are not literal is set at
  run time.
- KRL: ``$LOAD = {M m, CM {X x, Y y, Z z, ...}, ...}`` (kg, mm), or ``$LOAD = LOAD_DATA[n]``
  whose value is in the controller's ``$config.dat`` (given with ``--config``).
- FANUC TP: ``PAYLOAD[n]`` picks a payload schedule whose values live in the controller's
  system variables, not in the program: it is stated as set at run time.

:func:`program_loads` lists the distinct loads found (:class:`StatedLoad`) and the
statements that change the load at run time (``file:line: text``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["StatedLoad", "ProgramLoads", "program_loads"]

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_UR_PAYLOAD = re.compile(r"^\s*(set_payload|set_target_payload)\s*\(([^\n]*)\)", re.M)
_UR_ARGS = re.compile(rf"^\s*({_NUMBER})\s*(?:,\s*\[\s*({_NUMBER})\s*,\s*({_NUMBER})\s*,\s*"
                      rf"({_NUMBER})\s*\])?")
_KRL_LOAD = re.compile(r"^\s*\$LOAD\s*=\s*([^\n;]*)", re.M | re.I)
_KRL_VALUE = re.compile(rf"\{{\s*M\s+({_NUMBER})\s*,\s*CM\s*\{{\s*X\s+({_NUMBER})\s*,\s*Y\s+"
                        rf"({_NUMBER})\s*,\s*Z\s+({_NUMBER})", re.I)
_KRL_INDEX = re.compile(r"LOAD_DATA\s*\[\s*(\d+)\s*\]", re.I)
_FANUC_PAYLOAD = re.compile(r"^\s*\d+:\s*(PAYLOAD\s*\[[^\]]*\])", re.M | re.I)
_RAPID_GRIPLOAD = re.compile(r"^\s*(GripLoad\s+[^;\n]*)", re.M | re.I)


@dataclass(frozen=True)
class StatedLoad:
    """A load the program states: ``kg`` at ``cog_mm`` (3,) in the flange frame, and where
    (``'tooldata gun'``, ``'set_payload at cell.script:4'``)."""

    kg: float
    cog_mm: tuple[float, float, float]
    source: str


@dataclass(frozen=True)
class ProgramLoads:
    """``loads``: the distinct loads stated (first source kept); ``runtime``: statements
    that set the load at run time, ``file:line: text``."""

    loads: tuple[StatedLoad, ...]
    runtime: tuple[str, ...]


def _line(text: str, at: int) -> int:
    return text.count("\n", 0, at) + 1


def _distinct(found: list[StatedLoad]) -> tuple[StatedLoad, ...]:
    out: list[StatedLoad] = []
    for load in found:
        if not any(abs(o.kg - load.kg) < 1e-9 and
                   all(abs(a - b) < 1e-6 for a, b in zip(o.cog_mm, load.cog_mm)) for o in out):
            out.append(load)
    return tuple(out)


def _urscript(texts: dict[str, str]) -> ProgramLoads:
    found, runtime = [], []
    for name, text in texts.items():
        for match in _UR_PAYLOAD.finditer(text):
            where = f"{name}:{_line(text, match.start())}"
            args = _UR_ARGS.match(match.group(2))
            if args is None:
                runtime.append(f"{where}: {match.group(0).strip()}")
                continue
            cog = tuple(float(v) * 1e3 if v is not None else 0.0 for v in args.groups()[1:])
            found.append(StatedLoad(float(args.group(1)), cog, f"{match.group(1)} at {where}"))
    return ProgramLoads(_distinct(found), tuple(runtime))


def _rapid(programs) -> ProgramLoads:
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
            runtime.append(f"{program.file}:{_line(program.text, match.start())}: "
                           f"{match.group(1).strip()}")
    return ProgramLoads(_distinct(found), tuple(runtime))


def _krl(texts: dict[str, str], frames_text: str | None) -> ProgramLoads:
    found, runtime = [], []
    for name, text in texts.items():
        for match in _KRL_LOAD.finditer(text):
            where = f"{name}:{_line(text, match.start())}"
            value = _KRL_VALUE.search(match.group(1))
            index = _KRL_INDEX.search(match.group(1))
            if value is None and index is not None and frames_text is not None:
                value = _krl_load_data(frames_text, int(index.group(1)))
            if value is None:
                runtime.append(f"{where}: {match.group(0).strip()}")
                continue
            kg, *cog = (float(v) for v in value.groups())
            found.append(StatedLoad(kg, tuple(cog), f"$LOAD at {where}"))
    return ProgramLoads(_distinct(found), tuple(runtime))


def _krl_load_data(frames_text: str, index: int):
    pattern = re.compile(rf"LOAD_DATA\s*\[\s*{index}\s*\]\s*=\s*([^\n]*)", re.I)
    match = pattern.search(frames_text)
    return None if match is None else _KRL_VALUE.search(match.group(1))


def _fanuc(texts: dict[str, str]) -> ProgramLoads:
    runtime = [f"{name}:{_line(text, m.start())}: {m.group(1)} (a payload schedule of the "
               f"controller's system variables)"
               for name, text in texts.items() for m in _FANUC_PAYLOAD.finditer(text)]
    return ProgramLoads((), tuple(runtime))


def program_loads(dialect: str, texts: dict[str, str], programs=(),
                  frames_text: str | None = None) -> ProgramLoads:
    """The loads a program states (module docstring). ``texts``: file name -> text;
    ``programs``: the parsed RAPID modules (RAPID only); ``frames_text``: KRL's
    ``$config.dat``. Dialects that state no load (V+, VAL3) give none."""
    if dialect == "urscript":
        return _urscript(texts)
    if dialect == "rapid":
        return _rapid(programs)
    if dialect == "krl":
        return _krl(texts, frames_text)
    if dialect == "fanuc":
        return _fanuc(texts)
    return ProgramLoads((), ())
