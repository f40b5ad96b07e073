"""The RAPID parser's two hot paths (whole runs of simple statements).

The grammar hands over runs of one-line declarations (FAST_DECLS) and calls (FAST_CALLS) as
single tokens; the lexer callbacks here split them with anchored regular expressions, in
text order. The plainest forms (a module-level ``CONST robtarget p := [...]`` and
``MoveL p, v, z, tool\\WObj:=w``) each take one regex match and become a model object at
once, or (a column parse) a row of the parse's tables (columns.py); the others become the
same records the grammar rules produce (``Sink``), so one builder (build.py) handles both.
A motion call these regexes cannot read is parsed again by the grammar (start symbol
``call``), which gives the exact error if it is wrong.
"""

from __future__ import annotations

import functools
import re
from sys import intern

from lark import Token

from ..grammar import current_sink
from ..literals import NUMBER_GROUP, ROBTARGET_PATTERN
from ..regex_compat import portable
from ..targets import QUAT_WXYZ, CartesianTarget, MotionUse, RuntimeTarget, SourceLocation
from .instructions import RUNTIME_FUNCS
from .records import Arg, Decl, Ex, Opt, Sink, call_record_of


# ---- the two hot-path tokens: runs split in the whole program text (offsets are then its own),
# between the token's start and end; each statement's pattern takes the blanks and
# comments after it too, so the next statement starts where its match ends.

# blanks and comments, possessive: at the end of a pattern (its only use) the same match as
# greedy, without backtracking state
_SEP = portable(r"(?:[ \t\r\n\f]++|![^\r\n]*+)*+")   # (see .regex_compat)
_SEP_RE = re.compile(_SEP)
_FAST_DECL = re.compile(
    r"(?:(LOCAL|TASK)[ \t]+)?(CONST|PERS|VAR)[ \t]+([A-Za-z_][A-Za-z0-9_]*)[ \t]+"
    r"([A-Za-z_][A-Za-z0-9_]*)[ \t]*(?:\{([^{}]*)\}[ \t]*)?:=[ \t\r\n]*(\[[^\"!;]*\])[ \t]*;"
    + _SEP, re.I)

# a plain robtarget declaration: storage, type word, name, literal and its 17 numbers
_FAST_ROBTARGET_PATTERN = (
    r"(?:(?i:LOCAL|TASK)[ \t]+)?((?i:CONST|PERS|VAR))[ \t]+((?i:robtarget))[ \t]+"
    r"([A-Za-z_][A-Za-z0-9_]*)[ \t]*:=[ \t\r\n]*(" + ROBTARGET_PATTERN + r")[ \t]*;" + _SEP)
# the same without blanks inside the literal, as most are written, and ASCII only (\d is
# [0-9], keywords fold ASCII case only; the same as Unicode in latin-1 text): a fifth
# faster; wherever it matches, the general one matches the same text with the same groups
# (and reads what it refuses: non-ASCII digits, 'ſ' for 's')
_TIGHT_ROBTARGET_PATTERN = _FAST_ROBTARGET_PATTERN.replace(r"[ \t\r\n\f]*+", "")
_STORAGE = {"CONST": "CONST", "PERS": "PERS", "VAR": "VAR"}


def _row_pattern(pattern: str) -> str:
    """``pattern`` (a robtarget declaration) capturing, of the literal's 17 numbers, only
    the first (x) and the seventh (q4): groups storage, type word, name, literal, x, q4.
    It matches the same texts; a column parse reads the numbers in one batch afterwards,
    and a match with 6 groups instead of 21 takes a third less time."""
    pieces = pattern.split(NUMBER_GROUP)
    assert len(pieces) == 18, "a robtarget declaration has 17 numbers"
    quiet = "(?:" + NUMBER_GROUP[1:]
    return pieces[0] + "".join((NUMBER_GROUP if k in (0, 6) else quiet) + piece
                               for k, piece in enumerate(pieces[1:]))


