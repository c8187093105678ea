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
import numpy as np

from hg2prism.frontends.grid import ACTIONS, GridGeometry, geometry, outcome_directions
from hg2prism.model.world import World
from hg2prism.report.style import (TRAP_COLOUR, TRAPPED_COLOUR, change_handle,
                                   hypothesis_colour, hypothesis_handles, steps_text)

__all__ = ["CELL_STYLE", "WORLD_CELL_INCHES", "Move", "Segment", "grid_moves", "cell_kind",
           "draw_grid", "draw_move", "place_labels", "draw_key", "GridDrawer"]

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


def draw_grid(ax: plt.Axes, world: World, min_font: float = 0.0) -> list:
    """The map, every cell coloured by its kind, no text smaller than `min_font` points;
    returns legend handles for the kinds present."""
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
                        fontsize=max(13 if kind == "region" else 8, min_font), weight="bold")
            if cell in grid.trap_candidates:
                ax.text(x + 0.42, y - 0.42, "t", ha="right", va="bottom", fontsize=max(7, min_font),
                        color=TRAP_COLOUR, zorder=1)
    sx, sy = grid.start
    ax.plot(sx, sy, marker="o", ms=20, mfc="none", mec="black", mew=1.2, ls="", zorder=1)
    ax.set_xlim(-0.5, grid.width - 0.5)
    ax.set_ylim(-0.5, grid.height - 0.5)
    ax.set_aspect("equal")
    ax.set_xticks(range(grid.width))
    ax.set_yticks(range(grid.height))
    ax.tick_params(labelsize=max(7, min_font))
    handles = [plt.Rectangle((0, 0), 1, 1, facecolor=CELL_STYLE[k][0], edgecolor="0.6",
                             label=CELL_STYLE[k][1]) for k in CELL_STYLE if k in present]
    handles.append(plt.Line2D([], [], marker="o", ms=10, mfc="none", mec="black", ls="",
                              label="start cell"))
    return handles


def _move_handles(world: World, hypotheses: Sequence[int]) -> list:
    handles = hypothesis_handles(world.hypotheses, hypotheses)
    handles += [
        plt.Line2D([], [], color="0.2", lw=1.8, marker=">", label="step (n=its numbers; its colour: the\nhypothesis P2 set its traps on)"),
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


@dataclass(frozen=True)
class Segment:
    """Where a drawn move runs (data units): from `start` to `end`, `normal` pointing to its
    right; its label goes beside it."""

    start: tuple[float, float]
    end: tuple[float, float]
    normal: tuple[float, float]


def draw_move(ax: plt.Axes, move: Move, colour: str, offset: float = 0.14) -> Segment:
    """One step: the realised move as an arrow (dashed for a slip, ending in a bar for a bump),
    the chosen one as a grey dotted stub when they differ, a red X when the robot is trapped.
    Arrows run `offset` to the right of their direction, so that moves back and forth (and
    several moves over the same segment, at growing offsets) do not overlap. Returns the
    arrow's segment (for its label)."""
    dx, dy = _DIRECTION[move.realised]
    ox, oy = dy * offset, -dx * offset
    x0, y0 = move.start[0] + ox, move.start[1] + oy
    style = "--" if move.slip else "-"
    if move.bump:
        end = (x0 + 0.46 * dx, y0 + 0.46 * dy)
        begin = (x0 + 0.1 * dx, y0 + 0.1 * dy)
        _arrow(ax, begin, end, colour, style, head="-[")
    else:
        x1, y1 = move.landing[0] + ox, move.landing[1] + oy
        begin, end = (x0 + 0.22 * dx, y0 + 0.22 * dy), (x1 - 0.22 * dx, y1 - 0.22 * dy)
        _arrow(ax, begin, end, TRAPPED_COLOUR if move.trapped else colour, style)
    if move.slip:
        cx, cy = _DIRECTION[move.chosen]
        _arrow(ax, move.start, (move.start[0] + 0.38 * cx, move.start[1] + 0.38 * cy), "0.45",
               ":", width=1.2, head="->")
    if move.trapped:
        ax.plot(*move.landing, marker="X", ms=16, color=TRAPPED_COLOUR, zorder=4)
    return Segment(begin, end, (dy, -dx))


def _beside(segment: Segment, clearances=(0.06, 0.16, 0.28, 0.42, 0.58)):
    """Label centres beside a segment, nearest first, for a label of data size (w, h): at
    each clearance from the arrow, on its right then its left, at its middle then along it."""
    p0, p1 = np.array(segment.start), np.array(segment.end)

    def spots(w: float, h: float) -> list:
        out = []
        for clearance in clearances:
            for side in (1, -1):
                n = side * np.array(segment.normal, dtype=float)
                half = abs(n[0]) * w / 2 + abs(n[1]) * h / 2
                for t in (0.5, 0.3, 0.7, 0.1, 0.9):
                    out.append(p0 + t * (p1 - p0) + n * (clearance + half))
        return out
    return spots


TAG_REACH = tuple(np.round(np.arange(0.0, 1.0, 0.04), 2))     # a tag's clearances (cells)


def _around_cell(cell: tuple[int, int], reaches=(0.25, 0.36, 0.5, 0.65, 0.8)):
    """Label centres around a cell's centre, nearest first, for a label of data size (w, h)."""
    def spots(w: float, h: float) -> list:
        out = []
        for reach in reaches:
            for ux, uy in ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (-1, 1), (1, -1), (-1, -1)):
                out.append((cell[0] + ux * (reach + w / 2 - 0.2 * abs(ux)),
                            cell[1] + uy * (reach + h / 2 - 0.1 * abs(uy))))
        return out
    return spots


