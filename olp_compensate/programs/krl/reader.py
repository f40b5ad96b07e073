"""KUKA KRL programs: a ``.src`` module and its ``.dat`` data list, read together.

What is read (KUKA System Software 8 programming manual, "Data types" and "Motion
programming"; the formats seen in controller backups):

- declarations ``DECL [GLOBAL] E6POS|POS|FRAME NAME={X 1.0,Y 2.0,Z 3.0,A 0.0,B 90.0,C 0.0,
  S 2,T 10,E1 0.0,...}`` (mm; A about z, then B about the new y, then C about the new x,
  degrees; S status and T turn as integers or ``'B010'`` binary literals), array elements
  ``NAME[3]={...}``, and the same aggregates written inline in a motion
  (``LIN {X 10,Y 0,Z 5,A 0,B 90,C 0}``); ``E6AXIS``/``AXIS`` targets (axis values, kept as
  written), declared or inline (``PTP {A1 0,A2 -90,A3 90,A4 0,A5 90,A6 0}``);
- ``DECL FDAT FP1={TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE,...}``: the tool and base a motion
  uses once ``FDAT_ACT=FP1`` and ``BAS(#PTP_PARAMS|#CP_PARAMS, ...)`` load it; also
  ``BAS(#TOOL, n)``, ``BAS(#BASE, n)``, ``$TOOL=TOOL_DATA[n]``, ``$BASE=BASE_DATA[n]``;
- arrays declared without a value (``DECL E6POS XPATH[10]``) whose elements are given
  in the data list (``XPATH[1]={X ...}``);
- motions ``PTP``, ``LIN``, ``CIRC`` (auxiliary and end point), ``SPTP``, ``SLIN``,
  ``SCIRC``; ``..._REL`` motions, system variables (``$POS_ACT``...) and array elements
  indexed by a variable (``XPATH[I]``) are run-time targets;
- ``$config.dat``-style ``TOOL_DATA[n]={X ..,Y ..,Z ..,A ..,B ..,C ..}`` and ``BASE_DATA[n]``
  when such a file is given (frames of the program's tools and bases).

The tool and base in force are tracked in text order through the ``.src`` (branches and
loops are not followed: a tool chosen inside a branch stays chosen after it). ``FDAT``,
``PDAT`` and ``LDAT`` values are kept as written. Comments start with ``;``.
"""

from __future__ import annotations

import bisect
import functools
import re

from ...errors import ParseError
from ..pose_dialects import (JOINTS, POSE, PoseMotion, PoseProgram, PoseTarget, blank_comments,
                             is_finite_number, line_column, line_starts_of)
from ..targets import Number
from ..text_checks import check_closed, check_not_non_finite, check_number_end, check_text
from .frames import FIELD as _FIELD
from .frames import POSE_FIELDS, ToolBase
from .structs import closing_brace, frame_assignments, frame_fields, is_frame_literal, struc_fields

POSE_TYPES = {"E6POS", "POS", "FRAME"}
AXIS_TYPES = {"E6AXIS", "AXIS"}
MOTIONS = ("PTP", "LIN", "CIRC", "SPTP", "SLIN", "SCIRC")

_PREFIX = r"^[ \t]*(?:GLOBAL[ \t]+)?(?:DECL[ \t]+)?(?:GLOBAL[ \t]+)?(?:CONST[ \t]+)?"
_DECL = re.compile(_PREFIX + r"([A-Za-z_]\w*)[ \t]+([A-Za-z_$][\w$]*)"
                   r"[ \t]*(\[[^\]]*\])?[ \t]*=[ \t]*\{", re.I | re.M)
_DECL_ARRAY = re.compile(_PREFIX + r"([A-Za-z_]\w*)[ \t]+([A-Za-z_$][\w$]*)"
                         r"[ \t]*\[[^\]]*\][ \t]*(?:$|[;\r\n])", re.I | re.M)
