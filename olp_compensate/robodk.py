"""A compensating RoboDK post-processor: any vendor post, its targets compensated.

RoboDK makes a program by running a small script that builds the post's ``RobotPost`` and
calls it instruction by instruction (``ProgStart``, ``setFrame``, ``setTool``, ``MoveJ``,
``MoveL``, ``MoveC``, ``setSpeed``, ``RunCode``, ``ProgFinish``, ``ProgSave``...), with
poses as ``robodk.robomath.Mat`` 4x4 in mm and joints in degrees. Use::

    from ABB_RAPID_IRC5 import RobotPost as VendorPost
    from olp_compensate.robodk import compensated
    RobotPost = compensated(VendorPost, calibration="C:/cells/cell4/calib.json")

The class returned is a subclass of the vendor's, with its constructor and methods. Each
call is kept in order until the program ends (``ProgFinish``, ``ProgSave`` or
``ProgSendRobot``); then every Cartesian target is compensated in one batch and the calls
are handed to the vendor post in their order, each ``MoveJ``/``MoveL``/``MoveC`` with the
compensated pose (the same reference frame, mm) and the joints the real arm takes (deg).

Frames: ``setFrame(pose)`` is base_T_wobj and ``setTool(pose)`` flange_T_tool, as RoboDK
passes them; a tool of the same name in the calibration (``olp-cal tool``) is the real one,
as olp-fix takes it. The configuration asked for is that of the joints RoboDK passes (its
nominal solution), so the real arm stays on the branch RoboDK chose. A joint move (pose
None) is handed on unchanged.

Which calibration (first found):

1. the ``calibration`` argument of :func:`compensated` (a path);
2. the environment variable ``OLP_CALIBRATION`` (a path);
3. ``OLP_CALIBRATION_DIR/<robot name>.json``, the robot name as RoboDK passes it to the
   post's constructor (its second argument), with characters other than letters, digits,
   ``-``, ``_`` and ``.`` replaced by ``_``.

A target that cannot be compensated (out of reach, outside the axis ranges...) is never
written silently: its status and note (olp-fix's words) go to the post's log (``addlog``,
which RoboDK shows) and, where the post has ``RunMessage``, into the program as a comment
before the target, which is then written as RoboDK gave it. With ``strict=True`` the
program is refused instead (:class:`~olp_compensate.errors.UnreachableTarget`). A
compensated target where a part of the calibration fitted in a joint range did not apply
(the geometric model outside the named effects' ranges; the residual map) gets that note
in the log (``addlog``) too.

RoboDK's own "accurate kinematics" (its calibration option's ``FilterTarget``) must be off
for this robot, or every target is compensated twice.
"""

from __future__ import annotations

import functools
import inspect
import logging
import os
import re
import types
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import ModelError, UnreachableTarget

__all__ = ["compensated", "find_calibration", "PostCompensation", "ENV_FILE", "ENV_DIR"]

ENV_FILE = "OLP_CALIBRATION"
ENV_DIR = "OLP_CALIBRATION_DIR"
FLUSH = ("ProgFinish", "ProgSave", "ProgSendRobot")
"""Calls that end a program: the kept calls are compensated and handed on before them."""
PASS_THROUGH = frozenset({"addlog"})
"""Vendor methods called at once, never kept (logging)."""
MOVES = ("MoveJ", "MoveL", "MoveC")
TRACKED = ("setFrame", "setTool", *MOVES)
"""Calls whose arguments the wrapper reads (by position, keywords made positional)."""
log = logging.getLogger(__name__)


def find_calibration(calibration: str | os.PathLike | None, robot_name: str | None) -> Path:
    """The calib.json to use (see the module docstring); ModelError when none is found."""
    if calibration:
        return Path(calibration)
    if os.environ.get(ENV_FILE):
        return Path(os.environ[ENV_FILE])
    folder = os.environ.get(ENV_DIR)
    if folder and robot_name:
        return Path(folder) / (re.sub(r"[^A-Za-z0-9_.-]", "_", robot_name) + ".json")
    raise ModelError(f"olp-compensate: no calibration for robot {robot_name!r}: pass "
                     f"calibration= to compensated(), or set {ENV_FILE} (a calib.json) or "
                     f"{ENV_DIR} (a folder of <robot name>.json)")


@dataclass
class _Target:
    """One Cartesian target of a kept move: where its pose and joints go in the call."""

    call: int
    pose_arg: int
    joints_arg: int
    pose: object
    """wobj_T_target as RoboDK passed it (a Mat, mm), read when the program ends."""
    joints: object
    """The joints RoboDK passed (deg), read when the program ends."""
    base_T_wobj: np.ndarray
    tool: np.ndarray
    tool_name: str