@functools.cache
def robtarget_regexes(rows: bool) -> tuple[re.Pattern, re.Pattern]:
    """(tight, general) regexes of a plain robtarget declaration; ``rows``: the column
    parse's forms (:func:`_row_pattern`), else the full ones (groups storage, type word,
    name, literal, its 17 numbers). Compiled on first use (3 to 4 ms a pair): a run of
    olp-fix, which parses in columns, compiles only the row forms."""
    tight, general = _TIGHT_ROBTARGET_PATTERN, _FAST_ROBTARGET_PATTERN
    if rows:
        tight, general = _row_pattern(tight), _row_pattern(general)
    return re.compile(tight, re.ASCII), re.compile(general)


def _on_fast_decls(tok: Token) -> Token:
    """Lexer callback: split a FAST_DECLS run (see _split_fast_decls)."""
    _split_fast_decls(tok, current_sink.get())
    return tok


def _split_fast_decls(tok: Token, sink: Sink) -> None:
    """Record the declarations of a FAST_DECLS run (anchored, in order). At module level
    a plain robtarget becomes a target at once (one regex match for the whole
    declaration), in a column parse a routine's ``VAR``/``CONST`` one too (a table row
    with its routine); the others are appended to ``sink.decls``."""
    text, pos, end = sink.text, tok.start_pos, tok.end_pos
    out, match = sink.decls, _FAST_DECL.match
    plain = sink.depth == 0 or sink.columns is not None   # a column parse: routines' too
    while pos < end:
        if plain:
            pos = _plain_robtargets(sink, text, pos, end)
            if pos >= end:
                break
        m = match(text, pos, end)
        dims = m.group(5)
        out.append(Decl(scope=m.group(1), storage=m.group(2).upper(), type_name=m.group(3),
                        type_span=m.span(3), name=m.group(4), name_pos=m.start(4),
                        rank=dims.count(",") + 1 if dims is not None else 0,
                        value=Ex(m.start(6), m.end(6), "aggregate"), start=pos))
        pos = m.end()


def _plain_robtargets(sink: Sink, text: str, pos: int, end: int) -> int:
    """Record the plain robtarget declarations from ``pos`` on (one regex match each; the
    blank-free form first, and whichever read the previous declaration goes first): as
    rows of ``sink.columns.targets`` (a column parse, placed in lines afterwards), else as
    CartesianTarget objects in ``sink.targets``. Returns the offset after them."""
    if sink.columns is not None:
        first, second = (rx.match for rx in robtarget_regexes(rows=True))
        add, routine = sink.columns.targets.append, sink.routine
        while True:
            m = first(text, pos, end)
            if m is None:
                m = second(text, pos, end)
                if m is None:
                    return pos
                first, second = second, first
            if sink.depth and (m.start(1) != pos or m.group(1).upper() == "PERS"):
                return pos   # not a routine's data (LOCAL, TASK, PERS): the builder says
            add(m.group(3), m.group(1), m.regs, routine)   # then the run it starts, at once
            pos = sink.columns.targets.run(m.re, text, m.end(), end, routine, sink.depth > 0)
    first, second = (rx.match for rx in robtarget_regexes(rows=False))
    append, file = sink.targets.append, sink.file
    count, rfind = text.count, text.rfind
    index = sink.index
    last, line, line_start = index.position()  # sink.index.line_col, inlined (text order)
    while True:
        m = first(text, pos, end)
        if m is None:
            m = second(text, pos, end)
            if m is None:
                break
            first, second = second, first
        a = m.start(3)
        if a >= last:
            breaks = count("\n", last, a)
            if breaks:
                line += breaks
                line_start = rfind("\n", last, a) + 1
            last = a
            append(_target_of(m, file, line, a - line_start + 1))
        else:
            append(_target_of(m, file, *index.line_col(a)))
        pos = m.end()
    index.moved(last, line, line_start)
    return pos


_ROBTARGET_NUMBERS = range(5, 22)


def _target_of(m: re.Match, file: str, line: int, column: int) -> CartesianTarget:
    """The CartesianTarget of a plain declaration match (the full regexes' groups)."""
    g = m.groups()
    storage = g[0]
    return CartesianTarget(
        name=g[2], source=(file, line, column), texts=g[4:],
        starts=tuple(map(m.start, _ROBTARGET_NUMBERS)), orientation_kind=QUAT_WXYZ,
        span=m.span(4), storage=_STORAGE.get(storage) or storage.upper(), array_index=None,
        routine=None, type_span=m.span(2))


