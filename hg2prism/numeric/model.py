"""The explicit model every numeric routine reads: states, their choices, sparse transitions."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hg2prism.numeric.ties import first_index, near_best


@dataclass(frozen=True, eq=False)
class ExplicitModel:
    """An MDP (or, with one choice per state, a Markov chain) on states 0..n-1: the choices of
    state s are the rows group_start[s]..group_start[s+1]-1 of `matrix` [choices x states],
    each a (sub)distribution over successor states. A state without choices is absorbing."""

    matrix: sp.csr_matrix
    group_start: np.ndarray

    @classmethod
    def from_arrays(cls, row_start: np.ndarray, target: np.ndarray, probability: np.ndarray,
                    group_start: np.ndarray) -> "ExplicitModel":
        """From the flat CSR arrays of the choices (Storm's layout)."""
        n = len(group_start) - 1
        matrix = sp.csr_matrix((probability, target, row_start),
                               shape=(len(row_start) - 1, n))
        return cls(matrix=matrix, group_start=np.asarray(group_start, dtype=np.int64))

    @classmethod
    def from_tables(cls, successor: np.ndarray, weight: np.ndarray,
                    allowed: np.ndarray | None = None) -> "ExplicitModel":
        """From outcome tables successor/weight [states, choices, outcomes] (a choice's
        outcomes may repeat a successor: their weights add up), keeping only the `allowed`
        [states, choices] choices."""
        n, n_choices, _ = successor.shape
        keep = np.ones((n, n_choices), dtype=bool) if allowed is None else allowed
        succ, w = successor[keep], weight[keep]                     # [kept, outcomes]
        rows = np.repeat(np.arange(len(succ)), succ.shape[1])
        matrix = sp.csr_matrix((w.reshape(-1), (rows, succ.reshape(-1))), shape=(len(succ), n))
        group_start = np.r_[0, np.cumsum(keep.sum(axis=1))].astype(np.int64)
        return cls(matrix=matrix, group_start=group_start)

    @property
    def n_states(self) -> int:
        return len(self.group_start) - 1

    @property
    def n_choices(self) -> int:
        return self.matrix.shape[0]

    @functools.cached_property
    def counts(self) -> np.ndarray:
        """[states] the number of choices of each state."""
        return np.diff(self.group_start)

    @functools.cached_property
    def choice_state(self) -> np.ndarray:
        """[choices] the state each choice belongs to."""
        return np.repeat(np.arange(self.n_states), self.counts)

    @functools.cached_property
    def predecessors(self) -> sp.csr_matrix:
        """[states x choices]: row t lists the choices with a positive chance of entering t."""
        positive = self.matrix.copy()
        positive.data = (positive.data > 0).astype(np.int8)
        positive.eliminate_zeros()
        return positive.T.tocsr()

    def chain(self, choice: np.ndarray) -> sp.csr_matrix:
        """[states x states] the Markov chain of a memoryless strategy (`choice`: a global
        choice index per state; the rows of states without a choice are empty)."""
        has = self.counts > 0
        rows = np.where(has, choice, 0)
        chain = self.matrix[rows]
        if not has.all():
            chain = sp.diags(has.astype(float)) @ chain
        return sp.csr_matrix(chain)

    def best(self, per_choice: np.ndarray, sense: float = 1.0) -> np.ndarray:
        """[states] the largest (sense 1) or smallest (sense -1) per-choice quantity of each
        state, times `sense`; -inf for states without a choice."""
        best = np.full(self.n_states, -np.inf)
        has = self.counts > 0
        best[has] = np.maximum.reduceat(sense * per_choice, self.group_start[:-1][has])
        return best

    def first_best(self, per_choice: np.ndarray, sense: float = 1.0) -> np.ndarray:
        """[states] the first choice of each state attaining `best` (-1 without a choice)."""
        top = self.best(per_choice, sense)
        return first_index(self.choice_state, self.n_states,
                           near_best(sense * per_choice, best=top[self.choice_state]))
