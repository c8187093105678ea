"""The hypergame MDP on canonical states (docs/semantics.md §6), read off Storm's model: each
canonical state's choices are those of its first Storm state (its representative), their
successors mapped to canonical states. The objectives other than Pmax's default, the per-move
values of strategy.json and the induced DTMC are computed on it."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hg2prism.engines.engine import Transitions
from hg2prism.prism.decoding import DecodedStates
from hg2prism.numeric import ExplicitModel, first_index


@dataclass(frozen=True, eq=False)
class CanonicalMDP:
    """Canonical states 0..n-1 (goal states merged into one, failure states into another) and
    the labelled choices of the non-absorbing ones, in state order and, within a state, in
    move order: an explicit model (`model`, a numeric.ExplicitModel) whose choices carry a
    move and Storm's choice."""

    n: int
    representative: np.ndarray   # [n] the first Storm state of each canonical state
    goal: np.ndarray             # [n] bool
    fail: np.ndarray             # [n] bool
    choice_state: np.ndarray     # [choices] canonical source (non-absorbing states only)
    choice_action: np.ndarray    # [choices] P1's action slot at the state
    choice_storm: np.ndarray     # [choices] Storm's global choice index
    entry_choice: np.ndarray     # [entries] index into the choice arrays (ascending: each
                                 # choice's entries are contiguous, in choice order)
    entry_target: np.ndarray     # [entries] canonical successor
    entry_prob: np.ndarray       # [entries]
    n_actions: int = 0           # action slots per state (the TS's A1max)

    @property
    def absorbing(self) -> np.ndarray:
        return self.goal | self.fail

    @functools.cached_property
    def model(self) -> ExplicitModel:
        """The MDP as the numeric core reads it: choices of state s are group_start[s]..
        group_start[s+1]-1 (none for absorbing states), duplicate successors summed."""
        matrix = sp.csr_matrix((self.entry_prob, (self.entry_choice, self.entry_target)),
                               shape=(len(self.choice_state), self.n))
        group_start = np.r_[0, np.cumsum(np.bincount(self.choice_state, minlength=self.n))]
        return ExplicitModel(matrix=matrix, group_start=group_start.astype(np.int64))

    def matrix(self) -> sp.csr_matrix:
        """[choices, n] successor probabilities of every choice (duplicates summed)."""
        return self.model.matrix

    def choice_values(self, values: np.ndarray) -> np.ndarray:
        """[choices] sum_s' P(s' | s, a) values[s'] of every choice."""
        return np.bincount(self.entry_choice, weights=self.entry_prob * values[self.entry_target],
                           minlength=len(self.choice_state))

    def by_state(self, per_choice: np.ndarray, fill: float = np.nan) -> np.ndarray:
        """[n, action slots] a per-choice quantity laid out by (state, action slot); `fill`
        where there is none."""
        table = np.full((self.n, self.n_actions), fill, dtype=float)
        table[self.choice_state, self.choice_action] = per_choice
        return table


def canonical_mdp(decoded: DecodedStates, moves: Transitions,
                  n_actions: int | None = None) -> CanonicalMDP:
    """The canonical MDP of Storm's model (see the module docstring); `n_actions`: P1's action
    slots per state (the TS's A1max; by default one more than the largest action index)."""
    canonical = decoded.canonical
    n_states = len(canonical)
    n = decoded.n_canonical
    representative = first_index(canonical, n)                        # first Storm state of each
    absorbing = decoded.goal | decoded.fail
    goal = np.zeros(n, dtype=bool)
    goal[canonical[decoded.goal]] = True
    fail = np.zeros(n, dtype=bool)
    fail[canonical[decoded.fail]] = True
    is_rep = representative[canonical[moves.source]] == moves.source
    keep = is_rep & (moves.action >= 0) & ~absorbing[moves.source]
    chosen = np.flatnonzero(keep)                    # grouped by state, in move order
    del is_rep, keep
    # in canonical state order (stable: each state's choices keep their move order)
    chosen = chosen[np.argsort(canonical[moves.source[chosen]], kind="stable")]
    index = np.int32 if n_states < 2 ** 31 and len(chosen) < 2 ** 31 else np.int64
    counts = (moves.row_start[chosen + 1] - moves.row_start[chosen]).astype(index)
    # the chosen choices' entries, gathered block by block into their arrays
    entry_prob = np.empty(int(counts.sum()))
    entry_target = np.empty(len(entry_prob), dtype=index)
    canonical_index = canonical.astype(index)
    filled = 0
    for low in range(0, len(chosen), ENTRY_BLOCK):
        entries = _entries_of(moves.row_start, chosen[low:low + ENTRY_BLOCK])
        entry_prob[filled:filled + len(entries)] = moves.probability[entries]
        entry_target[filled:filled + len(entries)] = canonical_index[moves.target[entries]]
        filled += len(entries)
    del canonical_index
    return CanonicalMDP(
        n=n, representative=representative, goal=goal, fail=fail,
        choice_state=canonical[moves.source[chosen]].astype(index),
        choice_action=moves.action[chosen], choice_storm=chosen.astype(index), entry_choice=np.repeat(np.arange(len(chosen), dtype=index), counts),
        entry_target=entry_target, entry_prob=entry_prob,
        n_actions=max(int(moves.action.max(initial=-1)) + 1, n_actions or 0))


ENTRY_BLOCK = 1 << 20      # choices per block of canonical_mdp's entries


def _entries_of(row_start: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    """The entries of the choices `chosen`, choice after choice (choice c's entries are
    row_start[c]..row_start[c + 1] - 1), as one array: steps of 1 within a choice, a jump
    to the next choice's first entry, summed in place."""
    counts = row_start[chosen + 1] - row_start[chosen]
    some = counts > 0
    first, last = row_start[chosen[some]], row_start[chosen[some] + 1] - 1
    entries = np.ones(int(counts.sum()), dtype=np.int64)
    entries[(np.cumsum(counts) - counts)[some]] = first - np.r_[0, last[:-1]]
    return np.cumsum(entries, out=entries)


def canonical_values(decoded: DecodedStates, storm_values: np.ndarray) -> np.ndarray:
    """[n] Storm's value of each canonical state (its Storm copies agree to Storm's precision)."""
    values = np.zeros(decoded.n_canonical)
    values[decoded.canonical] = storm_values
    return values
