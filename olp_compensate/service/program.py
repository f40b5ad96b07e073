"""``compensate_program``: a whole program text compensated as olp-fix does it, with the
report's rows (the columns of olp-fix's ``--report`` CSV, numbers as JSON numbers and None
where the CSV leaves a field empty)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from ..compensation.files import CompensationRun, ProgramFiles
from ..compensation.pose import Compensator


def compensate_text(comp: Compensator, dialect: str, text: str, file: str,
                    frames_path: Path | None, dat: str | None = None) -> dict:
    """``{"text": new text, "rows": report rows}`` of program ``text`` named ``file``
    (KRL: a .src, with its .dat's text ``dat`` when given, answered as ``"dat"`` too;
    FANUC and KRL frames from ``frames_path``)."""
    if dialect in ("rapid", "vplus"):
        from ..programs.object_model.task import compensate_program

        new, report = compensate_program(text, dialect, comp, file=file)
        out = {"text": new}
    else:
        from ..programs.languages import language_named

        names = (file,) if dat is None else (file, str(Path(file).with_suffix(".dat")))
        files = ProgramFiles(dialect=dialect, paths=tuple(map(Path, names)), names=names)
        result = language_named(dialect).compensate(
            files, [text] if dat is None else [text, dat],
            CompensationRun(comp, frames=frames_path))
        report = result.report
        out = {"text": result.text(0)}
        if dat is not None:
            out["dat"] = result.text(1)
    out["rows"] = [row_dict(r, report.n_joints) for r in report.rows]
    return out


def row_dict(row, n_joints: int) -> dict:
    """One report row with the CSV's column names (mm, deg)."""
    d = dataclasses.asdict(row) if dataclasses.is_dataclass(row) else dict(row._asdict())
    dx, dy, dz = (d["correction_mm"] if len(d["correction_mm"]) == 3 else (math.nan,) * 3)
    joints = list(d["joints"]) or [math.nan] * n_joints
    out = {"target": d["target"], "file": d["file"], "line": d["line"],
           "column": d["column"], "status": d["status"], "tool": d["tool"],
           "wobj": d["wobj"], "dx_mm": _num(dx), "dy_mm": _num(dy), "dz_mm": _num(dz),
           "drot_deg": _num(d["correction_deg"]), "dq_max_deg": _num(d["joint_change"]),
           "config_before": d["config_before"], "config_after": d["config_after"]}
    for k, v in enumerate(joints):
        out[f"q{k + 1}_deg"] = _num(v)
    out["note"] = d["note"]
    return out


def _num(value):
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None
