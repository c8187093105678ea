"""The grid front end (docs/semantics.md §§1-2): reading a grid world file's grid parts, and
compiling a grid world to its arena.

Reading (`read`): `[grid] map`, `[robot] slip` and `[adversary]`'s traps, delay and
initial_traps (cells), each key checked with one error line; the loader (worldfile/loader.py)
reads the tables every world has. The `Grid` value keeps the map and the slip; the world's
`initial_standing` is the index of the initial traps among the trap sets (with delay 0 those a
sweep over delay starts from; 0, the first set, when the file names none).

Compiling (`to_arena`):
one arena state per free cell, in map reading order (top row first, left to right), named by
its coordinates (`x2_y4`: x the column from the left, y the row from the bottom); P1's actions
N, E, S, W at every cell, each with its slip outcomes (the intended direction with probability
1 - 2*slip, each perpendicular one with slip; a move into a wall or off the map stays); labels
`obs` on obstacles and the region letter on region cells; P2's actions the trap sets over the
candidate cells. Everything below this module sees only the arena.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from hg2prism.frontends.settings import Setting
from hg2prism.model.arena import Arena
from hg2prism.model.validation import DELAY_0_STANDING, Vocabulary
from hg2prism.model.world import World

Cell = tuple[int, int]

MAP_LEGEND = ". # o t @ A-Z"
# Region letters that Spot reads as temporal operators.
FORBIDDEN_REGION_LETTERS = frozenset("FGMRUVWX")     # Spot's operators (V: release)
# The tables a grid world has besides those of every world, and their keys (key -> required?)
TABLE_KEYS = {"grid": {"map": True}, "robot": {"slip": True}}
ADVERSARY_KEYS = {"traps": True, "delay": False, "initial_traps": False}
MISSING_HINT = {
    "grid.map": "a multi-line string with the map (legend: " + MAP_LEGEND + ")",
    "robot.slip": "a number in [0, 0.5)",
}
SLIP_EXPECTED = "a number in [0, 0.5)"
# Why P2 cannot set more traps than the map has candidates (Checks.traps)
TRAPS_BEYOND = ("the map has only {n} trap candidate cells 't'; expected traps <= the number "
                "of 't' cells")


@dataclass(frozen=True)
class Grid:
    """A grid world's map (docs/semantics.md §1) and its robot's slip (§2): a grid world's
    front-end value (model.world.Front: `World.front`)."""

    kind: ClassVar[str] = "grid"
    replaceable: ClassVar[frozenset[str]]      # what World.replace changes (below the class)

    rows: tuple[str, ...]                 # the map as written, top row first
    width: int
    height: int
    walls: frozenset[Cell]
    obstacles: frozenset[Cell]
    regions: tuple[tuple[str, frozenset[Cell]], ...]   # (letter, cells), letters sorted
    trap_candidates: tuple[Cell, ...]     # map reading order: top row first, left to right
    start: Cell
    slip: float = 0.0                     # probability of slipping to each side of a move

    def region_letters(self) -> tuple[str, ...]:
        return tuple(letter for letter, _ in self.regions)

    def propositions(self) -> tuple[str, ...]:
        """AP: `obs`, then the region letters of the map in alphabetical order."""
        return ("obs",) + self.region_letters()

    def check(self, checks) -> None:
        """What validation (model/validation.py) checks of a grid World's own values: the slip,
        and that the cells are those its map (`rows`) says (a Grid made by hand, or by
        dataclasses.replace, with a start or regions of its own would not be one)."""
        check_slip(checks, self.slip)
        if not (isinstance(self.rows, tuple) and self.rows
                and all(isinstance(row, str) for row in self.rows)):
            raise checks.fail("grid.rows", "must be a tuple of the map's rows (str), top row "
                                           f"first, got {self.rows!r}")
        mapped = read_map(checks, {"map": "\n".join(self.rows)})
        for name in ("width", "height", "walls", "obstacles", "regions", "trap_candidates",
                     "start"):
            if getattr(self, name) != getattr(mapped, name):
                raise checks.fail(f"grid.{name}", f"{getattr(self, name)!r} is not what the "
                                  f"map (grid.rows) says, {getattr(mapped, name)!r}: a grid's "
                                  "cells are read from its map; change the map instead")

    def vocabulary(self) -> Vocabulary:
        return Vocabulary(self.propositions(), "obs and the region letters of the map ("
                          + (", ".join(self.region_letters()) or "none") + ")")

    def count_p2_actions(self, checks, traps: object) -> tuple[int, str]:
        """|A2| (the traps-subsets of the candidate cells) and the key of the standing set."""
        traps = checks.traps(traps, len(self.trap_candidates), TRAPS_BEYOND)
        return math.comb(len(self.trap_candidates), traps), "adversary.initial_traps"

    def describe(self) -> str:
        from hg2prism.frontends import counted

        return f"{self.width}x{self.height} grid, {counted(len(self.trap_candidates), 'trap candidate')}"

# what World.replace changes in a grid world (its robot); the cells come from the map
Grid.replaceable = frozenset({"slip"})

ACTIONS = ("N", "E", "S", "W")
STEP = {"N": (0, 1), "E": (1, 0), "S": (0, -1), "W": (-1, 0)}
# The two directions perpendicular to each move, in a fixed order: its slips.
PERPENDICULAR = {"N": ("E", "W"), "E": ("N", "S"), "S": ("E", "W"), "W": ("N", "S")}


def outcome_directions(action: int) -> tuple[int, int, int]:
    """The directions (indices into ACTIONS) of a move's outcomes: the move itself, then its two
    slips, in the order of the arena's outcome axis."""
    name = ACTIONS[action]
    return (action, *(ACTIONS.index(p) for p in PERPENDICULAR[name]))


