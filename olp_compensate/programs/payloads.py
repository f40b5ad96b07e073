"""The load a program says its robot carries: the types, and the rule of each language
(its folder's ``payload`` module).

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

from dataclasses import dataclass

__all__ = ["StatedLoad", "ProgramLoads", "program_loads"]

NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
"""A decimal number as programs write it (a regular expression)."""


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


def line_of(text: str, at: int) -> int:
    """The 1-based line of offset ``at`` in ``text``."""
    return text.count("\n", 0, at) + 1


def distinct(found: list[StatedLoad]) -> tuple[StatedLoad, ...]:
    """The loads of ``found`` once each (the first source kept)."""
    out: list[StatedLoad] = []
    for load in found:
        if not any(abs(o.kg - load.kg) < 1e-9 and
                   all(abs(a - b) < 1e-6 for a, b in zip(o.cog_mm, load.cog_mm)) for o in out):
            out.append(load)
    return tuple(out)


def program_loads(dialect: str, texts: dict[str, str], config=None) -> ProgramLoads:
    """The loads a program of language ``dialect`` states (its ``stated_loads``; see the
    module docstring). ``texts``: file name -> text; ``config``: the controller files given
    with ``--config`` (KRL's ``$config.dat`` with ``LOAD_DATA``). Languages that state no
    load (V+, VAL3) give none."""
    from .languages import language_named

    stated = language_named(dialect).stated_loads
    return ProgramLoads((), ()) if stated is None else stated(texts, config)
