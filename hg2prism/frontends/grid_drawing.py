"""How a grid world is drawn (the grid front end's part of the figures, docs/semantics.md §15
"Figures"): the map cell by cell, and an episode's steps (analyses.episodes.Step, in the
arena's terms) as moves between cells, with the realised direction of a slip and bumps into
walls. The report layer (report/plots.py, report/replay.py) asks `GridDrawer` for the map, the
episode and the replay's frames of a grid world; every other world is drawn as a graph
(report/arena_graph.py)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import matplotlib.pyplot as plt

from hg2prism.frontends.grid import ACTIONS, GridGeometry, geometry, outcome_directions
from hg2prism.model.world import World
from hg2prism.report.style import (TRAP_COLOUR, TRAPPED_COLOUR, hypothesis_colour,
                                   hypothesis_handles, steps_text)

__all__ = ["CELL_STYLE", "WORLD_CELL_INCHES", "Move", "grid_moves", "cell_kind", "draw_grid",
           "draw_move", "GridDrawer"]

WORLD_CELL_INCHES = 0.85     # one grid cell
WORLD_LEGEND_INCHES = 4.2    # the legend column right of the grid
WORLD_MIN_HEIGHT = 5.0       # room for the legend on small grids

# cell kind -> (face colour, legend text)
CELL_STYLE = {
    "wall": ("0.35", "wall (moves into it bounce)"),
    "free": ("white", "free cell"),
    "obstacle": ("black", "obstacle (label obs)"),
    "region": ("#f4a6a6", "region (its letter is its label)"),
    "candidate": ("#c8ecc8", "trap candidate (t)"),
}
_DIRECTION = {"N": (0, 1), "E": (1, 0), "S": (0, -1), "W": (-1, 0)}


@dataclass(frozen=True)
class Move:
    """One step of an episode on the grid: where the robot was, the move it chose, the direction
    it actually went (a slip when they differ) and where it landed. A bump (into a wall) lands
    where it started; a trapped robot lands on the trap."""

    n: int
    start: tuple[int, int]
    chosen: str                 # "N", "E", "S" or "W"
    realised: str               # the direction taken
    landing: tuple[int, int]
    hypothesis: int             # P2's hypothesis when she set the traps of this step
    traps: tuple[tuple[int, int], ...]   # the cells P2 trapped at this step

    @property
    def slip(self) -> bool:
        return self.chosen != self.realised

    @property
    def bump(self) -> bool:
        return self.landing == self.start

    trapped: bool = False


def grid_moves(geo: GridGeometry, state_names: Sequence[str], steps) -> list[Move]:
    """An episode's steps (analyses.episodes.Step) as Moves: cells from the state names, the
    realised direction the outcome taken (the chosen direction, then its slips)."""
    def cell(state: int) -> tuple[int, int]:
        return geo.cell_of(state_names[state])

    moves = []
    for step in steps:
        directions = outcome_directions(ACTIONS.index(step.action_name))
        moves.append(Move(n=step.n, start=cell(step.start), chosen=step.action_name,
                          realised=ACTIONS[directions[step.outcome]], landing=cell(step.landing),
                          hypothesis=step.hypothesis, traps=tuple(cell(p) for p in step.traps),
                          trapped=step.trapped))
    return moves


def cell_kind(grid, regions: dict, cell: tuple[int, int]) -> tuple[str, str]:
    """A cell's kind (a key of CELL_STYLE) and the text drawn in it; `regions`: cell ->
    its region's letter."""
    if cell in grid.walls:
        return "wall", ""
    if cell in grid.obstacles:
        return "obstacle", "obs"
    if cell in regions:
        return "region", regions[cell]
    return ("candidate" if cell in grid.trap_candidates else "free"), ""


def draw_grid(ax: plt.Axes, world: World) -> list:
    """The map, every cell coloured by its kind; returns legend handles for the kinds present."""
    grid = world.grid
    regions = {cell: letter for letter, cells in grid.regions for cell in cells}
    present = {"wall", "free"}
    for x in range(grid.width):
        for y in range(grid.height):
            cell = (x, y)
            kind, text = cell_kind(grid, regions, cell)
            text_colour = "white" if kind == "obstacle" else "black"
            present.add(kind)
            ax.add_patch(plt.Rectangle((x - 0.5, y - 0.5), 1, 1, facecolor=CELL_STYLE[kind][0],
                                       edgecolor="0.8", lw=0.8, zorder=0))
            if text:
                ax.text(x, y, text, ha="center", va="center", color=text_colour, zorder=1,
                        fontsize=13 if kind == "region" else 8, weight="bold")
            if cell in grid.trap_candidates:
                ax.text(x + 0.42, y - 0.42, "t", ha="right", va="bottom", fontsize=7,
                        color=TRAP_COLOUR, zorder=1)
    sx, sy = grid.start
    ax.plot(sx, sy, marker="o", ms=20, mfc="none", mec="black", mew=1.2, ls="", zorder=1)
    ax.set_xlim(-0.5, grid.width - 0.5)
    ax.set_ylim(-0.5, grid.height - 0.5)
    ax.set_aspect("equal")
    ax.set_xticks(range(grid.width))
    ax.set_yticks(range(grid.height))
    ax.tick_params(labelsize=7)
    handles = [plt.Rectangle((0, 0), 1, 1, facecolor=CELL_STYLE[k][0], edgecolor="0.6",
                             label=CELL_STYLE[k][1]) for k in CELL_STYLE if k in present]
    handles.append(plt.Line2D([], [], marker="o", ms=10, mfc="none", mec="black", ls="",
                              label="start cell"))
    return handles