_NOT_TYPES = {"IF", "WHILE", "UNTIL", "WAIT", "ELSE", "RETURN", "DECL", "GLOBAL", "CONST",
              "REPEAT", "SWITCH", "CASE", "FOR", "LOOP", "ENUM", "STRUC", "SIGNAL"}
_ELEMENT = re.compile(r"^[ \t]*([A-Za-z_$][\w$]*)[ \t]*\[([^\]]*)\][ \t]*=[ \t]*\{", re.M)
_ASSIGNMENT = re.compile(r"^[ \t]*([A-Za-z_$][\w$]*)((?:[ \t]*\[[^\]\r\n]*\])?(?:\.[A-Za-z_$][\w$]*)*)"
                         r"[ \t]*=(?!=)[ \t]*([^\r\n]*)", re.M)
_MOTION = re.compile(r"^[ \t]*(PTP|LIN|CIRC|SPTP|SLIN|SCIRC)(_REL)?\b[ \t]*", re.I | re.M)
_LITERAL_INDEX = re.compile(r"\[\s*\d+\s*(?:,\s*\d+\s*)*\]$")
_NAME_ARG = re.compile(r"([A-Za-z_$][\w$]*(?:\[[^\]]*\])?(?:\.[A-Za-z_]\w*)*)")
_DEFFCT = re.compile(r"^[ \t]*(?:GLOBAL[ \t]+)?DEFFCT[ \t]+\w+[ \t]+([A-Za-z_]\w*)[ \t]*\(",
                     re.I | re.M)

AXIS_FIELDS = ("A1", "A2", "A3", "A4", "A5", "A6")


@functools.lru_cache(maxsize=8)
def strip_comments(text: str) -> str:
    """``text`` with every KRL comment (``;`` to the end of the line) blanked, offsets kept
    (the last few texts are kept: each pass over a module asks for the same)."""
    return blank_comments(text, ";")


def _aggregate_end(text: str, start: int, file: str, starts: list[int]) -> int:
    """Offset just past the ``}`` closing the aggregate whose ``{`` is at ``start``."""
    end = closing_brace(text, start, len(text))
    if end is not None:
        return end
    line, column = line_column(text, start, starts)
    raise ParseError("aggregate '{' is never closed", file, line, column)


def _fields(text: str, lo: int, hi: int) -> dict[str, Number]:
    """The ``NAME value`` fields of the aggregate ``text[lo:hi]`` (upper-case names)."""
    found = {}
    for m in _FIELD.finditer(text, lo, hi):
        found[m.group(1).upper()] = Number(m.start(2), m.end(2), m.group(2))
    return found


def _target(text: str, file: str, starts: list[int], name: str | None, typ: str,
            lo: int, hi: int) -> PoseTarget | None:
    check_not_non_finite(text, lo, hi, file)
    fields = _fields(text, lo, hi)
    for number in fields.values():
        if number.text[:1] not in "'#\"":
            check_number_end(text, number.end, file)
    where = (file, *line_column(text, lo, starts))
    if typ in AXIS_TYPES:
        numbers = tuple(fields[f] for f in AXIS_FIELDS if f in fields)
        return PoseTarget(name=name, source=where, kind=JOINTS, numbers=numbers)
    missing = [f for f in POSE_FIELDS if f not in fields]
    if missing:
        return PoseTarget(name=name, source=where, kind=POSE, numbers=(),
                          config=())               # partial aggregate: a run-time target
    config = tuple(fields[f] for f in ("S", "T") if f in fields)
    for number in config:
        try:
            status_value(number)
        except ValueError:
            line, column = line_column(text, number.start, starts)
            raise ParseError(f"status/turn {number.text} is not an integer from 0 to 65535",
                             file, line, column) from None
    for number in fields.values():
        if number.text[:1] not in "'#\"" and not is_finite_number(number.text):
            line, column = line_column(text, number.start, starts)
            raise ParseError(f"{number.text} is not a finite number", file, line, column)
    return PoseTarget(name=name, source=where, kind=POSE,
                      numbers=tuple(fields[f] for f in POSE_FIELDS), config=config)


