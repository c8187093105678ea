"""Certified maximal reachability on an MDP (docs/semantics.md §10, "certified"): a memoryless
strategy from a fast, unsound solver is evaluated exactly and improved until its value is a fixed
point of the Bellman operator.

Why this certifies: the value x of a strategy of the maximiser is at most the optimal value V;
V is the least fixed point of the Bellman operator T, so T(x) = x gives V <= x, hence x = V. The
strategy's value is computed exactly on its induced Markov chain: the states that cannot reach the
target in the chain get 0 by graph analysis (so the chain's linear system has a unique solution,
and x is the chain's least solution, not merely some solution), the others by a sparse direct
solve (hg2prism/numeric). Both checks are made in floating point with the tolerances below.

numpy and scipy only: engines/storm.py supplies the model's arrays and the first strategy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hg2prism.numeric import ExplicitModel, chain_reach, first_index, near_best, optimal_reach
from hg2prism.numeric.graph import backward_distance

BELLMAN_RESIDUAL = 1e-11   # max_a Q(s, a) - x(s) on every state: x is a fixed point of T
LINEAR_ERROR = 1e-11       # bound on the error of the chain's solve: x is the strategy's value
IMPROVEMENT = 1e-12        # a state switches only when another choice is better by more (plus
                           # twice the evaluation's error bound: numeric/policy.py)
MAX_ROUNDS = 30            # strategy-improvement rounds before giving up
SLACK = 1e-6               # choices this close to the best by the fast solver's values are good


@dataclass(frozen=True, eq=False)
class Certificate:
    """The outcome of `certify_reachability`: `values` are certified only if `certified`."""

    certified: bool
    values: np.ndarray          # the last strategy's exact value of every state
    choice: np.ndarray          # the last strategy: a global choice index per state
    bellman_residual: float     # max over states of max_a Q(s, a) - x(s)
    linear_error: float         # bound on the error of the strategy's evaluation
    rounds: int                 # strategy evaluations made
    reason: str                 # why not certified ("" when certified)


def initial_strategy(matrix: sp.csr_matrix, group_start: np.ndarray, target: np.ndarray,
                     estimate: np.ndarray, slack: float = SLACK) -> np.ndarray:
    """A strategy (a global choice index per state) from approximate values: among the choices
    within `slack` of the best by `estimate`, the first that maximises the probability of moving
    strictly closer to the target, distances counted in the graph of those choices' edges.
    Greedy choices alone may stall where several look equally good (a choice that stays put
    keeps the value), and a choice that moves closer only through an unlikely outcome makes
    the strategy's chain slow and badly conditioned: either costs a round of improvement."""
    n = len(target)
    counts = np.diff(group_start)
    source = np.repeat(np.arange(n), counts)
    q = matrix @ estimate
    best = np.full(n, -np.inf)
    best[counts > 0] = np.maximum.reduceat(q, group_start[:-1][counts > 0])
    good = near_best(q, slack, best=best[source])
    # only the entries of good choices of non-target states matter below
    useful = good & ~target[source]
    per_choice = np.diff(matrix.indptr)
    kept = np.repeat(useful, per_choice)
    kept &= matrix.data > 0
    distance = _distance_to_target(matrix, source, np.flatnonzero(kept), target)
    # the mass of each choice's entries that move strictly closer
    closer = distance[matrix.indices] < np.repeat(distance[source], per_choice)
    closer &= kept
    del kept
    moving = np.flatnonzero(closer)
    del closer
    mass = np.bincount(np.searchsorted(matrix.indptr, moving, side="right") - 1,
                       weights=matrix.data[moving], minlength=matrix.shape[0])
    score = np.where(good, mass, -1.0)
    top = np.full(n, -np.inf)
    top[counts > 0] = np.maximum.reduceat(score, group_start[:-1][counts > 0])
    return first_index(source, n, near_best(score, best=top[source]))


def _distance_to_target(matrix: sp.csr_matrix, source: np.ndarray, entries: np.ndarray,
                        target: np.ndarray) -> np.ndarray:
    """[states] the fewest steps to the target along `entries` (edges source -> successor of
    the matrix's entries), inf where there is none (numeric.graph.backward_distance)."""
    columns = matrix.indices[entries]
    rows = source[np.searchsorted(matrix.indptr, entries, side="right") - 1]
    return backward_distance(rows, columns, np.flatnonzero(target), len(target))


def certify_reachability(matrix: sp.csr_matrix, group_start: np.ndarray, target: np.ndarray,
                         choice: np.ndarray, max_rounds: int = MAX_ROUNDS) -> Certificate:
    """Maximal probability of reaching `target` on the MDP `matrix` (choices of state s are rows
    group_start[s]..group_start[s+1]-1), certified from the first strategy `choice` (a global
    choice index per state) by strategy improvement (`numeric.optimal_reach`: evaluate exactly,
    switch every state whose best choice beats its value by more than IMPROVEMENT plus twice the
    evaluation's error bound) until x is a fixed point of T within BELLMAN_RESIDUAL
    (certified) or `max_rounds` evaluations have been made (not certified)."""
    model = ExplicitModel(matrix=matrix, group_start=np.asarray(group_start, dtype=np.int64))
    found = optimal_reach(model, target, choice, floor=IMPROVEMENT, tolerance=BELLMAN_RESIDUAL,
                          max_rounds=max_rounds)
    values, choice, linear, bellman = found.values, found.choice, found.error, found.residual
    if bellman <= BELLMAN_RESIDUAL and linear > LINEAR_ERROR:
        # an ill-conditioned chain (world1 with a drawing Bayesian observer: a bound of 8.8e-10):
        # the same strategy again, its solve refined in extended precision
        precise = chain_reach(model.chain(choice), target, precise=True)
        gain = model.best(matrix @ precise.values, 1.0) - precise.values
        values, linear = precise.values, precise.error
        bellman = float(np.where(model.counts > 0, gain, 0.0)[~target].max(initial=0.0))
    if bellman > BELLMAN_RESIDUAL:
        return Certificate(False, values, choice, bellman, linear, found.rounds,
                           f"not a fixed point after {found.rounds} strategy evaluations "
                           f"(Bellman residual {bellman:.1e})")
    # (a strategy still to improve may stall, with a badly conditioned chain: only the last
    # one's error matters)
    if linear > LINEAR_ERROR:
        return Certificate(False, values, choice, bellman, linear, found.rounds,
                           f"the strategy's linear solve may be off by {linear:.1e}")
    if values.min(initial=0.0) < -1e-9 or values.max(initial=0.0) > 1 + 1e-9:
        return Certificate(False, values, choice, bellman, linear, found.rounds,
                           "values outside [0, 1]")
    return Certificate(True, values, choice, bellman, linear, found.rounds, "")
