"""The report of a fit: measured against simulated per recording, the residuals, the parameters with their
intervals, one HTML page that says how to read them.

``spirob-hil identify ... --report DIR`` writes ``DIR/index.html`` with three figures beside it
(``traces.png``, ``residuals.png``, ``parameters.png``) and, from MuJoCo's own toolbox, ``DIR/sysid/``
(its parameter table and signal plots; its covariance assumes independent residuals, which the page says).
"""

from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any

import numpy as np

from hil.experiments.common import pyplot, save_figure
from hil.identify.fit import FitResult
from hil.identify.intervals import ParamEstimate

__all__ = ["write_report"]


def write_report(result: FitResult, out: Path, title: str = "Identification") -> Path:
    """Write the report into ``out`` (created); returns the page's path."""
    out.mkdir(parents=True, exist_ok=True)
    _traces(result, out / "traces.png")
    _residuals(result, out / "residuals.png")
    _parameters(result.estimates, out / "parameters.png")
    page = out / "index.html"
    page.write_text(_page(result, title, (out / "sysid" / "report.html").exists()), encoding="utf-8")
    return page


def _traces(result: FitResult, path: Path) -> None:
    plt = pyplot()
    n = max(1, len(result.traces))
    fig, axes = plt.subplots(n, 1, figsize=(11, 2.8 * n), squeeze=False)
    for ax, tr in zip(axes[:, 0], result.traces, strict=False):
        for k, colour in enumerate(("tab:blue", "tab:orange", "tab:green")):
            ax.plot(tr.t_s, tr.measured_m[:, k] * 1e3, color=colour, lw=1.6, label=f"cable {k + 1} measured")
            ax.plot(tr.t_s, tr.fitted_m[:, k] * 1e3, color="k", lw=0.8, ls="--")
            ax.plot(tr.t_s, tr.nominal_m[:, k] * 1e3, color=colour, lw=0.8, ls=":", alpha=0.8)
        if tr.held_out.any():
            t0 = float(tr.t_s[tr.held_out][0])
            ax.axvspan(t0, float(tr.t_s[-1]), color="0.92", zorder=0)
            ax.text(t0, ax.get_ylim()[1], " held out", va="top", fontsize=8, color="0.4")
        ax.set_title(
            f"{tr.recording}: fitted {tr.rms_m(False) * 1e3:.3g} mm RMS on the fitted part, "
            f"{tr.rms_m(True) * 1e3:.3g} mm held out (preset: {tr.rms_m(True, 'nominal') * 1e3:.3g} mm)",
            fontsize=9,
        )
        ax.set_ylabel("cable wound in [mm]")
    axes[-1, 0].set_xlabel("time [s]  (solid: measured; dashed black: fitted model; dotted: preset)")
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=3)
    save_figure(fig, path)


def _residuals(result: FitResult, path: Path) -> None:
    plt = pyplot()
    n = max(1, len(result.traces))
    fig, axes = plt.subplots(n, 2, figsize=(11, 2.4 * n), squeeze=False, gridspec_kw={"width_ratios": [3, 1]})
    for row, tr in zip(axes, result.traces, strict=False):
        err = (tr.fitted_m - tr.measured_m) * 1e3
        for k in range(err.shape[1]):
            row[0].plot(tr.t_s, err[:, k], lw=0.8, label=f"cable {k + 1}")
        row[0].axhline(0.0, color="k", lw=0.5)
        row[0].set_ylabel("fitted - measured [mm]")
        row[0].set_title(tr.recording, fontsize=9)
        finite = err[np.isfinite(err)]
        if finite.size:
            row[1].hist(finite.ravel(), bins=40, color="0.5")
        row[1].set_xlabel("[mm]")
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    save_figure(fig, path)


