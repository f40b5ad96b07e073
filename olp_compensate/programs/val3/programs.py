"""The motions of a VAL3 project: its ``.pgx`` programs (XML; each ``<Program>`` holds its
code in ``<Code><![CDATA[begin ... end]]></Code>``), read for which point each motion moves
to and with which tool (VAL3 reference manual, motion control: ``movej(point|jointRx, tool,
mdesc)``, ``movel(point, tool, mdesc)``, ``movec(pointVia, pointTo, tool, mdesc)``; a
data name without an index is its element 0).

- a point of the data files (``pPick``, ``pPath[3]``) moved to with a tool of the data files
  (``tGripper``) or the flange (``flange``): compensated with that tool, in the point's own
  frame (its ``fatherId``);
- an element indexed by a variable (``pPath[i]``): run time, and every element of that
  point is compensated with the motion's tool;
- anything computed (``appro(p, trsf)``, ``compose(...)``, ``here(...)``), a program's
  parameter or local variable: run time, with the reason;
- comments (``//``) are skipped; the ``.pgx`` files are read, never written.
"""

from __future__ import annotations

import re

from ..brackets import argument_spans, strip_span
from ..pose_dialects import JOINTS, PoseMotion, PoseProgram, line_column, line_starts_of
from ..text_checks import check_text, check_xml

_CODE = re.compile(r"<Code\b[^>]*>\s*<!\[CDATA\[(.*?)\]\]>", re.S)
_PROGRAM = re.compile(r"<Program\b[^>]*\bname\s*=\s*\"([^\"]*)\"")
_DECLARED = re.compile(r"<(?:Local|Parameter)\b[^>]*\bname\s*=\s*\"([^\"]*)\"")
_MOTION = re.compile(r"(?<![\w.])(movej|movel|movec)[ \t]*\(")
_NAME = re.compile(r"([A-Za-z_]\w*)(?:[ \t]*\[[ \t]*([^\]]*?)[ \t]*\])?\Z")
_CALL = re.compile(r"(?<![\w.])call[ \t]+([A-Za-z_]\w*)[ \t]*\(")
_JOINT_DATA = re.compile(r"<Data\b(?=[^>]*\btype\s*=\s*\"jointRx\")[^>]*\bname\s*=\s*\"([^\"]*)\"")


def _blank_comments(code: str) -> str:
    """``code`` with ``//`` comments and string insides blanked (offsets kept)."""
    out = re.sub(r'"[^"\r\n]*"', lambda m: '"' + " " * (len(m.group()) - 2) + '"', code)
    return re.sub(r"//[^\r\n]*", lambda m: " " * len(m.group()), out)


def _args(code: str, open_at: int) -> list[tuple[int, int]]:
    """Top-level argument spans of the call whose ``(`` is at ``open_at``, blanks left out."""
    spans, _ = argument_spans(code, open_at)
    return [strip_span(code, a, b) for a, b in spans]


def _ref(text: str) -> tuple[str | None, str | None]:
    """(name, index text) of ``pName`` / ``pName[3]``; (None, None) for an expression."""
    m = _NAME.match(text.strip())
    if m is None:
        return None, None
    return m.group(1), (m.group(2) if m.group(2) is not None else "0")


def read_programs(programs: dict[str, str], program: PoseProgram,
                  fathers: dict[str, str | None]) -> None:
    """Append to ``program.motions`` the motions of the ``.pgx`` texts (file -> text).
    ``fathers``: each point of the data files (``pPick[0]``) -> its frame reference."""
    refs = {t.name: t for t in program.targets if t.name}
    joint_data = {n for text in program.texts.values() for n in _JOINT_DATA.findall(text)}
    arrays: dict[str, list[str]] = {}
    for name in refs:
        arrays.setdefault(name.split("[", 1)[0], []).append(name)
    for file, text in programs.items():
        check_text(text, file)
        check_xml(text, file, "VAL3 program (.pgx)")
        starts = line_starts_of(text)
        declared = set(_DECLARED.findall(text))
        for code_match in _CODE.finditer(text):
            offset = code_match.start(1)
            code = _blank_comments(code_match.group(1))
            owner = _PROGRAM.findall(text, 0, code_match.start())
            owner_name = owner[-1] if owner else "?"
            _calls(code, text, file, offset, starts, program, arrays, refs)
            for m in _MOTION.finditer(code):
                args = _args(code, m.end() - 1)
                call = m.group(1)
                n_points = 2 if call == "movec" else 1
                where = (file, *line_column(text, offset + m.start(), starts))
                if len(args) < n_points + 1:
                    program.unknown.append((where, call))
                    continue
                tool = _tool(code[slice(*args[n_points])], declared)
                for a, b in args[:n_points]:
                    name, _ = _ref(code[a:b])
                    if name in joint_data and f"{name}[0]" not in refs:
                        continue          # a jointRx declared without values: no literal
                    program.motions.append(_motion(call, code[a:b], where, tool, refs, arrays,
                                                   fathers, declared, owner_name))


def _tool(text: str, declared: set[str]) -> str | None:
    name, index = _ref(text)
    if name is None:
        return f"{text.strip()[:40]} (computed)"
    if name == "flange":
        return "flange[0]"
    return f"{name}[{index}]"


def _motion(call, text, where, tool, refs, arrays, fathers, declared, owner) -> PoseMotion:
    name, index = _ref(text)
    shown = text.strip()[:40]
    if name is None:
        return PoseMotion(call, shown, where, tool=tool,
                          runtime=f"{shown} is computed at run time")
    if name in declared and f"{name}[0]" not in refs:
        return PoseMotion(call, shown, where, tool=tool,
                          runtime=f"{name} is a parameter or local variable of program "
                                  f"{owner}: known only at run time")
    if not re.fullmatch(r"\d+", index):
        elements = tuple(arrays.get(name, ()))
        base = _common_father(elements, fathers)
        return PoseMotion(call, f"{name}[{index}]", where, tool=tool,
                          runtime=f"{name}[{index}] is indexed at run time",
                          candidates=elements if base is not None else (), base=base)
    ref = f"{name}[{int(index)}]"
    target = refs.get(ref)
    base = fathers.get(ref) if target is None or target.kind != JOINTS else None
    return PoseMotion(call, ref, where, tool=tool, base=base or "world[0]")


def _common_father(elements, fathers) -> str | None:
    found = {fathers.get(e) or "world[0]" for e in elements}
    return found.pop() if len(found) == 1 else None


def _calls(code, text, file, offset, starts, program, arrays, refs) -> None:
    """Points passed to another program (``call pick(pPoint[i])``): moved to there through
    a parameter, a run-time use of each (every element for a variable index)."""
    for m in _CALL.finditer(code):
        line = line_column(text, offset + m.start(), starts)[0]
        for a, b in _args(code, m.end() - 1):
            name, index = _ref(code[a:b])
            if name is None or name not in arrays:
                continue
            elements = ([f"{name}[{int(index)}]"] if re.fullmatch(r"\d+", index)
                        else arrays[name])
            for element in elements:
                if element in refs:
                    program.runtime_uses.setdefault(
                        element, f"passed to {m.group(1)}() ({file}:{line}): moved to there "
                                 f"through a parameter, known only at run time")
