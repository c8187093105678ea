"""The grid front end (docs/semantics.md §§1-2): a grid world compiles to its arena.

One arena state per free cell, in map reading order (top row first, left to right), named by
its coordinates (`x2_y4`: x the column from the left, y the row from the bottom); P1's actions
N, E, S, W at every cell, each with its slip outcomes (the intended direction with probability
1 - 2*slip, each perpendicular one with slip; a move into a wall or off the map stays); labels
`obs` on obstacles and the region letter on region cells; P2's actions the trap sets over the
candidate cells. Everything below this module sees only the arena.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hg2prism.model.arena import Arena
from hg2prism.model.world import Cell, World

ACTIONS = ("N", "E", "S", "W")
# LEGACY: action labels in generated PRISM (E, S and W are PRISM keywords)
ACTION_LABELS = {"N": "north", "E": "east", "S": "south", "W": "west"}
STEP = {"N": (0, 1), "E": (1, 0), "S": (0, -1), "W": (-1, 0)}
# The two directions perpendicular to each move, in a fixed order: its slips.
PERPENDICULAR = {"N": ("E", "W"), "E": ("N", "S"), "S": ("E", "W"), "W": ("N", "S")}
OUTCOMES = 3  # intended direction, then the two perpendicular slips


def outcome_directions(action: int) -> tuple[int, int, int]:
    """The directions (indices into ACTIONS) of a move's outcomes: the move itself, then its two
    slips, in the order of the arena's outcome axis."""
    name = ACTIONS[action]
    return (action, *(ACTIONS.index(p) for p in PERPENDICULAR[name]))


def cell_name(cell: Cell) -> str:
    return f"x{cell[0]}_y{cell[1]}"


@dataclass(frozen=True, eq=False)
class GridGeometry:
    """Where each arena state of a grid world lies, for drawing and for reading a state name
    back as a cell."""

    cells: tuple[Cell, ...]           # arena state i is cells[i]
    cell_index: dict[Cell, int]
    move: np.ndarray                  # [n_cells, 4] cell reached by a move in each direction
    slip: float = 0.0

    def cell_of(self, name: str) -> Cell:
        x, y = name[1:].split("_y")
        return int(x), int(y)


def geometry(world: World) -> GridGeometry:
    """The free cells in map reading order, their index and the cell each move reaches."""
    grid = world.grid
    cells = tuple(
        (x, grid.height - 1 - row)
        for row in range(grid.height)
        for x in range(grid.width)
        if (x, grid.height - 1 - row) not in grid.walls
    )
    cell_index = {cell: i for i, cell in enumerate(cells)}
    move = np.empty((len(cells), 4), dtype=np.int64)
    for i, (x, y) in enumerate(cells):
        for d, action in enumerate(ACTIONS):
            dx, dy = STEP[action]
            move[i, d] = cell_index.get((x + dx, y + dy), i)
    return GridGeometry(cells=cells, cell_index=cell_index, move=move, slip=world.slip)


def to_arena(world: World) -> Arena:
    """The grid world's arena (docs/semantics.md §15, last items)."""
    grid = world.grid
    geo = geometry(world)
    labels = []
    region_of = {cell: letter for letter, region in grid.regions for cell in region}
    for cell in geo.cells:
        if cell in grid.obstacles:
            labels.append(frozenset({"obs"}))
        elif cell in region_of:
            labels.append(frozenset({region_of[cell]}))
        else:
            labels.append(frozenset())
    directions = np.array([outcome_directions(a) for a in range(len(ACTIONS))])   # [4, 3]
    dest = geo.move[:, directions][:, :, None, :]                                   # [n, 4, 1, 3]
    prob = np.broadcast_to(np.array([1 - 2 * world.slip, world.slip, world.slip]),
                           dest.shape).copy()
    positions = tuple((float(x), float(y)) for x, y in geo.cells)
    return Arena(
        states=tuple(cell_name(c) for c in geo.cells), initial=geo.cell_index[grid.start],
        propositions=world.atomic_propositions(), labels=tuple(labels),
        actions=(ACTIONS,) * len(geo.cells), dest=dest, prob=prob,
        trap_candidates=tuple(geo.cell_index[c] for c in grid.trap_candidates),
        positions=positions,
    )


def initial_standing(world: World) -> int:
    """The index into A2 (the trap sets in combinations order) of the initial traps."""
    import itertools

    if not world.delay:
        return 0
    initial = tuple(sorted(world.grid.trap_candidates.index(c) for c in world.initial_traps))
    sets = list(itertools.combinations(range(len(world.grid.trap_candidates)), world.traps))
    return sets.index(initial)
