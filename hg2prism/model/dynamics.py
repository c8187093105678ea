"""The transition system TS of docs/semantics.md §2 as numpy tables.

TS states are numbered: with delay 0, state i is cell i; with delay k > 0, state
(cell * n_sets + traps) * (k + 1) + countdown. The last state is `trapped`.
Cells are the non-wall cells in map reading order (top row first, left to right).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from hg2prism.model.world import Cell, World

ACTIONS = ("N", "E", "S", "W")
# Action labels in generated PRISM: E, S and W are PRISM keywords.
ACTION_LABELS = {"N": "north", "E": "east", "S": "south", "W": "west"}
STEP = {"N": (0, 1), "E": (1, 0), "S": (0, -1), "W": (-1, 0)}
# The two directions perpendicular to each move, in a fixed order: its slips.
PERPENDICULAR = {"N": ("E", "W"), "E": ("N", "S"), "S": ("E", "W"), "W": ("N", "S")}
OUTCOMES = 3  # intended direction, then the two perpendicular slips


def outcome_directions(action: int) -> tuple[int, int, int]:
    """The directions (indices into ACTIONS) of a move's outcomes: the move itself, then its two
    slips, in the order of the `succ`/`prob` tables' last axis."""
    name = ACTIONS[action]
    return (action, *(ACTIONS.index(p) for p in PERPENDICULAR[name]))


@dataclass(frozen=True, eq=False)
class TransitionSystem:
    cells: tuple[Cell, ...]
    cell_index: dict[Cell, int]
    label_names: tuple[str, ...]      # label class names: "" (none), "obs", region letters
    cell_label: np.ndarray            # [n_cells] label class of each cell
    move: np.ndarray                  # [n_cells, 4] cell reached by a move in each direction (walls bounce)
    candidates: tuple[int, ...]       # cell index of each trap candidate, in candidate order
    trap_sets: tuple[tuple[int, ...], ...]   # candidate numbers of each P2 action, combinations order
    set_cells: np.ndarray             # [n_sets, n_cells] bool: does trap set T cover the cell
    delay: int
    slip: float
    start_state: int
    succ: np.ndarray                  # [n_states, 4, n_sets, 3] successor state of each outcome
    prob: np.ndarray                  # [n_states, 4, n_sets, 3] its probability (0 for dropped outcomes)
    allowed: np.ndarray               # [n_states, n_sets] bool: A2(v)

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    @property
    def letters(self) -> tuple[int, ...]:
        """The label classes the world's states produce: its cells' and none (trapped)."""
        return tuple(sorted(set(self.cell_label.tolist()) | {0}))

    @property
    def n_sets(self) -> int:
        return len(self.trap_sets)

    @property
    def n_states(self) -> int:
        return self.succ.shape[0]

    @property
    def trapped(self) -> int:
        return self.n_states - 1

    @property
    def phases(self) -> int:
        """Countdown values 0..delay."""
        return self.delay + 1

    def state(self, cell: int, traps: int = 0, countdown: int = 0) -> int:
        if self.delay == 0:
            return cell
        return (cell * self.n_sets + traps) * self.phases + countdown

    def decode(self, state: int) -> tuple[int, int, int]:
        """(cell, traps, countdown) of a non-trapped state (traps = countdown = 0 when delay is 0)."""
        if self.delay == 0:
            return state, 0, 0
        cell, rest = divmod(state, self.n_sets * self.phases)
        traps, countdown = divmod(rest, self.phases)
        return cell, traps, countdown

    def state_label(self) -> np.ndarray:
        """[n_states] label class of every TS state (`trapped` has the empty label)."""
        cells = np.array([self.decode(s)[0] for s in range(self.n_states - 1)], dtype=np.int64)
        return np.append(self.cell_label[cells], 0)

    def reachable(self, p2_sets: np.ndarray | None = None) -> np.ndarray:
        """[n_states] bool: the TS states reachable from the start, P1 playing every move (and
        every slip), P2 playing at each state v one of p2_sets[:, v] ([k, n_states] trap sets:
        her choice under each hypothesis, say), or any set A2(v) allows when p2_sets is None.
        The hypergame's tables are only ever read at these states."""
        plays = self.allowed.copy()
        if p2_sets is not None:
            plays[:] = False
            for sets in np.asarray(p2_sets).reshape(-1, self.n_states):
                plays[np.arange(self.n_states), sets] = True
            plays &= self.allowed
        seen = np.zeros(self.n_states, dtype=bool)
        seen[self.start_state] = True
        frontier = np.array([self.start_state])
        while frontier.size:
            taken = plays[frontier][:, None, :, None] & (self.prob[frontier] > 0)
            successors = np.unique(self.succ[frontier][taken])
            frontier = successors[~seen[successors]]
            seen[frontier] = True
        return seen

    def trap_cells(self, trap_set: int) -> tuple[Cell, ...]:
        return tuple(self.cells[self.candidates[c]] for c in self.trap_sets[trap_set])

    def describe_state(self, state: int) -> dict:
        """A TS state as JSON-ready fields: cell [x, y], traps, countdown (null when delay is 0)."""
        if state == self.trapped:
            return {"cell": None, "traps": None, "countdown": None}
        cell, traps, countdown = self.decode(state)
        if self.delay == 0:
            return {"cell": list(self.cells[cell]), "traps": None, "countdown": None}
        return {"cell": list(self.cells[cell]),
                "traps": [list(c) for c in self.trap_cells(traps)], "countdown": countdown}


