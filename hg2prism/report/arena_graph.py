"""The arena drawn as a graph (docs/semantics.md §15 "Figures"), for every world that is not a
grid: one box per state (its name and, in braces, its propositions), one grey arrow per pair
u -> v that some action of P1 at u reaches with positive probability (labelled with those
actions), trap candidates (honeypots) and labelled states filled, the start with a thick
border, terminal states with a dashed one; the drawn episode as a path over the graph, one
arrow per distinct step coloured by P2's hypothesis, with its step numbers; steps that stay
are loops over their state.

Positions: the arena's `positions` when given (scaled so that the closest two states are
SPACING_INCHES apart), else a layered layout: the states by their distance from the initial
state, each layer a column ordered by the mean row of its predecessors, then by number; the
states unreachable from it by their distance from the unreachable states no other
unreachable state leads to, one column further right, below the reachable ones of their
column; shrunk to fit MAP_MAX_INCHES, but never below MIN_SHRINK (a large arena's map grows,
up to MAP_CAP_INCHES).
Both are deterministic. One data unit is one inch of the map. Above MAX_NAMED_ARROWS arrows,
those of P1's actions carry no names.

Arrows and labels are placed after the figure is laid out, when the boxes' sizes are known:
every label (actions, step numbers, traps, changes of mind) goes to the first of a list of
candidate spots where its box overlaps no state box and no label placed before it.
"""

from __future__ import annotations

from collections import deque

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import FancyArrowPatch
from matplotlib.transforms import offset_copy

from hg2prism.model.arena import Arena
from hg2prism.model.world import World
from hg2prism.report.style import (TRAP_COLOUR, TRAPPED_COLOUR, Box, Placer,
                                   change_handle, hypothesis_colour, hypothesis_handles, steps_text)

__all__ = ["NODE_STYLE", "graph_edges", "layout", "ArenaDrawer"]

LAYER_INCHES = 2.0        # between the columns of the layered layout
ROW_INCHES = 1.1          # between the states of a column
SPACING_INCHES = 1.4      # the closest two given positions
MAP_MAX_INCHES = (12.0, 9.0)
# A layered layout is shrunk to MAP_MAX_INCHES, but never below this (columns 0.9 in, rows
# 0.5 in apart: a state's box is about 0.3 in high): a large arena's map grows instead.
MIN_SHRINK = 0.45
# ... and at most this many inches either way (a PNG stays below matplotlib's 2^16 pixels; a
# 900-state column would be 447 in tall): beyond it the map shrinks again, its boxes closer.
MAP_CAP_INCHES = 60.0
# Above this many arrows the arrows of P1's actions carry no names (the explorer lists them):
# on a large attack graph they cover the states and the episode.
MAX_NAMED_ARROWS = 60
MARGIN_INCHES = 0.8       # around the states
LEGEND_INCHES = 4.2
MIN_HEIGHT = 5.0
BASE_RAD = 0.15           # curvature of an arrow u -> v (v -> u bends the other way)
NODE_FONT = 7.5
LABEL_FONT = 6.5
MIN_PIXELS = 9        # no text of a picture is less high, in pixels
# state kind -> (face colour, legend text)
NODE_STYLE = {
    "state": ("white", "state (name, {its propositions})"),
    "labelled": ("#f4a6a6", "labelled state"),
    "candidate": ("#c8ecc8", "trap candidate (honeypot)"),
}


def graph_edges(arena: Arena) -> dict[tuple[int, int], list[str]]:
    """u -> v (u != v) for every pair some action at u reaches with positive probability
    under some P2 action: the names of those actions, in the order of the arena's actions."""
    edges: dict[tuple[int, int], list[str]] = {}
    for u, names in enumerate(arena.actions):
        for i, name in enumerate(names):
            reached = arena.dest[u, i][arena.prob[u, i] > 0]
            for v in dict.fromkeys(int(v) for v in reached.ravel()):
                if v != u and name not in edges.setdefault((u, v), []):
                    edges[(u, v)].append(name)
    return edges


def _depths(succ: dict[int, list[int]], roots: list[int], first: int) -> dict[int, int]:
    """BFS depth (from `first`) of every state the roots reach."""
    depth = {root: first for root in roots}
    queue = deque(roots)
    while queue:
        u = queue.popleft()
        for v in succ.get(u, []):
            if v not in depth:
                depth[v] = depth[u] + 1
                queue.append(v)
    return depth


