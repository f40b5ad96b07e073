"""``--emit joints``: Cartesian targets rewritten as joint targets, by splice edits.

RAPID: ``robtarget`` declarations become ``jointtarget`` ones and MoveL/MoveJ become
MoveAbsJ; V+: transformations become precision points (``#name``). Joint values are
written in degrees with :data:`~.number_format.DEG_DECIMALS` decimals.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from ..errors import DataError
from .number_format import DEG_DECIMALS, check_values, finite_floats, format_like
from .targets import CartesianTarget, Edit, MotionUse, Program


_JOINT_MOVES = {"movel": "MoveAbsJ", "movej": "MoveAbsJ"}


def _like_case(word: str, original: str) -> str:
    if original.isupper():
        return word.upper()
    if original.islower():
        return word.lower()
    return word


def joint_emit_edits(program: Program,
                     joints: Mapping[CartesianTarget, Iterable[float]]) -> list[Edit]:
    """Edits turning Cartesian targets into joint targets (``--emit joints``).

    RAPID: ``CONST robtarget p10 := [...]`` becomes ``CONST jointtarget p10 :=
    [[j1,...,j6],[eax_a,...]]`` (external axes copied as written), and every MoveL/MoveJ
    using it (or using a converted inline target) becomes MoveAbsJ. An array declaration
    is converted only whole. V+: a transformation ``name x y z y p r`` becomes the
    precision point ``#name j1 ... jn`` and its motion references become ``#name``;
    ``SET name = TRANS(...)`` becomes ``SET #name = #PPOINT(...)``.
    Raises DataError, naming the target and the place, when a use cannot take a joint
    target (MoveC, Offs(), a field assignment, a procedure argument...).

    joints : target -> robot joint values in degrees.
    """
    if program.dialect == "vplus":
        return _vplus_joint_edits(program, joints)
    text = program.text
    wanted = {id(t): (t, np.asarray(check_values(f"joints of {t.display_name}", q, 6)))
              for t, q in joints.items()}
    out: list[Edit] = []
    by_decl: dict = {}
    for t in program.targets:
        if t.storage not in ("inline", "assigned"):
            by_decl.setdefault(t.type_span, []).append(t)
    names = set()
    for type_span, members in by_decl.items():
        chosen = [m for m in members if id(m) in wanted]
        if not chosen:
            continue
        if len(chosen) != len(members):
            missing = [m.display_name for m in members if id(m) not in wanted]
            raise DataError(f"{members[0].location}: array {members[0].name} must be "
                            f"converted whole (missing {', '.join(missing[:5])})")
        word = text[type_span[0]:type_span[1]]
        out.append(Edit(type_span[0], type_span[1], _like_case("jointtarget", word)))
        for m in members:
            out.append(_rapid_joint_literal(text, m, wanted[id(m)][1]))
        names.add((members[0].name.lower(), members[0].routine))
    _check_other_uses(program, names)
    converted_inline = {id(t) for t, _ in wanted.values() if t.storage == "inline"}
    done_instr = set()
    for use in program.motions:
        hit = (use.inline is not None and id(use.inline) in converted_inline) or (
            use.target_name is not None and _resolves(program, use, names))
        if not hit:
            continue
        new = _JOINT_MOVES.get(use.instruction.lower())
        if new is None:
            raise DataError(f"{use.location}: {use.instruction} needs a robtarget; cannot "
                            f"emit joints for {use.target_name or 'its inline target'}")
        stmt = text[use.statement_span[0]:use.statement_span[1]]
        if "\\corr" in stmt.lower():
            raise DataError(f"{use.location}: MoveAbsJ has no \\Corr argument")
        if use.inline is not None:
            out.append(_rapid_joint_literal(text, use.inline, wanted[id(use.inline)][1]))
        if use.instruction_span not in done_instr:
            done_instr.add(use.instruction_span)
            out.append(Edit(*use.instruction_span, _like_case(new, use.instruction)))
    return out


def _resolves(program: Program, use: MotionUse, names: set) -> bool:
    key = use.target_name.lower()
    if (key, use.routine) in names:
        return True
    if (key, None) in names:
        # a routine-local declaration of the same name would shadow the module one
        return not any(t.name and t.name.lower() == key and t.routine == use.routine
                       for t in program.targets if use.routine is not None)
    return False


def _check_other_uses(program: Program, names: set) -> None:
    plain = {n for n, _ in names}
    for r in program.runtime:
        if r.base_name and r.base_name.lower() in plain:
            raise DataError(f"{r.location}: {r.base_name} is used in {r.expression!r}, "
                            f"which needs a robtarget; cannot emit joints for it")
    for r in program.references:
        if r.name.lower() in plain:
            raise DataError(f"{r.location}: {r.name} is passed to {r.context}, which may "
                            f"need a robtarget; cannot emit joints for it")


def _rapid_joint_literal(text: str, t: CartesianTarget, q: np.ndarray) -> Edit:
    if q.shape != (6,):
        raise DataError(f"{t.display_name}: expected 6 joint values, got {q.size}")
    ext = t.external
    a = text.rfind("[", 0, ext[0].start)
    b = text.find("]", ext[-1].end) + 1
    js = ",".join(format_like("0", v, DEG_DECIMALS) for v in q)
    return Edit(t.span[0], t.span[1], f"[[{js}],{text[a:b]}]")


def _vplus_joint_edits(program: Program, joints) -> list[Edit]:
    text = program.text
    out: list[Edit] = []
    existing = {j.name.lower() for j in program.joint_targets if j.name}
    chosen = {id(t) for t in joints}
    for t in joints:
        rest = [o.display_name for o in program.targets if o.name and t.name
                and o.name.lower() == t.name.lower() and id(o) not in chosen]
        if rest:
            raise DataError(f"{t.location}: {t.name} must be converted whole (missing "
                            f"{', '.join(rest[:5])})")
    converted = set()
    for t, q in joints.items():
        q = finite_floats(f"joints of {t.display_name}", q)
        if t.name is None or t.type_span is None:
            raise DataError(f"{t.location}: only named V+ transformations can become "
                            f"precision points")
        pp = "#" + t.name
        if pp.lower() in existing:
            raise DataError(f"{t.location}: precision point {pp} already exists")
        out.append(Edit(t.type_span[0], t.type_span[1], pp))
        js = [format_like("0", v, DEG_DECIMALS) for v in q]
        if text[t.span[0]:t.span[0] + 5].upper() == "TRANS":
            func = _like_case("#PPOINT", text[t.span[0]:t.span[0] + 5])
            out.append(Edit(t.span[0], t.span[1], f"{func}({','.join(js)})"))
        else:
            out.append(Edit(t.span[0], t.span[1], " ".join(js)))
        converted.add(t.name.lower())
    for use in program.motions:
        if use.target_name and use.target_name.lower() in converted:
            if use.wobj is not None:
                raise DataError(f"{use.location}: {use.wobj}:{use.target_name} is relative "
                                f"to a frame; a precision point cannot be")
            off = use.target_span[0]
            out.append(Edit(off, off, "#"))
    for r in program.runtime:
        if r.base_name and r.base_name.lower() in converted:
            raise DataError(f"{r.location}: {r.base_name} is used in {r.expression!r}; "
                            f"cannot make it a precision point")
    return out
