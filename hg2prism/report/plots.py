"""Figures a researcher opens: the world with one episode, the sweep, the detector, scaling."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from hg2prism.model.dynamics import TransitionSystem  # noqa: E402
from hg2prism.outputs import write_bytes  # noqa: E402
from hg2prism.model.world import World  # noqa: E402

_HYPOTHESIS_COLOURS = ("tab:blue", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive")


def _save(fig: plt.Figure, path: Path) -> None:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=130, bbox_inches="tight")
    plt.close(fig)
    write_bytes(path, buffer.getvalue())


def _save_png_and_svg(fig: plt.Figure, png: Path, svg: Path) -> None:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="svg", bbox_inches="tight", metadata={"Date": None})
    write_bytes(svg, buffer.getvalue())
    _save(fig, png)


def world_figure(world: World, ts: TransitionSystem, steps: Sequence, outcome: str, path: Path) -> None:
    """The grid, and one simulated deceptive episode: the robot's path coloured by P2's
    hypothesis, the trap P2 set at each step, and where P2 changed her mind."""
    grid = world.grid
    fig, ax = plt.subplots(figsize=(0.75 * grid.width + 3.5, 0.75 * grid.height + 0.6))
    for x in range(grid.width):
        for y in range(grid.height):
            cell = (x, y)
            colour, text = "white", ""
            if cell in grid.walls:
                colour = "0.45"
            elif cell in grid.obstacles:
                colour, text = "black", ""
            elif cell in grid.trap_candidates:
                colour = "#b8e6b8"
            for letter, cells in grid.regions:
                if cell in cells:
                    colour, text = "#f4a6a6", letter
            ax.add_patch(plt.Rectangle((x - 0.5, y - 0.5), 1, 1, facecolor=colour, edgecolor="0.8"))
            if text:
                ax.text(x, y, text, ha="center", va="center", fontsize=14, weight="bold")
    sx, sy = grid.start
    ax.text(sx, sy - 0.3, "start", ha="center", va="center", fontsize=7)

    trap_counts: dict[tuple[int, int], int] = {}
    for i, step in enumerate(steps):
        x0, y0 = ts.cells[ts.decode(step.ts_state)[0]]
        if step.next_state == ts.trapped:
            x1, y1 = x0, y0
        else:
            x1, y1 = ts.cells[ts.decode(step.next_state)[0]]
        colour = _HYPOTHESIS_COLOURS[step.p2_memory.hypothesis % len(_HYPOTHESIS_COLOURS)]
        ax.annotate("", xy=(x1, y1), xytext=(x0, y0),
                    arrowprops=dict(arrowstyle="->", color=colour, lw=2.2))
        for cell in ts.trap_cells(step.a2):
            trap_counts[cell] = trap_counts.get(cell, 0) + 1
        if i == 0 or steps[i - 1].p2_memory.hypothesis != step.p2_memory.hypothesis:
            ax.text(x0 + 0.12, y0 + 0.28, f"n={step.n}: x{step.p2_memory.hypothesis}",
                    fontsize=7, color=colour, weight="bold")
    for (x, y), count in trap_counts.items():
        ax.plot(x, y, marker="X", color="darkgreen", markersize=9 + min(count, 10))
        ax.text(x + 0.3, y - 0.35, f"{count}×", fontsize=7, color="darkgreen")

    handles = [plt.Line2D([], [], color=_HYPOTHESIS_COLOURS[i % len(_HYPOTHESIS_COLOURS)], lw=2.2,
                          label=f"P2 believes x{i}: {h}") for i, h in enumerate(world.hypotheses)]
    handles.append(plt.Line2D([], [], color="darkgreen", marker="X", ls="", label="trap set by P2 (× steps)"))
    handles.append(plt.Rectangle((0, 0), 1, 1, facecolor="#b8e6b8", label="trap candidate"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    ax.set_xlim(-0.5, grid.width - 0.5)
    ax.set_ylim(-0.5, grid.height - 0.5)
    ax.set_aspect("equal")
    ax.set_xticks(range(grid.width))
    ax.set_yticks(range(grid.height))
    ax.set_title(f"{world.name}: task {world.formula} — one deceptive episode ({outcome}, "
                 f"{len(steps)} steps)", fontsize=9)
    _save(fig, path)


def sweep_figure(parameter: str, rows: Sequence[dict], path: Path) -> None:
    """Completion probability against a swept parameter, one line per value."""
    fig, ax = plt.subplots(figsize=(6, 4))
    xs = [row[parameter] for row in rows]
    for key, label, style in (("deceptive_value", "deceptive (asymmetric)", "o-"),
                              ("v_lead", "symmetric, leader", "s--"),
                              ("v_ne", "symmetric, Nash", "^:")):
        if all(key in row for row in rows):
            ax.plot(xs, [row[key] for row in rows], style, label=label)
    ax.set_xlabel(parameter)
    ax.set_ylabel("P1's completion probability")
    ax.set_ylim(0, 1.02)
    ax.set_xticks(xs)
    ax.grid(alpha=0.3)
    ax.legend()
    _save(fig, path)


def detection_figure(statistics: Sequence[float], thresholds: Sequence[float | None],
                     deviate_after: int, detected_at: int | None, path: Path,
                     replanning: dict | None = None) -> None:
    """The likelihood-ratio statistic G per step against the chi-square threshold; with
    `replanning` (detection.json's section) a second panel: completion with and without
    re-planning in the deviation and compliant batches, with their 95% Wilson intervals."""
    if replanning is None:
        fig, ax = plt.subplots(figsize=(6.5, 4))
    else:
        fig, (ax, bars) = plt.subplots(1, 2, figsize=(11.5, 4),
                                       gridspec_kw={"width_ratios": [1.35, 1]})
    steps = list(range(1, len(statistics) + 1))
    ax.plot(steps, statistics, "o-", label="G = 2 (ln L1 − ln L0)")
    ax.plot(steps, [t if t is not None else float("nan") for t in thresholds], "s--",
            label="χ² threshold (1 − α, df)")
    ax.axvline(deviate_after + 0.5, color="grey", ls=":", label=f"P2 deviates after step {deviate_after}")
    if detected_at is not None:
        ax.axvline(detected_at, color="red", alpha=0.5, label=f"mismatch detected at step {detected_at}")
    ax.set_xlabel("step n")
    ax.set_ylabel("statistic")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if replanning is not None:
        shown = (f"robust strategy, δ = {replanning['delta']:g}" if replanning["fallback"] == "robust"
                 else "leader-game strategy")
        batches = (("deviation", "P2 deviates"), ("compliant", "P2 follows the model"))
        for offset, (key, label, colour) in enumerate((("without", "without re-planning", "tab:blue"),
                                                       ("with", f"re-planning ({shown})", "tab:green"))):
            xs = [i + (offset - 0.5) * 0.36 for i in range(len(batches))]
            rates = [replanning[b][key]["rate"] for b, _ in batches]
            low = [r - replanning[b][key]["ci95"][0] for r, (b, _) in zip(rates, batches)]
            high = [replanning[b][key]["ci95"][1] - r for r, (b, _) in zip(rates, batches)]
            bars.bar(xs, rates, width=0.34, color=colour, label=label, yerr=[low, high], capsize=4)
            for x, r in zip(xs, rates):
                bars.text(x, r / 2, f"{r:.3f}", ha="center", va="center", fontsize=8, color="white")
        bars.set_xticks(range(len(batches)))
        bars.set_xticklabels([name for _, name in batches])
        bars.set_ylabel("completion rate (95% Wilson interval)")
        bars.set_ylim(0, 1.05)
        bars.grid(alpha=0.3, axis="y")
        bars.legend(fontsize=8, loc="upper center")
    _save(fig, path)


def scaling_figure(rows: Sequence[dict], stages: Sequence[str], path: Path,
                   title: str | None = None) -> None:
    """Time per stage against canonical states, log-log, with a slope-1 guide through the
    largest world's total (a stage parallel to it grows linearly)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    rows = sorted(rows, key=lambda r: r["states"])
    xs = [r["states"] for r in rows]
    for stage in stages:
        ax.loglog(xs, [max(r[f"time_{stage}"], 1e-3) for r in rows], "o-", ms=4, lw=0.8,
                  alpha=0.85, label=stage)
    totals = [r["time_total"] for r in rows]
    ax.loglog(xs, totals, "k^-", lw=2, label="total")
    if len(xs) >= 2 and xs[0] < xs[-1]:
        ax.loglog([xs[0], xs[-1]], [totals[-1] * xs[0] / xs[-1], totals[-1]], "k:", lw=1,
                  label="slope 1")
    ax.set_xlabel("hypergame states (canonical)")
    ax.set_ylabel("seconds (floor 1 ms)")
    if title:
        ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))
    _save(fig, path)