def _enter_routine(tok: Token) -> Token:
    sink = current_sink.get()
    sink.depth += 1
    sink.pending = 2 if tok.type == "FUNC" else 1  # FUNC <type> <name>, PROC/TRAP <name>
    return tok


def _on_name(tok: Token) -> Token:
    sink = current_sink.get()
    if sink.pending:
        sink.pending -= 1
        if not sink.pending:
            sink.routine = tok.value
    return tok


def _leave_routine(tok: Token) -> Token:
    sink = current_sink.get()
    sink.depth -= 1
    sink.routine = None
    return tok


# a function call whose arguments are names, numbers and their sums and products (``Offs(p,
# 0, 0, dz)``, ``RelTool(p{2}, 0, 0, -20\Rz:=45)``), read whole; any other call (nested,
# strings, empty arguments) is left to the grammar, which reads it or says why not
_TERM = (r"-?(?:[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*(?:\{[^{}]*\})?"
         r"|(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")
_SUM = _TERM + r"(?:[ \t]*[-+*/][ \t]*" + _TERM + r")*"
_CALL_ARG = (r"[ \t]*" + _SUM + r"(?:[ \t]*\\[A-Za-z_]\w*(?:[ \t]*:=[ \t]*" + _SUM + r")?)*"
             r"[ \t]*")
_CALL_VAL = r"[A-Za-z_]\w*\(" + _CALL_ARG + r"(?:," + _CALL_ARG + r")*\)"
_VAL = portable(_CALL_VAL + r"|-?(?:[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*"
                r"|(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
                r"(?:\{[^{}]*\})?|\[(?:[^\[\]]++|\[[^\[\]]*+\])*+\]|\*")
_FAST_ITEM = re.compile(r"""
    [ \t]*(?:
      \\(?P<opt>[A-Za-z_]\w*)(?:[ \t]*(?P<op>:=|\?)[ \t]*(?P<oval>VAL))?
    | (?P<val>VAL)
    )?[ \t]*(?P<sep>[,;])?""".replace("VAL", _VAL), re.X)
_NAME_RE = re.compile(r"[A-Za-z_]\w*")
_IDX_RE = re.compile(r"([A-Za-z_]\w*)\{([^{}]*)\}")
_CALL_RE = re.compile(r"([A-Za-z_]\w*)\(\s*([A-Za-z_]\w*(?=\s*[,){\\]))?")


def value_ex(text: str, start: int, end: int) -> Ex:
    """The Ex of a fast-path value ``text[start:end]``: name, name{index}, number,
    aggregate, ``*``, function call (only its name and first argument's name are read),
    field chain, or anything else ("expr")."""
    c = text[start]
    if c == "[":
        return Ex(start, end, "aggregate")
    if c == "*":
        return Ex(start, end, "star")
    if c.isalpha() or c == "_":
        s = text[start:end]
        if s.isidentifier():
            return Ex(start, end, "name", s)
        if s[-1] == ")":
            m = _CALL_RE.match(s)
            first = [Arg(Ex(0, 0, "name", m.group(2)), ())] if m.group(2) else []
            return Ex(start, end, "call", m.group(1), None, first)
        if "{" in s:
            m = _IDX_RE.fullmatch(s)
            if m is None:
                return Ex(start, end, "complex", _NAME_RE.match(s).group())
            base = start + m.start(2)
            idx = []
            pos = 0
            for part in m.group(2).split(","):
                a = base + pos + (len(part) - len(part.lstrip()))
                b = base + pos + len(part.rstrip())
                idx.append(Ex(a, b, "num" if part.strip().isdigit() else "expr"))
                pos += len(part) + 1
            return Ex(start, end, "index", m.group(1), idx)
        return Ex(start, end, "complex", _NAME_RE.match(s).group())
    return Ex(start, end, "num" if c != "-" else "expr")


# MoveL/MoveJ <name or name{k}>, <speed>, <zone>, <tool>[\WObj:=<wobj>]; in one match:
# instruction, target (name, index), tool, wobj, () where the arguments end; the same with
# an inline robtarget (as RoboDK writes them): instruction, literal and its 17 numbers,
# tool, wobj, () where the arguments end
_PLAIN = portable(r"(?:[A-Za-z_][A-Za-z0-9_]*+(?:\.[A-Za-z_][A-Za-z0-9_]*+)*+"
                  r"|(?:\d++\.?+\d*+|\.\d++)(?:[eE]\d++)?+)")  # a name (field chain), a number
