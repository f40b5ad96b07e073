"""Where a six-number-target program's tool and base references get their poses: the
program's own frame data, the flange or robot base, or a tool of calib.json marked for
programs (:func:`.program_tools.program_tool`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..calibration.calibration import Calibration
from ..kinematics.conventions import matrix_from_quat_wxyz, pose_from_rotation_translation
from ..programs.pose_dialects import PoseProgram
from .dialect_rules import DialectRules
from .program_tools import program_tool as calibrated_program_tool
from .program_tools import program_tool_note


@dataclass(frozen=True)
class FrameLookup:
    """Where a tool or base reference of the program gets its pose: the program's own
    frame data (``program.frames``, file units), then a calibrated tool of that name."""

    program: PoseProgram
    rules: DialectRules
    calibration: Calibration

    def program_frame(self, key: str | None, kind: str) -> tuple[np.ndarray | None, str]:
        """(pose (4, 4) m or None, why not)."""
        if key is None:
            return np.eye(4), f"no {kind} set before the motion: the {kind} frame taken as " \
                              f"the {'flange' if kind == 'tool' else 'robot base'}"
        if key in self.program.frames:
            return self.rules.convention.pose(np.array(self.program.frames[key])), ""
        if self.rules.is_identity(key):
            return np.eye(4), ""
        tool = self._calibrated(key)
        if tool is not None:
            return tool, ""
        hint = self.rules.frames_source
        return None, f"{kind} {key} unknown: not defined in {hint} nor a calibrated tool " \
                     f"of that name in calib.json"

    def _calibrated(self, key: str) -> np.ndarray | None:
        found = calibrated_program_tool(self.calibration, self.rules.tool_names(key))
        if found is None:
            return None
        tool = found[1]
        rotation = np.eye(3) if tool.quat_wxyz is None else matrix_from_quat_wxyz(tool.quat_wxyz)
        return pose_from_rotation_translation(rotation, tool.xyz_m)

    def real_tool(self, key: str | None, program_tool: np.ndarray) -> tuple[np.ndarray, str]:
        """The real tool: a calibrated tool of the reference's name (its point; the program
        tool's orientation where the calibration has none), else the program's."""
        if key is None:
            return program_tool, ""
        found = calibrated_program_tool(self.calibration, self.rules.tool_names(key))
        if found is None:
            return program_tool, ""
        cal_name, tool = found
        rotation = (program_tool[:3, :3] if tool.quat_wxyz is None
                    else matrix_from_quat_wxyz(tool.quat_wxyz))
        return (pose_from_rotation_translation(rotation, tool.xyz_m),
                program_tool_note(key, cal_name))