def _move_handles(world: World, hypotheses: Sequence[int]) -> list:
    handles = hypothesis_handles(world.hypotheses, hypotheses)
    handles += [
        plt.Line2D([], [], color="0.2", lw=1.8, marker=">", label="move as chosen (step numbers n=…)"),
        plt.Line2D([], [], color="0.2", lw=1.8, ls="--", marker=">", label="slip: the realised move"),
        plt.Line2D([], [], color="0.5", lw=1.2, ls=":", marker=">", label="slip: the chosen move"),
        plt.Line2D([], [], color="0.2", lw=1.8, marker="|", ms=9, label="bump into a wall (stays)"),
        plt.Line2D([], [], color=TRAP_COLOUR, marker="X", ms=9, ls="", label="trap set by P2 (k× = steps)"),
    ]
    return handles


def _arrow(ax: plt.Axes, start: tuple[float, float], end: tuple[float, float], colour: str,
           style: str = "-", width: float = 1.8, head: str = "-|>") -> None:
    ax.annotate("", xy=end, xytext=start, zorder=3,
                arrowprops=dict(arrowstyle=head, color=colour, lw=width, ls=style,
                                shrinkA=0, shrinkB=0, mutation_scale=11))


def draw_move(ax: plt.Axes, move: Move, colour: str, label: str = "", offset: float = 0.14) -> None:
    """One step: the realised move as an arrow (dashed for a slip, ending in a bar for a bump),
    the chosen one as a grey dotted stub when they differ, a red X when the robot is trapped;
    `label` beside it. Arrows run `offset` to the right of their direction, so that moves back
    and forth do not overlap."""
    dx, dy = _DIRECTION[move.realised]
    ox, oy = dy * offset, -dx * offset
    x0, y0 = move.start[0] + ox, move.start[1] + oy
    style = "--" if move.slip else "-"
    if move.bump:
        end = (x0 + 0.46 * dx, y0 + 0.46 * dy)
        _arrow(ax, (x0 + 0.1 * dx, y0 + 0.1 * dy), end, colour, style, head="-[")
        text_at = (x0 + 0.25 * dx + 1.3 * ox, y0 + 0.25 * dy + 1.3 * oy)
    else:
        x1, y1 = move.landing[0] + ox, move.landing[1] + oy
        _arrow(ax, (x0 + 0.22 * dx, y0 + 0.22 * dy), (x1 - 0.22 * dx, y1 - 0.22 * dy),
               TRAPPED_COLOUR if move.trapped else colour, style)
        text_at = ((x0 + x1) / 2 + 1.4 * ox, (y0 + y1) / 2 + 1.4 * oy)
    if move.slip:
        cx, cy = _DIRECTION[move.chosen]
        _arrow(ax, move.start, (move.start[0] + 0.38 * cx, move.start[1] + 0.38 * cy), "0.45",
               ":", width=1.2, head="->")
    if move.trapped:
        ax.plot(*move.landing, marker="X", ms=16, color=TRAPPED_COLOUR, zorder=4)
    if label:
        # along the arrow: labels of vertical moves side by side would collide
        ax.text(*text_at, label, fontsize=6.5, color=colour, ha="center", va="center", zorder=5,
                rotation=90 if dx == 0 else 0,
                bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.75))