def _declarations(text: str, file: str, program: PoseProgram, types: dict[str, str],
                  fdat: dict[str, dict[str, Number]], frames: dict,
                  strucs: dict[str, dict[str, str]] | None = None) -> None:
    """Targets, FDATs and frame data declared in ``text`` (a .dat, a .src or $config.dat):
    with or without ``DECL``, ``GLOBAL``, ``CONST``; frames inside ``STRUC`` values."""
    clean = strip_comments(text)
    starts = line_starts_of(text)
    strucs = {} if strucs is None else strucs
    strucs.update(struc_fields(clean))
    for m in _DECL_ARRAY.finditer(clean):          # DECL E6POS XPATH[10]: elements follow
        if m.group(1).upper() not in _NOT_TYPES:
            types.setdefault(m.group(2).upper(), m.group(1).upper())
    for m in _DECL.finditer(clean):
        typ, name = m.group(1).upper(), m.group(2)
        if typ in _NOT_TYPES:
            continue
        lo = m.end() - 1
        hi = _aggregate_end(clean, lo, file, starts)
        types[name.upper()] = typ
        _value(text, clean, file, starts, program, name, typ, lo, hi, strucs)
        if typ == "FDAT":
            fdat[name.upper()] = _fields(text, lo, hi)
    for m in _ELEMENT.finditer(clean):
        name, index = m.group(1), m.group(2).strip()
        lo = m.end() - 1
        hi = _aggregate_end(clean, lo, file, starts)
        upper = name.upper()
        if upper in ("TOOL_DATA", "BASE_DATA"):
            fields = _fields(text, lo, hi)
            if all(f in fields for f in POSE_FIELDS):
                frames[f"{upper}[{int(index)}]"] = tuple(fields[f].value for f in POSE_FIELDS)
            continue
        _value(text, clean, file, starts, program, f"{name}[{index}]", types.get(upper), lo,
               hi, strucs)

    def six(lo: int, hi: int):
        fields = _fields(text, lo, hi)
        return (tuple(fields[f].value for f in POSE_FIELDS)
                if all(f in fields for f in POSE_FIELDS) else None)

    frame_assignments(clean, six, frames, program.notes,
                      lambda at: f"{file}:{line_column(text, at, starts)[0]}")


def _value(text, clean, file, starts, program, name, typ, lo, hi, strucs) -> None:
    """The targets of one value ``{...}`` of type ``typ``: itself (a pose or axis type), or
    the frame fields of a STRUC value (named ``name.field``)."""
    if typ in POSE_TYPES or typ in AXIS_TYPES:
        target = _target(text, file, starts, name, typ, lo, hi)
        if target is not None:
            program.targets.append(target)
    elif typ in strucs:
        for field, f_lo, f_hi in frame_fields(clean, lo, hi, strucs[typ], POSE_TYPES | AXIS_TYPES):
            f_typ = strucs[typ][field.upper()]
            target = _target(text, file, starts, f"{name}.{field}", f_typ, f_lo, f_hi)
            if target is not None:
                program.targets.append(target)


def read_frames(text: str, file: str) -> dict[str, tuple[float, ...]]:
    """``TOOL_DATA[n]`` and ``BASE_DATA[n]`` of a ``$config.dat`` text: name -> (X, Y, Z mm,
    A, B, C deg)."""
    program = PoseProgram("krl", {file: text}, [], [])
    frames: dict = {}
    _declarations(text, file, program, {}, {}, frames)
    return frames


def _statement_text(clean: str, start: int) -> str:
    """The statement starting at ``start``, continued over lines that end with a comma
    (a ``WITH`` clause spread over several lines)."""
    end = start
    while True:
        nl = clean.find("\n", end)
        if nl < 0:
            return clean[start:]
        if not clean[end:nl].rstrip().endswith(","):
            return clean[start:nl]
        end = nl + 1