@dataclass
class PostCompensation:
    """The state of one compensating post: the calibration's solver, the frame and tool
    in force, the calls kept since the last flush, and every problem reported."""

    compensator: object
    source: str
    strict: bool = False
    frame: np.ndarray = field(default_factory=lambda: np.eye(4))
    tool: np.ndarray = field(default_factory=lambda: np.eye(4))
    tool_name: str = ""
    calls: list = field(default_factory=list)
    targets: list = field(default_factory=list)
    problems: list = field(default_factory=list)
    """(move name, index of its call in the program, status, note) of each target not
    compensated."""


def _matrix(pose) -> np.ndarray:
    """A RoboDK Mat (or any 4x4) as a (4, 4) float array in mm."""
    rows = pose.rows if hasattr(pose, "rows") else pose
    a = np.array(rows, dtype=float)
    if a.shape != (4, 4):
        raise ModelError(f"olp-compensate: expected a 4x4 pose, got shape {a.shape}")
    return a


def _like(original, a: np.ndarray):
    """``a`` (4, 4) as the type RoboDK passed (a Mat, or a robodk Mat for anything else)."""
    if hasattr(original, "rows"):
        return type(original)(a.tolist())
    from robodk.robomath import Mat   # the robodk package: RoboDK's own, imported lazily

    return Mat(a.tolist())


def _keep(name: str, vendor_method):
    """A method that records the call (or, replaying, runs the vendor's)."""

    @functools.wraps(vendor_method)
    def kept(self, *args, **kwargs):
        state = self.__dict__.get("_olp")
        if state is None or self.__dict__.get("_olp_replaying"):
            return vendor_method(self, *args, **kwargs)
        if name in FLUSH:
            _flush(self)
            self._olp_replaying = True      # what the vendor's own method calls runs at once
            try:
                return vendor_method(self, *args, **kwargs)
            finally:
                self._olp_replaying = False
        if kwargs and name in TRACKED:      # pose=..., joints=...: made positional
            bound = inspect.signature(vendor_method).bind(self, *args, **kwargs)
            args, kwargs = bound.args[1:], bound.kwargs
        args = list(args)
        if name == "setFrame" and args and args[0] is not None:
            state.frame = _matrix(args[0])
        elif name == "setTool" and args and args[0] is not None:
            state.tool = _matrix(args[0])
            state.tool_name = str(args[2]) if len(args) > 2 else ""
        elif name in MOVES:
            _record_targets(state, name, args)
        state.calls.append((name, args, kwargs))
        return None

    return kept


def _record_targets(state: PostCompensation, name: str, args: list) -> None:
    """Note the Cartesian targets of a move call (pose/joints argument positions)."""
    pairs = ((0, 1), (2, 3)) if name == "MoveC" else ((0, 1),)
    for pose_arg, joints_arg in pairs:
        if len(args) <= joints_arg or args[pose_arg] is None:
            continue          # a joint move: the joints are what the robot does
        state.targets.append(_Target(len(state.calls), pose_arg, joints_arg, args[pose_arg],
                                     args[joints_arg], state.frame, state.tool,
                                     state.tool_name))


def _flush(post) -> None:
    """Compensate the kept targets in one batch and hand every kept call to the vendor."""
    state: PostCompensation = post._olp
    calls, targets = state.calls, state.targets
    state.calls, state.targets = [], []
    results = _solve_targets(state.compensator, targets) if targets else []
    messages: dict[int, list[str]] = {}
    for target, result in zip(targets, results):
        name, args, _ = calls[target.call]
        if result.ok:
            args[target.pose_arg] = _like(args[target.pose_arg], result.pose_mm)
            args[target.joints_arg] = result.joints_deg
            if result.model_note and callable(getattr(post, "addlog", None)):
                post.addlog(f"olp-compensate: {name} target: {result.model_note}")
            continue                  # (a target not compensated: RoboDK's own objects)
        state.problems.append((name, target.call, result.status, result.note))
        text = (f"olp-compensate: {name} target NOT compensated ({result.status}"
                + (f": {result.note}" if result.note else "") + "); written as RoboDK gave it")
        messages.setdefault(target.call, []).append(text)
    if state.problems and state.strict:
        name, _, status, note = state.problems[0]
        raise UnreachableTarget(f"olp-compensate: {name}: {status}: {note} "
                                f"({len(state.problems)} target(s) not compensated)")
    post._olp_replaying = True
    try:
        for k, (name, args, kwargs) in enumerate(calls):
            for text in messages.get(k, ()):
                _say(post, text)
            getattr(post, name)(*args, **kwargs)
    finally:
        post._olp_replaying = False