_MOVE_TAIL = (r"[ \t]*,[ \t]*" + _PLAIN + r"[ \t]*,[ \t]*" + _PLAIN + r"[ \t]*,[ \t]*"
              r"([A-Za-z_][A-Za-z0-9_]*)"
              r"(?:[ \t]*\\(?i:WObj)[ \t]*:=[ \t]*([A-Za-z_][A-Za-z0-9_]*))?()[ \t]*;" + _SEP)
_MOVE = r"((?i:MoveL|MoveJ))[ \t]+"
_NAMED = r"(([A-Za-z_][A-Za-z0-9_]*)(?:\{[ \t]*(\d+)[ \t]*\})?)"
_SIMPLE_MOVE = re.compile(_MOVE + _NAMED + _MOVE_TAIL)
_INLINE_MOVE = re.compile(_MOVE + "(" + ROBTARGET_PATTERN + ")" + _MOVE_TAIL)
_INLINE_NUMBERS = range(3, 20)
# MoveL/MoveJ Offs(<name>, <number>, <number>, <number>) or RelTool(...) of the same form
# (three numbers, no optional argument): instruction, target expression, function, its
# target's name, tool, wobj, () where the arguments end
_OFFSET = (r"(((?i:Offs|RelTool))\([ \t]*([A-Za-z_][A-Za-z0-9_]*)"
           r"(?:[ \t]*,[ \t]*-?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?){3}[ \t]*\))")
_DISPLACED_MOVE = re.compile(_MOVE + _OFFSET + _MOVE_TAIL)
# either (a column parse's runs of both, one match each): instruction, expression, function,
# its target's name, target, name, index, tool, wobj, () where the arguments end (columns.
# MIXED_GROUPS). Offs()/RelTool() first (no text is both): tried second, a displaced move
# gives back its function's name letter by letter, a fifth slower (realistic benchmark)
_MIXED_MOVE = re.compile(_MOVE + "(?:" + _OFFSET + "|" + _NAMED + ")" + _MOVE_TAIL)


def _on_fast_calls(tok: Token) -> Token:
    """Lexer callback: split a FAST_CALLS run (see _split_fast_calls)."""
    _split_fast_calls(tok, current_sink.get())
    return tok


def _split_fast_calls(tok: Token, sink: Sink) -> None:
    """Record the calls of a FAST_CALLS run (anchored, in order).

    MoveL/MoveJ of the plainest form (and of Offs()/RelTool(): :func:`_plain_moves`)
    become MotionUse, or table rows, at once (one regex match each); other argument
    lists are split by one regex (plain values and optional arguments) or item by item.
    A motion instruction whose arguments none of these reads is parsed again by the
    grammar (start symbol ``call``), which records it or raises the error; so is any
    other call whose arguments they do not read."""
    text, pos, end = sink.text, tok.start_pos, tok.end_pos
    out, inline, displaced = sink.calls, _INLINE_MOVE.match, _DISPLACED_MOVE.match
    name_match, skip = _NAME_RE.match, _SEP_RE.match
    while pos < end:
        pos = _plain_moves(sink, text, pos, end)
        if pos >= end:
            break
        m = inline(text, pos, end)
        if m is not None:
            _direct_inline_move(sink, m)
            pos = m.end()
            continue
        m = displaced(text, pos, end)
        if m is not None:
            _displaced_move(sink, m)
            pos = m.end()
            continue
        semi = text.index(";", pos, end)
        ne = name_match(text, pos, end).end()
        name = text[pos:ne]
        seg = text[ne:semi]
        if "[" in seg or "{" in seg or "(" in seg:
            items = _items_regex(text, ne, end)
        else:
            items = _items_split(seg, ne)
        if items is not None:
            out.append(call_record_of(name, pos, ne, items[0], items[1]))
        elif not sink.reparsing:   # the grammar reads it (a target may hide in it), or
            sink.reparse(pos, semi + 1)   # says why not
        pos = skip(text, semi + 1, end).end()


