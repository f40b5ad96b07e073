"""A vendor-like RoboDK post-processor for ABB RAPID, written for the tests.

It has the interface RoboDK's generated scripts call (``RobotPost(robotpost, robotname,
robot_axes, **kwargs)``, ``ProgStart``, ``setFrame``, ``setTool``, ``MoveJ``, ``MoveL``,
``MoveC``, ``setSpeed``, ``setZoneData``, ``RunCode``, ``RunMessage``, ``ProgFinish``,
``ProgSave``, ``addlog``) and writes what a RAPID post writes: tooldata and wobjdata
declarations, inline robtargets ``[[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[9E9...]]``
(mm, quaternion w first via ``robodk.robomath.Pose_2_ABB``), confdata from the joints it is
given (quadrants of axes 1, 4 and 6; cfx = 4 rear + 2 lower + flip of RoboDK's conf_RLF).
It knows nothing of olp-compensate.
"""

import math
import os

from robodk.robomath import Pose_2_ABB

EXT = "9E+09,9E+09,9E+09,9E+09,9E+09,9E+09"


def _pose(pose):
    x, y, z, q1, q2, q3, q4 = Pose_2_ABB(pose)
    return "[%.4f,%.4f,%.4f],[%.8f,%.8f,%.8f,%.8f]" % (x, y, z, q1, q2, q3, q4)


class RobotPost(object):
    """The RAPID post (a module with one PROC per program)."""

    PROG_EXT = "mod"

    def __init__(self, robotpost=None, robotname=None, robot_axes=6, **kwargs):
        self.ROBOT_POST = robotpost
        self.ROBOT_NAME = robotname
        self.PROG = []
        self.DECL = []
        self.LOG = ""
        self.MODULE = "Module1"
        self.TOOL = "tool0"
        self.WOBJ = "wobj0"
        self.SPEED = "v100"
        self.ZONE = "fine"

    def ProgStart(self, progname):
        self.MODULE = progname
        self.PROG.append("  PROC main()")

    def ProgFinish(self, progname):
        self.PROG.append("  ENDPROC")

    def ProgSave(self, folder, progname, ask_user=False, show_result=False):
        lines = ["MODULE %s" % self.MODULE, "  ! olp-robot: abb_irb2400"]
        lines += self.DECL + self.PROG + ["ENDMODULE", ""]
        with open(os.path.join(folder, progname + "." + self.PROG_EXT), "w") as stream:
            stream.write("\n".join(lines))

    def setFrame(self, pose, frame_id=None, frame_name=None):
        self.WOBJ = "wobj%d" % (len(self.DECL) + 1)
        self.DECL.append('  TASK PERS wobjdata %s:=[FALSE,TRUE,"",[%s],[[0,0,0],[1,0,0,0]]];'
                         % (self.WOBJ, _pose(pose)))

    def setTool(self, pose, tool_id=None, tool_name=None):
        self.TOOL = tool_name or "tool%d" % (len(self.DECL) + 1)
        self.DECL.append("  PERS tooldata %s:=[TRUE,[%s],[2,[0,0,100],[1,0,0,0],0,0,0]];"
                         % (self.TOOL, _pose(pose)))

    def _target(self, pose, joints, conf_RLF):
        cf = [int(math.floor(joints[a] / 90.0)) for a in (0, 3, 5)]
        rear, lower, flip = conf_RLF if conf_RLF is not None else (0, 0, 0)
        cfx = 4 * int(rear) + 2 * int(lower) + int(flip)
        return "[%s,[%d,%d,%d,%d],[%s]]" % (_pose(pose), cf[0], cf[1], cf[2], cfx, EXT)

    def _where(self):
        return "%s,%s,%s\\WObj:=%s;" % (self.SPEED, self.ZONE, self.TOOL, self.WOBJ)

    def MoveJ(self, pose, joints, conf_RLF=None):
        if pose is None:
            self.PROG.append("    MoveAbsJ [[%s],[%s]],%s" % (
                ",".join("%.4f" % j for j in joints[:6]), EXT, self._where()))
        else:
            self.PROG.append("    MoveJ %s,%s" % (self._target(pose, joints, conf_RLF),
                                                  self._where()))

    def MoveL(self, pose, joints, conf_RLF=None):
        self.PROG.append("    MoveL %s,%s" % (self._target(pose, joints, conf_RLF),
                                              self._where()))

    def MoveC(self, pose1, joints1, pose2, joints2, conf_RLF_1=None, conf_RLF_2=None):
        self.PROG.append("    MoveC %s,%s,%s" % (self._target(pose1, joints1, conf_RLF_1),
                                                 self._target(pose2, joints2, conf_RLF_2),
                                                 self._where()))

    def setSpeed(self, speed_mms):
        self.SPEED = "[%.1f,500,5000,1000]" % speed_mms

    def setZoneData(self, zone_mm):
        self.ZONE = "fine" if zone_mm < 0 else "z%d" % int(zone_mm)

    def RunCode(self, code, is_function_call=False):
        self.PROG.append("    %s;" % code if is_function_call else "    ! %s" % code)

    def RunMessage(self, message, iscomment=False):
        self.PROG.append("    ! %s" % message if iscomment else '    TPWrite "%s";' % message)

    def addlog(self, newline):
        self.LOG += newline + "\n"