@dataclass(frozen=True)
class _Result:
    pose_mm: np.ndarray
    joints_deg: list
    status: str
    note: str
    ok: bool
    model_note: str = ""


def _solve_targets(comp, targets: list[_Target]) -> list[_Result]:
    """Compensate the kept targets in one batch, each on the configuration of the joints
    RoboDK gave (its nominal solution) and with the calibrated tool of its tool's name."""
    from .compensation.explained import compensate_explained, confdata_of_joints
    from .programs.object_model.program import _real_tool

    n = comp.robot.n_joints
    joints = [np.asarray(t.joints.tolist() if hasattr(t.joints, "tolist") else t.joints,
                         dtype=float).ravel() for t in targets]
    short = [j for j in joints if len(j) < n]
    if short:
        raise ModelError(f"olp-compensate: a move gives {len(short[0])} joints; "
                         f"{comp.robot.name} has {n}")
    try:
        poses = np.array([t.pose.rows if hasattr(t.pose, "rows") else t.pose
                          for t in targets], dtype=float)
    except (TypeError, ValueError):
        poses = np.zeros(0)
    if poses.shape[1:] != (4, 4):
        raise ModelError("olp-compensate: a move's pose is not a 4x4 matrix")

    def metres(poses: list) -> np.ndarray:
        a = np.array(poses)
        a[:, :3, 3] *= 1e-3
        return a

    tools = metres([t.tool for t in targets])
    real_of: dict[tuple, np.ndarray] = {}      # one lookup per tool in force, not per target
    real = tools.copy()
    for i, t in enumerate(targets):
        if t.tool_name:
            key = (t.tool_name, id(t.tool))
            if key not in real_of:
                real_of[key] = _real_tool(comp.calibration, t.tool_name, tools[i])[0]
            real[i] = real_of[key]
    batch = compensate_explained(
        comp, metres(poses), tools, metres([t.base_T_wobj for t in targets]),
        confdata_of_joints(comp, np.array([j[:n] for j in joints])), real)
    new = batch.poses.copy()
    new[:, :3, 3] *= 1e3
    real_joints = batch.joints_deg.tolist()
    return [_Result(new[i], real_joints[i] + [float(v) for v in joints[i][n:]],
                    batch.status[i], batch.notes[i], ok, batch.model_notes[i])
            for i, ok in enumerate(batch.ok.tolist())]


def _say(post, text: str) -> None:
    """Report a problem in the post's log and, where it can, in the program."""
    if callable(getattr(post, "addlog", None)):
        post.addlog(text)
    else:
        log.warning("%s", text)
    if callable(getattr(post, "RunMessage", None)):
        post.RunMessage(text, True)


def compensated(post_class: type, calibration: str | os.PathLike | None = None, *,
                strict: bool = False) -> type:
    """A subclass of RoboDK post ``post_class`` whose targets are compensated on
    ``calibration`` (see the module docstring for where it is found otherwise).
    ``strict``: refuse the program when a target cannot be compensated (default: write it
    as given, saying so in the log and the program)."""

    def __init__(self, *args, **kwargs):
        from .io.calibration_file import read_calibration
        from .compensation.pose import Compensator

        self.__dict__["_olp"] = None
        post_class.__init__(self, *args, **kwargs)
        robot_name = args[1] if len(args) > 1 else kwargs.get("robotname")
        path = find_calibration(calibration, robot_name)
        cal = read_calibration(path)
        if cal.regions:
            from .compensation.regions import RegionalCompensator

            comp = RegionalCompensator(cal)
        else:
            comp = Compensator(cal)
        self._olp_replaying = False
        self.__dict__["_olp"] = PostCompensation(compensator=comp, source=str(path),
                                                 strict=strict)

    namespace = {"__init__": __init__, "__doc__": post_class.__doc__,
                 "__module__": post_class.__module__,
                 "olp_problems": property(lambda self: list(self._olp.problems))}
    for name in dir(post_class):
        if name.startswith("_") or name in PASS_THROUGH:
            continue
        member = inspect.getattr_static(post_class, name)
        if isinstance(member, types.FunctionType):   # plain methods (not static, class)
            namespace[name] = _keep(name, member)
    return type(post_class.__name__, (post_class,), namespace)