def outcome_name(action: str, outcome: int) -> str:
    """The direction of outcome `outcome` of move `action` (the move itself, then its slips)."""
    return ACTIONS[outcome_directions(ACTIONS.index(action))[outcome]]


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
    return GridGeometry(cells=cells, cell_index=cell_index, move=move, slip=world.grid.slip)


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
    prob = np.broadcast_to(np.array([1 - 2 * grid.slip, grid.slip, grid.slip]),
                           dest.shape).copy()
    positions = tuple((float(x), float(y)) for x, y in geo.cells)
    return Arena(
        states=tuple(cell_name(c) for c in geo.cells), initial=geo.cell_index[grid.start],
        propositions=world.atomic_propositions(), labels=tuple(labels),
        actions=(ACTIONS,) * len(geo.cells), dest=dest, prob=prob,
        trap_candidates=tuple(geo.cell_index[c] for c in grid.trap_candidates),
        positions=positions,
    )


def trap_sets(grid: Grid, traps: int) -> list[tuple[int, ...]]:
    """P2's actions: the trap sets as tuples of candidate numbers, in combinations order."""
    return list(itertools.combinations(range(len(grid.trap_candidates)), traps))


def with_slip(world: World, slip: float) -> World:
    """The grid world with another slip (checked by the caller)."""
    return replace(world, front=replace(world.grid, slip=slip))


# What sweeps may vary in a grid world only
SETTINGS = (Setting("slip", SLIP_EXPECTED, float, 0.0, False, 0.5, with_slip),)

# The front end (frontends/__init__.py)
KIND = Grid.kind
FILE_TABLES = {"grid": True, "robot": True}
DESCRIBED = "a grid world ([grid] and [robot])"
STANDING_RULE = ("delay > 0: the world's initial_traps, else the file's [adversary] "
                 "initial_traps, else the first `traps` candidates")


def describe(world: World) -> str:
    return world.front.describe()

# What draws a grid world (frontends/grid_drawing.py, which reads this module)
DRAWER = "hg2prism.frontends.grid_drawing.GridDrawer"


def parameters(world: World) -> dict[str, object]:
    """The grid's own parameters, as results.json echoes them."""
    return {"slip": world.grid.slip}


