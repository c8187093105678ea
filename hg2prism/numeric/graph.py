"""Graph analysis of explicit models: which states have a path into a set, attractors, and end
components."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph

from hg2prism.numeric.model import ExplicitModel
from hg2prism.numeric.tables import ranges
from hg2prism.numeric.ties import first_index


def _reversed(rows: np.ndarray, columns: np.ndarray, sources: np.ndarray, n: int
              ) -> sp.csr_matrix:
    """The edges rows[i] -> columns[i] reversed, and an extra node n with an edge to every
    source: a search from n along it goes backwards from all the sources at once (32-bit
    indices where they fit: Storm-sized graphs)."""
    index = np.int32 if n < 2 ** 31 - 1 else np.int64
    return sp.csr_matrix(
        (np.ones(rows.size + sources.size, dtype=np.int8),
         (np.concatenate([columns, np.full(sources.size, n)]).astype(index, copy=False),
          np.concatenate([rows, sources]).astype(index, copy=False))),
        shape=(n + 1, n + 1))


def backward_distance(rows: np.ndarray, columns: np.ndarray, sources: np.ndarray, n: int
                      ) -> np.ndarray:
    """[n] the fewest edges (rows[i] -> columns[i]) from each state into `sources` (indices),
    inf where there is no path."""
    return csgraph.dijkstra(_reversed(rows, columns, sources, n), directed=True, indices=n,
                            unweighted=True)[:n] - 1.0


def backward_reach(rows: np.ndarray, columns: np.ndarray, sources: np.ndarray, n: int
                   ) -> np.ndarray:
    """[n] bool: the states with a path (along the edges rows[i] -> columns[i]) into `sources`
    (indices): a breadth-first search along the reversed edges from all the sources at once."""
    reverse = _reversed(rows, columns, sources, n)
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


def attractor(model: ExplicitModel, target: np.ndarray, every: bool | np.ndarray = False,
              stop: np.ndarray | None = None, allowed: np.ndarray | None = None) -> np.ndarray:
    """The positive attractor of `target`: rank[s] is the least k such that from s some choice
    (every choice, where `every` holds: a bool or a mask over states) has a positive chance of
    entering the states of rank < k; rank 0 on the target, -1 outside. Only the `allowed`
    choices count (all by default); `stop` states and states without an allowed choice never
    enter.

    Breadth-first from the target over the choices' predecessor lists, so each choice is
    looked at once per successor that enters, not once per level."""
    n = model.n_states
    if allowed is None:
        choices = model.counts
        fresh = np.ones(model.n_choices, dtype=bool)       # a choice counts once, when it hits
    else:
        choices = np.zeros(n, dtype=np.int64)
        has = model.counts > 0
        choices[has] = np.add.reduceat(allowed.astype(np.int64), model.group_start[:-1][has])
        fresh = allowed.copy()
    every = np.broadcast_to(every, (n,))
    candidate = ~target & (choices > 0)
    if stop is not None:
        candidate &= ~stop
    start, choice_of, owner = (model.predecessors.indptr, model.predecessors.indices,
                               model.choice_state)
    hits = np.zeros(n, dtype=np.int64)      # distinct choices of a state that hit, if `every`
    scratch = np.empty(n, dtype=np.int64)
    rank = np.where(target, 0, -1)
    frontier = np.flatnonzero(target)
    level = 0
    while frontier.size:
        level += 1
        lengths = start[frontier + 1] - start[frontier]
        found = choice_of[ranges(start[frontier], lengths)]
        found = found[fresh[found]]
        fresh[found] = False
        states = owner[found]
        keep = candidate[states] & (rank[states] < 0)
        found, states = found[keep], states[keep]
        counted = every[states]
        np.add.at(hits, owner[np.unique(found[counted])], 1)
        enter = states[~counted | (hits[states] >= choices[states])]
        # distinct, without sorting: each state's last position wins a scatter of positions
        order = np.arange(enter.size)
        scratch[enter] = order
        frontier = enter[scratch[enter] == order]
        rank[frontier] = level
    return rank


def progress_choices(model: ExplicitModel, rank: np.ndarray,
                     allowed: np.ndarray | None = None) -> np.ndarray:
    """Per state of rank > 0 (an `attractor`'s ranks), its first allowed choice (in choice
    order) with a positive chance of entering a lower rank; -1 elsewhere."""
    graph = model.matrix
    entries = np.repeat(np.arange(model.n_choices), np.diff(graph.indptr))
    into = rank[graph.indices]
    closer = (graph.data > 0) & (into >= 0) & (into < rank[model.choice_state[entries]])
    good = np.zeros(model.n_choices, dtype=bool)
    good[entries[closer]] = True
    if allowed is not None:
        good &= allowed
    return first_index(model.choice_state, model.n_states, good)


def end_components(model: ExplicitModel, inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The maximal end components of `model` within the states `inside`: sets of states with
    choices that never leave the set and that let every state of it reach every other (Baier
    and Katoen, Principles of Model Checking, algorithm 47). Returns (component [states]: the
    component's label, -1 for a state in none; internal [choices]: the choice stays in its
    state's component). Strongly connected sets of the choices that stay inside, then the
    choices that leave their set are dropped, until nothing changes."""
    matrix = model.matrix
    owner = model.choice_state
    entry = np.repeat(np.arange(model.n_choices), np.diff(matrix.indptr))
    positive = matrix.data > 0
    entry, column = entry[positive], matrix.indices[positive]
    leaves = np.bincount(entry[~inside[column]], minlength=model.n_choices)
    internal = inside[owner] & (leaves == 0) & (np.bincount(entry, minlength=model.n_choices) > 0)
    n = model.n_states
    while True:
        kept = internal[entry]
        graph = sp.csr_matrix((np.ones(int(kept.sum()), dtype=np.int8),
                               (owner[entry[kept]], column[kept])), shape=(n, n))
        _, label = csgraph.connected_components(graph, directed=True, connection="strong")
        apart = np.bincount(entry[label[column] != label[owner[entry]]],
                            minlength=model.n_choices)
        narrower = internal & (apart == 0)
        if (narrower == internal).all():
            break
        internal = narrower
    member = np.zeros(n, dtype=bool)
    member[owner[internal]] = True
    return np.where(member, label, -1), internal