def _parameters(estimates: tuple[ParamEstimate, ...], path: Path) -> None:
    """Each parameter as a ratio to its preset value, with its interval."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 0.45 * len(estimates) + 1.2))
    for i, e in enumerate(estimates):
        ref = e.preset if e.preset not in (0.0,) and math.isfinite(e.preset) else 1.0
        value = e.value / ref
        lo, hi = (x / ref for x in e.interval)
        colour = "tab:blue" if e.identifiable else "tab:red"
        if math.isfinite(lo) and math.isfinite(hi):
            ax.plot([lo, hi], [i, i], color=colour, lw=3, alpha=0.5)
        ax.plot([value], [i], "o", color=colour)
    ax.axvline(1.0, color="k", lw=0.5)
    ax.set_yticks(
        range(len(estimates)), [f"{e.name}{'' if e.identifiable else ' (not identified)'}" for e in estimates]
    )
    ax.set_xlabel("fitted / preset value, with the 95 % interval (red: the data do not pin it down)")
    ax.invert_yaxis()
    save_figure(fig, path)


def _fmt(v: float, unit: str = "") -> str:
    if not math.isfinite(v):
        return "-"
    return f"{v:.4g}{' ' + unit if unit else ''}"


def _page(result: FitResult, title: str, has_sysid: bool) -> str:
    rows = "\n".join(
        "<tr>"
        f"<td>{html.escape(e.name)}</td><td>{_fmt(e.preset, e.unit)}</td>"
        f"<td><b>{_fmt(e.value, e.unit)}</b></td>"
        f"<td>{_fmt(e.interval[0])} .. {_fmt(e.interval[1])}</td>"
        f"<td>{_fmt(e.naive_interval[0])} .. {_fmt(e.naive_interval[1])}</td>"
        f"<td>{'yes' if e.identifiable else 'no'}{' (at a bound)' if e.at_bound else ''}</td>"
        f"<td>{html.escape(e.why)}</td></tr>"
        for e in result.estimates
    )
    recs = "\n".join(
        f"<tr><td>{html.escape(name)}</td><td><code>{sha[:16]}…</code></td><td>{_fmt(dur, 's')}</td></tr>"
        for name, sha, dur in result.recordings
    )
    summary: list[tuple[str, Any]] = [
        ("cable length error on the fitted samples, fitted model", _fmt(result.rms_m(False) * 1e3, "mm")),
        ("... the preset", _fmt(result.rms_m(False, "nominal") * 1e3, "mm")),
        ("cable length error on the held-out samples, fitted model", _fmt(result.rms_m(True) * 1e3, "mm")),
        ("... the preset", _fmt(result.rms_m(True, "nominal") * 1e3, "mm")),
        ("condition number of the Jacobian", _fmt(result.condition_number)),
        ("solver iterations", result.iterations),
        (
            "converged",
            "yes"
            if result.converged
            else f"no: the last iteration still gained {100 * result.last_reduction:.1f} %",
        ),
        ("rollouts / simulated seconds", f"{result.rollouts} / {result.simulated_s:.0f} s"),
        ("wall time", _fmt(result.wall_s, "s")),
    ]
    summ = "\n".join(f"<tr><td>{html.escape(k)}</td><td>{v}</td></tr>" for k, v in summary)
    sysid = (
        '<p>MuJoCo\'s own report of the same fit: <a href="sysid/report.html">sysid/report.html</a> (its '
        "covariance assumes independent residuals; the intervals above do not).</p>"
        if has_sysid
        else ""
    )
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto}}
td,th{{padding:2px 8px;border-bottom:1px solid #ddd}}
table{{border-collapse:collapse}}img{{max-width:100%}}</style></head><body>
<h1>{html.escape(title)}</h1>
<h2>Parameters</h2>
<table><tr><th>parameter</th><th>preset</th><th>fitted</th><th>95 % interval</th><th>naive interval</th>
<th>identified</th><th>why not</th></tr>
{rows}</table>
<p>The interval is autocorrelation-consistent (Newey-West around the fit's Jacobian): a simulated arm's
errors are smooth in time, so the residuals are not independent and the naive interval (MuJoCo's
<code>calculate_intervals</code>, shown for comparison) is far too narrow. It is never narrower than the
solver's finite-difference step (the solver cannot place a minimum more finely), and it is widened by how far
the fit stopped from its minimum. A parameter is called identified when its interval's half-width is within
10 % of its value and nothing else speaks against it (docs/identify.md); one that is not keeps its fitted
value in the model file, marked, and says why.</p>
<img src="parameters.png" alt="parameters">
<h2>Fit</h2><table>{summ}</table>
<h2>Measured against simulated</h2>
<p>Each recording simulated whole from its first sample (the only state known: friction holds a bent arm where
it was left). Grey: the samples the fit never saw.</p>
<img src="traces.png" alt="traces">
<img src="residuals.png" alt="residuals">
{sysid}
<h2>Recordings</h2><table><tr><th>file</th><th>SHA-256</th><th>duration</th></tr>{recs}</table>
</body></html>
"""
