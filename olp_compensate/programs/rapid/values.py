"""RAPID data values: robtarget, jointtarget, tooldata and wobjdata literals read into the
shared target model, every number with its character span.

Each reader takes the text, where the literal starts and where it may end at most, and a
:class:`Placement` (the name and place of the declaration or instruction holding it);
it returns the model object, or a :class:`~.targets.RuntimeTarget` when the literal holds
names instead of numbers. Malformed literals raise :class:`~.literals.LiteralError` at the
offending character.
"""

from __future__ import annotations

from typing import NamedTuple

from ..literals import (JOINTTARGET_RE, ROBTARGET_RE, Agg, Atom, LiteralError, fast_groups,
                        numbers_of, read_aggregate, shape_of)
from ..targets import (QUAT_WXYZ, CartesianTarget, JointTarget, Number, RuntimeTarget,
                       SourceLocation, ToolData, WorkObject)

class Placement(NamedTuple):
    """Where a literal stands: the declared name (None inline), the (file, line, column)
    ``source`` of the literal or its name, storage ('CONST', 'PERS', 'VAR', 'inline',
    'assigned'), 1-based array index, routine, and the declaration's type word span."""

    name: str | None
    source: tuple[str, int, int]
    storage: str
    array_index: tuple[int, ...] | None = None
    routine: str | None = None
    type_span: tuple[int, int] | None = None


ROBTARGET_SHAPE = "robtarget [[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[eax_a..eax_f]]"
JOINTTARGET_SHAPE = "jointtarget [[rax_1..rax_6],[eax_a..eax_f]]"


def read_robtarget(text: str, pos: int, limit: int, place: Placement
                   ) -> CartesianTarget | RuntimeTarget:
    """The robtarget literal at ``pos`` (not beyond ``limit``)."""
    got = fast_groups(ROBTARGET_RE, text, pos)
    if got is not None:
        texts, starts, end = got
    else:
        agg = read_aggregate(text, pos, limit)
        end = agg.end
        groups = shape_of(agg, (3, 4, 4, 6), ROBTARGET_SHAPE)
        if groups is None:
            return _non_numeric(text, pos, end, place, "robtarget")
        texts, starts = _flat(groups)
    return CartesianTarget(name=place.name, source=place.source, texts=texts, starts=starts,
                           orientation_kind=QUAT_WXYZ, span=(pos, end), storage=place.storage,
                           array_index=place.array_index, routine=place.routine,
                           type_span=place.type_span)


def read_jointtarget(text: str, pos: int, limit: int, place: Placement
                     ) -> JointTarget | RuntimeTarget:
    """The jointtarget literal at ``pos`` (not beyond ``limit``)."""
    got = fast_groups(JOINTTARGET_RE, text, pos)
    if got is not None:
        texts, starts, end = got
    else:
        agg = read_aggregate(text, pos, limit)
        end = agg.end
        groups = shape_of(agg, (6, 6), JOINTTARGET_SHAPE)
        if groups is None:
            return _non_numeric(text, pos, end, place, "jointtarget")
        texts, starts = _flat(groups)
    return JointTarget(name=place.name, source=place.source, texts=texts, starts=starts,
                       n_joints=6, span=(pos, end), storage=place.storage,
                       array_index=place.array_index, routine=place.routine,
                       type_span=place.type_span)


def read_tooldata(text: str, pos: int, limit: int, place: Placement) -> ToolData:
    """The tooldata literal at ``pos`` (not beyond ``limit``)."""
    agg = read_aggregate(text, pos, limit)
    what = "tooldata [robhold,[[x,y,z],[q1..q4]],[mass,[cx,cy,cz],[a1..a4],ix,iy,iz]]"
    if len(agg.items) != 3:
        raise LiteralError(f"expected 3 components in {what}, found {len(agg.items)}",
                           agg.start)
    robhold = _bool(agg.items[0], what)
    frame = shape_of(_agg(agg.items[1], what), (3, 4), what)
    load = _agg(agg.items[2], what)
    if len(load.items) != 6:
        raise LiteralError(f"expected 6 components in the load of {what}", load.start)
    mass = load.items[0] if type(load.items[0]) is Number else None
    cog = numbers_of(_agg(load.items[1], what), 3, "the centre of gravity") or ()
    aom = numbers_of(_agg(load.items[2], what), 4, "the load orientation") or ()
    inertia = tuple(i for i in load.items[3:] if type(i) is Number)
    return ToolData(name=_element_name(place), location=SourceLocation(*place.source),
                    robhold=robhold, position=frame[0] if frame else (),
                    orientation=frame[1] if frame else (), span=(pos, agg.end),
                    storage=place.storage, mass=mass, cog=cog, load_orientation=aom,
                    inertia=inertia, orientation_kind=QUAT_WXYZ, routine=place.routine)


def read_wobjdata(text: str, pos: int, limit: int, place: Placement) -> WorkObject:
    """The wobjdata literal at ``pos`` (not beyond ``limit``)."""
    agg = read_aggregate(text, pos, limit)
    what = 'wobjdata [robhold,ufprog,"ufmec",[[x,y,z],[q1..q4]],[[x,y,z],[q1..q4]]]'
    if len(agg.items) != 5:
        raise LiteralError(f"expected 5 components in {what}, found {len(agg.items)}",
                           agg.start)
    robhold = _bool(agg.items[0], what)
    ufprog = _bool(agg.items[1], what)
    mec = agg.items[2]
    ufmec = mec.text[1:-1].replace('""', '"') if isinstance(mec, Atom) and \
        mec.kind == "string" else None
    uf = shape_of(_agg(agg.items[3], what), (3, 4), "the user frame of " + what)
    of = shape_of(_agg(agg.items[4], what), (3, 4), "the object frame of " + what)
    ok = uf is not None and of is not None
    return WorkObject(name=_element_name(place), location=SourceLocation(*place.source),
                      robhold=robhold, ufprog=ufprog, ufmec=ufmec,
                      uframe_position=uf[0] if ok else (),
                      uframe_orientation=uf[1] if ok else (),
                      oframe_position=of[0] if ok else (),
                      oframe_orientation=of[1] if ok else (), span=(pos, agg.end),
                      storage=place.storage, routine=place.routine)


READERS = {"robtarget": read_robtarget, "jointtarget": read_jointtarget,
           "tooldata": read_tooldata, "wobjdata": read_wobjdata}
"""The reader of each target type (lower case)."""


def _non_numeric(text: str, pos: int, end: int, place: Placement, kind: str) -> RuntimeTarget:
    return RuntimeTarget(expression=text[pos:end], location=SourceLocation(*place.source),
                         reason=f"{kind} literal holds non-numeric values",
                         base_name=place.name, routine=place.routine, span=(pos, end))


def _element_name(place: Placement) -> str | None:
    if place.array_index is None:
        return place.name
    return f"{place.name}{{{','.join(map(str, place.array_index))}}}"


def _flat(groups) -> tuple[tuple[str, ...], tuple[int, ...]]:
    nums = [n for g in groups for n in g]
    return tuple(n.text for n in nums), tuple(n.start for n in nums)


def _agg(item, what) -> Agg:
    if not isinstance(item, Agg):
        raise LiteralError(f"expected [...] in {what}", item.start)
    return item


def _bool(item, what) -> bool | None:
    if isinstance(item, Atom) and item.kind == "name" and item.text.upper() in ("TRUE",
                                                                                "FALSE"):
        return item.text.upper() == "TRUE"
    if isinstance(item, Agg):
        raise LiteralError(f"expected TRUE or FALSE in {what}", item.start)
    return None
