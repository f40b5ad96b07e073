"""Figures of a validation (matplotlib, Agg backend) and a self-contained HTML report.

Figures: the histogram of the position errors before and after calibration, the error
against each controller axis, the error against the distance from the calibration volume's
centre (the validation points' centroid when no volume is known), and a 3-D scatter of the
validation points (base frame) coloured by the error after calibration.
"""

from __future__ import annotations

import base64
import html
import math
from pathlib import Path

import numpy as np

from ..calibration.validation import ErrorStats, ValidationReport, validation_summary
from ..io.atomic import write_text_atomic
from .figures import figure_html, png, pyplot

BEFORE, AFTER = "#9a9a9a", "#1f77b4"


def histogram_figure(report: ValidationReport):
    """Histogram of the error norms before and after, mm."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.6))
    before, after = report.errors_before_m * 1e3, report.errors_after_m * 1e3
    top = max(float(np.max(before)), float(np.max(after)), 1e-6)
    bins = np.linspace(0.0, top * 1.02, 40)
    ax.hist(before, bins=bins, color=BEFORE, alpha=0.7,
            label=f"before (nominal, registered): mean {report.before.mean * 1e3:.3f} mm")
    ax.hist(after, bins=bins, color=AFTER, alpha=0.8,
            label=f"after (calibrated): mean {report.after.mean * 1e3:.3f} mm")
    ax.set_xlabel("position error, mm")
    ax.set_ylabel("measured points")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def axes_figure(report: ValidationReport, joint_units: list[str]):
    """Error against each controller axis, before and after."""
    plt = pyplot()
    n = report.joints.shape[1]
    cols = 3
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(10, 2.8 * rows), squeeze=False)
    scale = np.array([180.0 / np.pi if u == "deg" else 1e3 for u in joint_units])
    for k in range(rows * cols):
        ax = axes[k // cols][k % cols]
        if k >= n:
            ax.axis("off")
            continue
        q = report.joints[:, k] * scale[k]
        ax.scatter(q, report.errors_before_m * 1e3, s=8, color=BEFORE, label="before")
        ax.scatter(q, report.errors_after_m * 1e3, s=8, color=AFTER, label="after")
        ax.set_xlabel(f"axis {k + 1}, {joint_units[k]}")
        ax.set_ylabel("error, mm")
        ax.grid(alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def distance_figure(report: ValidationReport):
    """Error against the distance from the volume's centre (base frame), mm."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.6))
    d = report.distance_from_centre_m * 1e3
    ax.scatter(d, report.errors_before_m * 1e3, s=10, color=BEFORE, label="before")
    ax.scatter(d, report.errors_after_m * 1e3, s=10, color=AFTER, label="after")
    ax.set_xlabel(f"distance from {report.centre_source}, mm")
    ax.set_ylabel("position error, mm")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def scatter3d_figure(report: ValidationReport):
    """The validation points in the base frame, coloured by the error after calibration."""
    plt = pyplot()
    fig = plt.figure(figsize=(7, 5.5))
    ax = fig.add_subplot(projection="3d")
    p = report.points_base_m * 1e3
    dots = ax.scatter(p[:, 0], p[:, 1], p[:, 2], c=report.errors_after_m * 1e3, cmap="viridis",
                      s=14)
    ax.scatter(*(report.centre_m * 1e3), marker="x", color="red", s=40, label="centre")
    fig.colorbar(dots, ax=ax, shrink=0.7, label="error after calibration, mm")
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_zlabel("z, mm")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def figures(report: ValidationReport, joint_units: list[str]) -> list[tuple[str, object]]:
    """(caption, figure) of every figure of the report."""
    return [("position error per measured point, before and after calibration",
             histogram_figure(report)),
            ("position error against each controller axis", axes_figure(report, joint_units)),
            (f"position error against the distance from {report.centre_source} (base frame)",
             distance_figure(report)),
            ("validation points in the base frame, coloured by the error after calibration",
             scatter3d_figure(report))]


def _cells(s: ErrorStats) -> str:
    std = "" if not math.isfinite(s.std) else f"{s.std * 1e3:.3f}"
    return "".join(f"<td>{v}</td>" for v in (
        s.n, f"{s.mean * 1e3:.3f}", std, f"{s.median * 1e3:.3f}", f"{s.p95 * 1e3:.3f}",
        f"{s.max * 1e3:.3f}"))


