"""What the deception is worth (docs/semantics.md §11): V_static and V_naive.

* **V_static**: P2 never revises her first guess x0 and plays pi2_x0(v) forever. P1 knows it, so
  it plays in an MDP on TS x DFA(phi) (DFA state tracked). The value is P1's best response to
  that stationary trap policy, computed by policy iteration with exact (sparse linear)
  evaluation, as the upper end of V_NE's bracket (docs/semantics.md §7, §10), and certified: a
  fixed point of the MDP's operator that is 0 wherever no move sequence reaches the goal.
* **V_naive**: P1 ignores P2's misperception. It answers the trap set in force with its move of
  the leader game G(phi) (docs/semantics.md §7), while P2 runs her real inference. The pair is a
  Markov chain on the hypergame's states (v, q, M); it is explored here explicitly, from the
  initial state, with the hypergame's successor function in Python (analyses/successor.py,
  built on the Observer interface), so it works for every observer without Storm. The chain has one successor list per state (not four, as
  the MDP), and its value is one sparse linear solve.

Why not Storm with P1's choices fixed: the naive strategy needs P2's trap set at each state,
which Storm's state encoding holds only implicitly (for an observer whose hypothesis is a
function of its window). The explicit chain needs nothing but the Observer interface, visits
only the states the naive pair reaches, and its solve is exact up to rounding.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from hg2prism import numeric
from hg2prism.analyses.baselines import ConcurrentGame, best_response_value, concurrent_game
from hg2prism.analyses.successor import (GOAL as REACHED, RUNNING, Hypergame, HypergameState,
                                         explore_chain)
from hg2prism.errors import SolverError, probability
from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.model.product import product, product_state
from hg2prism.numeric import ExplicitModel, first_near_best, near_best
from hg2prism.numeric.fastest import DISCOUNT, EXACT_SLACK, RELATIVE_TIE
from hg2prism.opponent.perceptual_games import (GameSolution, PerceptualGame, TurnBasedGame,
                                                fastest_moves)
from hg2prism.strategy.policy import Policy, ProductPolicy

if TYPE_CHECKING:
    from hg2prism.results import Analysis

# Below this a difference of two values computed two ways (Storm's and the naive chain's) is 0
WORTH_TOLERANCE = 1e-12


def value_difference(value: float, other: float) -> float:
    """value - other, what one value is worth over another (the value of deception, of
    adaptivity, the cost of not knowing P2's type): equal values computed two ways differ in
    their last bits (mir100 gave -1.4e-17, printed "-0.000000"), so below WORTH_TOLERANCE, the
    certification's own, the difference is 0."""
    worth = value - other
    return 0.0 if abs(worth) < WORTH_TOLERANCE else worth

__all__ = ["StaticValue", "static_value", "naive_answers", "NaiveStrategy", "InducedChain",
           "induced_chain", "DeceptionValues", "deception_values", "value_difference"]

# the fastest-first rule's constants (numeric/fastest.py): leader-game moves within
# ANSWER_TIE of the best answer to a2 are maximising; scores within a relative SCORE_TIE tie
ANSWER_TIE, SCORE_TIE = EXACT_SLACK, RELATIVE_TIE
RESIDUAL = 1e-11        # accepted residual of a solved value vector (docs/semantics.md §10)
STRICT = 1e-12          # policy iteration switches a move only when it gains more than this

GOAL, FAIL = 0, 1       # the merged absorbing states of an InducedChain


# ---------------------------------------------------------------------------------------------
# V_static
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class StaticValue:
    """P1 against a P2 who keeps her first guess x0 forever, on TS x DFA(phi) (g = s * n_q + q)."""

    first_guess: int          # x0: the hypothesis P2 acts on before any observation
    values: np.ndarray        # [G] P1's maximal probability of reaching the goal
    p1: np.ndarray            # [G] P1's fastest optimal move (docs/semantics.md §§6-7's rule)
    p2: np.ndarray            # [G] the trap set pi2_x0(v) of each game state
    value: float              # V_static at the initial state
    n_q: int                  # the task DFA's states
    n_actions: int = 0        # P1's action slots per state (the TS's A1max)

    @property
    def policy(self) -> ProductPolicy:
        """P1's strategy `p1` as a Policy on hypergame states (it ignores P2's memory)."""
        return ProductPolicy(self.p1, self.n_q, self.n_actions)


def static_value(ts: TransitionSystem, task: DFA, games: list[PerceptualGame],
                 first_guess: int) -> StaticValue:
    """V_static (docs/semantics.md §11) with P2 playing pi2 of hypothesis `first_guess`."""
    n_q = task.n_states
    trap_choice = np.asarray(games[first_guess].trap_choice)
    p2 = np.repeat(trap_choice, n_q)                                   # [G]
    game = concurrent_game(ts, task)
    values = best_response_value(game, np.eye(ts.n_sets)[p2], improvement=STRICT)
    _certify_mdp(game, p2, values)
    moves = fastest_moves(ts, task, values, p2, DISCOUNT)
    arena = product(ts, task)
    return StaticValue(first_guess=first_guess, values=values, p1=moves.answers, p2=p2,
                       value=probability(values[arena.start], "V_static"), n_q=n_q,
                       n_actions=ts.n_actions)


def _certify_mdp(game: ConcurrentGame, p2: np.ndarray, values: np.ndarray) -> None:
    """Certify that `values` is the maximal reach probability of the MDP where P2 plays p2[g]
    (docs/semantics.md §10). Policy iteration returned the value of one of P1's strategies, a
    lower bound of the maximum; it must also be a fixed point of the MDP's operator (residual at
    most 1e-11), hence above the least fixed point, which is the maximum, and 0 wherever no
    sequence of moves reaches the goal."""
    rows = np.arange(game.size)
    nxt, prob = game.next[rows, :, p2], game.prob[rows, :, p2]        # [G, A1, K]
    best = (prob * values[nxt]).sum(-1).max(axis=1)
    free = game.free
    residual = np.abs(best - values)[free].max(initial=0.0)
    if residual > RESIDUAL:
        raise SolverError(f"V_static: the MDP operator moves the values by {residual:.2e}")
    # The states from which some sequence of moves reaches the goal.
    can = numeric.can_reach(ExplicitModel.from_tables(nxt, prob), game.goal, ~free)
    if (values[~can] > 1e-12).any():
        raise SolverError("V_static: positive value where the goal cannot be reached")


# ---------------------------------------------------------------------------------------------
# The naive strategy
# ---------------------------------------------------------------------------------------------

def naive_answers(ts: TransitionSystem, task: DFA, leader: GameSolution) -> np.ndarray:
    """[G, n_sets]: P1's leader-game move at game state g against trap set a2
    (docs/semantics.md §11): among the moves with `Q_phi(g, a1, a2) >= max_b Q_phi(g, b, a2) -
    1e-9`, the largest discounted score `sum_k P(k) * (1 if goal else 0.9 * W(next_k))`, W the
    leader pair's scores (docs/semantics.md §7); scores within a relative 1e-12 of the best
    tie, and ties go to the first action slot. Rows of absorbing states are 0."""
    game = TurnBasedGame(ts, task)
    lead = leader.values.reshape(-1)
    q = game.q_values(lead)                                            # [G, A1, A2]
    maximising = near_best(q, ANSWER_TIE, axis=1)
    w = fastest_moves(ts, task, lead, leader.p2_strategy, DISCOUNT).scores
    reached = np.where(game.goal[game.next], 1.0, DISCOUNT * w[game.next])
    score = (game.prob * reached).sum(-1)                              # [G, A1, A2]
    answers = first_near_best(np.where(maximising, score, -np.inf), SCORE_TIE, axis=1,
                              relative=True)
    answers[~game.free] = 0
    return answers


class NaiveStrategy:
    """P1's naive strategy on hypergame states, a Policy: the leader-game answer
    (`naive_answers`) to the trap set in force, pi2 of the hypothesis P2 acts on
    (`Hypergame.predicted` of the hypergame `game`)."""

    def __init__(self, answers: np.ndarray, game: Hypergame) -> None:
        self.answers = answers
        self.game = game
        self.n_q = game.task.n_states

    def action(self, ts_state: int, q: int, memory: Hashable) -> int:
        return int(self.answers[product_state(ts_state, q, self.n_q),
                                self.game.predicted(ts_state, memory)])


# ---------------------------------------------------------------------------------------------
# The Markov chain a strategy induces on the hypergame
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class InducedChain:
    """The Markov chain a deterministic memoryless P1 strategy induces on the hypergame MDP
    (docs/semantics.md §6), over the states reachable from the initial one. States 0 and 1 are
    the merged goal and failure (absorbing); the others are (v, q, M)."""

    states: list[tuple[int, int, Hashable] | None]   # None for GOAL and FAIL
    chain: ExplicitModel      # one choice per state: its one-step probabilities (absorbing: empty)
    hypothesis: np.ndarray    # P2's hypothesis in each state (-1 for GOAL and FAIL)
    action: np.ndarray        # P1's move in each state (-1 for GOAL and FAIL)
    start: int                # the initial state (GOAL or FAIL when already absorbing)

    @property
    def size(self) -> int:
        return len(self.states)

    @property
    def matrix(self) -> sp.csr_matrix:
        """[states x states] the one-step probabilities."""
        return self.chain.matrix

    @property
    def goal(self) -> np.ndarray:
        return np.arange(self.size) == GOAL

    @property
    def stop(self) -> np.ndarray:
        return np.arange(self.size) <= FAIL

    def reach(self) -> np.ndarray:
        """[states] the probability of reaching the goal from each state, exact up to rounding
        (`numeric.chain_reach`), whose error bound must be at the residual's level."""
        reach = numeric.chain_reach(self.matrix, self.goal, self.stop)
        if reach.error > RESIDUAL:
            raise SolverError(f"the induced chain's linear solve may be off by {reach.error:.2e}")
        return reach.values

    def value(self, what: str) -> float:
        """The probability of reaching the goal from the initial state."""
        return probability(self.reach()[self.start], what)

    def within(self, horizon: int) -> float:
        """The probability of reaching the goal within `horizon` steps (docs/semantics.md §8)."""
        return numeric.bounded_reach(self.matrix, self.goal, self.stop, self.start, horizon)


def induced_chain(game: Hypergame, strategy: Policy) -> InducedChain:
    """The chain P1's deterministic `strategy` induces on the hypergame `game` (docs/semantics.md
    §6), explored breadth-first from the initial state with `game.successors`: from (v, q, M) P1
    plays strategy.action(v, q, M), P2 pi2 of her hypothesis (with a Bayesian "sample"
    observer, of each hypothesis with its probability). Goal and failure are merged into the
    states GOAL and FAIL; the probabilities of the transitions into one state are summed."""
    ended = ("goal", "fail")            # the keys of GOAL and FAIL (no hypergame state's)

    def key(state: HypergameState) -> Hashable:
        status = game.status(state[0], state[1])
        return state if status == RUNNING else ended[0 if status == REACHED else 1]

    hypothesis, action = [-1, -1], [-1, -1]

    def moves(state: HypergameState) -> Iterator[tuple[Hashable, float]]:
        v, q, memory = state
        a1 = int(strategy.action(v, q, memory))
        hypothesis.append(game.observer.hypothesis(memory))
        action.append(a1)
        return ((key(successor), p) for successor, p in game.successors(state, a1))

    explored = explore_chain(key(game.initial()), moves, fixed=ended)
    states: list[HypergameState | None] = [None, None] + explored.states[2:]
    start, matrix, n = explored.start, explored.matrix, len(states)
    return InducedChain(states=states, chain=ExplicitModel(matrix, np.arange(n + 1)),
                        hypothesis=np.array(hypothesis),
                        action=np.array(action), start=start)


# ---------------------------------------------------------------------------------------------
# Both values
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class DeceptionValues:
    """docs/semantics.md §11 at the initial state, with what the simulations need."""

    v_static: float
    v_naive: float
    value_of_deception: float     # deceptive value - V_naive
    static: StaticValue
    naive: NaiveStrategy
    naive_chain: InducedChain


def deception_values(analysis: Analysis, deceptive_value: float) -> DeceptionValues:
    """V_static, V_naive and the value of deception of a results.Analysis, given the
    deceptive value Storm computed for it."""
    ts, task, games, observer = analysis.ts, analysis.task, analysis.games, analysis.inference
    first_guess = observer.hypothesis(observer.initial_memory())
    static = static_value(ts, task, games, first_guess)
    game = Hypergame(ts, task, games, observer)
    naive = NaiveStrategy(naive_answers(ts, task, analysis.leader), game)
    chain = induced_chain(game, naive)
    v_naive = chain.value("V_naive")
    worth = value_difference(deceptive_value, v_naive)
    return DeceptionValues(v_static=static.value, v_naive=v_naive,
                           value_of_deception=worth, static=static,
                           naive=naive, naive_chain=chain)
