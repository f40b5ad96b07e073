"""The loads a KRL program states: ``$LOAD = {M m, CM {X x, Y y, Z z, ...}, ...}`` (kg, mm),
or ``$LOAD = LOAD_DATA[n]`` whose value is in the controller's ``$config.dat``."""

from __future__ import annotations

import re
from pathlib import Path

from ..payloads import NUMBER, ProgramLoads, StatedLoad, distinct, line_of

_KRL_LOAD = re.compile(r"^\s*\$LOAD\s*=\s*([^\n;]*)", re.M | re.I)
_KRL_VALUE = re.compile(rf"\{{\s*M\s+({NUMBER})\s*,\s*CM\s*\{{\s*X\s+({NUMBER})\s*,\s*Y\s+"
                        rf"({NUMBER})\s*,\s*Z\s+({NUMBER})", re.I)
_KRL_INDEX = re.compile(r"LOAD_DATA\s*\[\s*(\d+)\s*\]", re.I)


def stated_loads(texts: dict[str, str], config=None) -> ProgramLoads:
    """The ``$LOAD`` assignments; ``LOAD_DATA[n]`` read from the ``$config.dat`` among the
    ``config`` files (the one that declares ``LOAD_DATA``)."""
    return loads_with(texts, _load_data_text(config))


def _load_data_text(config) -> str | None:
    from ..backup_files import backup_files

    for path in backup_files(config).paths:
        text = Path(path).read_bytes().decode("latin-1")
        if "LOAD_DATA" in text.upper():
            return text
    return None


def loads_with(texts: dict[str, str], frames_text: str | None) -> ProgramLoads:
    """The ``$LOAD`` assignments of ``texts``, ``LOAD_DATA`` from ``frames_text``."""
    found, runtime = [], []
    for name, text in texts.items():
        for match in _KRL_LOAD.finditer(text):
            where = f"{name}:{line_of(text, match.start())}"
            value = _KRL_VALUE.search(match.group(1))
            index = _KRL_INDEX.search(match.group(1))
            if value is None and index is not None and frames_text is not None:
                value = _krl_load_data(frames_text, int(index.group(1)))
            if value is None:
                runtime.append(f"{where}: {match.group(0).strip()}")
                continue
            kg, *cog = (float(v) for v in value.groups())
            found.append(StatedLoad(kg, tuple(cog), f"$LOAD at {where}"))
    return ProgramLoads(distinct(found), tuple(runtime))


def _krl_load_data(frames_text: str, index: int):
    pattern = re.compile(rf"LOAD_DATA\s*\[\s*{index}\s*\]\s*=\s*([^\n]*)", re.I)
    match = pattern.search(frames_text)
    return None if match is None else _KRL_VALUE.search(match.group(1))