def standing_candidates(world: World) -> tuple[int, ...]:
    """The trap candidates (numbers) standing at the start when the world is re-solved with a
    positive delay (a sweep, docs/semantics.md §7 Sweeps): its initial traps, which a world with
    delay 0 keeps as its file names them (the first `traps` candidates when it names none)."""
    return trap_sets(world.grid, world.traps)[world.initial_standing]


# ---------------------------------------------------------------------------------------------
# Reading a grid world file
# ---------------------------------------------------------------------------------------------

def read(ld, root: dict) -> Grid:
    """The grid of a world file: [grid] map and [robot] slip. `ld` is the loader
    (worldfile/loader.py): its typed getters raise its one-line errors."""
    grid = read_map(ld, ld.table(root, "grid", TABLE_KEYS["grid"]))
    return replace(grid, slip=check_slip(ld, ld.table(root, "robot", TABLE_KEYS["robot"])["slip"]))


def check_slip(checks, value: object) -> float:
    """[robot] slip: a number in [0, 0.5) (`checks`: model/validation.py's Checks)."""
    slip = checks.number(value, "robot.slip")
    if not 0.0 <= slip < 0.5:
        raise checks.fail("robot.slip", f"slip must be in [0, 0.5), got {slip}")
    return slip


def read_adversary(ld, adv: dict, grid: Grid) -> dict:
    """The World fields of [adversary] that depend on the grid: traps, delay and
    initial_standing (from initial_traps)."""
    traps = ld.traps(adv["traps"], len(grid.trap_candidates), TRAPS_BEYOND)
    delay = ld.delay(adv.get("delay", 0))
    cells = initial_traps(ld, adv, grid, traps, delay)
    standing = trap_sets(grid, traps).index(_numbers(grid, cells)) if cells else 0
    return dict(traps=traps, delay=delay, initial_standing=standing)


def _numbers(grid: Grid, cells) -> tuple[int, ...]:
    return tuple(sorted(grid.trap_candidates.index(c) for c in cells))


def read_map(ld, grid_table: dict) -> Grid:
    key = "grid.map"
    text = ld.string(grid_table["map"], key)
    text = text.replace("\r\n", "\n")
    if text.startswith("\n"):
        text = text[1:]
    rows = text.split("\n")
    while rows and rows[-1].strip() == "":
        rows.pop()
    if not rows:
        raise ld.fail(key, "the map is empty; expected rows of cells (legend: "
                           + MAP_LEGEND + ")")
    height = len(rows)
    width = len(rows[0])
    for i, row in enumerate(rows):
        if len(row) != width:
            raise ld.fail(key, f"ragged rows: row {i + 1} (from the top) has {len(row)} "
                               f"cells but row 1 has {width}; every row must be the same "
                               "length")
    walls: set[Cell] = set()
    obstacles: set[Cell] = set()
    regions: dict[str, set[Cell]] = {}
    candidates: list[Cell] = []
    starts: list[Cell] = []
    kinds = {"#": walls, "o": obstacles}
    for i, row in enumerate(rows):
        y = height - 1 - i
        for x, ch in enumerate(row):
            cell = (x, y)
            if ch == ".":
                pass
            elif ch in kinds:
                kinds[ch].add(cell)
            elif ch == "t":
                candidates.append(cell)
            elif ch == "@":
                starts.append(cell)
            elif "A" <= ch <= "Z":
                if ch in FORBIDDEN_REGION_LETTERS:
                    raise ld.fail(key, f"region letter {ch} at (x={x}, y={y}) is not "
                                       "allowed: F, G, M, R, U, V, W and X are Spot "
                                       "operators; use another letter")
                regions.setdefault(ch, set()).add(cell)
            else:
                raise ld.fail(key, f"unknown character {ch!r} at (x={x}, y={y}) "
                                   f"(row {i + 1}, column {x + 1}); expected one of "
                                   + MAP_LEGEND)
    if not starts:
        raise ld.fail(key, "no robot start '@' in the map; expected exactly one")
    if len(starts) > 1:
        where = ", ".join(f"({x}, {y})" for x, y in starts)
        raise ld.fail(key, f"{len(starts)} robot starts '@' at {where}; expected exactly one")
    return Grid(rows=tuple(rows), width=width, height=height, walls=frozenset(walls),
                obstacles=frozenset(obstacles),
                regions=tuple((letter, frozenset(c)) for letter, c in sorted(regions.items())),
                trap_candidates=tuple(candidates), start=starts[0])


