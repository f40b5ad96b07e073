"""The tool and base in force while a KRL ``.src`` is read in text order (see :mod:`.reader`):
``FDAT_ACT`` with ``BAS(#PTP_PARAMS|#CP_PARAMS, ...)`` or, in older inline forms,
``BAS(#FRAMES)`` (the FDAT's ``TOOL_NO``/``BASE_NO``: KUKA's BAS.SRC runs ``FRAMES()`` for
the three),
``BAS(#TOOL, n)``, ``BAS(#BASE, n)``, ``$TOOL=TOOL_DATA[n]``, ``$BASE=BASE_DATA[n]``, a
spline motion's ``WITH $TOOL=STOOL2(FP1)``, and ``$TOOL = {X .., Y .., ...}`` written as a
frame of its own (mm, deg); ``$TOOL`` or ``$BASE`` set from anything else is a frame known
only at run time. A call of a user routine while the tool or base is still unset (a routine
such as ``MoveSettings(nBase, nTool, ..)`` setting ``FDAT_ACT``/``$TOOL`` at run time, as
real cells do) makes the frame of the motions after it unknown too.
"""

from __future__ import annotations

import re

from ..pose_dialects import is_finite_number
from ..targets import Number

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
FIELD = re.compile(rf"([A-Za-z_][A-Za-z0-9_]*)\s+({_NUMBER}|'[BbHh][0-9A-Fa-f]*'|#\w+|\"[^\"]*\")")
"""One ``NAME value`` field of a KRL aggregate."""
POSE_FIELDS = ("X", "Y", "Z", "A", "B", "C")
_FDAT_ACT = re.compile(r"\bFDAT_ACT\s*=\s*([A-Za-z_]\w*)", re.I)
_BAS_PARAMS = re.compile(r"\bBAS\s*\(\s*#(PTP_PARAMS|CP_PARAMS|FRAMES|TOOL|BASE)\s*(?:,\s*(\d+))?", re.I)
_TOOL_SET = re.compile(r"\$TOOL\s*=\s*(TOOL_DATA\s*\[\s*(\d+)\s*\]|\$NULLFRAME)", re.I)
_BASE_SET = re.compile(r"\$BASE\s*=\s*(BASE_DATA\s*\[\s*(\d+)\s*\]|\$NULLFRAME|\$WORLD)", re.I)
_FRAME_VALUE = re.compile(r"(?<![\w.])\$(TOOL|BASE)[ \t]*=(?!=)[ \t]*([^\r\n]*)", re.I)
_CALL = re.compile(r"^[ \t]*([A-Za-z_]\w*)[ \t]*\(")
_NOT_ROUTINES = frozenset((        # statements and built-ins written NAME( that set no frame
    "IF", "WHILE", "UNTIL", "SWITCH", "CASE", "RETURN", "WAIT", "BAS", "PULSE", "CWRITE",
    "CREAD", "SWRITE", "SREAD", "CAST_TO", "CAST_FROM", "ON_ERROR_PROCEED", "ERR_RAISE",
    "ERR_CLEAR", "HALT", "BRAKE", "RESUME", "ELSE", "ENDIF", "DEF", "DEFFCT", "GLOBAL"))
_WITH_FDAT = re.compile(r"\bSTOOL2\s*\(\s*([A-Za-z_]\w*)\s*\)|\b([A-Za-z_]\w*)\.(?:BASE_NO|TOOL_NO)\b",
                        re.I)


class ToolBase:
    """The tool and base in force while the ``.src`` is read in text order."""

    def __init__(self, fdat: dict[str, dict[str, Number]], frames: dict | None = None):
        self.fdat = fdat
        self.frames = {} if frames is None else frames     # inline $TOOL/$BASE values go here
        self.active: str | None = None
        self.tool: str | None = None
        self.base: str | None = None
        self.routine: tuple[str, int] | None = None   # (name, line) of a user routine called

    def load_fdat(self) -> None:
        fields = self.fdat.get((self.active or "").upper())
        if fields is None:
            return
        if "TOOL_NO" in fields:
            self.tool = f"TOOL_DATA[{int(fields['TOOL_NO'].value)}]"
        if "BASE_NO" in fields:
            self.base = f"BASE_DATA[{int(fields['BASE_NO'].value)}]"
        ipo = fields.get("IPO_FRAME")
        if ipo is not None and ipo.text.upper() == "#TCP":
            self.tool = "external TCP (IPO_FRAME #TCP)"

    def with_clause(self, statement: str) -> None:
        """A spline motion's ``WITH $TOOL=STOOL2(FP1), $BASE=...(FP1.BASE_NO)``: the FDAT
        named there gives its tool and base."""
        m = _WITH_FDAT.search(statement)
        if m:
            self.active = m.group(1) or m.group(2)
            self.load_fdat()

    def statement(self, line: str, number: int = 0) -> None:
        self._assigned_frame(line, number)
        call = _CALL.match(line)
        if call and call.group(1).upper() not in _NOT_ROUTINES and self.routine is None:
            self.routine = (call.group(1), number)
        m = _FDAT_ACT.search(line)
        if m:
            self.active = m.group(1)
        for m in _BAS_PARAMS.finditer(line):
            kind, number = m.group(1).upper(), m.group(2)
            if kind in ("PTP_PARAMS", "CP_PARAMS", "FRAMES"):
                self.load_fdat()
            elif kind == "TOOL" and number is not None:
                self.tool = f"TOOL_DATA[{int(number)}]"
            elif kind == "BASE" and number is not None:
                self.base = f"BASE_DATA[{int(number)}]"
        m = _TOOL_SET.search(line)
        if m:
            self.tool = f"TOOL_DATA[{int(m.group(2))}]" if m.group(2) else "TOOL_DATA[0]"
        m = _BASE_SET.search(line)
        if m:
            self.base = f"BASE_DATA[{int(m.group(2))}]" if m.group(2) else "BASE_DATA[0]"


    def unknown_frame(self) -> str | None:
        """Why the motion's tool or base is known only at run time because a user routine
        was called while it was unset, or None."""
        if self.routine is None or (self.tool is not None and self.base is not None):
            return None
        kind = "tool" if self.tool is None else "base"
        name, line = self.routine
        return (f"no {kind} is set in this file before the motion, and {name}() (line {line}) "
                f"may set it at run time: the {kind} frame is not known")

    def _assigned_frame(self, line: str, number: int) -> None:
        """``$TOOL = {X ..}`` (a frame of its own, named ``$TOOL@L<line>``), or ``$TOOL =``
        anything computed (an unknown frame, so its targets are unresolved, never solved
        with the frame in force before); ``TOOL_DATA[n]``, ``$NULLFRAME`` and spline
        ``STOOL2``/``SBASE`` are read elsewhere."""
        for m in _FRAME_VALUE.finditer(line):
            kind, value = m.group(1).upper(), m.group(2).strip().rstrip(",")
            if re.match(r"(TOOL_DATA|BASE_DATA)\s*\[\s*\d+\s*\]|\$NULLFRAME|\$WORLD|STOOL2|SBASE",
                        value, re.I):
                continue
            fields = {f.group(1).upper(): f.group(2) for f in FIELD.finditer(value)}
            if value.startswith("{") and all(f in fields for f in POSE_FIELDS) and all(
                    is_finite_number(fields[f]) for f in POSE_FIELDS):
                key = f"${kind}@L{number}"
                self.frames[key] = tuple(float(fields[f]) for f in POSE_FIELDS)
            else:
                key = f"${kind} = {value[:30]}"
            if kind == "TOOL":
                self.tool = key
            else:
                self.base = key