def _motions(text: str, file: str, program: PoseProgram, frames: ToolBase) -> None:
    """The motions of a ``.src`` text, with the tool and base in force at each."""
    clean = strip_comments(text)
    starts0 = line_starts_of(text)
    functions = {m.group(1).upper(): line_column(text, m.start(), starts0)[0]
                 for m in _DEFFCT.finditer(clean)}
    starts = line_starts_of(text)
    motion_at = {m.start(): m for m in _MOTION.finditer(clean)}
    line_bounds = list(zip(starts, starts[1:] + [len(clean)]))
    for number, (lo, hi) in enumerate(line_bounds, 1):
        line = clean[lo:hi]
        frames.statement(line, number)
        m = _MOTION.match(clean, lo)
        if m is None or m.start() not in motion_at or m.end() > hi + 1:
            continue
        instruction = m.group(1).upper() + (m.group(2) or "").upper()
        where = (file, *line_column(text, m.start(1), starts))
        if instruction[0] == "S":
            frames.with_clause(_statement_text(clean, m.start()))
        args = []
        k = m.end()
        for _ in range(2 if instruction.startswith(("CIRC", "SCIRC")) else 1):
            arg, k = _operand(text, clean, file, starts, program, k)
            if arg is None:
                break
            after = _skip_blanks(clean, k)
            if after < len(clean) and clean[after] == ":":            # geometric operator
                right, k = _operand(text, clean, file, starts, program, after + 1)
                if right is None:
                    program.unknown.append((where, instruction))
                    break
                arg = (arg, right)
            elif after < len(clean) and clean[after] == "(" and arg[0] is not None:
                k = after
                arg = (f"{arg[0]}(..)", None, "call")
            args.append(arg)
        if not args:
            program.unknown.append((where, instruction))
            continue
        for arg in args:
            program.motions.append(_motion(program, instruction, where, arg, frames, functions))


def _skip_blanks(clean: str, k: int) -> int:
    while k < len(clean) and clean[k] in " \t":
        k += 1
    return k


def _operand(text, clean, file, starts, program, k):
    """((name, inline index, kind), end) of the motion operand at ``k`` (an inline aggregate
    is appended to ``program.targets``), or (None, k)."""
    while k < len(clean) and clean[k] in " \t,":
        k += 1
    if k < len(clean) and clean[k] == "{":
        end = _aggregate_end(clean, k, file, starts)
        fields = _fields(text, k, end)
        typ = ("E6AXIS" if "X" not in fields and any(f in fields for f in AXIS_FIELDS)
               else "E6POS")              # PTP {A1 0, A2 -90, ...}: axis values
        program.targets.append(_target(text, file, starts, None, typ, k, end))
        return (None, len(program.targets) - 1, "inline"), end
    name = _NAME_ARG.match(clean, k)
    if name is None:
        return None, k
    return (name.group(1), None, "name"), name.end()


def _runtime(program: PoseProgram, instruction: str, name: str | None, inline: int | None,
             kind: str, functions: dict[str, int]) -> str | None:
    """Why the operand's target is known only at run time, or None."""
    if instruction.endswith("_REL"):
        return f"{instruction} moves relative to where the robot is at run time"
    if kind == "call":
        function = name[:-4]
        line = functions.get(function.upper())
        where = f" (DEFFCT at line {line} of this file)" if line else ""
        return f"{name} is the result of the function {function}{where}, known only at run time"
    if name is not None and name.startswith("$"):
        return f"{name} is a system variable, known only at run time"
    if name is not None and "[" in name and not _LITERAL_INDEX.search(name.split(".")[0]):
        return f"{name} is indexed at run time"
    if inline is not None and not program.targets[inline].numbers:
        return "the aggregate leaves some of X, Y, Z, A, B, C to the current position"
    return None


