"""FANUC teach-pendant programs in their ASCII form (``.ls``), read with every number's span.

What is read (FANUC HandlingTool operator's manual V9.40 as summarised in public notes:
sec. 12.2.7 the ``.LS`` layout ``/PROG /ATTR /APPL /MN /POS /END``; sec. 7.2.1 a motion
line is ``<n>:<J|L|C|A> P[i] <speed> <FINE|CNTn> <options> ;``; sec. 7.2.6/7.2.9 position
records ``P[n]{ GP1: UF : u, UT : t, CONFIG : 'N U T, 0, 0, 0', X = .. mm, ... R = .. deg };``
with ``UF``/``UT`` the user frame and tool numbers (0 = world; ``F`` = the number in force);
sec. 11.9 the joint record ``J1 = .. deg``; real ``.ls`` backups on GitHub for the spacing,
tabs, ``-.131`` number forms and labels ``P[1:"App"]`` / ``P[1:App]``):

- the ``/POS`` records: Cartesian (``kind='pose'``: X, Y, Z mm; W, P, R deg, about the
  fixed x, y, z axes, i.e. ``Rz(R) Ry(P) Rx(W)``), with the CONFIG letters and the three
  turn numbers as spans (``config``: letters then turns), or joint records
  (``kind='joints'``, kept as written); only group 1 (``GP1``) is read, other groups'
  values are kept as written; a record in another representation (``RX = .. mm`` ...
  ``RR = .. deg``, as some controller backups write) is kept as written and reported
  (``unknown``), its motions as not read; so is a point never taught
  (``X = ********  mm``), and a record of other groups only (a servo gun's ``GP4``);
- motions ``J``, ``L``, ``C`` (with its second point on the ``:`` continuation line) and
  ``A`` to ``P[i]``; ``PR[i]`` (position registers), indirect ``P[R[i]]`` and motions with
  ``Offset``, ``Tool_Offset``, ``VOFFSET`` or ``INC`` are run-time targets;
- each motion's tool and base: the point's ``UT``/``UF`` numbers (``UT4``, ``UF0``), or
  the ``UTOOL_NUM``/``UFRAME_NUM`` in force (text order) where the record says ``F``.

Frames (``UFRAME``/``UTOOL`` data) live in the controller's system variables, not in the
program: pass them as ``frames={"UF1": (x, y, z, w, p, r), "UT4": (...)}`` (mm, deg), or as
the ``$MNUFRAME``/``$MNUTOOL`` of a backup's ``SYSFRAME.VA``
(``system_frames=read_system_frames(text, "SYSFRAME.VA")``, :mod:`.frames`); a frame
the program uses that the file holds no value for (uninitialized, or not in the file) is
named in a note with the file, and its targets stay unresolved (unless calib.json has a tool
of that name).
Remarks (``!``) and disabled lines (``//``) are skipped.
"""

from __future__ import annotations

import re

from ...errors import ParseError
from ..brackets import closing
from ..brackets import line_end as next_line_break
from ..pose_dialects import (JOINTS, POSE, PoseMotion, PoseProgram, PoseTarget, is_finite_number,
                             line_column, line_starts_of)
