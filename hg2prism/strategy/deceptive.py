"""P1's deceptive strategy (docs/semantics.md §6), chosen on canonical hypergame states from the
values Storm computed: among the value-optimal moves, the fastest."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hg2prism.engines.engine import Transitions
from hg2prism.numeric import argmax_by_group, first_best
from hg2prism.prism.decoding import DecodedStates
from hg2prism.strategy.canonical import CanonicalMDP


@dataclass(frozen=True, eq=False)
class StormChoices:
    """P1's deceptive strategy on canonical states: the chosen Storm choice of each."""

    representative: np.ndarray   # [n_canonical] a Storm state of each canonical state
    choice: np.ndarray           # [n_storm_states] global choice index P1 takes in each Storm state


OPTIMAL_SLACK = 1e-8   # Storm's values are sound to 1e-10; choices within this are optimal
DISCOUNT = 0.9         # how strongly P1 prefers finishing soon among optimal moves
MAX_DISCOUNT_SWEEPS = 1000


def deceptive_actions(mdp: CanonicalMDP, values: np.ndarray) -> np.ndarray:
    """An optimal strategy that does not stall, computed on canonical states from Storm's
    values (`values`: [mdp.n] by canonical state): the move of every canonical state, -1 in
    absorbing ones.

    Storm's own scheduler is optimal in the limit but may dither (push into a wall) for a long
    time: on world1 it completes within 200 steps with probability 0.02 for a value of 0.95.
    Its copies of one canonical state (differing in the DFA's previous state) may also pick
    different optimal moves, which mixed together need not be optimal. Here every canonical
    state takes, among its value-optimal moves, the one that maximises the discounted
    probability of reaching the goal (lexicographically: value first, then speed).
    """
    choice_state = mdp.choice_state
    optimal = mdp.choice_values(values) >= values[choice_state] - OPTIMAL_SLACK

    # Among optimal choices, prefer reaching the goal soon: the discounted probability
    # W(s) = max over optimal choices of E[DISCOUNT^steps; reach goal]. A choice that stalls
    # scores 0 there, so the greedy choice keeps moving, and every state of positive value
    # keeps a positive chance of reaching the goal: the strategy stays optimal.
    goal = mdp.goal
    opt_choices = np.flatnonzero(optimal)                            # sorted, grouped by state
    keep = np.flatnonzero(optimal[mdp.entry_choice])
    k_choice, k_target, k_prob = (mdp.entry_choice[keep], mdp.entry_target[keep],
                                  mdp.entry_prob[keep])
    # The optimal choices of each canonical state that has some form a column of a
    # [width, states] table (padded with -1, below every score), so that a sweep is one sparse
    # product and a maximum over the table's few contiguous rows.
    group_start = np.flatnonzero(np.diff(np.r_[-1, choice_state[opt_choices]]) != 0)
    group_size = np.diff(np.r_[group_start, len(opt_choices)])
    n_groups, width = len(group_start), int(group_size.max(initial=1))
    group_of = np.full(mdp.n, -1, dtype=np.int64)
    group_of[choice_state[opt_choices[group_start]]] = np.arange(n_groups)
    group_of_slot = np.repeat(np.arange(n_groups), group_size)
    rank_in_group = np.arange(len(opt_choices)) - np.repeat(group_start, group_size)
    cell_of_slot = rank_in_group * n_groups + group_of_slot
    k_cell = cell_of_slot[(np.cumsum(optimal) - 1)[k_choice]]
    n_cells = n_groups * width
    reached = np.full(n_cells, -1.0)
    reached[cell_of_slot] = 0.0
    reached += np.bincount(k_cell, weights=k_prob * goal[k_target], minlength=n_cells)
    # Onward entries lead to states that still have choices (goal counts in `reached`, and
    # failure adds nothing).
    onward = (group_of[k_target] >= 0) & ~goal[k_target]
    onward_matrix = sp.csr_matrix(
        (k_prob[onward] * DISCOUNT, (k_cell[onward], group_of[k_target[onward]])),
        shape=(n_cells, n_groups))
    # Each sweep runs on two threads, each over half of the states (numpy and scipy release
    # the GIL): the same sums and maxima, row by row, as one thread would take.
    table = np.empty((width, n_groups))
    reached_rows = reached.reshape(width, n_groups)
    halves = []
    for low, high in ((0, n_groups // 2), (n_groups // 2, n_groups)):
        rows = [onward_matrix[r * n_groups + low:r * n_groups + high] for r in range(width)]
        halves.append((low, high, rows))

    def sweep(half: tuple[int, int, list[sp.csr_matrix]], w: np.ndarray, new: np.ndarray
              ) -> float:
        low, high, rows = half
        for r, block in enumerate(rows):
            np.add(block @ w, reached_rows[r, low:high], out=table[r, low:high])
        np.max(table[:, low:high], axis=0, out=new[low:high])
        return float(np.abs(new[low:high] - w[low:high]).max(initial=0.0))

    w = np.zeros(n_groups)
    with ThreadPoolExecutor(max_workers=2) as pool:
        for _ in range(MAX_DISCOUNT_SWEEPS):
            new = np.empty(n_groups)
            change = max(pool.map(lambda half: sweep(half, w, new), halves))  # noqa: B023
            w = new
            if change < 1e-9:      # enough to rank the moves
                break
    score = np.full(len(choice_state), -1.0)
    score[opt_choices] = (reached + onward_matrix @ w)[cell_of_slot]
    # Scores equal but for rounding (symmetric moves) count as tied, so that the first move
    # wins whatever order the sums were taken in.
    best = first_best(score, choice_state, relative_tie=1e-12)
    action = np.full(mdp.n, -1, dtype=np.int64)
    action[choice_state[best]] = mdp.choice_action[best]
    return action


def storm_choices(decoded: DecodedStates, moves: Transitions, representative: np.ndarray,
                  action: np.ndarray) -> StormChoices:
    """The Storm choices of a strategy given per canonical state (`action`, a move index; any
    value in absorbing states): every Storm state takes the move its canonical state takes."""
    wanted = action[decoded.canonical]
    match = (moves.action == wanted[moves.source]) & (moves.action >= 0)
    choice = argmax_by_group(np.where(match, 1.0, 0.0), moves.source, len(decoded.canonical))
    return StormChoices(representative=representative, choice=choice)
