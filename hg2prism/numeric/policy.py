"""Optimal reachability on an explicit MDP by policy iteration with exact evaluation.

Termination, with floating point. Each round evaluates the current memoryless strategy exactly
up to a bound e on the error (`chains.chain_reach`), so every computed one-step value q(s, a) =
sum_s' P(s' | s, a) x(s') is within e (plus the rounding of the sum) of the exact one. (e is
computed with the evaluation's own LU factors and includes the rounding of the residual, which
dominates on ill-conditioned chains: where P2's mixed strategy plays a set with probability
2e-9, as on maze 113 of tests/mazegen.py, e reaches 1e-6.) A state switches only when its best
choice beats its current value by more than the margin `floor + 2 e`, with `floor` above the
summation's rounding: so every switch is a strict improvement in exact arithmetic, never a tie
that rounding made look better.

Then, for the maximiser, let C be a set of states the new strategy never leaves and that holds
no target state, and M the states of C of largest old value x. A switched state of M would
have q > x(s) with all its successors in C, of value at most x(s): impossible. So the states
of M keep their old choice, whose successors (in C, x(s) being their average) are all in M: M
is closed under the old strategy, which never reaches the target from it, so x = 0 on M, hence
on C, and no state of C switched (it would need a successor of positive value). The new
strategy's chain therefore ends, with probability 1, in the target or in sets where the old
value is 0; with T' its one-step operator, x <= T'(x) (equal where nothing switched), so its
value lim T'^k(x) is at least x, and strictly larger at every switched state. No strategy comes
back and the iteration stops after finitely many rounds (at most the number of memoryless
strategies). For the minimiser the states from which it can avoid the target surely are `stop`
states of value 0, so every strategy reaches the target or them with probability 1 from the
rest, and the same argument applies with the inequalities reversed. A margin of 1e-14 alone
did let the iteration cycle (issue 22, item 9): where values are within rounding of 1, a move
that stalls looked better by a few 1e-13, and on maze 113 the solve's error was 1e-6.

When it stops, no state gains more than the margin: the values are a fixed point of the
Bellman operator within `max(tolerance, margin)`.

Near-stalling strategies. The argument above keeps the maximiser out of sets it never leaves,
not out of sets it leaves with tiny probability: inside an end component (states the
maximiser can keep the play in and move between at will) every state has the same value, and
a strategy that walks back and forth and leaves only by a run of unlikely outcomes is as good,
in exact arithmetic, as one that heads for the best exit. Its chain is ill-conditioned (on the
two-trap delay-1 bench world, a walk left with probability about 1e-10 per step: an error bound
of 1.5e-6, and values 3.5e-7 above the optimum, above its real fixed point), and the margin
then hides real gains. With `collapse` the maximiser's iteration, when its last evaluation's
bound exceeds ILL_CONDITIONED, is run again on the quotient where each maximal end component
of the non-absorbing states is one node whose choices are its states' choices that leave it
(de Alfaro 1997; Baier and Katoen, Principles of Model Checking, 10.6.1). The quotient has no
end component outside the absorbing states, so every strategy of it reaches them with
probability 1, every one is proper, and the values are those of the model (a component's
states can reach each other surely, so each is worth its best exit). Back on the model, the
state of a component's chosen exit plays it and the others walk to that state by an attractor
strategy of the component's own choices. That walk may itself leave slowly (an attractor's
move only has a positive chance of getting closer), so the values returned are the
quotient's, which are the walk's exact values, with the quotient's error bound; the result is
the better-conditioned of the two.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import scipy.sparse as sp

from hg2prism.numeric.chains import chain_reach, solve_plain
from hg2prism.numeric.graph import attractor, end_components, progress_choices
from hg2prism.numeric.model import ExplicitModel

FLOOR = 1e-14        # the least margin of a switch: above the rounding of a one-step value
ILL_CONDITIONED = 1e-11   # an evaluation's error bound above which `collapse` solves the quotient


@dataclass(frozen=True, eq=False)
class OptimalReach:
    """The outcome of `optimal_reach`."""

    values: np.ndarray      # the last strategy's exact value of every state
    choice: np.ndarray      # the last strategy: a global choice index per state (-1: none)
    residual: float         # max over the non-absorbing states of the best choice's gain
    error: float            # bound on the error of the last evaluation
    rounds: int             # evaluations made
    converged: bool         # no state gains more than max(tolerance, the margin)


def optimal_reach(model: ExplicitModel, target: np.ndarray, choice: np.ndarray,
                  maximise: bool = True, stop: np.ndarray | None = None,
                  floor: float = FLOOR, tolerance: float = 0.0,
                  max_rounds: int = 10_000, collapse: bool = False) -> OptimalReach:
    """The maximal (or minimal) probability of reaching `target` on `model`, by policy
    iteration from the strategy `choice` (a global choice index per state; for the maximiser
    it must be proper, as an attractor strategy is, see the module docstring). `stop` states
    are absorbing with value 0 (their choices are ignored). Stops when no state gains more than
    the margin floor + 2 e (module docstring) or the largest gain is at most `tolerance`; after
    `max_rounds` evaluations it returns with `converged` False. `collapse` (the maximiser only):
    where the last evaluation's bound exceeds ILL_CONDITIONED, solve again on the quotient of the
    end components and keep the better-conditioned result (module docstring)."""
    found = _iterate(model, target, choice, maximise, stop, floor, tolerance, max_rounds)
    if collapse and maximise and found.error > ILL_CONDITIONED:
        collapsed = _on_quotient(model, target, choice, stop, floor, tolerance, max_rounds)
        if collapsed.converged and collapsed.error <= found.error:
            return collapsed
    return found


def _iterate(model: ExplicitModel, target: np.ndarray, choice: np.ndarray, maximise: bool,
             stop: np.ndarray | None, floor: float, tolerance: float,
             max_rounds: int) -> OptimalReach:
    """Policy iteration from `choice` (`optimal_reach`'s arguments)."""
    sense = 1.0 if maximise else -1.0
    absorbing = target if stop is None else target | stop
    active = ~absorbing & (model.counts > 0)
    choice = np.asarray(choice, dtype=np.int64).copy()
    values, error, residual = target.astype(float), 0.0, np.inf
    for rounds in range(1, max_rounds + 1):
        evaluated = chain_reach(model.chain(choice), target, stop)
        values, error = evaluated.values, evaluated.error
        q = model.matrix @ values
        gain = np.where(active, model.best(q, sense) - sense * values, 0.0)
        residual = float(gain.max(initial=0.0))
        improve = gain > floor + 2.0 * error
        if residual <= tolerance or not improve.any():
            return OptimalReach(values, choice, residual, error, rounds, True)
        choice[improve] = model.first_best(q, sense)[improve]
    return OptimalReach(values, choice, residual, error, max_rounds, False)


@dataclass(frozen=True, eq=False)
class ExpectedSteps:
    """The outcome of `min_expected_steps`."""

    values: np.ndarray      # [n] the least expected steps to the end on `states`, 0 elsewhere
    choice: np.ndarray      # [n] the last strategy (global choice indices) on `states`
    rounds: int
    converged: bool


def min_expected_steps(model: ExplicitModel, states: np.ndarray, allowed: np.ndarray,
                       choice: np.ndarray, max_rounds: int = 1000) -> ExpectedSteps:
    """The least expected number of steps until an absorbing state, on `states`, using only the
    `allowed` choices (a mask over choices), which must never leave `states` but for absorbing
    states, from a proper strategy `choice` (a global choice index for each of `states`: it
    ends the play with probability 1). Policy iteration with an exact evaluation (one sparse
    solve) per round; a state switches to its first best allowed choice when that beats its
    current one by more than 1e-12 relative: every switch of a proper strategy to a cheaper
    choice keeps it proper and lowers the values (stochastic shortest paths: Bertsekas and
    Tsitsiklis 1991), so it stops; `converged` False after `max_rounds` rounds."""
    matrix = model.matrix
    choice = np.asarray(choice, dtype=np.int64).copy()
    expected = np.zeros(model.n_states)
    per_choice = np.empty(0)
    for rounds in range(1, max_rounds + 1):
        system = sp.identity(len(states), format="csc") - matrix[choice[states]][:, states].tocsc()
        expected[:] = 0.0
        expected[states] = solve_plain(system, np.ones(len(states))) if len(states) else []
        per_choice = np.where(allowed, 1.0 + matrix @ expected, np.inf)
        current = per_choice[choice[states]]
        best = -model.best(per_choice, -1.0)[states]
        improve = best < current - 1e-12 * np.maximum(1.0, current)
        if not improve.any():
            return ExpectedSteps(expected, choice, rounds, True)
        choice[states[improve]] = model.first_best(per_choice, -1.0)[states[improve]]
    return ExpectedSteps(expected, choice, max_rounds, False)


def _on_quotient(model: ExplicitModel, target: np.ndarray, choice: np.ndarray,
                 stop: np.ndarray | None, floor: float, tolerance: float,
                 max_rounds: int) -> OptimalReach:
    """The maximiser's policy iteration on the quotient of the end components of the
    non-absorbing states (module docstring), its strategy brought back to `model` and evaluated
    there."""
    absorbing = target if stop is None else target | stop
    component, internal = end_components(model, ~absorbing & (model.counts > 0))
    labels, member = np.unique(component, return_inverse=True)   # -1 (none) first, if any
    alone = component < 0
    node = np.where(alone, np.cumsum(alone) - 1, alone.sum() + member - (labels[0] < 0))
    n_nodes = int(node.max(initial=-1)) + 1
    exits = np.flatnonzero(~internal)
    exits = exits[np.argsort(node[model.choice_state[exits]], kind="stable")]
    merge = sp.csr_matrix((np.ones(model.n_states), (np.arange(model.n_states), node)),
                          shape=(model.n_states, n_nodes))
    counts = np.bincount(node[model.choice_state[exits]], minlength=n_nodes)
    quotient = ExplicitModel(sp.csr_matrix(model.matrix[exits] @ merge),
                             np.r_[0, np.cumsum(counts)].astype(np.int64))
    on = np.zeros(n_nodes, dtype=bool)
    on[node[target]] = True
    off = None
    if stop is not None:
        off = np.zeros(n_nodes, dtype=bool)
        off[node[stop]] = True
    # every strategy of the quotient is proper: start from the first choices
    first = np.minimum(quotient.group_start[:-1], max(quotient.n_choices - 1, 0))
    solved = _iterate(quotient, on, first, True, off, floor, tolerance, max_rounds)
    if not solved.converged:
        return solved
    choice = np.asarray(choice, dtype=np.int64).copy()
    playing = quotient.counts[node] > 0
    chosen = exits[solved.choice[node[playing]]]                   # the node's exit, per state
    outside = playing & alone
    choice[outside] = chosen[alone[playing]]
    exit_states = model.choice_state[exits[solved.choice[quotient.counts > 0]]]
    choice[exit_states] = exits[solved.choice[node[exit_states]]]
    # the other states of a component walk to its exit's state along its own choices
    walk = np.zeros(model.n_states, dtype=bool)
    walk[exit_states] = True
    rank = attractor(model, walk & ~alone, allowed=internal)
    progress = progress_choices(model, rank, allowed=internal)
    inner = (rank > 0) & playing & ~alone
    choice[inner] = progress[inner]
    # The walk may leave slowly (it only has a positive chance of getting closer): its chain
    # can be as ill-conditioned as the one avoided, so the values are the quotient's, which
    # are the walk's exact values, with the quotient's error bound.
    values = solved.values[node]
    active = ~absorbing & (model.counts > 0)
    gain = np.where(active, model.best(model.matrix @ values, 1.0) - values, 0.0)
    residual = float(gain.max(initial=0.0))
    converged = residual <= tolerance or residual <= floor + 2.0 * solved.error
    return OptimalReach(values, choice, residual, solved.error, solved.rounds, converged)