from ..targets import Number
from ..text_checks import check_not_non_finite, check_number_end, check_text
from .backup import PositionRegisters, config_numbers
from .frames import SystemFrames

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_SECTION = re.compile(r"^/(PROG|ATTR|APPL|MN|POS|END)\b", re.M)
_RECORD = re.compile(r"^[ \t]*P\[[ \t]*(\d+)[ \t]*(?::[^\]]*)?\][ \t]*\{", re.M)
_GROUP = re.compile(r"\bGP(\d+)[ \t]*:")
_FRAME_NO = re.compile(r"\b(UF|UT)[ \t]*:[ \t]*(\d+|F)\b")
_ANY_FIELD = re.compile(rf"(?<![\w\[])([A-Z]{{1,3}}\d?)[ \t]*=[ \t]*{_NUMBER}")
_UNTAUGHT = re.compile(r"(?<![\w\[])(?:[XYZWPR]|J\d)[ \t]*=[ \t]*\*+")
_CONFIG = re.compile(r"\bCONFIG[ \t]*:[ \t]*'([^']*)'")
_FIELD = re.compile(rf"(?<![\w\[])([XYZWPR]|J\d|E\d)[ \t]*=[ \t]*({_NUMBER})[ \t]*(mm|deg)?")
_LINE = re.compile(r"^[ \t]*\d+[ \t]*:[ \t]*([^\r\n]*)", re.M)
_CONTINUATION = re.compile(r"^[ \t]*:[ \t]*([^\r\n]*)", re.M)
_MOTION = re.compile(r"([JLCA])[ \t]+")
_POSITION = re.compile(r"(PR|P)[ \t]*\[")
_SET_NUM = re.compile(r"\b(UFRAME_NUM|UTOOL_NUM)[ \t]*=[ \t]*(\d+|\S+)")
_RUNTIME_OPTIONS = re.compile(r"\b(Tool_Offset|VOFFSET|Offset|INC)\b", re.I)

POSE_FIELDS = ("X", "Y", "Z", "W", "P", "R")


def _sections(text: str) -> dict[str, tuple[int, int]]:
    found = list(_SECTION.finditer(text))
    out = {}
    for m, nxt in zip(found, found[1:] + [None]):
        out[m.group(1)] = (m.end(), nxt.start() if nxt is not None else len(text))
    return out


def _record_end(text: str, lo: int, file: str, starts: list[int]) -> int:
    k = text.find("};", lo)
    if k < 0:
        line, column = line_column(text, lo, starts)
        raise ParseError("position record '{' is never closed by '};'", file, line, column)
    return k


def _gp1(text: str, lo: int, hi: int) -> tuple[int, int]:
    """The span of group 1's data inside a record (the whole record when no ``GPn:``)."""
    groups = list(_GROUP.finditer(text, lo, hi))
    for g, nxt in zip(groups, groups[1:] + [None]):
        if g.group(1) == "1":
            return g.end(), nxt.start() if nxt is not None else hi
    return (lo, hi) if not groups else (hi, hi)


