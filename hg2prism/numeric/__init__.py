"""The numeric core for explicit models (docs/semantics.md §10): graph analysis, exact values of
Markov chains with a bound on their rounding error, policy iteration for optimal reachability,
bounded reachability and expected steps, and the tie rules (ties.py: which of near-tied options
is taken, among them the first best choice of each state, the rule every strategy is read
with). numpy and scipy only; the analyses that solve an explicit MDP or chain (certification,
baselines, the value of deception, exports, simulation) solve it here. P2's perceptual games
(opponent/perceptual_games.py: turn-based games, solved part by part) and robust deception's
interval games (strategy/robust.py) have solvers of their own, on the graph analysis and the
linear solves here."""

from hg2prism.numeric.chains import (ChainValue, Steps, bounded_reach, chain_reach,
                                     expected_steps, solve_m_matrix, solve_plain)
from hg2prism.numeric.graph import (alternating_attractor, attractor, backward_distance,
                                    backward_reach, can_reach,
                                    downstream_first, end_components, move_predecessors,
                                    progress_choices)
from hg2prism.numeric.model import ExplicitModel
from hg2prism.numeric.policy import ExpectedSteps, OptimalReach, min_expected_steps, optimal_reach
from hg2prism.numeric.ties import (argmax_by_group, choices_taking, first_best, first_index,
                                   first_near_best, first_near_best_of, keep_or_first, near_best)

__all__ = ["ChainValue", "Steps", "bounded_reach", "chain_reach", "expected_steps",
           "solve_m_matrix", "solve_plain", "attractor", "alternating_attractor", "move_predecessors", "backward_distance", "backward_reach", "can_reach", "downstream_first", "end_components", "progress_choices", "ExplicitModel",
           "argmax_by_group", "choices_taking", "first_best", "first_index", "first_near_best",
           "first_near_best_of", "keep_or_first", "near_best",
           "OptimalReach", "optimal_reach", "ExpectedSteps", "min_expected_steps"]