def robust_figure(result: dict, png: Path, svg: Path) -> None:
    """Robust deception (docs/semantics.md §13) against the deviation budget: R_delta, what the
    deceptive strategy guarantees under the same budget, and the nominal references."""
    rows = sorted(result["rows"], key=lambda row: row["delta"])
    deltas = [row["delta"] for row in rows]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    ax.plot(deltas, [row["robust_value"] for row in rows], "o-",
            label="robust value $R_\\delta$ (robust strategy, worst case)")
    ax.plot(deltas, [row["nominal_worst_case"] for row in rows], "s--",
            label="deceptive strategy, worst case")
    ax.plot(deltas, [row["robust_strategy_nominal_value"] for row in rows], "^:", alpha=0.8,
            label="robust strategy when P2 does not deviate")
    ax.axhline(result["deceptive_value"], color="grey", lw=0.8, ls="-.",
               label=f"deceptive value {result['deceptive_value']:.4f}")
    ax.axhline(result["v_lead"], color="grey", lw=0.8, ls=":",
               label=f"V_lead (P2 knows the task) {result['v_lead']:.4f}")
    ax.set_xlabel("deviation budget $\\delta$ (P2 leaves her predicted trap set with probability ≤ δ)")
    ax.set_ylabel("P1's completion probability")
    ax.set_xticks(deltas)
    ax.set_title(f"{result['world']}: robust deception", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5)
    _save_png_and_svg(fig, png, svg)