def _layers(arena: Arena, edges) -> list[list[int]]:
    """States by BFS distance from the initial state, each layer ordered by the mean row of its
    predecessors in earlier layers, then by number. The unreachable states (an attack graph's
    nodes no entry leads to) by their own BFS distance, from column 1, from those no other
    unreachable state leads to, below the reachable states of their column (they were all in
    one last column, their edges crossing the whole figure)."""
    succ: dict[int, list[int]] = {}
    for u, v in edges:
        succ.setdefault(u, []).append(v)
    depth = _depths(succ, [arena.initial], 0)
    rest = [s for s in range(arena.n_states) if s not in depth]
    entered = {v for u, v in edges if u not in depth and v not in depth}
    roots = [s for s in rest if s not in entered] or rest[:1]
    only = {u: [v for v in vs if v not in depth] for u, vs in succ.items() if u not in depth}
    apart = _depths(only, roots, 1)
    for s in rest:                  # on a cycle no root reaches: from column 1
        if s not in apart:
            for t, d in _depths(only, [s], 1).items():
                apart.setdefault(t, d)
    column = {**depth, **apart}
    layers: list[list[int]] = [[] for _ in range(max(column.values()) + 1)]
    for s in range(arena.n_states):
        layers[column[s]].append(s)
    row: dict[int, float] = {}
    for layer in layers:
        def key(s: int) -> tuple[bool, float, int]:
            above = [row[u] for u, v in edges if v == s and u in row]
            return (s not in depth, float(np.mean(above)) if above else float("inf"), s)
        layer.sort(key=key)
        row.update({s: i - (len(layer) - 1) / 2 for i, s in enumerate(layer)})
    return [layer for layer in layers if layer]


def layout(arena: Arena, edges=None) -> np.ndarray:
    """[S, 2] positions in inches of the map, from (0, 0) (module docstring)."""
    if arena.positions is not None:
        points = np.array(arena.positions, dtype=float)
        gaps = np.linalg.norm(points[:, None] - points[None, :], axis=-1)
        gaps = gaps[gaps > 1e-12]
        points = points * (SPACING_INCHES / gaps.min() if gaps.size else 1.0)
    else:
        points = np.zeros((arena.n_states, 2))
        for x, layer in enumerate(_layers(arena, graph_edges(arena) if edges is None else edges)):
            for i, s in enumerate(layer):
                points[s] = (x * LAYER_INCHES, -(i - (len(layer) - 1) / 2) * ROW_INCHES)
    points = points - points.min(axis=0)
    span = points.max(axis=0)
    shrink = min([1.0] + [m / s for m, s in zip(MAP_MAX_INCHES, span) if s > m])
    if arena.positions is None:
        shrink = max(shrink, MIN_SHRINK)
        shrink = min([shrink] + [MAP_CAP_INCHES / s for s in span if s * shrink > MAP_CAP_INCHES])
    return points * shrink


def _bezier(p0: np.ndarray, p2: np.ndarray, rad: float, t: float) -> np.ndarray:
    """matplotlib's arc3 curve from p0 to p2 (its control point at the chord's middle moved by
    rad times the chord turned clockwise), at parameter t."""
    d = p2 - p0
    c = (p0 + p2) / 2 + rad * np.array([d[1], -d[0]])
    return (1 - t) ** 2 * p0 + 2 * (1 - t) * t * c + t ** 2 * p2


def _spots(p0: np.ndarray, p2: np.ndarray, rad: float, offsets) -> list[np.ndarray]:
    """Label spots along the arc from p0 to p2: its points at t = 0.5, 0.4, 0.6, 0.3, 0.7,
    moved by each offset (inches) along the chord's normal (positive: the side it bends to)."""
    d = p2 - p0
    normal = np.array([d[1], -d[0]]) * (1 if rad >= 0 else -1) / max(np.linalg.norm(d), 1e-12)
    return [_bezier(p0, p2, rad, t) + o * normal for o in offsets
            for t in (0.5, 0.4, 0.6, 0.3, 0.7)]