def _plain_moves(sink: Sink, text: str, pos: int, end: int) -> int:
    """Record the plainest MoveL/MoveJ from ``pos`` on: as rows of ``sink.columns.moves``
    (a column parse, placed in lines afterwards), else as MotionUse objects in
    ``sink.motions``. Returns the offset after them."""
    match, routine = _SIMPLE_MOVE.match, sink.routine
    if sink.columns is not None:
        moves = sink.columns.moves
        while (m := match(text, pos, end)) is not None:   # then the run it starts, at once
            regs = m.regs
            moves.append(*m.group(1, 3, 4, 5, 6), routine, (*regs[1], pos, regs[7][0], *regs[2]))
            pos = moves.run(m.re, text, m.end(), end, routine)
        if sink.displaced is None:   # from an Offs()/RelTool() on, both kinds, as rows
            return pos
        return moves.run_mixed(_MIXED_MOVE, text, pos, end, routine, sink.displaced)
    append, file = sink.motions.append, sink.file
    count, rfind = text.count, text.rfind
    index = sink.index
    last, line, line_start = index.position()  # sink.index.line_col, inlined (text order)
    while (m := match(text, pos, end)) is not None:
        a = m.start(2)
        if a >= last:
            breaks = count("\n", last, a)
            if breaks:
                line += breaks
                line_start = rfind("\n", last, a) + 1
            last = a
            append(_use_of(m, pos, file, line, a - line_start + 1, routine))
        else:
            append(_use_of(m, pos, file, *index.line_col(a), routine))
        pos = m.end()
    index.moved(last, line, line_start)
    return pos


def _use_of(m: re.Match, start: int, file: str, line: int, column: int,
            routine: str | None) -> MotionUse:
    """The MotionUse of a _SIMPLE_MOVE match starting at ``start``."""
    instruction, name, number, tool, wobj = m.group(1, 3, 4, 5, 6)
    return MotionUse(
        instruction=instruction, source=(file, line, column), role="to", target_name=name,
        target_index=None if number is None else (int(number),), inline=None, runtime=None,
        tool=tool, tool_inline=None, wobj=wobj, wobj_inline=None, joint=False,
        routine=routine, instruction_span=m.span(1), statement_span=(start, m.start(7)),
        target_span=m.span(2))


def _direct_inline_move(sink: Sink, m: re.Match) -> None:
    """Append the MotionUse and the inline target of an _INLINE_MOVE match."""
    span = m.span(2)
    line, col = sink.index.line_col(span[0])
    source = (sink.file, line, col)
    target = CartesianTarget(name=None, source=source, texts=m.groups()[2:19],
                             starts=tuple(map(m.start, _INLINE_NUMBERS)),
                             orientation_kind=QUAT_WXYZ, span=span, storage="inline",
                             routine=sink.routine)
    sink.targets.append(target)
    sink.motions.append(MotionUse(
        instruction=m.group(1), source=source, role="to", inline=target,
        tool=m.group(20), wobj=m.group(21), routine=sink.routine,
        instruction_span=m.span(1), statement_span=(m.start(), m.start(22)),
        target_span=span))


def _displaced_move(sink: Sink, m: re.Match) -> None:
    """Append the MotionUse and the RuntimeTarget of a _DISPLACED_MOVE match: the objects
    the builder makes of the same call (build.py ``Builder.call``), without its records."""
    span = m.span(2)
    line, col = sink.index.line_col(span[0])
    instruction, expression, function, tool, wobj = m.group(1, 2, 3, 5, 6)
    # one string per distinct word (a module holds thousands of these motions)
    instruction, tool = intern(instruction), intern(tool)
    reason = intern(f"{RUNTIME_FUNCS[function.lower()]} ({instruction})")
    wobj = None if wobj is None else intern(wobj)
    runtime = RuntimeTarget(
        expression=expression, location=SourceLocation(sink.file, line, col),
        reason=reason, base_name=m.group(4), routine=sink.routine, span=span)
    sink.runtime.append(runtime)
    sink.motions.append(MotionUse(
        instruction=instruction, source=(sink.file, line, col), role="to", runtime=runtime,
        tool=tool, wobj=wobj, routine=sink.routine,
        instruction_span=m.span(1), statement_span=(m.start(), m.start(7)),
        target_span=span))