def _positions(text: str, file: str, starts: list[int], lo: int, hi: int,
               program: PoseProgram, unreadable: dict[str, str] | None = None
               ) -> dict[str, tuple[str, str]]:
    """The ``/POS`` records: targets appended to ``program``; returns name -> (UF, UT).
    Records in another representation are added to ``unreadable`` (name -> reason)."""
    unreadable = {} if unreadable is None else unreadable
    frames_of = {}
    for m in _RECORD.finditer(text, lo, hi):
        name = f"P[{int(m.group(1))}]"
        end = _record_end(text, m.end(), file, starts)
        g_lo, g_hi = _gp1(text, m.end(), end)
        if g_lo == g_hi == end and _GROUP.search(text, m.end(), end):
            groups = ", ".join(f"GP{g.group(1)}" for g in _GROUP.finditer(text, m.end(), end))
            where = (file, *line_column(text, m.start(), starts))
            program.unknown.append((where, f"{name} has no group 1 data ({groups} only)"))
            unreadable[name] = f"{name} moves {groups} only, not the robot arm (group 1); " \
                               f"kept as written"
            continue
        numbers = {}
        check_not_non_finite(text, g_lo, g_hi, file)
        for f in _FIELD.finditer(text, g_lo, g_hi):
            value = f.group(2)
            check_number_end(text, f.end(2), file)
            if not is_finite_number(value):
                line, column = line_column(text, f.start(2), starts)
                raise ParseError(f"{value} is not a finite number", file, line, column)
            numbers[f.group(1).upper()] = Number(f.start(2), f.end(2), value)
        uf = ut = "F"
        for f in _FRAME_NO.finditer(text, g_lo, g_hi):
            if f.group(1) == "UF":
                uf = f.group(2)
            else:
                ut = f.group(2)
        frames_of[name] = (uf, ut)
        where = (file, *line_column(text, m.start(), starts))
        frame = (None if uf == "F" else f"UF{int(uf)}", None if ut == "F" else f"UT{int(ut)}")
        if all(f in numbers for f in POSE_FIELDS):
            config_spans = _config(text, file, starts, g_lo, g_hi)
            if config_spans is None:
                first = numbers["X"]
                at = (file, *line_column(text, first.start, starts))
                words = _CONFIG.search(text, g_lo, g_hi).group(1)
                why = (f"{name} has a SCARA configuration '{words}': the FANUC rules read "
                       f"six-axis arms (N/F U/D T/B); kept as written")
                program.kept.append((at, name, "unresolved", why))
                unreadable[name] = why
                continue
            config, config_text = config_spans
            first = numbers["X"]
            where = (file, *line_column(text, first.start, starts))
            program.targets.append(PoseTarget(
                name=name, source=where, kind=POSE,
                numbers=tuple(numbers[f] for f in POSE_FIELDS), config=config,
                config_text=config_text, frame=frame))
        elif any(k.startswith("J") for k in numbers):
            joints = tuple(numbers[k] for k in sorted(numbers) if k.startswith("J"))
            program.targets.append(PoseTarget(name=name, source=where, kind=JOINTS,
                                              numbers=joints, frame=frame))
        elif _UNTAUGHT.search(text, g_lo, g_hi):
            # X = ******** mm: a point recorded but never taught; kept as written
            program.unknown.append((where, f"{name} never taught (values ********)"))
            unreadable[name] = f"{name} was never taught (its values are ********)"
        else:
            others = sorted({f.group(1) for f in _ANY_FIELD.finditer(text, g_lo, g_hi)})
            if not others:
                line, column = where[1:]
                raise ParseError(f"{name}: group 1 has neither X..R nor J1..J6 values", file,
                                 line, column)
            # another representation (RX..RR as some backups write): kept as written, the
            # record reported at its place and its motions as not read
            program.unknown.append((where, f"{name} written as {', '.join(others)} (not "
                                           f"X..R nor J1..J6)"))
            unreadable[name] = (f"{name} is written as {', '.join(others)}, a representation "
                                f"not read; kept as written")
    return frames_of


def _config(text: str, file: str, starts: list[int], lo: int, hi: int):
    """(letters and turns as Numbers, the whole CONFIG string as a Number), ((), None)
    without CONFIG, None for a SCARA's configuration (``'L, 0, 0, -1'``)."""
    m = _CONFIG.search(text, lo, hi)
    if m is None:
        return (), None
    return config_numbers(text, file, starts, m.start(1), m.group(1))


class _Numbers:
    """``UFRAME_NUM`` / ``UTOOL_NUM`` in force while ``/MN`` is read in text order."""

    def __init__(self):
        self.uf: str | None = None
        self.ut: str | None = None

    def statement(self, line: str) -> None:
        for m in _SET_NUM.finditer(line):
            value = m.group(2).rstrip(";")
            known = value.isdigit()
            if m.group(1).upper() == "UFRAME_NUM":
                self.uf = f"UF{int(value)}" if known else f"UFRAME_NUM={value}"
            else:
                self.ut = f"UT{int(value)}" if known else f"UTOOL_NUM={value}"