def _draw_moves(ax: plt.Axes, world: World, moves: list[Move]) -> list:
    """Every distinct move drawn once, coloured by P2's hypothesis and labelled with its step
    numbers; the traps P2 set (k× = the steps she set each); where she changed her mind.
    Returns the legend handles of the moves."""
    groups: dict[tuple, list[int]] = {}
    first_of: dict[tuple, Move] = {}
    for move in moves:
        key = (move.start, move.landing, move.chosen, move.realised, move.trapped, move.hypothesis)
        groups.setdefault(key, []).append(move.n)
        first_of.setdefault(key, move)
    for key, numbers in groups.items():
        move = first_of[key]
        draw_move(ax, move, hypothesis_colour(move.hypothesis), "n=" + steps_text(numbers))
    trap_counts: dict[tuple[int, int], int] = {}
    for move in moves:
        for cell in move.traps:
            trap_counts[cell] = trap_counts.get(cell, 0) + 1
    for (x, y), count in trap_counts.items():
        ax.plot(x - 0.3, y + 0.3, marker="X", color=TRAP_COLOUR, ms=9, ls="", zorder=2)
        ax.text(x - 0.3, y + 0.08, f"{count}×", fontsize=6.5, color=TRAP_COLOUR, ha="center",
                va="top", zorder=2)
    for i, move in enumerate(moves):
        if i > 0 and moves[i - 1].hypothesis != move.hypothesis:
            ax.text(move.start[0], move.start[1] + 0.38, f"n={move.n}: P2 now x{move.hypothesis}",
                    fontsize=6.5, color=hypothesis_colour(move.hypothesis), weight="bold",
                    ha="center", zorder=5)
    used = sorted({m.hypothesis for m in moves}) or [world.initial_hypothesis]
    handles = _move_handles(world, used)
    if any(m.trapped for m in moves):
        handles.append(plt.Line2D([], [], color=TRAPPED_COLOUR, marker="X", ms=9, ls="",
                                  label="robot trapped"))
    return handles


class GridDrawer:
    """A grid world's pictures: the world figure (map and episode) and the replay's map and
    frames. Steps are analyses.episodes.Step; positions are cells."""

    def __init__(self, world: World, ts) -> None:
        self.world = world
        self.geo = geometry(world)
        self.state_names = ts.arena.states

    # ---- the world figure ----
    def world_inches(self) -> tuple[float, float]:
        """The grid at WORLD_CELL_INCHES a cell, and the legend."""
        grid = self.world.grid
        return (WORLD_CELL_INCHES * grid.width + WORLD_LEGEND_INCHES,
                max(WORLD_CELL_INCHES * grid.height + 1.0, WORLD_MIN_HEIGHT))

    def draw_world(self, ax: plt.Axes, steps) -> list:
        """The map and the episode; returns the legend handles (moves first, then cells)."""
        cell_handles = draw_grid(ax, self.world)
        moves = grid_moves(self.geo, self.state_names, steps)
        return _draw_moves(ax, self.world, moves) + cell_handles

    def finish(self, ax: plt.Axes) -> None:
        """After the layout: nothing to place on a grid."""

    # ---- the replay ----
    robot_style = {"ms": 15}

    def replay_inches(self) -> tuple[float, float]:
        """The grid at 0.55 in a cell beside a 4.5 in panel."""
        grid = self.world.grid
        return (0.55 * grid.width + 4.5, max(0.55 * grid.height + 1.2, 4.0))

    @property
    def replay_map_width(self) -> float:
        return 0.55 * self.world.grid.width

    def draw_map(self, ax: plt.Axes) -> None:
        draw_grid(ax, self.world)

    def position(self, state: int) -> tuple[float, float]:
        return self.geo.cell_of(self.state_names[state])

    def draw_step(self, ax: plt.Axes, step) -> None:
        draw_move(ax, grid_moves(self.geo, self.state_names, [step])[0], "black", offset=0.0)

    def caption(self, step) -> str:
        move = grid_moves(self.geo, self.state_names, [step])[0]
        what = ("bumped into a wall" if move.bump else "slipped" if move.slip else "moved")
        return (f"chose {move.chosen}, went {move.realised} "
                f"({what}{', trapped' if move.trapped else ''})")

    def widest_caption(self, steps) -> str:
        """A caption at least as wide as any frame's, for the layout."""
        return "chose W, went W (bumped into a wall, trapped)"

    # ---- the explorer (report/explorer.py) ----
    def explorer_map(self) -> dict:
        """The map as the explorer draws it: the grid's cells with their kinds, colours and
        texts (cells are positions, `position`)."""
        from matplotlib.colors import to_hex

        grid = self.world.grid
        regions = {cell: letter for letter, cells in grid.regions for cell in cells}
        cells = []
        for y in range(grid.height):
            for x in range(grid.width):
                kind, text = cell_kind(grid, regions, (x, y))
                cells.append({"x": x, "y": y, "kind": kind, "text": text,
                              "fill": to_hex(CELL_STYLE[kind][0])})
        return {"kind": "grid", "width": grid.width, "height": grid.height, "cells": cells,
                "legend": {k: [to_hex(CELL_STYLE[k][0]), CELL_STYLE[k][1]] for k in CELL_STYLE}}