def _exit(box: Box, centre: np.ndarray, towards: np.ndarray, gap: float = 0.04) -> np.ndarray:
    """Where the ray from `centre` towards `towards` leaves `box` (plus `gap`)."""
    d = towards - centre
    half = np.array([(box[2] - box[0]) / 2 + gap, (box[3] - box[1]) / 2 + gap])
    scales = [half[k] / abs(d[k]) for k in range(2) if abs(d[k]) > 1e-12]
    return centre + d * min(scales + [1.0])


def _around(box: Box, step: float = 0.16) -> list[tuple[float, float]]:
    """Spots around a state's box: below, above, right, left, then further out."""
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    spots = []
    for k in (1, 2, 3):
        reach = k * step
        spots += [(cx, box[1] - reach), (cx, box[3] + reach), (box[2] + 2 * reach, cy),
                  (box[0] - 2 * reach, cy), (box[2] + reach, box[1] - reach),
                  (box[0] - reach, box[3] + reach)]
    return spots


def _beside_mark(box: Box, w: float, h: float) -> list[tuple[float, float]]:
    """Spots for a trap's label (w x h) beside its mark, which sits 6 pt out from the box's
    top-left corner: left of the mark, then above it (so that the label is read with its
    state, not with a neighbour: a stress test's "trap 14×" sat between two states)."""
    x, y = box[0] - 6 / 72, box[3] + 6 / 72
    return [(x - 0.1 - w / 2, y), (x, y + 0.1 + h / 2), (x - 0.1 - w / 2, y + h / 2)]


def _group_key(step, general: bool) -> tuple:
    return (step.start, step.landing, step.action_name, step.trapped, step.hypothesis,
            step.p2_action_name if general else None)


