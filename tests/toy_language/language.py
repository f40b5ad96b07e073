"""The toy language's reader, configuration rule and registration record."""

from __future__ import annotations

import re

import numpy as np

from olp_compensate.compensation.dialect_rules import DialectRules
from olp_compensate.compensation.files import pose_program_result
from olp_compensate.kinematics.conventions import euler_zyx_from_matrix, matrix_from_euler_zyx
from olp_compensate.programs.languages import Language
from olp_compensate.programs.pose_dialects import (PoseConvention, PoseMotion, PoseProgram,
                                                   PoseTarget, line_column, line_starts_of)
from olp_compensate.programs.targets import Number

_NUMBER = r"[-+]?\d+(?:\.\d*)?"
_MOVE = re.compile(rf"^[ \t]*MOVE((?:[ \t]+{_NUMBER}){{6}})[ \t]*$", re.M | re.I)
_TOOL = re.compile(r"^[ \t]*TOOL[ \t]+(\w+)[ \t]*$", re.M | re.I)


def read_toy(text: str, name: str) -> PoseProgram:
    """The moves of a ``.toy`` text: one inline target per ``MOVE``, with the tool in force."""
    starts = line_starts_of(text)
    tools = [(m.start(), m.group(1)) for m in _TOOL.finditer(text)]
    targets, motions = [], []
    for move in _MOVE.finditer(text):
        numbers = tuple(Number(m.start(), m.end(), m.group(0)) for m in
                        re.finditer(_NUMBER, text[:move.end(1)]) if m.start() >= move.start(1))
        line, column = line_column(text, numbers[0].start, starts)
        tool = next((t for at, t in reversed(tools) if at < move.start()), None)
        motions.append(PoseMotion("MOVE", None, (name, line, column), tool=tool,
                                  inline=len(targets)))
        targets.append(PoseTarget(None, (name, line, column), "pose", numbers))
    return PoseProgram("toy", {name: text}, targets, motions)


def nearest_previous(geometry, target, branches, previous):
    """The branch inside the axis ranges nearest the previous move's joints (zero for the
    first)."""
    ranges = geometry.robot.controller_ranges
    finite = [q for q in branches if np.all(np.isfinite(q))
              and np.all((q >= ranges[:, 0]) & (q <= ranges[:, 1]))]
    if not finite:
        return None, "the nominal arm does not reach the target inside the axis ranges"
    reference = np.zeros(len(finite[0])) if previous is None else previous
    return min(finite, key=lambda q: float(np.sum((q - reference) ** 2))), None


TOY_RULES = DialectRules(
    name="toy",
    convention=PoseConvention(
        position_scale=1e-3,
        rotation=lambda abc: matrix_from_euler_zyx(*np.radians(abc)),
        angles=lambda rotation, ref: np.degrees(euler_zyx_from_matrix(rotation,
                                                                      np.radians(ref))),
        position_decimals=3, angle_decimals=4),
    choose=nearest_previous, config=lambda geometry, q, target: (),
    written=lambda target: (), config_edits=lambda target, values: [],
    config_words=lambda values: "", is_identity=lambda key: False)


def compensate(files, texts, run):
    return pose_program_result(files, read_toy(texts[0], files.names[0]), TOY_RULES, run)


LANGUAGE = Language(name="toy", title="Toy", extensions=(".toy",), compensate=compensate)
