"""``olp-cal validate``: how well a calibration predicts measurements the fit never saw.

"After" is the calibrated model's prediction in its own device frame (as ``olp-cal
predict`` gives it); "before" is the nominal arm after a rigid registration to the same
measurements. Figures per region when the CSV has a ``region`` column.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ..calibration.validation import validate, validation_summary, validation_to_dict
from ..errors import DataError
from ..io.atomic import write_text_atomic
from ..io.calibration_file import read_calibration
from ..io.measurements import read_measurements

HELP = ("validate a calibration on measurements it never saw: position errors before "
        "(nominal, registered) and after (calibrated), overall and per region")


def add_arguments(p) -> None:
    p.add_argument("--model", required=True, help="calib.json to validate")
    p.add_argument("measurements", help="measurement CSV (q1_deg..qN_deg, x_mm, y_mm, z_mm "
                                        "in the calibration's device frame; optional point, "
                                        "region)")
    p.add_argument("--json", dest="json_out", metavar="OUT.json",
                   help="write the figures as JSON (mm)")
    p.add_argument("--html", dest="html_out", metavar="REPORT.html",
                   help="write an HTML report with figures")


def _check_outputs(args) -> None:
    outputs = [Path(p) for p in (args.json_out, args.html_out) if p]
    for out in outputs:
        for source in (args.model, args.measurements):
            same = False
            try:
                same = out.exists() and os.path.samefile(out, source)
            except OSError:
                same = out.resolve() == Path(source).resolve()
            if same or out.resolve() == Path(source).resolve():
                raise DataError(f"{out}: is an input ({source}); inputs are never "
                                f"overwritten, choose another output file")
    if len(outputs) == 2 and outputs[0].resolve() == outputs[1].resolve():
        raise DataError(f"{outputs[0]}: named for both --json and --html")


def run(args) -> int:
    _check_outputs(args)
    cal = read_calibration(args.model)
    meas = read_measurements(args.measurements, cal.robot)
    report = validate(cal, meas)
    for line in validation_summary(report):
        print(line)
    if args.json_out:
        write_text_atomic(args.json_out,
                          json.dumps(validation_to_dict(report), indent=2) + "\n")
        print(f"wrote {args.json_out}")
    if args.html_out:
        from ..report.validation_html import write_html

        write_html(report, [j.unit for j in cal.robot.joints], args.html_out)
        print(f"wrote {args.html_out}")
    return 0