class ArenaDrawer:
    """An arena world's pictures (the same interface as the grid front end's GridDrawer):
    `draw_world` draws the states and returns the legend; `finish`, once the figure is laid
    out, draws the arrows, the episode and the labels."""

    # the replay's P1: a ring around the state's box (ring_points), coloured by P2's
    # hypothesis, so that the state's name shows (a dot over it hid it)
    robot_style = {"ms": 13, "mfc": "none", "mew": 3.0}

    def __init__(self, world: World, ts) -> None:
        self.world, self.ts, self.arena = world, ts, ts.arena
        self.edges = graph_edges(self.arena)
        self.points = layout(self.arena, self.edges)
        self.span = self.points.max(axis=0)
        self.general = not ts.traps_mode
        self.steps: list = []
        self.changes_shown: tuple = ()
        self.boxes: list[Box] = []
        self.nodes: list = []

    # ---- sizes ----
    def _map_inches(self) -> tuple[float, float]:
        return (max(self.span[0] + 2 * MARGIN_INCHES, 3.0),
                max(self.span[1] + 2 * MARGIN_INCHES, MIN_HEIGHT - 1.0))

    def world_inches(self) -> tuple[float, float]:
        width, height = self._map_inches()
        return (width + LEGEND_INCHES, max(height + 1.0, MIN_HEIGHT))

    def replay_inches(self) -> tuple[float, float]:
        width, height = self._map_inches()
        return (width + 4.5, max(height + 2.4, 4.8))

    @property
    def replay_map_width(self) -> float:
        return self._map_inches()[0]

    def position(self, state: int) -> tuple[float, float]:
        return float(self.points[state][0]), float(self.points[state][1])

    def ring_points(self, state: int) -> float:
        """The replay's ring around the state's box: its diameter in points (one data unit is
        an inch), once the boxes are measured (`finish`)."""
        x0, y0, x1, y1 = self.boxes[state]
        return float(np.hypot(x1 - x0, y1 - y0)) * 72 + 8

    def trap_spot(self, state: int) -> tuple[float, float]:
        """Where the replay marks a trap on the state: its box's top-left corner (the replay
        moves the mark a little further out, as the world figure does)."""
        x0, _, _, y1 = self.boxes[state]
        return float(x0), float(y1)

    # ---- the states ----
    def _kind(self, s: int) -> str:
        if self.arena.labels[s]:
            return "labelled"
        return "candidate" if s in self.arena.trap_candidates else "state"

    def node_text(self, s: int) -> str:
        label = self.arena.labels[s]
        props = [p for p in self.arena.propositions if p in label]
        return self.arena.states[s] + ("\n{" + ", ".join(props) + "}" if props else "")

    def draw_map(self, ax: plt.Axes, min_font: float = 0.0) -> list:
        """The states (arrows follow in `finish`), no text smaller than `min_font` points;
        returns the legend handles of the map."""
        width, height = self._map_inches()
        pad_x, pad_y = (width - self.span[0]) / 2, (height - self.span[1]) / 2
        ax.set_xlim(-pad_x, self.span[0] + pad_x)
        ax.set_ylim(-pad_y, self.span[1] + pad_y)
        ax.set_aspect("equal")
        ax.set_anchor("NW")
        ax.set_axis_off()
        candidates = set(self.arena.trap_candidates)
        self.nodes = []
        for s in range(self.arena.n_states):
            edge = TRAP_COLOUR if s in candidates else "black"
            self.nodes.append(ax.text(
                *self.position(s), self.node_text(s), ha="center", va="center",
                fontsize=max(NODE_FONT, min_font), zorder=5, multialignment="center",
                bbox=dict(boxstyle="round,pad=0.35", fc=NODE_STYLE[self._kind(s)][0], ec=edge,
                          lw=2.6 if s == self.arena.initial else 1.0,
                          ls="--" if self.arena.terminal[s] else "-")))
        present = {self._kind(s) for s in range(self.arena.n_states)}
        handles = [plt.Rectangle((0, 0), 1, 1, facecolor=NODE_STYLE[k][0], edgecolor="0.3",
                                 label=NODE_STYLE[k][1]) for k in NODE_STYLE if k in present]
        handles.append(plt.Rectangle((0, 0), 1, 1, facecolor="white", edgecolor="black", lw=2.6,
                                     label=f"start state ({self.arena.states[self.arena.initial]})"))
        if self.arena.terminal.any():
            handles.append(plt.Rectangle((0, 0), 1, 1, facecolor="white", edgecolor="black",
                                         ls="--", label="terminal state (the episode ends)"))
        named = "" if self.names_arrows else f";\n{len(self.edges)} arrows, unnamed"
        handles.append(plt.Line2D([], [], color="0.6", lw=1.0, marker=">",
                                  label=f"P1's actions u → v (self-loops not drawn{named})"))
        return handles

    @property
    def names_arrows(self) -> bool:
        """Whether the arrows of P1's actions carry their names (MAX_NAMED_ARROWS)."""
        return len(self.edges) <= MAX_NAMED_ARROWS

    # ---- the world figure ----
    def draw_world(self, ax: plt.Axes, steps, changes) -> list:
        """The states; the episode, P2's `changes` of mind (n, x) at state n
        (episodes.BeliefTrace.changes) and the arrows follow in `finish` (after the layout).
        Returns the legend handles (episode first, then the map)."""
        self.steps = list(steps)
        landing = {step.n: step.landing for step in self.steps}
        self.changes_shown = tuple((n, x) for n, x in changes if n in landing)
        map_handles = self.draw_map(ax)
        used = sorted({s.hypothesis for s in self.steps}) or [self.world.initial_hypothesis]
        handles = hypothesis_handles(self.world.hypotheses, used)
        what = "P1's action (P2's)" if self.general else "P1's action"
        handles.append(plt.Line2D([], [], color="0.2", lw=2.2, marker=">",
                                  label=f"episode step (n=step numbers: {what};\nits colour: "
                                        "P2's hypothesis during it)"))
        if self.changes_shown:
            handles.append(change_handle())
        if any(s.stays for s in self.steps):
            handles.append(plt.Line2D([], [], color="0.2", lw=2.2, marker="o", mfc="none", ms=9,
                                      ls="", label="a step that stays (loop)"))
        if any(s.traps for s in self.steps):
            handles.append(plt.Line2D([], [], color=TRAP_COLOUR, marker="X", ms=9, ls="",
                                      label="trap set by P2 (k× = steps)"))
        if any(s.trapped for s in self.steps):
            handles.append(plt.Line2D([], [], color=TRAPPED_COLOUR, marker="X", ms=9, ls="",
                                      label="P1 trapped"))
        return handles + map_handles

    def finish(self, ax: plt.Axes) -> None:
        """Once laid out: the arrows of P1's actions, the episode and every label."""
        figure = ax.figure
        figure.canvas.draw()
        figure.set_layout_engine("none")
        renderer = figure.canvas.get_renderer()
        inverse = ax.transData.inverted()
        self.boxes = []
        for node in self.nodes:
            (x0, y0), (x1, y1) = inverse.transform(
                node.get_bbox_patch().get_window_extent(renderer).get_points())
            self.boxes.append((x0, y0, x1, y1))
        placer = Placer(ax, list(self.boxes))
        self._draw_episode(ax, placer)
        # at least MIN_PIXELS high at the figure's resolution (the replay's 72 dpi frames)
        edge_font = max(LABEL_FONT - 0.5, MIN_PIXELS * 72 / figure.dpi)
        for (u, v), names in self.edges.items():
            p0, p2 = self._ends(u, v, BASE_RAD)
            self._curve(ax, p0, p2, BASE_RAD, "0.6", 1.0, zorder=1)
            if self.names_arrows:
                placer.place(_spots(p0, p2, BASE_RAD, (0, -0.1, 0.1, -0.2, 0.2, -0.3, 0.3)),
                             ", ".join(names), fontsize=edge_font, color="0.35", style="italic")

    # ---- arrows ----
    def _ends(self, u: int, v: int, rad: float) -> tuple[np.ndarray, np.ndarray]:
        """An arrow's ends on the borders of the boxes of u and v."""
        a, b = np.array(self.position(u)), np.array(self.position(v))
        control = _bezier(a, b, rad, 0.5)
        return _exit(self.boxes[u], a, control), _exit(self.boxes[v], b, control)

    def _loop_ends(self, s: int, k: int) -> tuple[np.ndarray, np.ndarray, float]:
        """A loop over the top of the box of s (the k-th there): its ends and curvature."""
        x0, _, x1, y1 = self.boxes[s]
        cx, half = (x0 + x1) / 2, max((x1 - x0) / 4, 0.12) + 0.05 * k
        return np.array([cx - half, y1]), np.array([cx + half, y1]), -1.3 - 0.35 * k

    @staticmethod
    def _curve(ax, p0, p2, rad: float, colour: str, width: float, zorder: int = 4,
               style: str = "-") -> None:
        ax.add_patch(FancyArrowPatch(tuple(p0), tuple(p2), arrowstyle="-|>", color=colour,
                                     lw=width, ls=style, connectionstyle=f"arc3,rad={rad}",
                                     shrinkA=0, shrinkB=0, mutation_scale=10, zorder=zorder))

    def _step_arrow(self, ax, step, k: int, colour: str, width: float = 2.2):
        """Draw `step` as the k-th arrow of its pair (a loop when it stays); returns the spots
        for its label."""
        if step.stays:
            p0, p2, rad = self._loop_ends(step.start, k)
            self._curve(ax, p0, p2, rad, colour, width)
            top = _bezier(p0, p2, rad, 0.5)
            return [top + offset for offset in ((0, 0.1), (0.45, 0.0), (-0.45, 0.0), (0, 0.22),
                                                (0.5, 0.15), (-0.5, 0.15), (0, 0.34))]
        rad = BASE_RAD + 0.14 * k
        p0, p2 = self._ends(step.start, step.landing, rad)
        self._curve(ax, p0, p2, rad, colour, width)
        if step.trapped:        # beside the box's top-right corner, off the state's name
            from matplotlib.transforms import ScaledTranslation

            _, _, x1, y1 = self.boxes[step.landing]
            beside = ScaledTranslation(8 / 72, 8 / 72, ax.figure.dpi_scale_trans)
            ax.plot(x1, y1, marker="X", ms=14, color=TRAPPED_COLOUR, zorder=7,
                    transform=ax.transData + beside)
        return _spots(p0, p2, rad, (0.12, -0.12, 0.24, -0.24, 0.36, -0.36, 0))

    def _head_boxes(self, step, k: int, half: float = 0.06) -> list[Box]:
        """Boxes along the last fifth of the k-th arrow of `step` (its head), for labels to
        avoid."""
        rad = BASE_RAD + 0.14 * k
        p0, p2 = self._ends(step.start, step.landing, rad)
        points = [_bezier(p0, p2, rad, t) for t in (0.8, 0.87, 0.94, 1.0)]
        return [(x - half, y - half, x + half, y + half) for x, y in points]

    def _step_label(self, step, numbers) -> str:
        text = f"n={steps_text(numbers)}: {step.action_name}"
        return text + (f" (P2 {step.p2_action_name})" if self.general else "")

    def _draw_episode(self, ax: plt.Axes, placer: Placer) -> None:
        """Every distinct step once (by start, landing, action, trapped, hypothesis and, with
        general P2 actions, P2's action), coloured by P2's hypothesis, with its step numbers;
        the traps P2 set; where she changed her mind."""
        groups: dict[tuple, list] = {}
        for step in self.steps:
            groups.setdefault(_group_key(step, self.general), []).append(step)
        # the trap marks first, just outside their state box's top-left corner (over the box they
        # would cover its name), so that no label is placed on them
        traps: dict[int, int] = {}
        for step in self.steps:
            for s in step.traps:
                traps[s] = traps.get(s, 0) + 1
        beside = offset_copy(ax.transData, fig=ax.figure, x=-6, y=6, units="points")
        for s in traps:
            x0, _, _, y1 = self.boxes[s]
            (mark,) = ax.plot(x0, y1, marker="X", ms=10, color=TRAP_COLOUR, zorder=7,
                              transform=beside)
            placer.taken.append(placer.box_of(mark, 1.0))
        on_pair: dict[tuple[int, int], int] = {}
        labels = []
        for members in groups.values():
            step = members[0]
            pair = (step.start, step.landing)
            k = on_pair[pair] = on_pair.get(pair, -1) + 1
            colour = TRAPPED_COLOUR if step.trapped else hypothesis_colour(step.hypothesis)
            spots = self._step_arrow(ax, step, k, colour)
            labels.append((spots, self._step_label(step, [m.n for m in members]), colour))
            if not step.stays:
                placer.soft.extend(self._head_boxes(step, k))
        # the labels after every arrow, avoiding the arrowheads where they can (a label over
        # the head of the step into the target hid where the episode ended)
        for spots, text, colour in labels:
            placer.place(spots, text, fontsize=LABEL_FONT, color=colour)
        for s, count in traps.items():
            placer.place(lambda w, h, box=self.boxes[s]: _beside_mark(box, w, h) + _around(box),
                         f"trap {count}×", fontsize=LABEL_FONT, color=TRAP_COLOUR,
                         weight="bold")
        landing = {step.n: step.landing for step in self.steps}
        for n, x in self.changes_shown:
            placer.place(_around(self.boxes[landing[n]]), f"n={n}: P2 now x{x}",
                         fontsize=LABEL_FONT, color=hypothesis_colour(x), weight="bold")

    # ---- the replay ----
    def draw_step(self, ax: plt.Axes, step) -> None:
        """One frame's step: a black arrow over the graph (the state boxes are measured)."""
        self._step_arrow(ax, step, 0, TRAPPED_COLOUR if step.trapped else "black", 2.6)

    def caption(self, step) -> str:
        names = self.arena.states
        where = (f"stayed at {names[step.start]}" if step.stays
                 else f"{names[step.start]} → {names[step.landing]}")
        text = f"{step.action_name}: {where}"
        if self.general:
            text += f"; P2 {step.p2_action_name}"
        return text + (", trapped" if step.trapped else "")

    # ---- the explorer (report/explorer.py) ----
    def explorer_map(self) -> dict:
        """The graph as the explorer draws it: each state's text, kind and colour (at
        `position`), whether it is terminal, and the arrows u -> v with their actions."""
        from matplotlib.colors import to_hex

        nodes = [{"text": self.node_text(s), "kind": self._kind(s),
                  "fill": to_hex(NODE_STYLE[self._kind(s)][0]),
                  "terminal": bool(self.arena.terminal[s])}
                 for s in range(self.arena.n_states)]
        return {"kind": "graph", "nodes": nodes,
                "edges": [[u, v, ", ".join(names)] for (u, v), names in self.edges.items()],
                "legend": {k: [to_hex(NODE_STYLE[k][0]), NODE_STYLE[k][1]] for k in NODE_STYLE}}
