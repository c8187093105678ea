"""Graph analysis of explicit models: which states have a path into a set, and attractors."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph

from hg2prism.numeric.model import ExplicitModel


def backward_reach(rows: np.ndarray, columns: np.ndarray, sources: np.ndarray, n: int
                   ) -> np.ndarray:
    """[n] bool: the states with a path (along the edges rows[i] -> columns[i]) into `sources`
    (indices): a breadth-first search from an extra node n, linked to every source, along
    reversed edges."""
    reverse = sp.csr_matrix(
        (np.ones(rows.size + sources.size, dtype=np.int8),
         (np.concatenate([columns, np.full(sources.size, n)]), np.concatenate([rows, sources]))),
        shape=(n + 1, n + 1))
    found = np.zeros(n + 1, dtype=bool)
    found[csgraph.breadth_first_order(reverse, n, directed=True,
                                      return_predecessors=False)] = True
    return found[:n]


def edges(matrix: sp.csr_matrix, free: np.ndarray, owner: np.ndarray | None = None
          ) -> tuple[np.ndarray, np.ndarray]:
    """The edges (source state, successor) of the positive entries of `matrix` whose row
    belongs to a `free` state: row i belongs to state owner[i] (to state i by default)."""
    rows = np.repeat(np.arange(matrix.shape[0]), np.diff(matrix.indptr))
    if owner is not None:
        rows = owner[rows]
    edge = free[rows] & (matrix.data > 0)
    return rows[edge], matrix.indices[edge]


def can_reach(model: ExplicitModel, target: np.ndarray, stop: np.ndarray | None = None
              ) -> np.ndarray:
    """[n] bool: the states of `model` from which some sequence of choices reaches `target`
    with positive probability (the target among them) without passing a `stop` state (the
    choices of target and stop states are ignored)."""
    free = ~target if stop is None else ~(target | stop)
    rows, columns = edges(model.matrix, free, model.choice_state)
    return backward_reach(rows, columns, np.flatnonzero(target), model.n_states)


def attractor(model: ExplicitModel, target: np.ndarray, every: bool = False,
              stop: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The positive attractor of `target`, level by level: rank[s] is the least k such that from
    s some (every, with `every`) choice of s has a positive chance of entering the states of
    rank < k; rank 0 on the target, -1 outside the attractor. `stop` states never enter
    (their choices are ignored), nor do states without a choice. Also returns, per state of
    rank > 0, its first choice (in choice order) with an edge into a lower rank, else -1.

    Level by level, each choice is looked at once per level; the models here are solved in a
    handful of levels per state layer, so this stays far below the cost of the solves."""
    n = model.n_states
    rank = np.where(target, 0, -1)
    progress = np.full(n, -1, dtype=np.int64)
    candidate = ~target & (model.counts > 0)
    if stop is not None:
        candidate &= ~stop
    graph = model.matrix.copy()
    graph.data = (graph.data > 0).astype(float)
    owner = model.choice_state
    for level in range(1, n + 1):
        closer = (graph @ (rank >= 0).astype(float)) > 0                # [choices]
        hits = np.bincount(owner, weights=closer, minlength=n)
        new = candidate & (rank < 0) & ((hits == model.counts) if every else (hits > 0))
        if not new.any():
            break
        first = np.flatnonzero(closer & new[owner])[::-1]
        progress[owner[first]] = first          # reversed: each state's first choice wins
        rank[new] = level
    return rank, progress
