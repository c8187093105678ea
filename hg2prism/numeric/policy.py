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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hg2prism.numeric.chains import chain_reach
from hg2prism.numeric.model import ExplicitModel

FLOOR = 1e-14        # the least margin of a switch: above the rounding of a one-step value


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
                  max_rounds: int = 10_000) -> OptimalReach:
    """The maximal (or minimal) probability of reaching `target` on `model`, by policy
    iteration from the strategy `choice` (a global choice index per state; for the maximiser
    it must be proper, as an attractor strategy is, see the module docstring). `stop` states
    are absorbing with value 0 (their choices are ignored). Stops when no state gains more than
    the margin floor + 2 e (module docstring) or the largest gain is at most `tolerance`; after
    `max_rounds` evaluations it returns with `converged` False."""
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