def _motion(program: PoseProgram, instruction: str, where, arg, frames: ToolBase,
            functions: dict[str, int]) -> PoseMotion:
    """The motion to one operand (a name, an inline aggregate, a call, or ``left : right``)."""
    if len(arg) == 2:                                      # left : right
        (l_name, l_inline, l_kind), (r_name, r_inline, r_kind) = arg
        left_text = l_name or "{...}"
        why = (_runtime(program, instruction, l_name, l_inline, l_kind, functions)
               or _runtime(program, instruction, r_name, r_inline, r_kind, functions))
        if why is not None:
            why = f"{left_text} : {r_name or '{...}'}: {why}"
        elif frames.unknown_frame() is not None:
            why = frames.unknown_frame()
        elif l_name is None or r_inline is None:
            why = (f"{left_text} : {r_name or '{...}'} is composed with the geometric "
                   f"operator; only 'point : {{literal}}' is written back (into the literal)")
        return PoseMotion(instruction=instruction, target=r_name, source=where,
                          tool=frames.tool, base=frames.base, inline=r_inline, runtime=why,
                          left=l_name)
    name, inline, kind = arg
    return PoseMotion(instruction=instruction, target=name, source=where, tool=frames.tool,
                      base=frames.base, inline=inline,
                      runtime=(_runtime(program, instruction, name, inline, kind, functions)
                               or frames.unknown_frame()))


def parse_krl(src_text: str | None, dat_text: str | None, src_file: str = "<src>",
              dat_file: str = "<dat>", config_text: str | dict[str, str] | None = None,
              config_file: str = "$config.dat") -> PoseProgram:
    """Read a KRL module (either text may be None: a ``.dat`` alone holds targets but no
    motion) and, optionally, the controller's ``$config.dat`` (``config_text``, or several
    such files as file -> text) with the tool and base data and points (``XHOME``): a
    motion to a point declared only there is solved with its value, reported as
    ``config_point`` (that file is not written)."""
    configs = ({config_file: config_text} if isinstance(config_text, str)
               else dict(config_text or {}))
    texts = {}
    if src_text is not None:
        texts[src_file] = src_text
    if dat_text is not None:
        texts[dat_file] = dat_text
    for name, text in {**texts, **configs}.items():
        check_text(text, name)
        check_closed(text, strip_comments(text), name, _BLOCKS)
    program = PoseProgram(dialect="krl", texts=texts, targets=[], motions=[])
    types: dict[str, str] = {}
    fdat: dict[str, dict[str, Number]] = {}
    strucs: dict[str, dict[str, str]] = {}
    config_points = PoseProgram("krl", dict(configs), [], [])
    for name, text in configs.items():
        _declarations(text, name, config_points, types, fdat, program.frames, strucs)
    program.notes.extend(config_points.notes)
    if dat_text is not None:
        _declarations(dat_text, dat_file, program, types, fdat, program.frames, strucs)
    if src_text is not None:
        _declarations(src_text, src_file, program, types, fdat, program.frames, strucs)
        _motions(src_text, src_file, program, ToolBase(fdat, program.frames))
        _assignments(src_text, src_file, program)
    _resolve_names(program, config_points)
    return program


_BLOCKS = (("DEFDAT", "ENDDAT"), ("DEFFCT", "ENDFCT"), ("DEF", "END"))


