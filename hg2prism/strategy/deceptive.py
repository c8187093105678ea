"""P1's deceptive strategy (docs/semantics.md §6), chosen on canonical hypergame states from the
values Storm computed: among the value-optimal moves, the fastest."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hg2prism.engines.engine import Transitions
from hg2prism.numeric import argmax_by_group, first_best
from hg2prism.numeric.fastest import (DISCOUNT, MAX_SCORE_SWEEPS, RELATIVE_TIE, SCORE_STOP,
                                      STORM_SLACK)
from hg2prism.prism.decoding import DecodedStates
from hg2prism.strategy.canonical import CanonicalMDP


@dataclass(frozen=True, eq=False)
class StormChoices:
    """P1's deceptive strategy on canonical states: the chosen Storm choice of each."""

    representative: np.ndarray   # [n_canonical] a Storm state of each canonical state
    choice: np.ndarray           # [n_storm_states] global choice index P1 takes in each Storm state


# the fastest-first rule's constants (numeric/fastest.py)
OPTIMAL_SLACK, MAX_DISCOUNT_SWEEPS = STORM_SLACK, MAX_SCORE_SWEEPS


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
    # The states with an optimal choice are the groups 0..n_groups-1, in state order; the
    # optimal choices of group g are opt_choices[bounds[g]:bounds[g + 1]].
    group_start = np.flatnonzero(np.diff(np.r_[-1, choice_state[opt_choices]]) != 0)
    n_groups = len(group_start)
    bounds = np.r_[group_start, len(opt_choices)]
    group_of = np.full(mdp.n, -1, dtype=np.int64)
    group_of[choice_state[opt_choices[group_start]]] = np.arange(n_groups)
    # What each optimal choice reaches at once (the goal), and onward: a [optimal choices,
    # groups] matrix to the states that still have choices (the goal counts in `reached`,
    # failure adds nothing).
    reached = np.bincount(mdp.entry_choice, weights=mdp.entry_prob * goal[mdp.entry_target],
                          minlength=len(choice_state))[opt_choices]
    onward = _onward_matrix(mdp, optimal, opt_choices, group_of)
    del optimal, group_of
    # Each sweep runs on two threads, each over half of the states (numpy and scipy release
    # the GIL): the same sums and maxima, row by row, as one thread would take.
    halves = [(low, high, _row_block(onward, bounds[low], bounds[high]),
               reached[bounds[low]:bounds[high]], group_start[low:high] - bounds[low])
              for low, high in ((0, n_groups // 2), (n_groups // 2, n_groups)) if high > low]

    def sweep(half: tuple, w: np.ndarray, new: np.ndarray) -> float:
        low, high, block, reach, starts = half
        np.maximum.reduceat(block @ w + reach, starts, out=new[low:high])
        return float(np.abs(new[low:high] - w[low:high]).max(initial=0.0))

    w = np.zeros(n_groups)
    with ThreadPoolExecutor(max_workers=2) as pool:
        for _ in range(MAX_DISCOUNT_SWEEPS):
            new = np.empty(n_groups)
            change = max(pool.map(lambda half: sweep(half, w, new), halves),  # noqa: B023
                         default=0.0)
            w = new
            if change < SCORE_STOP:      # enough to rank the moves
                break
    score = np.full(len(choice_state), -1.0)
    score[opt_choices] = reached + onward @ w
    # Scores equal but for rounding (symmetric moves) count as tied, so that the first move
    # wins whatever order the sums were taken in.
    best = first_best(score, choice_state, relative_tie=RELATIVE_TIE)
    action = np.full(mdp.n, -1, dtype=np.int64)
    action[choice_state[best]] = mdp.choice_action[best]
    return action


def _onward_matrix(mdp: CanonicalMDP, optimal: np.ndarray, opt_choices: np.ndarray,
                   group_of: np.ndarray) -> sp.csr_matrix:
    """[optimal choices, groups] DISCOUNT x the probability of each optimal choice's move to
    each state that still has choices and is not the goal (its group), duplicates summed:
    built in place from the MDP's entries (each choice's entries are contiguous), one copy."""
    onward_state = (group_of >= 0) & ~mdp.goal
    selected = optimal[mdp.entry_choice]
    selected &= onward_state[mdp.entry_target]
    selected = np.flatnonzero(selected)
    counts = np.bincount(mdp.entry_choice[selected], minlength=len(optimal))[opt_choices]
    data = mdp.entry_prob[selected]
    data *= DISCOUNT
    columns = group_of[mdp.entry_target[selected]]
    del selected
    index = np.int32 if max(len(opt_choices), len(data)) < 2 ** 31 - 1 else np.int64
    row_start = np.r_[0, np.cumsum(counts)].astype(index)
    matrix = sp.csr_matrix((data, columns.astype(index), row_start),
                           shape=(len(opt_choices), int(group_of.max(initial=-1)) + 1))
    matrix.sum_duplicates()
    return matrix


def _row_block(matrix: sp.csr_matrix, low: int, high: int) -> sp.csr_matrix:
    """Rows low..high-1 of `matrix`, sharing its data and indices (a slice would copy them)."""
    start, end = matrix.indptr[low], matrix.indptr[high]
    return sp.csr_matrix((matrix.data[start:end], matrix.indices[start:end],
                          matrix.indptr[low:high + 1] - start),
                         shape=(high - low, matrix.shape[1]))


def storm_choices(decoded: DecodedStates, moves: Transitions, representative: np.ndarray,
                  action: np.ndarray) -> StormChoices:
    """The Storm choices of a strategy given per canonical state (`action`, a move index; any
    value in absorbing states): every Storm state takes the move its canonical state takes."""
    wanted = action[decoded.canonical]
    match = (moves.action == wanted[moves.source]) & (moves.action >= 0)
    choice = argmax_by_group(np.where(match, 1.0, 0.0), moves.source, len(decoded.canonical))
    return StormChoices(representative=representative, choice=choice)
