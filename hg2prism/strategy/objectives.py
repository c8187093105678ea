"""Timing-aware objectives for P1's strategy (docs/semantics.md §6 "Objectives"), computed on
the canonical hypergame MDP from Storm's Pmax values:

- "pmax" (the default): Pmax=? [F "goal"], ties among optimal moves broken by the discounted
  reach score (hg2prism.strategy.deceptive);
- "lexicographic": among the Pmax-optimal moves, the fewest expected steps until the episode
  ends (goal or failure); where that expectation is infinite whatever optimal moves P1 plays,
  the default's choice;
- "bounded": Pmax=? [F<=H "goal"], a strategy that depends on the number of steps taken.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hg2prism.numeric import (attractor, keep_or_first, min_expected_steps, near_best,
                              progress_choices)
from hg2prism.numeric.fastest import RELATIVE_TIE     # scores this close are tied, as for pmax
from hg2prism.progress import warn
from hg2prism.strategy.canonical import CanonicalMDP
from hg2prism.strategy.deceptive import optimal_choices

OBJECTIVES = ("pmax", "bounded", "lexicographic")
MAX_POLICY_ITERATIONS = 1000


def _pick(table: np.ndarray, preferred: np.ndarray, relative_tie: float, lowest: bool
          ) -> np.ndarray:
    """[n] per row of `table` ([n, action slots], NaN where a move is not allowed) the
    preferred move if it is within `relative_tie` of the row's best, else the first such move
    in slot order (the lowest value with `lowest`)."""
    score = np.where(np.isnan(table), np.inf if lowest else -np.inf, table)
    return keep_or_first(near_best(score, relative_tie, axis=1, relative=True, lowest=lowest),
                         preferred)


# ---------------------------------------------------------------------------------------------
# Lexicographic: Pmax first, then the fewest expected steps
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Lexicographic:
    action: np.ndarray          # [n] move of every non-absorbing canonical state (-1 absorbing)
    finite: np.ndarray          # [n] bool: some optimal strategy ends the episode surely
    expected: np.ndarray        # [n] least expected steps to the end (inf where not finite)


def lexicographic_actions(mdp: CanonicalMDP, values: np.ndarray,
                          default_action: np.ndarray) -> Lexicographic:
    """Among the Pmax-optimal moves, those that minimise the expected number of steps until
    the goal or a failure; ties go to the first action slot.

    A state is *finite* when some strategy using only optimal moves ends the episode with
    probability 1 from it (the greatest set of states from which the absorbing states can be
    reached using optimal moves that never leave the set). Elsewhere every optimal strategy
    has an infinite expected length, and the state keeps the default's move
    (`default_action`, the Pmax strategy's). Finite states use moves that stay finite, so the
    two parts never mix within an episode that has entered a finite state."""
    optimal = optimal_choices(mdp, values)
    absorbing = mdp.absorbing
    model = mdp.model
    finite = ~absorbing
    while True:
        # the optimal moves that never leave the finite states, and the states from which
        # they reach the absorbing ones (an attractor: rank > 0), until nothing changes
        inside = finite | absorbing
        allowed = optimal & finite[mdp.choice_state] & (np.bincount(
            mdp.entry_choice, weights=~inside[mdp.entry_target], minlength=len(optimal)) == 0)
        rank = attractor(model, absorbing, allowed=allowed)
        now = rank > 0
        if (now == finite).all():
            break
        finite = now

    # Policy iteration for the expected steps on the finite states (numeric core), from the
    # proper strategy of the attractor (each move gets one rank closer with positive
    # probability).
    states = np.flatnonzero(finite)
    first = progress_choices(model, rank, allowed)
    steps = min_expected_steps(mdp.model, states, allowed, first, MAX_POLICY_ITERATIONS)
    if not steps.converged:
        warn(f"the lexicographic objective's policy iteration stopped after "
             f"{MAX_POLICY_ITERATIONS} rounds: its moves are Pmax-optimal, but may not take "
             f"the fewest expected steps")
    expected = steps.values.copy()
    # Final moves: the first of the (numerically) best, so that exact ties follow move order.
    action = default_action.copy()
    if len(states):
        table = mdp.by_state(np.where(allowed, 1.0 + mdp.matrix() @ expected, np.nan))
        action[states] = _pick(table[states], np.full(len(states), -1), 1e-9, lowest=True)
    expected[~finite & ~absorbing] = np.inf
    return Lexicographic(action=action, finite=finite, expected=expected)


# ---------------------------------------------------------------------------------------------
# Step-bounded: Pmax=? [F<=H "goal"]
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Bounded:
    bound: int
    actions: np.ndarray         # [H, n] int8: P1's move after t steps (t = 0..H-1)
    value: float                # Pmax=? [F<=H "goal"] at the initial state
    move_values: np.ndarray     # [n, action slots] each move's P(goal within H steps) at t = 0

    def action_at(self, t: int) -> np.ndarray:
        return self.actions[t].astype(np.int64)

    def schedules(self) -> list[list]:
        """Per canonical state, its moves over t = 0..H-1 as runs [first t, last t, action
        slot] (strategy.json names the actions: records.RecordExtras)."""
        changes = np.flatnonzero(np.diff(self.actions, axis=0).any(axis=1)) + 1
        starts = np.r_[0, changes]
        ends = np.r_[changes - 1, self.bound - 1]
        block = self.actions[starts].T.tolist()       # [n, blocks]
        schedules = []
        for row in block:
            runs: list[list] = []
            for first, last, a in zip(starts.tolist(), ends.tolist(), row):
                if a < 0:
                    continue
                if runs and runs[-1][2] == a:
                    runs[-1][1] = last
                else:
                    runs.append([first, last, a])
            schedules.append(runs)
        return schedules


def bounded_actions(mdp: CanonicalMDP, default_action: np.ndarray, initial: int,
                    bound: int) -> Bounded:
    """Pmax=? [F<=bound "goal"] by backward induction, V_0 = [goal] and
    V_k(s) = max_a sum_s' P(s' | s, a) V_{k-1}(s'), and the strategy that, with k steps left,
    takes a maximising move: the default's move if it is within a relative 1e-12 of the best,
    else the first best in slot order."""
    matrix = mdp.matrix()
    goal = mdp.goal.astype(float)
    live = ~mdp.absorbing
    v = goal.copy()
    actions = np.full((bound, mdp.n), -1, dtype=np.int8)
    table = mdp.by_state(matrix @ v)
    for k in range(1, bound + 1):
        table = mdp.by_state(matrix @ v)
        pick = _pick(table, default_action, RELATIVE_TIE, lowest=False)
        actions[bound - k, live] = pick[live]
        best = table[np.arange(mdp.n), pick]
        v = np.where(live, best, goal)
    return Bounded(bound=bound, actions=actions, value=float(np.clip(v[initial], 0.0, 1.0)),
                   move_values=table)
