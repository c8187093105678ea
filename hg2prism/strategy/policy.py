"""P1's policies: the one interface every strategy of P1 implements (docs/semantics.md §6).

A policy answers "which move does P1 play in the hypergame state (v, q, M)?": v the TS state,
q the task DFA's state after reading v's label, M P1's model of P2's memory. The simulation,
the detection experiment, re-planning and the value of deception ask P1 for its moves through
this interface only, so any of the package's strategies can be played, evaluated or used as a
fallback there:

* `records.Strategy`: the deceptive strategy read from strategy.json (and the robust one,
  whose records have the same format, docs/semantics.md §13);
* `stepped.SteppedStrategy`: the step-bounded objective's strategy, on (v, q, (M, t));
* `deception_value.NaiveStrategy`: the leader-game answer to the trap set in force (§11);
* `ProductPolicy`: a strategy that reads only (v, q) and ignores M: the leader game's P1
  (`simulation.LeaderStrategy`, the "leader" fallback of §14) and V_static's P1
  (`deception_value.StaticValue.policy`, §11).

Policies are deterministic: the same state always gets the same move (the simulation and the
induced chains memoise moves per state).
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from hg2prism.model.product import product_state

__all__ = ["Policy", "ProductPolicy"]


@runtime_checkable
class Policy(Protocol):
    """P1's deterministic strategy on hypergame states (v, q, M)."""

    def action(self, ts_state: int, q: int, memory: Hashable) -> int:
        """P1's move, its action slot at `ts_state` (ts.action_names), in the hypergame state
        (`ts_state`, `q`, `memory`). May raise records.StrategyError for a state the
        strategy does not cover."""


class ProductPolicy:
    """A policy on the product TS x DFA: one move per product state g = s * n_q + q (the
    convention of model.product), whatever P2's memory. `answers` holds the moves [G];
    `n_actions` the action slots per state (the TS's A1max) its mixed form ranges over."""

    def __init__(self, answers: Sequence[int] | np.ndarray, n_q: int, n_actions: int = 0) -> None:
        self.answers = [int(a) for a in np.asarray(answers).reshape(-1).tolist()]
        self.n_q = int(n_q)
        self.n_actions = max(int(n_actions), max(self.answers, default=-1) + 1)

    def action(self, ts_state: int, q: int, memory: Hashable) -> int:
        return self.answers[product_state(ts_state, q, self.n_q)]

    def mixed(self) -> np.ndarray:
        """[G, n_actions] the policy as a (degenerate) mixed strategy over P1's action slots
        (ts.n_actions), one row per product state: what simulation.simulate_nash and
        exact_completion play."""
        return np.eye(self.n_actions)[self.answers]
