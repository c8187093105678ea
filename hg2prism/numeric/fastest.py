"""The fastest-first rule (docs/semantics.md §6): among the moves optimal for the value, P1
plays the one with the largest discounted probability of reaching the goal,
W = max over optimal moves of E[DISCOUNT^steps; goal], so that it never stalls; scores within
a relative RELATIVE_TIE of the best are tied, and ties go to the first move. `fastest_first` is
the rule on an explicit MDP, and every strategy read this way calls it or (robust deception's
worst case over intervals, naive answers to every trap set) takes its constants from here:

- the deceptive strategy on Storm's values (strategy/deceptive.py) and the robust one on its
  certified worst-case values (strategy/robust.py), optimal within STORM_SLACK, their scores
  iterated until they change by less than SCORE_STOP;
- P1's answers in P2's games and the naive strategy (opponent/perceptual_games.py
  `fastest_moves`, analyses/deception_value.py `naive_answers`), on values solved exactly,
  optimal within EXACT_SLACK, scores iterated to EXACT_SCORE_STOP.

The slacks differ with where the values come from, and the strategies and documents were
computed with them as they are: changing one changes strategies.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hg2prism.numeric.ties import first_best

DISCOUNT = 0.9              # how strongly P1 prefers finishing soon among optimal moves
STORM_SLACK = 1e-8          # Storm's values are sound to 1e-10: choices this close are optimal
EXACT_SLACK = 1e-9          # values solved exactly (numpy): moves this close are optimal
SCORE_STOP = 1e-9           # the scores' iteration stops below this change (enough to rank)
EXACT_SCORE_STOP = 1e-12    # ... on the small exact games
RELATIVE_TIE = 1e-12        # scores this close (relative) are tied: the first move wins
MAX_SCORE_SWEEPS = 1000


@dataclass(frozen=True, eq=False)
class Fastest:
    """The fastest-first rule's result on an explicit MDP."""

    choice: np.ndarray      # [states] the chosen choice (a global index); -1 without an optimal one
    scores: np.ndarray      # [states] W(s): 0 where no choice is optimal


def fastest_first(choice_state: np.ndarray, entry_choice: np.ndarray, entry_target: np.ndarray,
                  entry_prob: np.ndarray, goal: np.ndarray, optimal: np.ndarray,
                  score_stop: float, relative_tie: float = RELATIVE_TIE,
                  discount: float = DISCOUNT, max_sweeps: int = MAX_SCORE_SWEEPS) -> Fastest:
    """The rule on an MDP given by its choices (`choice_state` [choices], ascending: each
    state's choices contiguous) and their entries (`entry_choice` ascending, `entry_target`,
    `entry_prob`; a choice's entries may repeat a target), among the `optimal` [choices]:

        W(s) = max over optimal choices c of s of  sum_e P(e) * (1 if the target is a goal,
               else discount * W(target))

    (0 where s has no optimal choice), iterated from 0 until it changes by less than
    `score_stop`; each state takes the first optimal choice whose score is within
    `relative_tie` (relative) of the best. Each sweep is one sparse product over the optimal
    choices, on two threads for large models (numpy and scipy release the GIL; the same sums,
    row by row, as one thread would take)."""
    n_states = len(goal)
    opt_choices = np.flatnonzero(optimal)                          # sorted, grouped by state
    # The states with an optimal choice are the groups 0..n_groups-1, in state order; the
    # optimal choices of group g are opt_choices[bounds[g]:bounds[g + 1]].
    group_start = np.flatnonzero(np.diff(np.r_[-1, choice_state[opt_choices]]) != 0)
    n_groups = len(group_start)
    bounds = np.r_[group_start, len(opt_choices)]
    group_of = np.full(n_states, -1, dtype=np.int64)
    group_of[choice_state[opt_choices[group_start]]] = np.arange(n_groups)
    # What each optimal choice reaches at once (the goal), and onward: a [optimal choices,
    # groups] matrix to the states that still have choices.
    reached = np.bincount(entry_choice, weights=entry_prob * goal[entry_target],
                          minlength=len(choice_state))[opt_choices]
    onward = _onward_matrix(entry_choice, entry_target, entry_prob, goal, optimal, opt_choices,
                            group_of, discount)
    del group_of
    blocks = ((0, n_groups // 2), (n_groups // 2, n_groups)) if n_groups >= THREADED_GROUPS \
        else ((0, n_groups),)
    parts = [(low, high, _row_block(onward, bounds[low], bounds[high]),
              reached[bounds[low]:bounds[high]], group_start[low:high] - bounds[low])
             for low, high in blocks if high > low]

    def sweep(part: tuple, w: np.ndarray, new: np.ndarray) -> float:
        low, high, block, reach, starts = part
        np.maximum.reduceat(block @ w + reach, starts, out=new[low:high])
        return float(np.abs(new[low:high] - w[low:high]).max(initial=0.0))

    w = np.zeros(n_groups)
    pool = ThreadPoolExecutor(max_workers=2) if len(parts) > 1 else None
    try:
        for _ in range(max_sweeps):
            new = np.empty(n_groups)
            run = pool.map if pool else map
            change = max(run(lambda part: sweep(part, w, new), parts), default=0.0)  # noqa: B023
            w = new
            if change < score_stop:      # enough to rank the moves
                break
    finally:
        if pool:
            pool.shutdown()
    score = reached + onward @ w                                    # [optimal choices]
    # Scores equal but for rounding (symmetric moves) count as tied, so that the first move
    # wins whatever order the sums were taken in.
    best = first_best(score, choice_state[opt_choices], relative_tie=relative_tie)
    choice = np.full(n_states, -1, dtype=np.int64)
    choice[choice_state[opt_choices[best]]] = opt_choices[best]
    scores = np.zeros(n_states)
    scores[choice_state[opt_choices[group_start]]] = w
    return Fastest(choice=choice, scores=scores)


THREADED_GROUPS = 100_000       # states with optimal choices from which a sweep takes two threads


def _onward_matrix(entry_choice: np.ndarray, entry_target: np.ndarray, entry_prob: np.ndarray,
                   goal: np.ndarray, optimal: np.ndarray, opt_choices: np.ndarray,
                   group_of: np.ndarray, discount: float) -> sp.csr_matrix:
    """[optimal choices, groups] discount x the probability of each optimal choice's move to
    each state that still has choices and is not the goal (its group), duplicates summed:
    built in place from the entries (each choice's entries are contiguous), one copy."""
    onward_state = (group_of >= 0) & ~goal
    selected = optimal[entry_choice]
    selected &= onward_state[entry_target]
    selected = np.flatnonzero(selected)
    counts = np.bincount(entry_choice[selected], minlength=len(optimal))[opt_choices]
    data = entry_prob[selected]
    data *= discount
    columns = group_of[entry_target[selected]]
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