def _assignments(text: str, file: str, program: PoseProgram) -> None:
    """Assignments in a ``.src``: a motion to a name the program assigns (``XP1 = ...``,
    ``XP1.Z = ...``) moves to a value known at run time; a frame or pose literal assigned
    that is no target read gets a row (a tool, base or load frame: ``frame``; else
    ``runtime``)."""
    clean = strip_comments(text)
    starts: list[int] = []

    def place(offset: int) -> tuple[int, int]:
        if not starts:
            starts.extend(line_starts_of(text))
        return line_column(text, offset, starts)

    covered = sorted(n.start for t in program.targets if t.source[0] == file
                     for n in t.numbers)
    assigned: dict[str, int] = {}                       # name -> offset of its first assignment
    for m in _ASSIGNMENT.finditer(clean):
        name, rest, value = m.group(1), m.group(2), m.group(3)
        if name.upper() in _NOT_TYPES:
            continue
        if not (rest.startswith("[") and _LITERAL_INDEX.search(rest.split(".")[0].strip())
                and value.lstrip().startswith("{") and "." not in rest):
            assigned.setdefault(name.upper(), m.start(1))
        for brace in re.finditer(r"\{", value):
            lo = m.start(3) + brace.start()
            if clean[lo - 1:lo] == "{" or not is_frame_literal(clean, lo):
                continue
            place(lo)                                      # the line starts, once
            hi = _aggregate_end(clean, lo, file, starts)
            k = bisect.bisect_left(covered, lo)
            if k < len(covered) and covered[k] < hi:      # a target read already
                continue
            system = name.startswith("$") or name.upper() in ("TOOL_DATA", "BASE_DATA")
            what = (f"a frame assigned to {name}{rest} by the program at run time, not a "
                    f"target; kept as written" if system else
                    f"assigned to {name}{rest} by the program at run time (line "
                    f"{place(m.start(1))[0]}); kept as written")
            program.kept.append(((file, *place(lo)), f"{name}{rest}",
                                 "frame" if system else "runtime", what))
    for k, motion in enumerate(program.motions):
        base = (motion.target or "").split("[")[0].split(".")[0].upper()
        if motion.runtime is None and motion.inline is None and base in assigned:
            program.motions[k] = motion._replace(runtime=(
                f"{motion.target} is assigned by the program (line "
                f"{place(assigned[base])[0]}): the value moved to is known only at run time"))


def _resolve_names(program: PoseProgram, config_points: PoseProgram) -> None:
    """Points only ``$config.dat`` declares join the program (that file kept unwritten);
    a motion to an array element indexed at run time may move to every element."""
    declared = {t.name.upper() for t in program.targets if t.name}
    wanted = {(m.target or "").upper() for m in program.motions} | \
             {(m.left or "").upper() for m in program.motions}
    for target in config_points.targets:
        if target.name and target.name.upper() in wanted - declared:
            program.targets.append(target)
            file = target.source[0]
            program.texts.setdefault(file, config_points.texts[file])
            program.external[file] = ("config_point", "a point of the controller's data "
                                                      "list, not of this program")
    names = [t.name for t in program.targets if t.name]
    for k, motion in enumerate(program.motions):
        if motion.runtime is None or "indexed at run time" not in motion.runtime:
            continue
        m = re.fullmatch(r"([^\[]+)\[[^\]]*\](.*)", motion.target or "")
        if m is None:
            continue
        element = re.compile(re.escape(m.group(1)) + r"\[\s*\d+\s*(?:,\s*\d+\s*)*\]"
                             + re.escape(m.group(2)), re.I)
        found = tuple(n for n in names if element.fullmatch(n))
        if found:
            program.motions[k] = motion._replace(candidates=found)


def status_text(original: Number, value: int) -> str:
    """``value`` written as ``original`` wrote S or T: decimal, ``'B0110'`` (as many digits
    as the original, more if needed) or ``'H1A'``."""
    text = original.text
    if text.startswith("'") and text[1:2].upper() == "B":
        digits = len(text) - 3
        return f"'{text[1]}{value:0{digits}b}'"
    if text.startswith("'") and text[1:2].upper() == "H":
        digits = len(text) - 3
        return f"'{text[1]}{value:0{digits}X}'"
    return str(int(value))


def status_value(number: Number) -> int:
    """The integer of an S or T as written (decimal, ``'B...'`` or ``'H...'``)."""
    text = number.text
    if text.startswith("'"):
        base = 2 if text[1:2].upper() == "B" else 16
        return int(text[2:-1] or "0", base)
    value = float(text)
    if value != int(value) or not 0 <= value < 1 << 16:
        raise ValueError(f"{text} is not a status or turn value")
    return int(value)