def html_report(report: ValidationReport, joint_units: list[str]) -> str:
    """One self-contained HTML page: the figures table, per region, and the figures."""
    rows = [("all", "before", report.before), ("all", "after", report.after)]
    for r in report.regions:
        rows += [(r.name, "before", r.before), (r.name, "after", r.after)]
    table = "".join(f"<tr><td>{html.escape(name)}</td><td>{when}</td>{_cells(s)}</tr>"
                    for name, when, s in rows)
    figs = "".join(
        figure_html(png(fig, dpi=100), caption)
        for caption, fig in figures(report, joint_units))
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>olp-cal validate: {html.escape(report.robot)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 1100px; }}
pre {{ background: #f5f5f5; padding: 1em; white-space: pre-wrap; font-size: 0.85em; }}
table {{ border-collapse: collapse; }} td, th {{ border: 1px solid #ccc; padding: 4px 8px; }}
figure {{ margin: 1.5em 0; }} img {{ max-width: 100%; }}
figcaption {{ color: #555; font-size: 0.9em; }}
</style></head><body>
<h1>Validation of {html.escape(report.robot)}</h1>
<p>{html.escape(report.source)}: {report.n} measured points. <b>Before</b>: the nominal arm,
its device frame registered rigidly to these measurements (the best without calibration).
<b>After</b>: the calibrated model as <code>olp-cal predict</code> gives it, no re-fit.</p>
<table><tr><th>region</th><th></th><th>n</th><th>mean, mm</th><th>std, mm</th>
<th>median, mm</th><th>95 %, mm</th><th>max, mm</th></tr>{table}</table>
{figs}
<h2>Summary</h2>
<pre>{html.escape(chr(10).join(validation_summary(report)))}</pre>
</body></html>
"""


def write_html(report: ValidationReport, joint_units: list[str], path: str | Path) -> None:
    """Write the HTML report atomically."""
    write_text_atomic(path, html_report(report, joint_units))


# -- ISO 9283 ---------------------------------------------------------------------------------

def iso_figure(results, attained_m: np.ndarray, poses: np.ndarray):
    """Attained positions of each pose relative to its commanded position (x-y and x-z
    projections, mm), with the barycentre and the RP_l circle about it."""
    plt = pyplot()
    fig, axes = plt.subplots(2, len(results), figsize=(2.6 * len(results), 5.4), squeeze=False)
    theta = np.linspace(0, 2 * np.pi, 100)
    for k, r in enumerate(results):
        d = (attained_m[poses == r.pose] - r.commanded_m) * 1e3
        b = r.ap_xyz_m * 1e3
        for row, (i, j, label) in enumerate(((0, 1, "y"), (0, 2, "z"))):
            ax = axes[row][k]
            ax.scatter(d[:, i], d[:, j], s=8, color=AFTER)
            ax.scatter([0], [0], marker="+", color="black", s=60, label="commanded")
            ax.scatter([b[i]], [b[j]], marker="x", color="red", s=40, label="barycentre")
            rp = r.rp_l_m * 1e3
            ax.plot(b[i] + rp * np.cos(theta), b[j] + rp * np.sin(theta), color="red", lw=0.8)
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_xlabel("dx, mm", fontsize=8)
            ax.set_ylabel(f"d{label}, mm", fontsize=8)
            ax.tick_params(labelsize=7)
            if row == 0:
                ax.set_title(f"{r.pose}: AP {r.ap_p_m * 1e3:.3f} mm, RP {rp:.3f} mm", fontsize=8)
            if k == 0 and row == 0:
                ax.legend(fontsize=6)
    fig.tight_layout()
    return fig


def iso_html(results, conditions: dict, attained_m: np.ndarray, poses: np.ndarray) -> str:
    """One self-contained HTML page of an ISO 9283 AP/RP test."""
    from ..calibration.iso9283 import iso_summary

    oriented = results[0].ap_abc_rad is not None
    head = "<th>pose</th><th>n</th><th>AP_P, mm</th><th>RP_l, mm</th>" + (
        "".join(f"<th>AP_{a}, deg</th>" for a in "abc")
        + "".join(f"<th>RP_{a}, deg</th>" for a in "abc") if oriented else "")
    rows = []
    for r in results:
        cells = [r.pose, r.n, f"{r.ap_p_m * 1e3:.4f}", f"{r.rp_l_m * 1e3:.4f}"]
        if oriented:
            cells += [f"{np.degrees(v):+.4f}" for v in r.ap_abc_rad]
            cells += [f"&plusmn;{np.degrees(v):.4f}" for v in r.rp_abc_rad]
        rows.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    image = base64.b64encode(png(iso_figure(results, attained_m, poses), dpi=100)).decode()
    summary = html.escape(chr(10).join(iso_summary(results, conditions)))
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>ISO 9283 AP and RP</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 1100px; }}
pre {{ background: #f5f5f5; padding: 1em; white-space: pre-wrap; font-size: 0.85em; }}
table {{ border-collapse: collapse; }} td, th {{ border: 1px solid #ccc; padding: 4px 8px; }}
img {{ max-width: 100%; }}
</style></head><body>
<h1>ISO 9283:1998 pose accuracy and repeatability</h1>
<table><tr>{head}</tr>{''.join(rows)}</table>
<figure><img src='data:image/png;base64,{image}' alt='attained positions per pose'>
<figcaption>attained positions relative to the commanded one; red: barycentre and the
RP_l circle</figcaption></figure>
<pre>{summary}</pre>
</body></html>
"""


def write_iso_html(results, conditions: dict, attained_m, poses, path: str | Path) -> None:
    """Write the ISO 9283 HTML report atomically."""
    write_text_atomic(path, iso_html(results, conditions, np.asarray(attained_m),
                                     np.asarray(poses, dtype=object)))