_ARG_VAL = r"(-?(?:[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*|(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|\*)"
_ARG_OPTS = r"((?:[ \t]*\\[A-Za-z_]\w*(?:[ \t]*(?::=|\?)[ \t]*-?[A-Za-z0-9_.]+)?)*)"
_ARG_ITEM = r"[ \t]*" + _ARG_VAL + r"?" + _ARG_OPTS + r"[ \t]*"
_OPT_RE = re.compile(r"\\([A-Za-z_]\w*)(?:[ \t]*(:=|\?)[ \t]*(-?[A-Za-z0-9_.]+))?")
_ARGS_RES: dict[int, re.Pattern] = {}


def _args_re(n: int) -> re.Pattern:
    """A regex for n comma-separated simple items (value and/or optional arguments)."""
    r = _ARGS_RES.get(n)
    if r is None:
        r = _ARGS_RES[n] = re.compile(r"(?:[ \t]+|(?=\\))" + ",".join([_ARG_ITEM] * n))
    return r


def _items_split(seg: str, base: int):
    """(positional spans, opts) of a bracket-free argument list by one regex match, or
    None when it is not a list of simple values and optional arguments."""
    positional: list = []
    opts: list = []
    if not seg or seg.isspace():
        return positional, opts
    n = seg.count(",") + 1
    m = _args_re(n).fullmatch(seg)
    if m is None:
        return None
    regs = m.regs
    for k in range(1, 2 * n, 2):
        a, b = regs[k]
        if a >= 0:
            positional.append((base + a, base + b))
        elif regs[k + 1][0] == regs[k + 1][1]:
            return None  # an empty argument
        a, b = regs[k + 1]
        if a != b:
            for o in _OPT_RE.finditer(seg, a, b):
                if o.group(2) == ":=":
                    opts.append(Opt(o.group(1), (base + o.start(3), base + o.end(3)), None,
                                    base + o.start(), base + o.end()))
                elif o.group(2) == "?":
                    if not o.group(3).isidentifier():
                        return None
                    opts.append(Opt(o.group(1), None, o.group(3), base + o.start(),
                                    base + o.end()))
                else:
                    opts.append(Opt(o.group(1), None, None, base + o.start(),
                                    base + o.end()))
    return positional, opts


def _items_regex(text: str, pos: int, end: int):
    """(positional spans, opts) of the arguments from ``pos`` to the ';' (not beyond
    ``end``), read item by item with a strict regex, or None."""
    positional: list = []
    opts: list = []
    item_match = _FAST_ITEM.match
    has_value = has_opt = False  # within the current comma-separated item
    if text[pos] not in " \t\\":
        return None
    while True:
        m = item_match(text, pos, end)
        if m.end() == pos:
            return None
        pos = m.end()
        if m.group("opt") is not None:
            has_opt = True
            bs = m.start("opt") - 1
            if m.group("oval") is None:
                opts.append(Opt(m.group("opt"), None, None, bs, m.end("opt")))
            elif m.group("op") == "?":
                if not m.group("oval").isidentifier():
                    return None
                opts.append(Opt(m.group("opt"), None, m.group("oval"), bs,
                                m.end("oval")))
            else:
                span = (m.start("oval"), m.end("oval"))
                opts.append(Opt(m.group("opt"), span, None, bs, span[1]))
        elif m.group("val") is not None:
            if has_value or has_opt:  # two values, or a value after \opt, in one item
                return None
            has_value = True
            positional.append((m.start("val"), m.end("val")))
        sep = m.group("sep")
        if sep is not None and not (has_value or has_opt):
            return None  # an empty argument
        if sep == ";":
            return positional, opts
        if sep == ",":
            has_value = has_opt = False
        elif m.group("opt") is None and m.group("val") is None:
            return None


LEXER_CALLBACKS = {
    "FAST_DECLS": _on_fast_decls, "FAST_CALLS": _on_fast_calls, "NAME": _on_name,
    "PROC": _enter_routine, "FUNC": _enter_routine, "TRAP": _enter_routine,
    "ENDPROC": _leave_routine, "ENDFUNC": _leave_routine, "ENDTRAP": _leave_routine}
"""Token callbacks (lark ``lexer_callbacks``): they run in text order, as tokens are read."""
