"""Tool recalibration wizard: a terminal session a technician follows at the robot.

Every question goes through one injected ``ask(prompt) -> str`` and every message through
``say(text)``, so tests drive the wizard with a script. The wizard builds the same
:class:`~olp_compensate.calibration.tool.ToolRequest` the library call :func:`calibrate_tool` takes.
Typing ``q`` at any prompt cancels (nothing is written).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Callable

import numpy as np

from ..calibration.tool import (MIN_MARKS, FlangePose, PoorlyDeterminedTool, ToolCalibration,
                                ToolRequest, calibrate_tool, rapid_tooldata, tool_report)
from ..errors import DataError
from ..io.atomic import write_text_atomic
from ..io.rtde_source import Ask, JointSource, Say, TypedJointSource
from ..io.tool_marks import format_marks_csv, write_tool_json
from ..kinematics.conventions import MM

MAX_ATTEMPTS = 10
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,31}")
BAD_POINT_MM = 1.0
"""A touch whose residual exceeds this (or 3x the expected noise) is flagged at once."""


class _Cancelled(Exception):
    pass


class _Dialog:
    """ask/say with cancellation and bounded retries."""

    def __init__(self, ask: Ask, say: Say):
        self.ask_raw, self.say = ask, say

    def ask(self, prompt: str) -> str:
        answer = self.ask_raw(prompt).strip()
        if answer.lower() == "q":
            raise _Cancelled
        return answer

    def choose(self, prompt: str, options: dict[str, str], default: str) -> str:
        for _ in range(MAX_ATTEMPTS):
            answer = self.ask(prompt).lower() or default
            if answer in options:
                return options[answer]
            self.say(f"  Please answer one of: {', '.join(sorted(set(options) - {''}))}.")
        raise DataError(f"no valid answer to '{prompt.strip()}' after {MAX_ATTEMPTS} attempts")


def _numbers(text: str, count: int) -> np.ndarray:
    fields = [f for f in re.split(r"[\s,;]+", text.strip().strip("[](){}")) if f]
    try:
        values = np.array([float(f) for f in fields])
    except ValueError:
        raise DataError(f"expected {count} numbers, got '{text}'") from None
    if len(values) != count or not np.all(np.isfinite(values)):
        raise DataError(f"expected {count} finite numbers, got {len(values)}")
    return values


def _fmt(values_m, decimals: int = 3) -> str:
    return "(" + ", ".join(f"{v / MM:.{decimals}f}" for v in values_m) + ")"


class _Wizard:
    def __init__(self, flange_pose, dialog, source, n_joints, expected_noise_mm):
        self.flange_pose = flange_pose
        self.d = dialog
        self.source = source
        self.n_joints = n_joints
        self.limit_m = min(3.0 * expected_noise_mm, BAD_POINT_MM) * MM
        self.joints: list[np.ndarray] = []
        self.marks: list[np.ndarray] = []
        self.labels: list[str] = []

    def request(self, name, method, frame) -> ToolRequest:
        return ToolRequest(name=name, method=method, joints=np.array(self.joints),
                           marks=np.array(self.marks) if method == "known_marks" else None,
                           frame=frame, mark_names=tuple(self.labels))

    def ask_name(self) -> str:
        for _ in range(MAX_ATTEMPTS):
            name = self.d.ask("Tool name as in the robot program (e.g. tGun1): ")
            if _NAME.fullmatch(name):
                return name
            self.d.say("  A name starts with a letter and holds up to 32 letters, digits or _.")
        raise DataError(f"no valid tool name after {MAX_ATTEMPTS} attempts")

    def ask_mark(self, label: str, allow_done: bool):
        done = ", or 'done' to finish" if allow_done else ""
        for _ in range(MAX_ATTEMPTS):
            answer = self.d.ask(f"Mark {label}: its coordinates x y z in mm{done}: ")
            if allow_done and answer.lower() == "done":
                return None
            try:
                return _numbers(answer, 3) * MM
            except DataError as exc:
                self.d.say(f"  {exc}; type three numbers in mm, e.g. 1250.5 -300 412.25")
        raise DataError(f"no valid coordinates for mark {label} after {MAX_ATTEMPTS} attempts")

    def capture(self, instruction: str, commands=("q",)):
        reading = self.source.capture(self.d.ask_raw, self.d.say, instruction, commands)
        if reading == "q":
            raise _Cancelled
        if isinstance(reading, str):
            return reading
        q = np.asarray(reading.q_rad, dtype=float)
        if q.shape != (self.n_joints,):
            raise DataError(f"the joint source gave {q.size} joints, the robot has "
                            f"{self.n_joints}")
        return q

    def running_fit(self, name, method, frame, minimum) -> str:
        """Fit so far; returns 'keep', 'redo' or 'drop' for the newest touch."""
        if len(self.joints) < minimum:
            self.d.say(f"  {len(self.joints)} of at least {minimum} touches.")
            return "keep"
        try:
            fit = calibrate_tool(self.request(name, method, frame), self.flange_pose)
        except PoorlyDeterminedTool as exc:
            self.d.say(f"  Not determined yet: {exc.hint}")
            return "keep"
        self.d.say(f"  Fit with {len(self.joints)} touches: TCP {_fmt(fit.xyz_m)} mm "
                   f"+/- {_fmt(fit.xyz_std_m)} mm, RMS residual {fit.rms_m / MM:.3f} mm")
        newest = fit.residuals_m[-1]
        if newest <= self.limit_m:
            return "keep"
        self.d.say(f"  Warning: {self.labels[-1]} misses the fit by {newest / MM:.3f} mm "
                   f"(expected at most {self.limit_m / MM:.3f} mm): the tip may have slipped, "
                   f"or the mark's coordinates are wrong.")
        return self.d.choose("  [r]edo this touch, [k]eep it, or [d]rop it? [r]: ",
                             {"r": "redo", "k": "keep", "d": "drop", "redo": "redo",
                              "keep": "keep", "drop": "drop"}, "r")

    def collect(self, name, method, frame, max_marks) -> None:
        minimum = MIN_MARKS[(method, frame if method == "known_marks" else None)]
        pending = None
        while len(self.joints) < max_marks:
            k = len(self.joints) + 1
            label = f"M{k}" if method == "known_marks" else f"P{k}"
            if method == "known_marks":
                mark = pending if pending is not None else self.ask_mark(label, k > minimum)
                if mark is None:
                    return
                q = self.capture(f"Jog the tool tip onto mark {label} at {_fmt(mark)} mm")
            else:
                tilt = "" if k == 1 else ", tilted by 30 degrees or more from the earlier touches"
                q = self.capture(f"Pose {label}: touch the fixed point with the tool tip{tilt}",
                                 ("q", "done") if k > minimum else ("q",))
                if isinstance(q, str):
                    return
                mark = None
            self.joints.append(q)
            self.labels.append(label)
            if mark is not None:
                self.marks.append(mark)
            verdict = self.running_fit(name, method, frame, minimum)
            pending = None
            if verdict in ("redo", "drop"):
                self.joints.pop()
                self.labels.pop()
                if mark is not None:
                    self.marks.pop()
                pending = mark if verdict == "redo" else None
                if verdict == "redo" and method == "fixed_point":
                    self.d.say(f"  Touch the point again for {label}.")

    def report(self, result: ToolCalibration, mass_kg, cog_mm) -> None:
        for line in tool_report(result, self.limit_m):
            self.d.say(line)
        if mass_kg is not None:
            self.d.say(f"  RAPID: PERS tooldata {result.name} := "
                       f"{rapid_tooldata(result, mass_kg=mass_kg, cog_mm=cog_mm)};")


def run_wizard(flange_pose: FlangePose, ask: Ask, say: Say, *,
               joint_source: JointSource | None = None, n_joints: int = 6,
               out_path=None, expected_noise_mm: float = 0.1, mass_kg: float | None = None,
               cog_mm=(0.0, 0.0, 0.0), max_marks: int = 50, name: str | None = None,
               save: Callable[[ToolCalibration, ToolRequest], list[str]] | None = None,
               save_to: Callable[[str], str] | None = None) -> ToolCalibration | None:
    """Guide a tool recalibration at the robot; return the result, or None if cancelled.

    ``flange_pose``: joints (m, n) rad -> base_T_flange (m, 4, 4) m. ``joint_source``: live
    (e.g. :class:`~olp_compensate.io.rtde_source.RtdeJointSource`) or None to type the
    joints from the pendant in degrees. ``out_path``: where to write the tool (JSON entry
    for calib.json) on confirmation, with the touches beside it as ``<stem>_marks.csv``.
    ``expected_noise_mm``: touch noise; a touch off by more than 3x that (or 1 mm) is
    flagged at once. ``mass_kg``: when given, the RAPID tooldata is shown too.
    ``name``: the tool's name (asked for when None). ``save(result, request)``: writes the
    result on confirmation and returns the paths written (used instead of ``out_path``);
    ``save_to(name)`` says where, for the confirmation question.
    """
    if name is not None and not _NAME.fullmatch(name):
        raise DataError(f"tool name {name!r}: a name starts with a letter and holds up to 32 "
                        f"letters, digits or _")
    dialog = _Dialog(ask, say)
    source = joint_source or TypedJointSource(n_joints)
    n_joints = source.n_joints
    wizard = _Wizard(flange_pose, dialog, source, n_joints, expected_noise_mm)
    try:
        say(f"Tool recalibration (joints {source.description}). Type q at any prompt to "
            f"cancel.")
        if name is None:
            name = wizard.ask_name()
        else:
            say(f"Tool: {name}")
        method, frame = _method_and_frame(dialog, say)
        while True:
            wizard.collect(name, method, frame, max_marks)
            try:
                result = calibrate_tool(wizard.request(name, method, frame), flange_pose)
                break
            except PoorlyDeterminedTool as exc:
                say(str(exc))
            except DataError as exc:
                say(f"Cannot compute the tool yet: {exc}")
            more = dialog.choose("Add more touches? [Y/n]: ",
                                 {"y": True, "yes": True, "n": False, "no": False}, "y")
            if not more or len(wizard.joints) >= max_marks:
                raise _Cancelled
        wizard.report(result, mass_kg, cog_mm)
        _offer_to_write(dialog, say, wizard, result, name, (method, frame), save, save_to,
                        out_path)
        return result
    except _Cancelled:
        say("Cancelled; nothing written.")
        return None


def _method_and_frame(dialog: _Dialog, say: Say) -> tuple[str, str]:
    """The method asked (known marks or fixed point) and the frame of the marks' coordinates,
    with the touching instructions for it."""
    method = dialog.choose(
        "Method: [1] known marks (touch marks with known coordinates), [2] fixed point "
        "(touch one point from 4 or more orientations) [1]: ",
        {"1": "known_marks", "known": "known_marks", "2": "fixed_point",
         "fixed": "fixed_point"}, "1")
    frame = "base"
    if method == "known_marks":
        frame = dialog.choose("Mark coordinates are in the robot [b]ase frame or a "
                              "[w]orld frame? [b]: ",
                              {"b": "base", "base": "base", "w": "world", "world": "world"},
                              "b")
        say(f"Touch at least {MIN_MARKS[(method, frame)]} marks (6 recommended), changing "
            f"the tool's tilt by 30 degrees or more between marks.")
    else:
        say("Touch one fixed point (a cone tip, a sharp pin) from at least 4 orientations "
            "(6 recommended), tilting the tool by 30 degrees or more about different axes.")
    return method, frame


def _offer_to_write(dialog: _Dialog, say: Say, wizard: _Wizard, result: ToolCalibration,
                    name: str, method_frame: tuple[str, str], save, save_to, out_path) -> None:
    """Ask before writing the tool (through ``save``, or to ``out_path`` with the touches
    beside it); nothing is written without a yes."""
    method, frame = method_frame
    if save is not None:
        where = f" to {save_to(name)}" if save_to is not None else ""
        if dialog.choose(f"Write tool {name}{where}? [y/N]: ",
                         {"y": True, "yes": True, "n": False, "no": False}, "n"):
            written = save(result, wizard.request(name, method, frame))
            say(f"Written {', '.join(map(str, written))}.")
        else:
            say("Not written.")
    elif out_path is not None:
        out_path = Path(out_path)
        marks_path = out_path.with_name(out_path.stem + "_marks.csv")
        write = dialog.choose(f"Write tool {name} to {out_path} (touches to "
                              f"{marks_path.name})? [y/N]: ",
                              {"y": True, "yes": True, "n": False, "no": False}, "n")
        if write:
            write_tool_json(result, out_path)
            write_text_atomic(marks_path,
                              format_marks_csv(wizard.request(name, method, frame)))
            say(f"Written {out_path} and {marks_path}.")
        else:
            say("Not written.")
