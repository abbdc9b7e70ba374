"""Run reports: a table in the terminal, PNG plots of a run's signals over time, pictures of its moments
rendered by MuJoCo (:mod:`hil.render`), and an index (``NAME.md``) that lists them."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table

from hil.run_record import RunRecord, ScenarioResult
from protocol.messages import Mode, Phase

if TYPE_CHECKING:
    from hil.render import Film, Pictures


def results_table(results: Sequence[ScenarioResult], clock: str = "simulated time") -> Table:
    """One row per check: scenario, check, measured value, bound, verdict; then the plant's extremes over
    the run (lockstep), which have no bound: they say whether the physics behind the checks was sound."""
    table = Table(title=f"scenario checks ({clock})", show_lines=False)
    for col, justify in (
        ("scenario", "left"),
        ("check", "left"),
        ("measured", "right"),
        ("bound", "right"),
        ("", "center"),
    ):
        table.add_column(col, justify=justify)  # type: ignore[arg-type]
    for r in results:
        for i, c in enumerate(r.checks):
            verdict = "[green]pass[/green]" if c.passed else "[bold red]FAIL[/bold red]"
            table.add_row(
                r.name if i == 0 else "",
                c.name,
                f"{c.value:.6g} {c.unit}".strip(),
                f"{c.op} {c.bound:.6g} {c.unit}".strip(),
                verdict,
            )
        e = r.extremes
        if e is not None:
            for label, value in (
                ("plant: largest cable tension", f"{e.tension_n:.1f} N"),
                ("plant: largest joint-limit overshoot", f"{math.degrees(e.limit_overshoot_rad):.2f}°"),
                (
                    "plant: largest arm-object penetration",
                    f"{e.penetration_m * 1000:.2f} mm ({100 * e.penetration_ratio:.0f} % of its radius)",
                ),
            ):
                table.add_row("", f"[dim]{label}[/dim]", value, "", "")
    return table


def print_results(results: Sequence[ScenarioResult], console: Console, clock: str = "simulated time") -> None:
    """The table (its title names the clock the checks were measured on), then one summary line."""
    console.print(results_table(results, clock))
    failed = [r.name for r in results if not r.passed]
    if failed:
        console.print(
            f"[bold red]{len(failed)} of {len(results)} scenarios failed:[/bold red] {', '.join(failed)}"
        )
    else:
        console.print(f"[green]all {len(results)} scenarios passed[/green]")


def plot_run(run: RunRecord, out_dir: str | Path, name: str) -> Path:
    """Tensions, currents, cable lengths, failsafe phase and tip trajectory of one run, as one PNG.

    The plant's curves (true tensions, cable lengths, tip) appear when the run has a plant (lockstep).

    Returns:
        The PNG's path (``out_dir/name.png``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    s, plant = run.samples, run.plant
    t = s.t_us / 1e6
    fig, axes = plt.subplots(5 if plant is not None else 3, 1, figsize=(9, 13), sharex=False)
    colors = ("tab:red", "tab:green", "tab:blue")
    ax = axes[0]
    for k in range(3):
        if plant is not None:
            ax.plot(t, plant.tension_n[:, k], color=colors[k], label=f"cable {k + 1} (plant)")
        ax.plot(t, s.target_n[:, k], color=colors[k], ls="--", lw=0.8, label=f"cable {k + 1} target")
    ax.set_ylabel("tension [N]")
    ax.legend(ncol=3, fontsize=7)
    ax = axes[1]
    for k in range(3):
        ax.plot(t, s.current_raw[:, k] / 1000.0, color=colors[k], label=f"motor {k + 1}")
    ax.set_ylabel("current to ESC [A]")
    ax.legend(ncol=3, fontsize=7)
    ax = axes[2]
    ax.step(t, s.phase, where="post", color="tab:blue")
    ax.set_yticks([int(p) for p in Phase], [p.name for p in Phase], fontsize=7)
    ax.set_ylabel("failsafe phase", color="tab:blue")
    mode_ax = ax.twinx()
    mode_ax.step(t, s.mode, where="post", color="tab:orange", alpha=0.8)
    mode_ax.set_yticks([int(m) for m in Mode], [m.name for m in Mode], fontsize=7)
    mode_ax.set_ylabel("mode", color="tab:orange")
    ax.set_xlabel("time [s]")
    if plant is not None and plant.cable_m.size:
        ax = axes[3]
        for k in range(3):
            ax.plot(
                t, (plant.cable_m[:, k] - plant.cable_m[0, k]) * 1000, color=colors[k], label=f"cable {k + 1}"
            )
        ax.set_ylabel("cable length change [mm]")
        ax.legend(ncol=3, fontsize=7)
        ax = axes[4]
        tip = plant.tip_m
        sc = ax.scatter(tip[:, 0] * 1000, tip[:, 2] * 1000, c=t, s=2, cmap="viridis")
        ax.set_xlabel("tip x [mm]")
        ax.set_ylabel("tip z [mm]")
        ax.set_aspect("equal", adjustable="datalim")
        fig.colorbar(sc, ax=ax, label="time [s]")
    fig.suptitle(name)
    fig.tight_layout()
    path = out / f"{name}.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def write_index(
    out_dir: str | Path,
    name: str,
    title: str,
    figures: Sequence[Path],
    pictures: Sequence[tuple[str, Pictures]],
    notes: Sequence[str] = (),
) -> Path:
    """Write ``out_dir/NAME.md``: the report's 2-D figures, then each set of rendered pictures under its
    heading with their times and what they show (or the one line saying why there are none), then notes.

    Returns:
        The index's path.
    """
    out = Path(out_dir)
    lines = [f"# {title}", "", "## Figures", ""]
    lines += [f"![{f.stem}]({f.name})" for f in figures] or ["none"]
    lines += ["", "## Pictures", ""]
    for heading, pics in pictures:
        if heading:
            lines += [f"### {heading}", ""]
        if pics.note:
            lines += [pics.note, ""]
            continue
        for p in pics.stills:
            lines += [f"![{p.caption}]({p.path.name})", "", f"t = {p.t_s:.3f} s: {p.caption}", ""]
        if pics.video is not None:
            lines += [f"![video]({pics.video.path.name})", "", pics.video.caption, ""]
        lines += [pics.lines()[-1], ""]
    lines += list(notes)
    if not pictures and not notes:
        lines.append("none")
    path = out / f"{name}.md"
    path.write_text("\n".join(lines).rstrip("\n") + "\n", encoding="utf-8")
    return path


def write_run_report(run: RunRecord, film: Film, out_dir: str | Path, name: str) -> Pictures:
    """A scenario's report: the 2-D plot (:func:`plot_run`), the pictures of its film (the run's own
    states) and the index ``NAME.md`` listing both.

    Returns:
        The pictures (their ``note`` says in one line why there are none).
    """
    from hil.render import render_film

    figure = plot_run(run, out_dir, name)
    pictures = render_film(film, out_dir, name)
    write_index(out_dir, name, f"scenario {name}", [figure], [("", pictures)])
    return pictures
