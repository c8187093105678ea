"""Exact numbers of Markov chains: reachability probabilities with a bound on their rounding
error, bounded reachability and expected numbers of steps.

Every solve is of a system (I - A) x = b with A >= 0 substochastic and I - A regular (graph
analysis first removes the states that make it singular). Then (I - A)^-1 is nonnegative (its
entries are expected visits), so the error of a computed x is at most (I - A)^-1 |b - (I - A) x|
state by state, which the same LU factorisation gives: `solve_m_matrix` returns that bound."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse import csgraph

from hg2prism.numeric.graph import backward_reach, edges

CONVERGED = 1e-12   # a bounded probability this close to the unbounded one is taken as final


@dataclass(frozen=True, eq=False)
class ChainValue:
    """Reachability probabilities of a chain and a bound on their floating-point error."""

    values: np.ndarray      # [n] probability of reaching the target from each state
    error: float            # max over states of the bound on |values - exact|


def solve_plain(system: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """x with system @ x = rhs by one sparse LU solve, without refinement or error bound: for
    the inner rounds of a strategy iteration whose result is certified afterwards (P2's games
    by their Bellman residual and attractor check, the expected-steps iteration of the
    lexicographic objective by its improvement test), where a round costs one factorisation."""
    return np.atleast_1d(spla.spsolve(sp.csc_matrix(system), rhs))


def solve_m_matrix(system: sp.spmatrix, rhs: np.ndarray, precise: bool = False
                   ) -> tuple[np.ndarray, float]:
    """x with system @ x = rhs for system = I - A (A >= 0, I - A regular), by a sparse LU
    factorisation and one step of iterative refinement, and the bound on the error of x
    (module docstring). `precise`: two steps of refinement with the residuals in extended
    precision (np.longdouble: a 64-bit mantissa on x86), for a chain left with probability
    1e-10 from some states, where the double solve's bound is 1e-9 or more."""
    system = sp.csc_matrix(system)
    factor = spla.splu(system)
    x = factor.solve(rhs)
    if precise:
        return _refined(system, rhs, x, factor)
    x += factor.solve(rhs - system @ x)                          # one step of refinement
    # (I - A)^-1 is nonnegative, so the error is at most (I - A)^-1 |residual| state by state;
    # the computed residual itself is off by at most gamma (|I - A| |x| + |b|) in each row,
    # gamma = (entries in the row + 1) * unit roundoff, which is added so that the bound holds
    # on ill-conditioned chains too (a class left with probability 1e-9 multiplies it by 1e9)
    residual = np.abs(rhs - system @ x)
    size = sp.csr_matrix(system)
    gamma = (np.diff(size.indptr) + 1) * (np.finfo(float).eps / 2)
    residual += gamma * (abs(size) @ np.abs(x) + np.abs(rhs))
    error = factor.solve(residual)
    return x, float(np.abs(error).max(initial=0.0))


def _refined(system: sp.csc_matrix, rhs: np.ndarray, x: np.ndarray, factor
             ) -> tuple[np.ndarray, float]:
    """solve_m_matrix's refinement and bound, the residuals in extended precision."""
    wide = sp.csr_matrix(system, dtype=np.longdouble)
    b = rhs.astype(np.longdouble)
    refined = x.astype(np.longdouble)
    for _ in range(2):
        refined += factor.solve((b - wide @ refined).astype(float))
    gamma = (np.diff(wide.indptr) + 1) * (np.finfo(np.longdouble).eps / 2)
    residual = np.abs(b - wide @ refined) + gamma * (abs(wide) @ np.abs(refined) + np.abs(b))
    x = refined.astype(float)
    # the bound of the extended solution, and its rounding to double (half an ulp)
    error = factor.solve(residual.astype(float)) + np.abs(x) * (np.finfo(float).eps / 2)
    return x, float(np.abs(error).max(initial=0.0))


def chain_reach(chain: sp.csr_matrix, target: np.ndarray, absorbing: np.ndarray | None = None,
                precise: bool = False) -> ChainValue:
    """The exact probability of reaching `target` (a mask) from every state of the Markov
    chain `chain` [n x n] (the rows of the target and of the `absorbing` states are ignored:
    those states stay where they are), and a bound on its floating-point error.

    Graph analysis first: 0 where the chain cannot reach the target, 1 where it cannot reach
    those states without passing the target (so the linear system has a unique solution, the
    chain's least one, and no state of value 1 sits in it, where long cycles would make it
    ill-conditioned). The rest by `solve_m_matrix` (`precise`: in extended precision)."""
    n = len(target)
    free = ~target if absorbing is None else ~(target | absorbing)
    rows, columns = edges(chain, free)
    reaches = backward_reach(rows, columns, np.flatnonzero(target), n)
    zero = ~target & ~reaches
    sure = free & ~backward_reach(rows, columns, np.flatnonzero(zero), n)
    del rows, columns         # (large chains: one copy of anything large during the solve)
    values = (target | sure).astype(float)
    solve = np.flatnonzero(free & reaches & ~sure)
    if solve.size == 0:
        return ChainValue(values, 0.0)
    sub = chain[solve]
    rhs = sub @ values                                           # one step out, weighted
    system = sp.identity(solve.size, format="csr") - sub[:, solve]
    del sub
    x, error = solve_m_matrix(system, rhs, precise)
    values[solve] = x
    return ChainValue(values, error)


