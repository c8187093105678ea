"""P1's deceptive strategy (docs/semantics.md §6), chosen on canonical hypergame states from the
values Storm computed: among the value-optimal moves, the fastest."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hg2prism.engines.engine import Transitions
from hg2prism.numeric import choices_taking
from hg2prism.numeric.fastest import SCORE_STOP, STORM_SLACK, fastest_first
from hg2prism.prism.decoding import DecodedStates
from hg2prism.strategy.canonical import CanonicalMDP


@dataclass(frozen=True, eq=False)
class StormChoices:
    """P1's deceptive strategy on canonical states: the chosen Storm choice of each."""

    representative: np.ndarray   # [n_canonical] a Storm state of each canonical state
    choice: np.ndarray           # [n_storm_states] global choice index P1 takes in each Storm state


# the fastest-first rule's slack (numeric/fastest.py)
OPTIMAL_SLACK = STORM_SLACK


def optimal_choices(mdp: CanonicalMDP, values: np.ndarray) -> np.ndarray:
    """[choices] bool: the Pmax-optimal moves (within OPTIMAL_SLACK of the state's value),
    among which every objective picks its move."""
    return mdp.choice_values(values) >= values[mdp.choice_state] - OPTIMAL_SLACK


def deceptive_actions(mdp: CanonicalMDP, values: np.ndarray) -> np.ndarray:
    """An optimal strategy that does not stall, computed on canonical states from Storm's
    values (`values`: [mdp.n] by canonical state): the move of every canonical state, -1 in
    absorbing ones.

    Storm's own scheduler is optimal in the limit but may dither (push into a wall) for a long
    time: on world1 it completes within 200 steps with probability 0.02 for a value of 0.95.
    Its copies of one canonical state (differing in the DFA's previous state) may also pick
    different optimal moves, which mixed together need not be optimal. Here every canonical
    state takes, among its value-optimal moves, the one that maximises the discounted
    probability of reaching the goal (lexicographically: value first, then speed).
    """
    optimal = optimal_choices(mdp, values)
    # Among optimal choices, prefer reaching the goal soon: the discounted probability
    # W(s) = max over optimal choices of E[DISCOUNT^steps; reach goal]. A choice that stalls
    # scores 0 there, so the greedy choice keeps moving, and every state of positive value
    # keeps a positive chance of reaching the goal: the strategy stays optimal.
    best = fastest_first(mdp.choice_state, mdp.entry_choice, mdp.entry_target, mdp.entry_prob,
                         mdp.goal, optimal, SCORE_STOP).choice
    del optimal
    action = np.full(mdp.n, -1, dtype=np.int64)
    action[best >= 0] = mdp.choice_action[best[best >= 0]]
    return action


def storm_choices(decoded: DecodedStates, moves: Transitions, representative: np.ndarray,
                  action: np.ndarray) -> StormChoices:
    """The Storm choices of a strategy given per canonical state (`action`, a move index; any
    value in absorbing states): every Storm state takes the move its canonical state takes."""
    choice = choices_taking(moves.source, moves.action, action[decoded.canonical],
                            len(decoded.canonical))
    return StormChoices(representative=representative, choice=choice)