def _cells(world: World) -> tuple[tuple[Cell, ...], dict[Cell, int], np.ndarray, np.ndarray]:
    """The non-wall cells in map reading order, their index, label class and the cell each
    move reaches (walls bounce)."""
    grid = world.grid
    cells = tuple(
        (x, grid.height - 1 - row)
        for row in range(grid.height)
        for x in range(grid.width)
        if (x, grid.height - 1 - row) not in grid.walls
    )
    cell_index = {cell: i for i, cell in enumerate(cells)}
    cell_label = np.zeros(len(cells), dtype=np.int64)
    for i, cell in enumerate(cells):
        if cell in grid.obstacles:
            cell_label[i] = 1
    for k, (_, region) in enumerate(grid.regions):
        for cell in region:
            cell_label[cell_index[cell]] = 2 + k
    move = np.empty((len(cells), 4), dtype=np.int64)
    for i, (x, y) in enumerate(cells):
        for d, action in enumerate(ACTIONS):
            dx, dy = STEP[action]
            move[i, d] = cell_index.get((x + dx, y + dy), i)
    return cells, cell_index, cell_label, move


def build_transition_system(world: World) -> TransitionSystem:
    grid = world.grid
    cells, cell_index, cell_label, move = _cells(world)
    label_names = ("", "obs") + grid.region_letters()
    candidates = tuple(cell_index[c] for c in grid.trap_candidates)
    trap_sets = tuple(itertools.combinations(range(len(candidates)), world.traps))
    set_cells = np.zeros((len(trap_sets), len(cells)), dtype=bool)
    for t, members in enumerate(trap_sets):
        for c in members:
            set_cells[t, candidates[c]] = True

    n_sets, phases, delay = len(trap_sets), world.delay + 1, world.delay
    n_cells = len(cells)
    n_states = (n_cells * n_sets * phases if delay else n_cells) + 1
    trapped = n_states - 1

    # Outcome directions and probabilities, [4 actions, 3 outcomes].
    directions = np.array([[ACTIONS.index(a), *(ACTIONS.index(p) for p in PERPENDICULAR[a])]
                           for a in ACTIONS])
    outcome_prob = np.array([1 - 2 * world.slip, world.slip, world.slip])

    # Per non-trapped state: cell, standing traps, countdown.
    if delay:
        idx = np.arange(n_states - 1)
        state_cell, rest = np.divmod(idx, n_sets * phases)
        state_traps, state_count = np.divmod(rest, phases)
    else:
        state_cell = np.arange(n_cells)
        state_traps = np.zeros(n_cells, dtype=np.int64)
        state_count = np.zeros(n_cells, dtype=np.int64)

    target = move[state_cell][:, directions]                        # [S, 4, 3] cell reached
    a2 = np.arange(n_sets)
    hit = set_cells[a2[None, None, :, None], target[:, :, None, :]]  # [S, 4, n_sets, 3]
    if delay:
        changed = a2[None, :] != state_traps[:, None]                # [S, n_sets]
        next_count = np.where(changed, delay, np.maximum(state_count[:, None] - 1, 0))
        next_state = ((target[:, :, None, :] * n_sets + a2[None, None, :, None]) * phases
                      + next_count[:, None, :, None])
    else:
        next_state = np.broadcast_to(target[:, :, None, :], hit.shape)
    succ = np.where(hit, trapped, next_state)
    succ = np.concatenate([succ, np.full((1, 4, n_sets, OUTCOMES), trapped)], axis=0)
    prob = np.broadcast_to(outcome_prob, succ.shape).copy()
    prob[trapped] = 0.0
    prob[trapped, :, :, 0] = 1.0

    allowed = np.ones((n_states, n_sets), dtype=bool)
    if delay:
        waiting = state_count > 0
        allowed[:-1][waiting] = False
        allowed[np.flatnonzero(waiting), state_traps[waiting]] = True

    start_cell = cell_index[grid.start]
    if delay:
        initial = tuple(sorted(grid.trap_candidates.index(c) for c in world.initial_traps))
        start_state = (start_cell * n_sets + trap_sets.index(initial)) * phases
    else:
        start_state = start_cell
    return TransitionSystem(
        cells=cells, cell_index=cell_index, label_names=label_names, cell_label=cell_label,
        move=move, candidates=candidates, trap_sets=trap_sets, set_cells=set_cells,
        delay=delay, slip=world.slip, start_state=start_state,
        succ=succ, prob=prob, allowed=allowed,
    )
