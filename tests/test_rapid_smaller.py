"""Smaller RAPID reader items: RETURN in a FUNC is no unknown instruction; RAPID's letters
are Latin-1's (a routine or target named with an accented letter reads)."""

from __future__ import annotations

from olp_compensate.calibration.calibration import nominal_calibration
from olp_compensate.kinematics.robot import load_robot
from olp_compensate.programs import loads
from olp_compensate.programs.object_model.task import compensate_program

TARGET = "[[1200,100,900],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]"
FUNCS = f"""MODULE R
  CONST robtarget p1:={TARGET};
  FUNC num Dist(robtarget a)
    VAR num result;
    result := a.trans.x;
    TPWrite "x"\\Num:=result;
    RETURN result;
  ENDFUNC
  FUNC jointtarget JHome()
    VAR jointtarget result;
    result := CJointT();
    RETURN result;
  ENDFUNC
  FUNC robtarget Here()
    VAR robtarget result;
    result := CRobT();
    RETURN result;
  ENDFUNC
  FUNC robtarget First()
    RETURN p1;
  ENDFUNC
  PROC main()
    MoveL p1,v100,fine,tool0;
    MyMove p1;
  ENDPROC
ENDMODULE
"""


def _nominal():
    return nominal_calibration(load_robot("abb_irb2400"))


def test_return_in_a_func_is_no_unknown_instruction():
    program = loads(FUNCS, "rapid", "r.mod")
    unknown = [(p.target, p.location.line) for p in program.problems
               if p.status == "unknown_instruction"]
    # only the real unknown instruction with a robtarget (line 24): no RETURN (lines 7,
    # 12, 17, 20), no TPWrite of the FUNC's own num 'result' (a robtarget elsewhere)
    assert unknown == [("p1", 24)]
    out, report = compensate_program(FUNCS, "rapid", _nominal())
    assert out == FUNCS
    assert sorted({r.status for r in report.rows}) == ["ok", "unknown_instruction"]


def test_latin1_letters_name_routines_targets_and_arguments():
    text = (f"MODULE Zelle\n  CONST robtarget pÄnde:={TARGET};\n"
            f"  PROC Ñ(num wert)\n    MoveL pÄnde,v100,fine,tool0;\n  ENDPROC\n"
            f"  PROC main()\n    Ñ wert:=1;\n    Ñ 2;\n  ENDPROC\nENDMODULE\n")
    program = loads(text, "rapid", "z.mod")
    assert [r.name for r in program.routines] == ["Ñ", "main"]
    assert [t.name for t in program.targets] == ["pÄnde"]
    assert not program.problems
    out, report = compensate_program(text, "rapid", _nominal())
    assert out == text and [r.status for r in report.rows] == ["ok"]
    assert report.rows[0].target == "pÄnde"
