"""Targets with their tool and work object as poses in metres."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from olp_compensate.kinematics.conventions import (MM, invert_pose, matrix_from_euler_zyz,
                                                   matrix_from_quat_wxyz,
                                                   pose_from_rotation_translation)
from olp_compensate.programs import load, loads, resolve
from olp_compensate.programs.targets import CartesianTarget

ROOT = Path(__file__).resolve().parents[1]
NINES = "[9E9,9E9,9E9,9E9,9E9,9E9]"


def _pose(xyz_mm, quat):
    return pose_from_rotation_translation(matrix_from_quat_wxyz(np.array(quat, float)),
                                          np.array(xyz_mm, float) * MM)


def _by_name(resolution, name):
    return [r for r in resolution.targets if r.target.display_name == name]


def test_sample_flange_poses_match_a_hand_computation():
    program = load(ROOT / "samples" / "cell_a.mod")
    res = resolve(program)
    tool = _pose([120.5, 0, 210], [0.92388, 0, 0.382683, 0])
    (p10,) = _by_name(res, "p10")
    want = _pose([1020.35, -250.4, 620.1], [0.0436194, 0, 0.999048, 0]) @ invert_pose(tool)
    np.testing.assert_allclose(p10.base_T_flange, want, atol=1e-12)
    np.testing.assert_allclose(p10.base_T_tcp[:3, 3], [1.02035, -0.2504, 0.6201], atol=1e-12)
    (w3,) = _by_name(res, "pWeld{3}")
    want = _pose([700, -300, 300], [1, 0, 0, 0]) @ _pose([190, 100, 20], [0, 0, 1, 0]) \
        @ invert_pose(tool)
    np.testing.assert_allclose(w3.base_T_flange, want, atol=1e-12)
    assert w3.wobj_name == "wTable" and w3.tool_name == "tGun"
    (svc,) = _by_name(res, "pService")
    assert "unused" in svc.notes and svc.tool_name == "tool0" and svc.wobj_name == "wobj0"
    np.testing.assert_allclose(svc.base_T_flange, svc.wobj_T_target)
    (home,) = _by_name(res, "jHome")
    assert home.base_T_flange is None and not home.resolved
    for r in res.targets:  # a reachable IRB 2400 cell: flange within 1.7 m of the base
        if r.resolved:
            assert np.linalg.norm(r.base_T_flange[:3, 3]) < 1.7
    assert [why for _, why in res.unresolved] == [
        "Offs() displaces the target at run time (MoveJ)",
        "RelTool() displaces the target in the tool frame at run time (MoveL)"]


MODULE = f"""MODULE Sem
  PERS tooldata tHeld:=[TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];
  PERS tooldata tStat:=[FALSE,[[800,100,500],[0,0,1,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];
  PERS tooldata tElse;
  PERS wobjdata wHeld:=[TRUE,TRUE,"",[[0,0,50],[1,0,0,0]],[[0,0,10],[1,0,0,0]]];
  PERS wobjdata wConv:=[FALSE,FALSE,"CNV1",[[0,0,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST robtarget pA:=[[10,20,30],[0,0,1,0],[0,0,0,0],{NINES}];
  CONST robtarget pB:=[[40,50,60],[1,0,0,0],[0,0,0,0],{NINES}];
  CONST robtarget pC:=[[1,2,3],[1,0,0,0],[0,0,0,0],{NINES}];
  CONST robtarget pD:=[[4,5,6],[1,0,0,0],[0,0,0,0],{NINES}];
  PROC main()
    MoveL pA, v100, fine, tHeld;
    MoveL pA, v100, fine, tool0;
    MoveL pB, v100, fine, tStat\\WObj:=wHeld;
    MoveL pC, v100, fine, tNone;
    MoveL pC, v100, fine, tElse;
    MoveL pC, v100, fine, tHeld\\WObj:=wConv;
    MoveL Offs(pD,0,0,10), v100, fine, tHeld;
    local_one;
    MyMove pA;
  ENDPROC
  PROC local_one()
    CONST robtarget pA:=[[7,7,7],[1,0,0,0],[0,0,0,0],{NINES}];
    MoveJ pA, v100, fine, [TRUE,[[0,0,50],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];
  ENDPROC
  PROC by_param(robtarget p)
    MoveL p, v100, fine, tHeld;
  ENDPROC
ENDMODULE
"""


def test_tools_work_objects_and_notes():
    program = loads(MODULE, "rapid", "sem.mod")
    res = resolve(program)
    a = [r for r in res.targets if r.target.name == "pA" and r.target.routine is None]
    assert [(r.tool_name, len(r.uses)) for r in a] == [("tHeld", 1), ("tool0", 1)]
    assert any("pA is used with 2 tool/work-object pairs" in w for w in res.warnings)
    np.testing.assert_allclose(a[0].base_T_flange,
                               _pose([10, 20, 30], [0, 0, 1, 0]) @ invert_pose(
                                   _pose([0, 0, 100], [1, 0, 0, 0])))
    # stationary tool, work object on the flange: target frame meets the tool frame
    (b,) = _by_name(res, "pB")
    assert b.stationary_tool and "stationary tool (robhold FALSE)" in b.notes
    flange_T_wobj = _pose([0, 0, 50], [1, 0, 0, 0]) @ _pose([0, 0, 10], [1, 0, 0, 0])
    np.testing.assert_allclose(b.base_T_flange @ flange_T_wobj @ b.wobj_T_target,
                               _pose([800, 100, 500], [0, 0, 1, 0]), atol=1e-12)
    c = _by_name(res, "pC")
    assert [r.base_T_flange for r in c] == [None, None, None]
    notes = [n for r in c for n in r.notes]
    assert "tool tNone unknown" in notes and "tool tElse has no value in this file" in notes
    assert "work object wConv has a user frame moved by CNV1 (ufprog FALSE)" in notes
    (d,) = _by_name(res, "pD")
    assert d.notes == ("moved to only through Offs()",) and d.tool_name == "tHeld"
    # the routine-local pA shadows the module one, and has an inline tool
    (local,) = [r for r in res.targets if r.target.routine == "local_one"]
    assert local.tool_name == "<inline>"
    np.testing.assert_allclose(local.flange_T_tool[:3, 3], [0, 0, 0.05])
    assert any("parameter of by_param" in why for _, why in res.unresolved)


def test_passed_to_a_procedure_is_warned():
    text = MODULE.replace("    MoveL pA, v100, fine, tHeld;\n    MoveL pA, v100, fine, tool0;\n",
                          "")
    res = resolve(loads(text, "rapid", "sem.mod"))
    (a,) = [r for r in res.targets if r.target.name == "pA" and r.target.routine is None]
    assert a.notes == ("unused",)
    assert any("pA is passed to MyMove" in w for w in res.warnings)


def test_vplus_tool_and_frame():
    program = load(ROOT / "samples" / "cell_b.pg")
    res = resolve(program)
    assert res.frames == ("gripper", "table")
    names = [r.target.display_name for r in res.targets]
    assert "gripper" not in names and "table" not in names
    (insp,) = _by_name(res, "inspect")
    tool = pose_from_rotation_translation(np.eye(3), [0, 0, 0.145])
    table = pose_from_rotation_translation(np.eye(3), [0.35, 0, 0.30])
    rot = matrix_from_euler_zyz(*np.deg2rad([90.0, 180.0, 0.0]))
    target = pose_from_rotation_translation(rot, [0.1, 0.05, 0.25])
    np.testing.assert_allclose(insp.base_T_flange, table @ target @ invert_pose(tool),
                               atol=1e-12)
    (ready,) = _by_name(res, "#ready")  # a precision point: one entry, no pose
    assert len(ready.uses) == 2 and ready.base_T_flange is None
    trays = [r for r in res.targets if r.target.name == "tray"]
    assert len(trays) == 4 and all(r.tool_name == "gripper" for r in trays)
    assert any("tray[i] has a run-time index" in w for w in res.warnings)


@pytest.mark.parametrize("seed", range(3))
def test_batched_poses_match_one_by_one(seed):
    rng = np.random.default_rng(seed)
    lines = []
    for k in range(40):
        q = rng.normal(size=4) * rng.uniform(0.5, 3)  # unnormalized, as RAPID allows
        xyz = rng.uniform(-1000, 1000, 3)
        lines.append(f"  CONST robtarget t{k}:=[[{xyz[0]:.3f},{xyz[1]:.3f},{xyz[2]:.3f}],"
                     f"[{q[0]:.6f},{q[1]:.6f},{q[2]:.6f},{q[3]:.6f}],[0,0,0,0],{NINES}];")
    program = loads("MODULE R\n" + "\n".join(lines) + "\nENDMODULE\n", "rapid")
    for r in resolve(program).targets:
        np.testing.assert_allclose(r.wobj_T_target, r.target.pose(), atol=1e-12)
        np.testing.assert_allclose(r.base_T_flange, r.target.pose(), atol=1e-12)


def test_run_time_changes_are_noted():
    res = resolve(load(ROOT / "tests" / "programs" / "rapid_runtime" / "input.mod"))
    (work,) = _by_name(res, "pWork")
    assert work.notes[0].startswith("changed at run time by 'pWork.trans.z := pWork.trans.z")
    (p10,) = _by_name(res, "p10")
    assert p10.notes == ("moved to only through Offs(), RelTool()",)
    assert any("parameter of go_to" in why for _, why in res.unresolved)
    assert any("pNow has no literal value" in why for _, why in res.unresolved)


def test_resolution_columns_agree_with_the_records():
    """The columns resolve() fills in batches hold, row for row, what each ResolvedTarget
    says, and the written numbers are the file's (V+ has no confdata)."""
    for name in ("cell_a.mod", "cell_b.pg"):
        program = load(ROOT / "samples" / name)
        res = resolve(program)
        assert len(res.targets) == len(res.entry_targets) == len(res.base_T_flange)
        for k, rt in enumerate(res.targets):
            assert rt.target is res.entry_targets[k]
            assert rt.tool_name == res.pairs[res.entry_pairs[k]].tool_name
            if rt.base_T_flange is None:
                assert np.isnan(res.base_T_flange[k]).all()
            else:
                np.testing.assert_array_equal(rt.base_T_flange, res.base_T_flange[k])
            t = rt.target
            if isinstance(t, CartesianTarget):
                written = res.written[k]
                np.testing.assert_array_equal(written[:3], t.position_mm())
                o = t.orientation_values()
                np.testing.assert_array_equal(written[3:3 + len(o)], o)
                config = t.config_values()
                if config:
                    np.testing.assert_array_equal(written[7:11], config)
                else:
                    assert np.isnan(written[6:]).all()
            else:
                assert np.isnan(res.written[k]).all()
