"""The figure of adaptive deception (docs/semantics.md §16): P1's belief over P2's types along
a drawn episode (`adaptive_belief.{png,svg}`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.ticker import MaxNLocator

from hg2prism.report.plots import BELIEF_INCHES, figure_axes, figure_done
from hg2prism.report.style import hypothesis_colour

__all__ = ["adaptive_belief_figure"]


def adaptive_belief_figure(world_name: str, names: Sequence[str], beliefs: Sequence[Sequence[float]],
                           true_type: int, seed: int, outcome: str, path: Path | None,
                           ax=None) -> list[Path]:
    """P1's belief in each type (the prior restricted to the consistent types) against the
    step of the episode, P2's true type drawn bold (into `ax` when given, then writing
    nothing)."""
    given = ax
    fig, ax = figure_axes(ax, BELIEF_INCHES)
    values = np.asarray(beliefs, dtype=float)
    steps = np.arange(len(values))
    for k, name in enumerate(names):
        true = k == true_type
        # the true type's bold line under the others' dashes: equal beliefs (1/2 each until
        # P2's actions differ) show both, not the bold line alone
        ax.step(steps, values[:, k], where="post", color=hypothesis_colour(k),
                lw=2.2 if true else 1.4, ls="-" if true else "--", zorder=2 if true else 3,
                label=f"{name}" + (" (P2's type)" if true else ""))
    singled = next((i for i, row in enumerate(values) if row.max() >= 1.0 - 1e-12), None)
    if singled is not None:
        ax.axvline(singled, color="black", lw=0.8, alpha=0.6)
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlim(0, max(len(values) - 1, 1))
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))      # steps (a short episode: 0.5)
    ax.set_xlabel("step n" + ("" if singled is None else
                              f" (P1's belief singles out P2's type at step {singled})"),
                  fontsize=8)
    ax.set_ylabel("P1's belief in the type", fontsize=8)
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1), frameon=False)
    ax.set_title(f"{world_name}: P1's belief over P2's types along the drawn episode "
                 f"(seed {seed}, {len(values) - 1} steps, {outcome})", fontsize=9)
    return figure_done(fig, path, given)


def weight_sweep_figure(world_name: str, names: Sequence[str], rows: Sequence[dict],
                        path: Path | None, ax=None) -> list[Path]:
    """V_adapt, V_oracle and every V_commit(j) against the first type's prior weight (into
    `ax` when given, then writing nothing)."""
    given = ax
    fig, ax = figure_axes(ax, BELIEF_INCHES)
    rows = sorted(rows, key=lambda row: row["weight"])      # the given order may be any
    weights = [row["weight"] for row in rows]
    ax.plot(weights, [row["v_oracle"] for row in rows], "k:", lw=1.2, label="V_oracle")
    ax.plot(weights, [row["v_adapt"] for row in rows], "k-o", ms=3, lw=1.8, label="V_adapt")
    for k, name in enumerate(names):
        ax.plot(weights, [row["v_commit"][name] for row in rows], "--o", ms=2.5, lw=1.1,
                color=hypothesis_colour(k), label=f"V_commit({name})")
    ax.set_xlabel(f"prior weight of {names[0]}", fontsize=8)
    ax.set_ylabel("probability of completing the task", fontsize=8)
    ax.set_ylim(-0.03, 1.03)
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1), frameon=False)
    ax.set_title(f"{world_name}: adaptive deception against the prior", fontsize=9)
    return figure_done(fig, path, given)