def downstream_first(successor: np.ndarray) -> list[list[int]]:
    """The strongly connected sets of a small graph (successor[i] the nodes i has an edge to),
    each listed after every set it can reach: the order in which values that flow backwards
    along the edges (reachability) can be computed one set at a time."""
    n = successor.shape[0]
    reach = np.eye(n, dtype=bool)
    reach[np.repeat(np.arange(n), successor.shape[1]), successor.reshape(-1)] = True
    for k in range(n):                                                # transitive closure
        reach |= reach[:, k:k + 1] & reach[k:k + 1, :]
    done = np.zeros(n, dtype=bool)
    order: list[list[int]] = []
    while not done.all():
        for i in np.flatnonzero(~done):
            if done[i]:
                continue
            same = reach[i] & reach[:, i]
            if not (reach[i] & ~same & ~done).any():                  # all it reaches is done
                order.append([int(j) for j in np.flatnonzero(same)])
                done |= same
    return order


def move_predecessors(successor: np.ndarray, probability: np.ndarray,
                      only: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(moves, start, pairs) of a game given as outcome tables successor/probability
    [G, A1, A2, K]: moves[start[t]:start[t + 1]] are the moves (g, a1, a2), as flat indices
    into [G, A1, A2], with a positive chance of entering state t, in increasing order; only the
    moves of the mask `only` [G, A1, A2] (all by default). pairs[i] is the (g, a2) of moves[i],
    as a flat index into [G, A2]."""
    outcomes = successor.shape[-1]
    positive = probability > 0
    if only is not None:
        positive &= only[..., None]
    positive = np.flatnonzero(positive.reshape(-1))
    target = successor.reshape(-1)[positive]
    order = stable_order(target, successor.shape[0])
    start = np.r_[0, np.cumsum(np.bincount(target, minlength=successor.shape[0]))]
    moves = positive[order] // outcomes
    n_a1, n_a2 = successor.shape[1:3]
    return moves, start, moves // (n_a1 * n_a2) * n_a2 + moves % n_a2


def stable_order(keys: np.ndarray, bound: int) -> np.ndarray:
    """np.argsort(keys, kind="stable") for integer keys in 0..bound-1, as a radix sort on
    16-bit digits (numpy sorts 16-bit integers by counting, several times faster than its
    merge sort of wider ones)."""
    digits = np.uint16
    order = np.argsort(keys.astype(digits), kind="stable")
    shift = 16
    while bound > 1 << shift:
        digit = (keys[order] >> shift).astype(digits)
        order = order[np.argsort(digit, kind="stable")]
        shift += 16
    return order


def alternating_attractor(predecessors: tuple[np.ndarray, ...], shape: tuple[int, int, int],
                          target: np.ndarray, free: np.ndarray, allowed: np.ndarray,
                          actions: np.ndarray | None = None) -> np.ndarray:
    """The positive attractor of `target` in a turn-based game where the opponent moves first
    (docs/semantics.md §4): rank[g] is the least k such that for every allowed opponent action
    a2 (`allowed` [G, A2]) some move a1 (of `actions` [G, A1, A2], all by default) has a
    positive chance of entering the states of rank < k; rank 0 on the target, -1 outside; only
    `free` states enter. `predecessors` are the game's `move_predecessors`, `shape` (G, A1, A2).

    The alternating form of `attractor` (there: some, or every, choice of a state), kept apart
    because its quantifiers pair up per a2 and because it runs dozens of times per game on
    products of 10^5 states: breadth-first from the target over the predecessor moves, so each
    move is looked at once per state that enters, not once per level. A pair (g, a2) is marked
    once one of its moves enters (or when a2 is not allowed): g enters with all its pairs
    marked. Few numpy calls a level: on small games the levels' calls are the time."""
    moves, start, pairs = predecessors
    size, n_a1, n_a2 = shape
    allowed_moves = None if actions is None else actions.reshape(-1)
    counts = np.diff(start)
    hit = ~allowed                                   # [G, A2] the pair has a move that enters
    hit_pairs = hit.reshape(-1)
    open_ = free & ~target                           # may still enter
    rank = np.where(target, 0, -1)
    frontier = np.flatnonzero(target)
    level = 0
    while frontier.size:
        level += 1
        at = ranges(start[frontier], counts[frontier])
        found = pairs[at] if allowed_moves is None else pairs[at[allowed_moves[moves[at]]]]
        hit_pairs[found] = True
        # sorted distinct states by marking: numpy's hash-based unique is several times slower
        marked = np.zeros(size, dtype=bool)
        marked[found // n_a2] = True
        marked &= open_
        candidates = np.flatnonzero(marked)
        frontier = candidates[hit[candidates].all(axis=1)]
        rank[frontier] = level
        open_[frontier] = False
    return rank