def _motions(text: str, file: str, starts: list[int], lo: int, hi: int, program: PoseProgram,
             frames_of: dict[str, tuple[str, str]], unreadable: dict[str, str]) -> None:
    numbers = _Numbers()
    lines = [(s, e) for s, e in zip(starts, starts[1:] + [len(text)]) if lo <= s < hi]
    k = 0
    while k < len(lines):
        s, e = lines[k]
        k += 1
        m = _LINE.match(text, s, e)
        if m is None:
            continue
        body_at = m.start(1)
        body = text[body_at:e].rstrip("\r\n")
        if body.startswith(("!", "//")):
            continue
        numbers.statement(body)
        motion = _MOTION.match(text, body_at)
        if motion is None or motion.end() > e:
            continue
        instruction = motion.group(1)
        where = (file, *line_column(text, motion.start(), starts))
        args = [motion.end()]
        rest = [(motion.end(), e)]
        if instruction == "C":                        # the end point: the next ':' line
            if k < len(lines):
                cs, ce = lines[k]
                cont = _CONTINUATION.match(text, cs, ce)
                if cont is not None:
                    args.append(cont.start(1))
                    rest.append((cont.start(1), ce))
                    k += 1
        for at, (_, r_hi) in zip(args, rest):
            _motion(text, file, starts, instruction, where, at, r_hi, program, frames_of,
                    numbers, unreadable)


def _motion(text, file, starts, instruction, where, at, line_end, program, frames_of,
            numbers: _Numbers, unreadable: dict[str, str]) -> None:
    p = _POSITION.match(text, at)
    if p is None:
        program.unknown.append((where, instruction))
        return
    close = closing(text, p.end() - 1, next_line_break(text, p.end() - 1), "[]") or -1
    if close < 0:
        program.unknown.append((where, instruction))
        return
    inside = text[p.end():close - 1]
    index = inside.split(":", 1)[0].strip()
    kind = p.group(1)
    options = text[close:line_end]
    runtime = None
    option = _RUNTIME_OPTIONS.search(options)
    if not index.isdigit():
        runtime = f"{kind}[{index}] is indexed at run time"
    elif option is not None:
        runtime = f"{option.group(1)} moves the point by an offset known at run time"
    elif kind == "PR":
        runtime = (f"PR[{index}] is a position register, known only at run time (give the "
                   f"backup's POSREG.VA with --config to read its value)")
    name = f"{kind}[{int(index)}]" if index.isdigit() else f"{kind}[{index}]"
    if runtime is None and name in unreadable:
        runtime = unreadable[name]
    uf, ut = frames_of.get(name, ("F", "F"))
    base = numbers.uf if uf == "F" else f"UF{int(uf)}"
    tool = numbers.ut if ut == "F" else f"UT{int(ut)}"
    program.motions.append(PoseMotion(instruction=instruction, target=name, source=where,
                                      tool=tool, base=base, runtime=runtime))


def parse_fanuc_tp(text: str, file: str = "<ls>",
                   frames: dict[str, tuple[float, ...]] | None = None,
                   system_frames: SystemFrames | None = None,
                   registers: PositionRegisters | None = None) -> PoseProgram:
    """Read a FANUC ``.ls`` program (decoded text). ``frames``: user frames and tools the
    controller holds, ``"UF<n>"``/``"UT<n>"`` -> (x, y, z mm, w, p, r deg);
    ``system_frames``: those of a ``SYSFRAME.VA`` (``frames`` wins where both name one);
    ``registers``: the position registers of a ``POSREG.VA`` (motions to a register the
    program never sets are solved with its value, reported as ``register`` rows)."""
    check_text(text, file, "a binary .tp program cannot be read; save it as .ls")
    program = PoseProgram(dialect="fanuc_tp", texts={file: text}, targets=[], motions=[])
    if system_frames is not None:
        program.frames.update(system_frames.frames)
    if frames:
        program.frames.update({k: tuple(float(v) for v in vals) for k, vals in frames.items()})
    starts = line_starts_of(text)
    sections = _sections(text)
    if "MN" not in sections and "POS" not in sections:
        raise ParseError("not a FANUC .ls program: neither /MN nor /POS found", file, 1, 1)
    if "END" not in sections:
        line, column = line_column(text, len(text.rstrip()), starts)
        raise ParseError("no /END: the program is cut short", file, line, column)
    frames_of: dict[str, tuple[str, str]] = {}
    unreadable: dict[str, str] = {}
    if "POS" in sections:
        frames_of = _positions(text, file, starts, *sections["POS"], program, unreadable)
    if "MN" in sections:
        _motions(text, file, starts, *sections["MN"], program, frames_of, unreadable)
        if registers is not None:
            _read_registers(text, starts, *sections["MN"], program, registers)
    if system_frames is not None:
        if "MN" in sections:
            _drop_reassigned(text, file, starts, *sections["MN"], program, system_frames,
                             frames)
        _frame_notes(program, system_frames)
    return program