@dataclass(frozen=True)
class _Label:
    """A label to place on the map: its text and colour, where it may go, its key tag."""

    text: str
    colour: str
    spots: object               # label centres for its size (w, h), nearest first
    tag_spots: object           # the same for its tag, reaching further
    bold: bool = False


LABEL_FONT = 6.5
KEY_FONTS = (6.5, 6.0, 5.5, 5.0, 4.5)      # the key's font sizes, tried in turn


def _tag(i: int) -> str:
    """The i-th key tag: a..z, then a2..z2, ... (regions are capital letters)."""
    letter, round_ = "abcdefghijklmnopqrstuvwxyz"[i % 26], i // 26
    return letter + (str(round_ + 1) if round_ else "")


def place_labels(ax: plt.Axes, labels: Sequence[_Label]) -> list[tuple[str, _Label]]:
    """Place each label where it hides no text, mark or other label (style.Placer), avoiding
    the arrows where it can; a label with no free spot is replaced by a short tag (a, b, ...)
    beside its arrow, and listed in the key. Returns the key: (tag, label) in order."""
    from hg2prism.report.style import Placer

    placer = Placer(ax, gap=1.5)
    for text in ax.texts:
        if text.get_text():
            placer.taken.append(placer.box_of(text))
        else:                                   # an arrow (an annotation without text)
            placer.soft.append(placer.box_of(text.arrow_patch))
    placer.taken += [placer.box_of(line) for line in ax.lines]
    key: list[tuple[str, _Label]] = []
    for label in labels:
        style = dict(fontsize=LABEL_FONT, color=label.colour,
                     weight="bold" if label.bold else "normal")
        if placer.place(label.spots, label.text, pad=0.1, strict=True, **style) is None:
            tag = _tag(len(key))
            key.append((tag, label))
            if placer.place(label.tag_spots, tag, pad=0.1, strict=True, **style) is None:
                key[-1] = (tag + " (not on the map)", label)
    return key


def draw_key(ax: plt.Axes, key: Sequence[tuple[str, _Label]]) -> None:
    """The labels that did not fit on the map, by tag, in the legend's column below the
    legend, in as many columns as the height needs, at the largest of KEY_FONTS that keeps
    them inside the figure."""
    if not key:
        return
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    legend = ax.get_legend()
    to_fig = fig.transFigure.inverted()
    if legend is not None:
        box = legend.get_window_extent(renderer).transformed(to_fig)
        left, top = box.x0, box.y0 - 0.02
    else:
        box = ax.get_window_extent(renderer).transformed(to_fig)
        left, top = box.x1 + 0.02, box.y1
    for size in KEY_FONTS:
        drawn = _key_texts(fig, key, left, top, size)
        right = max(t.get_window_extent(renderer).transformed(to_fig).x1 for t in drawn)
        if right <= 0.995 or size == KEY_FONTS[-1]:
            return
        for text in drawn:
            text.remove()


def _key_texts(fig, key: Sequence[tuple[str, _Label]], left: float, top: float,
               size: float) -> list:
    """The key's texts at font `size` from (left, top) down, column after column."""
    renderer = fig.canvas.get_renderer()
    to_fig = fig.transFigure.inverted()
    line = size * 1.5 / 72 / fig.get_size_inches()[1]
    drawn = [fig.text(left, top, "labels that did not fit on the map, by their tag:",
                      fontsize=size, va="top", ha="left", style="italic")]
    rows = max(1, int((top - line - 0.02) / line))
    column_width = 0.0
    x, y = left, top - line
    for i, (tag, label) in enumerate(key):
        if i and i % rows == 0:
            x, y = x + column_width + 0.01, top - line
            column_width = 0.0
        drawn.append(fig.text(x, y, f"{tag}: {label.text}", fontsize=size, va="top",
                              ha="left", color=label.colour,
                              weight="bold" if label.bold else "normal"))
        column_width = max(column_width,
                           drawn[-1].get_window_extent(renderer).transformed(to_fig).width)
        y -= line
    return drawn