def _cells(ld, value: object, key: str) -> list[Cell]:
    """[[x, y], ...], each item checked."""
    cells: list[Cell] = []
    for i, item in enumerate(ld.array(value, key, "an array of [x, y] cells")):
        if (not isinstance(item, list) or len(item) != 2
                or any(isinstance(c, bool) or not isinstance(c, int) for c in item)):
            raise ld.fail(f"{key}[{i}]", f"each initial trap must be a cell [x, y] of two "
                                         f"integers, got {ld.written(item)}")
        cells.append((item[0], item[1]))
    return cells


def initial_traps(ld, adv: dict, grid: Grid, traps: int, delay: int) -> tuple[Cell, ...]:
    """Parse [[x, y], ...], the traps standing at the start when delay > 0; with delay 0 what a
    re-solve with a positive delay starts from (a sweep over delay), checked alike, and an empty
    list names none. Returns cells sorted by candidate number (none: empty)."""
    key = "adversary.initial_traps"
    if "initial_traps" not in adv:
        if delay > 0:
            raise ld.fail(key, f"initial_traps is required when delay > 0; expected "
                               f"{traps} distinct trap candidate cells as [[x, y], ...]")
        return ()
    cells = _cells(ld, adv["initial_traps"], key)
    if delay == 0 and not cells:
        return ()
    numbering = {cell: n for n, cell in enumerate(grid.trap_candidates)}
    cand_text = ", ".join(f"[{x}, {y}]" for x, y in grid.trap_candidates)
    why = "" if delay else DELAY_0_STANDING
    for i, cell in enumerate(cells):
        if cell not in numbering:
            raise ld.fail(f"{key}[{i}]", f"[{cell[0]}, {cell[1]}] is not a trap candidate "
                                         f"'t' cell; candidates are {cand_text}{why}")
    for i, cell in enumerate(cells):
        if cell in cells[:i]:
            raise ld.fail(f"{key}[{i}]", f"[{cell[0]}, {cell[1]}] is repeated; initial "
                                         f"traps must be distinct cells{why}")
    if len(cells) != traps:
        raise ld.fail(key, f"expected {traps} distinct trap candidate cells (traps = "
                           f"{traps}), got {len(cells)}{why}")
    return tuple(sorted(cells, key=numbering.__getitem__))


def world_file(*, name: str, description: str, rows: list[str], slip: float, formula: str,
               traps: int, delay: int, hypotheses, inference: dict) -> str:
    """The text of a grid world file with map `rows` (top row first); with delay > 0 the traps
    stand on the first `traps` candidates in reading order at the start."""
    height = len(rows)
    candidates = [(x, height - 1 - r) for r, row in enumerate(rows)
                  for x, char in enumerate(row) if char == "t"]
    initial = ", ".join(f"[{x}, {y}]" for x, y in candidates[:traps])
    delay_lines = f"delay = {delay}\ninitial_traps = [{initial}]\n" if delay else ""
    hyps = ", ".join(f'"{h}"' for h in hypotheses)
    inference_lines = "".join(f"{key} = {value}\n" for key, value in inference.items())
    newline = "\n"
    return f'''name = "{name}"
description = "{description}"

[grid]
map = """
{newline.join(rows)}
"""

[robot]
slip = {slip}

[task]
formula = "{formula}"

[adversary]
traps = {traps}
{delay_lines}hypotheses = [{hyps}]

[inference]
{inference_lines}'''