_FRAME_SET = re.compile(r"^[ \t]*\d+:[ \t]*(UFRAME|UTOOL)[ \t]*\[[ \t]*(\d+)[ \t]*\][ \t]*=",
                        re.M)


def _drop_reassigned(text: str, file: str, starts: list[int], lo: int, hi: int,
                     program: PoseProgram, system_frames: SystemFrames, given) -> None:
    """A frame the program sets at run time (``UFRAME[2]=PR[5]``, ``UTOOL[3]=...``) is not
    the backup's value while the program runs: its SYSFRAME.VA value is not used (its
    targets stay unresolved, unless calib.json has a tool of its name), with a note."""
    for m in _FRAME_SET.finditer(text, lo, hi):
        key = ("UF" if m.group(1) == "UFRAME" else "UT") + str(int(m.group(2)))
        if key in system_frames.frames and not (given and key in given):
            program.frames.pop(key, None)
            line = line_column(text, m.start(1), starts)[0]
            program.notes.append(f"{file}:{line}: {key} is set at run time "
                                 f"({m.group(1)}[{m.group(2)}]=...): its value in "
                                 f"{system_frames.file} is not used")



def _frame_notes(program: PoseProgram, system_frames: SystemFrames) -> None:
    """A note for each frame the program's motions use that ``system_frames`` holds no
    value for (and no other frame data gives), once, in the order first used."""
    used = dict.fromkeys(key for m in program.motions if m.runtime is None
                         for key in (m.base, m.tool) if key is not None)
    for key in used:
        why = None if key in program.frames else system_frames.why_unknown(key)
        if why is None:
            continue
        targets = (f"targets in {key} are left unresolved" if key.startswith("UF") else
                   f"targets with {key} are left unresolved unless calib.json has a tool "
                   f"{key} (or tool{key[2:]})")
        program.notes.append(f"{why}: {targets}")


_PR_SET = re.compile(r"^[ \t]*\d+[ \t]*:[ \t]*PR[ \t]*\[[ \t]*(\d+)[ \t]*(?:[,:][^\]\r\n]*)?\]"
                     r"[ \t]*=", re.M)


def _read_registers(text: str, starts: list[int], lo: int, hi: int, program: PoseProgram,
                    registers: PositionRegisters) -> None:
    """Motions to ``PR[n]`` with the register's value from ``registers``: solved where the
    program never sets the register; run-time (the register and why named) otherwise."""
    assigned = {}
    for m in _PR_SET.finditer(text, lo, hi):
        assigned.setdefault(f"PR[{int(m.group(1))}]", line_column(text, m.start(), starts)[0])
    used: dict[str, None] = {}
    for k, motion in enumerate(program.motions):
        name = motion.target or ""
        if not name.startswith("PR[") or motion.runtime is None or \
                "position register" not in motion.runtime:
            continue
        if name in assigned:
            why = (f"{name} is set by the program (line {assigned[name]}): its value is "
                   f"known only at run time")
        elif name in registers.uninitialized:
            line, column = registers.uninitialized[name]
            why = f"{name} is uninitialized in {registers.file} ({registers.file}:{line}:{column})"
        elif name not in registers.registers:
            why = f"{name} is not in {registers.file}: known only at run time"
        else:
            why = None
            used[name] = None
        program.motions[k] = motion._replace(runtime=why)
    for name in used:
        program.targets.append(registers.registers[name])
    if used:
        program.texts[registers.file] = registers.text
        program.external[registers.file] = (
            "register", "a position register: its value is on the controller, not in the "
                        "program")