def bounded_reach(chain: sp.csr_matrix, goal: np.ndarray, stop: np.ndarray, start: int,
                  horizon: int) -> float:
    """P(goal within `horizon` steps) from `start` in the Markov chain `chain`: the probability
    that a path from `start` enters a `goal` state after at most `horizon` transitions (with
    horizon 0: 1.0 at a goal state, else 0.0). The `stop` states are absorbing and must
    include the goal: their rows are ignored, and so are entries of probability 0 (no path
    goes through them). The one implementation of bounded reachability on an explicit chain
    (docs/architecture.md, "One place per concept").

    Backward iteration from x_0 = [goal]: x_k = x_{k-1} on `stop` and chain @ x_{k-1}
    elsewhere (one sparse product per step, each row summed in the chain's stored order, the
    order of the numbers written to results.json, whose last bits another order changes). The
    k-step probabilities increase towards the unbounded one, computed exactly first
    (`chain_reach`); the iteration stops at the horizon or at the first k whose probability is
    within CONVERGED of it, so a horizon of millions of steps costs only what convergence
    needs, and the value returned is below the horizon's by at most CONVERGED plus the
    unbounded solve's rounding error."""
    if (goal & ~stop).any():
        raise ValueError("bounded_reach: every goal state must be a stop state")
    chain = sp.csr_matrix(chain, copy=True)
    chain.eliminate_zeros()       # an edge of probability 0 must not count as a path
    limit = float(chain_reach(chain, goal, stop).values[start])
    reach = goal.astype(float)
    for _ in range(horizon):
        reach = np.where(stop, goal.astype(float), chain @ reach)
        if reach[start] >= limit - CONVERGED:
            break
    return float(reach[start])


@dataclass(frozen=True)
class Steps:
    """Expected numbers of steps of a chain from its initial state."""

    goal_probability: float        # P(F "goal")
    to_end: float | None           # E[steps until an absorbing state]; None if infinite
    to_goal: float | None          # E[steps | the goal is reached]; None if it is never reached


def expected_steps(chain: sp.csr_matrix, initial: int, goal: np.ndarray,
                   absorbing: np.ndarray) -> Steps:
    """P(F goal), the expected steps until an `absorbing` state (goal among them), and the
    expected steps to the goal given that it is reached (docs/semantics.md §6 "Timing"), by
    sparse linear solves over the states the initial state reaches, with one LU
    factorisation."""
    if absorbing[initial]:
        hit = bool(goal[initial])
        return Steps(float(hit), 0.0, 0.0 if hit else None)
    reached = np.zeros(len(goal), dtype=bool)
    reached[csgraph.breadth_first_order(chain, initial, directed=True,
                                        return_predecessors=False)] = True
    transient = np.flatnonzero(reached & ~absorbing)
    rows = chain[transient]
    inner = rows[:, transient]
    to_goal = np.asarray(rows[:, np.flatnonzero(goal)].sum(axis=1)).ravel()
    exits = np.asarray(rows[:, np.flatnonzero(absorbing)].sum(axis=1)).ravel()
    s0 = int(np.searchsorted(transient, initial))

    # Every state here is reached from the initial state with positive probability, so the
    # expected time is finite iff each of them can reach an absorbing state; then I - P is
    # invertible on all of them. Otherwise P(F goal) and the steps to the goal are solved on
    # the states that can reach the goal, where it is invertible too.
    edges = inner.tocoo()
    ends = backward_reach(edges.row, edges.col, np.flatnonzero(exits > 0), len(transient))
    solve_on = (np.arange(len(transient)) if ends.all() else
                np.flatnonzero(backward_reach(edges.row, edges.col, np.flatnonzero(to_goal > 0),
                                              len(transient))))
    if s0 not in solve_on:      # the goal is unreachable
        return Steps(0.0, None, None)
    sub = inner[solve_on][:, solve_on] if len(solve_on) < len(transient) else inner
    lu = spla.splu(sp.identity(len(solve_on), format="csc") - sub.tocsc())
    at = int(np.searchsorted(solve_on, s0))
    reach = lu.solve(to_goal[solve_on])
    end = float(lu.solve(np.ones(len(solve_on)))[at]) if ends.all() else None
    probability = float(np.clip(reach[at], 0.0, 1.0))
    if probability <= 0.0:
        return Steps(probability, end, None)
    # E[T 1{goal}] = y with y = x + P y, x = P(F goal).
    weighted = float(lu.solve(reach)[at])
    return Steps(probability, end, weighted / probability)