def _draw_moves(ax: plt.Axes, world: World, moves: list[Move],
                changes: Sequence[tuple[int, int]]) -> tuple[list, list[_Label]]:
    """Every distinct move drawn once, coloured by the hypothesis P2 set her traps on, at a
    growing offset when several share a segment; the traps P2 set (k× = the steps she set
    each). Returns the legend handles of the moves and the labels to place (changes of mind
    first, at the cell where they happened, then each move's step numbers)."""
    groups: dict[tuple, list[int]] = {}
    first_of: dict[tuple, Move] = {}
    for move in moves:
        key = (move.start, move.landing, move.chosen, move.realised, move.trapped, move.hypothesis)
        groups.setdefault(key, []).append(move.n)
        first_of.setdefault(key, move)
    landing = {move.n: move.landing for move in moves}
    labels = [_Label(f"n={n}: P2 now x{x}", hypothesis_colour(x), _around_cell(landing[n]),
                     _around_cell(landing[n], TAG_REACH), bold=True)
              for n, x in changes if n in landing]
    on_segment: dict[tuple, int] = {}
    for key, numbers in groups.items():
        move = first_of[key]
        k = on_segment[move.start, move.landing, move.realised] = on_segment.get(
            (move.start, move.landing, move.realised), -1) + 1
        colour = hypothesis_colour(move.hypothesis)
        segment = draw_move(ax, move, colour, offset=0.14 + 0.11 * k)
        labels.append(_Label("n=" + steps_text(numbers), colour, _beside(segment),
                             _beside(segment, TAG_REACH)))
    trap_counts: dict[tuple[int, int], int] = {}
    for move in moves:
        for cell in move.traps:
            trap_counts[cell] = trap_counts.get(cell, 0) + 1
    for (x, y), count in trap_counts.items():
        ax.plot(x - 0.3, y + 0.3, marker="X", color=TRAP_COLOUR, ms=9, ls="", zorder=2)
        ax.text(x - 0.3, y + 0.08, f"{count}×", fontsize=6.5, color=TRAP_COLOUR, ha="center",
                va="top", zorder=2)
    used = sorted({m.hypothesis for m in moves}) or [world.initial_hypothesis]
    handles = _move_handles(world, used)
    if any(m.trapped for m in moves):
        handles.append(plt.Line2D([], [], color=TRAPPED_COLOUR, marker="X", ms=9, ls="",
                                  label="robot trapped"))
    if any(n in landing for n, _ in changes):
        handles.append(change_handle())
    return handles, labels


class GridDrawer:
    """A grid world's pictures: the world figure (map and episode) and the replay's map and
    frames. Steps are analyses.episodes.Step; positions are cells."""

    def __init__(self, world: World, ts) -> None:
        self.world = world
        self.geo = geometry(world)
        self.state_names = ts.arena.states
        self.labels: list[_Label] = []
        self.key: list = []
        self.changes_shown: tuple = ()

    # ---- the world figure ----
    def world_inches(self) -> tuple[float, float]:
        """The grid at WORLD_CELL_INCHES a cell, and the legend."""
        grid = self.world.grid
        return (WORLD_CELL_INCHES * grid.width + WORLD_LEGEND_INCHES,
                max(WORLD_CELL_INCHES * grid.height + 1.0, WORLD_MIN_HEIGHT))

    def draw_world(self, ax: plt.Axes, steps, changes: Sequence[tuple[int, int]]) -> list:
        """The map and the episode, P2's `changes` of mind (n, x) at the cell of state n
        (episodes.BeliefTrace.changes); the labels follow in `finish`. Returns the legend
        handles (moves first, then cells)."""
        cell_handles = draw_grid(ax, self.world)
        moves = grid_moves(self.geo, self.state_names, steps)
        handles, self.labels = _draw_moves(ax, self.world, moves, changes)
        self.changes_shown = tuple((n, x) for n, x in changes
                                   if any(m.n == n for m in moves))
        return handles + cell_handles

    def finish(self, ax: plt.Axes) -> None:
        """Once laid out: every label where it hides nothing, the rest in the key (nothing to
        place on the replay's map)."""
        if not self.labels:
            return
        figure = ax.figure
        figure.canvas.draw()
        figure.set_layout_engine("none")
        self.key = place_labels(ax, self.labels)
        draw_key(ax, self.key)

    # ---- the replay ----
    robot_style = {"ms": 15}

    def replay_inches(self) -> tuple[float, float]:
        """The grid at 0.55 in a cell beside a 4.5 in panel, room above for the captions and
        below for the hypotheses."""
        grid = self.world.grid
        return (0.55 * grid.width + 4.5, max(0.55 * grid.height + 2.4, 4.8))

    @property
    def replay_map_width(self) -> float:
        return 0.55 * self.world.grid.width

    def draw_map(self, ax: plt.Axes, min_font: float = 0.0) -> None:
        draw_grid(ax, self.world, min_font)

    def position(self, state: int) -> tuple[float, float]:
        return self.geo.cell_of(self.state_names[state])

    def draw_step(self, ax: plt.Axes, step) -> None:
        draw_move(ax, grid_moves(self.geo, self.state_names, [step])[0], "black", offset=0.0)

    def caption(self, step) -> str:
        move = grid_moves(self.geo, self.state_names, [step])[0]
        what = ("bumped into a wall" if move.bump else "slipped" if move.slip else "moved")
        return (f"chose {move.chosen}, went {move.realised} "
                f"({what}{', trapped' if move.trapped else ''})")

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
