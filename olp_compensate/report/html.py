"""Figures of a diagnosis (matplotlib, Agg backend) and a self-contained HTML report.

Residuals are shown the way a calibration engineer reads them: as the *apparent error of
one axis*, the residual of each measured point projected on the direction that axis moves
it, divided by how far it moves it (mdeg); for thermal expansion as the apparent length
error, the residual along the flange position over its distance from the base (ppm).
Points whose measured point barely moves with the axis are left out (their projection is
noise).

Figures: one per named effect (apparent error against the variable that explains it,
before and after, with the fitted effect), the residual structure of the geometric model
against every axis angle, gravity torque, temperature and time, the held-out error
histograms before and after, and measured against predicted error per point.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from ..calibration.diagnose import Diagnosis, KeptEffect, diagnosis_to_dict, summary
from ..calibration.effects import Backlash, JointCompliance, ThermalExpansion
from ..errors import OlpError
from ..io.atomic import write_bytes_atomic, write_text_atomic
from .figures import figure_html, png, pyplot

MDEG_PER_RAD = 180.0 / np.pi * 1e3
BEFORE, AFTER, CURVE = "#9a9a9a", "#1f77b4", "#d62728"


def apparent_axis_error(d: Diagnosis, residual: np.ndarray, joint: int):
    """(values (m,) mdeg, mask (m,)): residual (m, 3) projected on how controller axis
    ``joint`` moves each measured point, per unit of that motion; mask keeps the rows that
    move at least a quarter of the median."""
    s = d.dpoint_dq[:, :, joint]
    norm2 = np.sum(s * s, axis=1)
    keep = norm2 > (0.25**2) * np.median(norm2)
    value = np.einsum("mi,mi->m", s, residual) / np.where(norm2 > 0, norm2, 1.0)
    return value * MDEG_PER_RAD, keep


def apparent_length_error(d: Diagnosis, residual: np.ndarray) -> np.ndarray:
    """(m,) ppm: residual along the flange position over its distance from the base."""
    u = d.flange_device
    return np.einsum("mi,mi->m", u, residual) / np.sum(u * u, axis=1) * 1e6


def _variable(d: Diagnosis, kept: KeptEffect):
    """(x values, x label, y converter name) of the variable that explains ``kept``."""
    e = kept.effect
    if isinstance(e, ThermalExpansion):
        return d.measurements.temperature_c, "temperature, deg C"
    if isinstance(e, (JointCompliance, Backlash)):
        return d.inputs.torque[:, e.joint], f"gravity load torque on axis {e.joint + 1}, N.m"
    return np.degrees(d.inputs.q[:, e.joint]), f"axis {e.joint + 1} angle, deg"


def effect_figure(d: Diagnosis, kept: KeptEffect):
    """Apparent error against the explaining variable, before (geometric model, with the
    fitted effect) and after (extended model)."""
    plt = pyplot()
    e = kept.effect
    x, xlabel = _variable(d, kept)
    if isinstance(e, ThermalExpansion):
        before = apparent_length_error(d, d.residual_before)
        after = apparent_length_error(d, d.residual_after)
        partial = apparent_length_error(d, d.residual_after + kept.displacement)
        curve = e.evaluate(d.inputs) * 1e6
        keep = np.ones(len(x), bool)
        ylabel = "apparent length error, ppm"
    else:
        before, keep = apparent_axis_error(d, d.residual_before, e.joint)
        after, _ = apparent_axis_error(d, d.residual_after, e.joint)
        partial, _ = apparent_axis_error(d, d.residual_after + kept.displacement, e.joint)
        curve = e.evaluate(d.inputs) * MDEG_PER_RAD
        ylabel = f"apparent axis {e.joint + 1} error, mdeg"
    order = np.argsort(x)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    ax = axes[0]
    ax.scatter(x[keep], before[keep], s=14, color=BEFORE, label="geometric model residual")
    ax.scatter(x[keep], partial[keep], s=14, color=AFTER, alpha=0.6,
               label="extended residual + this effect")
    ax.plot(x[order], curve[order], color=CURVE, lw=2, label=f"fitted {e.label}")
    ax.set_title("before: geometric model")
    ax.legend(fontsize=8, loc="best")
    ax = axes[1]
    ax.scatter(x[keep], after[keep], s=14, color=AFTER, label="extended model residual")
    ax.axhline(0.0, color="black", lw=0.8)
    ax.set_title(f"after: with {e.label}")
    for ax in axes:
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(ylabel)
    fig.suptitle(f"{e.label}: {e.description}", fontsize=11)
    fig.tight_layout()
    return fig


def structure_figure(d: Diagnosis):
    """Apparent axis errors of the geometric model against every axis angle and, where
    gravity loads the axis, its torque; plus temperature, time and payload when measured."""
    plt = pyplot()
    n = d.robot.n_joints
    torque = d.inputs.torque
    loaded = [j for j in range(n) if torque is not None and np.ptp(torque[:, j]) > 1e-3]
    extra = [name for name, col in (("temperature", d.measurements.temperature_c),
                                    ("time", d.measurements.time_s),
                                    ("payload", d.measurements.payload_kg)) if col is not None]
    panels = [("torque", j) for j in loaded] + [(name, None) for name in extra]
    cols = n
    rows = 1 + -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(2.6 * cols, 2.6 * rows), squeeze=False)
    named = {k.effect.joint for k in d.effects}
    for j in range(n):
        y, keep = apparent_axis_error(d, d.residual_before, j)
        ax = axes[0, j]
        ax.scatter(np.degrees(d.inputs.q[keep, j]), y[keep], s=8,
                   color=CURVE if j in named else BEFORE)
        ax.set_xlabel(f"q{j + 1}, deg")
        ax.set_title(f"axis {j + 1} error vs q{j + 1}", fontsize=9)
    axes[0, 0].set_ylabel("apparent error, mdeg")
    for k, (what, j) in enumerate(panels):
        ax = axes[1 + k // cols, k % cols]
        if what == "torque":
            y, keep = apparent_axis_error(d, d.residual_before, j)
            ax.scatter(torque[keep, j], y[keep], s=8, color=CURVE if j in named else BEFORE)
            ax.set_xlabel(f"load torque {j + 1}, N.m")
            ax.set_title(f"axis {j + 1} error vs torque", fontsize=9)
        elif what == "temperature":
            ax.scatter(d.measurements.temperature_c, apparent_length_error(d, d.residual_before),
                       s=8, color=BEFORE)
            ax.set_xlabel("temperature, deg C")
            ax.set_title("length error (ppm) vs T", fontsize=9)
        else:
            column = d.measurements.time_s if what == "time" else d.measurements.payload_kg
            ax.scatter(column, np.linalg.norm(d.residual_before, axis=1) * 1e3, s=8, color=BEFORE)
            ax.set_xlabel("time, s" if what == "time" else "payload, kg")
            ax.set_title(f"|residual| (mm) vs {what}", fontsize=9)
    for k in range(len(panels), (rows - 1) * cols):
        axes[1 + k // cols, k % cols].axis("off")
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    fig.suptitle("residual structure of the geometric model (red: axes with a named effect)",
                 fontsize=10)
    fig.tight_layout()
    return fig


def histogram_figure(d: Diagnosis):
    """Held-out errors of each point before and after, with the noise's own distribution."""
    plt = pyplot()
    before = d.geometric.heldout_errors * 1e3
    after = d.extended.heldout_errors * 1e3
    fig, ax = plt.subplots(figsize=(6.5, 4))
    top = np.nanmax(np.concatenate([before, after]))
    bins = np.linspace(0.0, top * 1.05, 30)
    ax.hist(before[np.isfinite(before)], bins=bins, color=BEFORE, alpha=0.7,
            label=f"geometric model (RMS {d.geometric.heldout_rms * 1e3:.3f} mm)")
    if d.extends:
        ax.hist(after[np.isfinite(after)], bins=bins, color=AFTER, alpha=0.6,
                label=f"extended model (RMS {d.extended.heldout_rms * 1e3:.3f} mm)")
    sigma = d.noise.sigma_m * 1e3
    r = np.linspace(0.0, bins[-1], 200)
    maxwell = np.sqrt(2 / np.pi) * r**2 / sigma**3 * np.exp(-r**2 / (2 * sigma**2))
    ax.plot(r, maxwell * len(before) * (bins[1] - bins[0]), color="black", lw=1.5,
            label=f"noise alone ({sigma:.3f} mm per axis)")
    ax.set_xlabel("held-out error of a measured point, mm")
    ax.set_ylabel("points")
    ax.set_title("held-out errors (k-fold by pose), before and after")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def prediction_figure(d: Diagnosis):
    """Measured error of the geometric model against the error the extended model predicts
    for it, per point and device axis."""
    plt = pyplot()
    measured = d.residual_before * 1e3
    predicted = d.predicted_change * 1e3
    fig, ax = plt.subplots(figsize=(5, 5))
    for axis, color in zip("xyz", ("#1f77b4", "#2ca02c", "#ff7f0e")):
        k = "xyz".index(axis)
        ax.scatter(measured[:, k], predicted[:, k], s=10, color=color, label=f"{axis} (device)")
    lim = np.max(np.abs(np.concatenate([measured.ravel(), predicted.ravel()]))) * 1.05
    ax.plot([-lim, lim], [-lim, lim], color="black", lw=0.8)
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ss = np.sum(measured**2)
    explained = 1.0 - np.sum((measured - predicted) ** 2) / ss if ss > 0 else 0.0
    ax.set_xlabel("measured error of the geometric model, mm")
    ax.set_ylabel("error predicted by the named effects, mm")
    ax.set_title(f"per measured point: {100 * explained:.0f} % of the error explained",
                 fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def figures(d: Diagnosis) -> list[tuple[str, str, object]]:
    """(file stem, caption, matplotlib figure) of every figure of the report."""
    out = []
    for k, kept in enumerate(d.effects, start=1):
        stem = f"effect{k}_{kept.effect.label.replace(' ', '_').replace('=', '')}"
        out.append((stem, f"{kept.effect.label}: apparent error against the variable that "
                          f"explains it, before and after the extension", effect_figure(d, kept)))
    out.append(("structure", "residual structure of the geometric model", structure_figure(d)))
    if d.geometric.heldout_errors is not None:
        out.append(("histogram", "held-out error per measured point, before and after",
                    histogram_figure(d)))
    if d.extends:
        out.append(("measured_vs_predicted", "measured against predicted error per measured "
                                             "point", prediction_figure(d)))
    return out


def write_pngs(d: Diagnosis, folder: str | Path) -> list[str]:
    """Write every figure as ``folder/STEM.png``; returns the file names."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OlpError(f"{folder}: cannot create the folder ({exc.strerror})") from None
    names = []
    for stem, _, fig in figures(d):
        write_bytes_atomic(folder / f"{stem}.png", png(fig))
        names.append(f"{stem}.png")
    return names


def html_report(d: Diagnosis) -> str:
    """One self-contained HTML page: the summary, the effects table and the figures."""
    doc = diagnosis_to_dict(d)

    def row(e: dict) -> str:
        joint = "" if e["joint"] is None else str(e["joint"])
        std = "" if e["std"] is None else f"{e['std']:.2g}"
        order = f" (order {e['order']})" if "order" in e else ""
        return (f"<tr><td>{html.escape(e['kind'])}{order}</td><td>{joint}</td>"
                f"<td>{e['value']:.4g}</td><td>{std}</td><td>{html.escape(e['unit'])}</td>"
                f"<td>{e['point_rms_mm']:.3f}</td><td>{e['p_value']:.1e}</td>"
                f"<td>{html.escape(', '.join(e['alternatives']))}</td></tr>")

    rows = "".join(row(e) for e in doc["effects"])
    table = ("<p><b>No effect found</b>: no candidate lowers the held-out error significantly.</p>"
             if not rows else
             "<table><tr><th>kind</th><th>joint</th><th>value</th><th>std</th><th>unit</th>"
             "<th>moves the point, mm RMS</th><th>p</th><th>alternatives</th></tr>"
             + rows + "</table>")
    held = doc["heldout_rms_mm"]
    figs = "".join(
        figure_html(png(fig), caption)
        for _, caption, fig in figures(d))
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>olp-cal diagnose: {html.escape(d.robot.name)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 1100px; }}
pre {{ background: #f5f5f5; padding: 1em; white-space: pre-wrap; font-size: 0.85em; }}
table {{ border-collapse: collapse; }} td, th {{ border: 1px solid #ccc; padding: 4px 8px; }}
figure {{ margin: 1.5em 0; }} img {{ max-width: 100%; }}
figcaption {{ color: #555; font-size: 0.9em; }}
</style></head><body>
<h1>Diagnosis of {html.escape(d.robot.name)}</h1>
<p>{html.escape(d.measurements.source)}: {d.measurements.n_poses} poses,
{d.measurements.n_rows} measured points. Held-out RMS {held['geometric']:.4f} mm (geometric)
&rarr; {held['extended']:.4f} mm (extended); noise {doc['noise_3d_rms_mm']:.4f} mm 3-D RMS
({html.escape(d.noise.source)}).</p>
{table}
{figs}
<h2>Summary</h2>
<pre>{html.escape(summary(d))}</pre>
</body></html>
"""


def write_html(d: Diagnosis, path: str | Path) -> None:
    """Write the HTML report atomically."""
    write_text_atomic(path, html_report(d))
