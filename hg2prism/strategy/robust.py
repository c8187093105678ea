"""Robust deception (docs/semantics.md §13): the max-min reachability value of an interval MDP,
solved exactly in numpy, and P1's robust strategy read off it.

The interval model (hg2prism.prism.robust_model) is built by Storm; `IntervalGame` holds its
states, choices and branches with their probability intervals. P1 chooses a choice in every
state; the adversary resolves the intervals of the chosen choice, seeing it, to minimise the
probability of reaching the goal. The robust value is the least fixed point of

    R(s) = max_c  min_{p in P(c)}  sum_b p_b R(target_b),   P(c) = {p : lower <= p <= upper, sum p = 1}

(goal 1, failure 0). The inner minimum is attained by filling the lower bounds and giving the
remaining mass to the branches of smallest value first, up to their upper bounds.

Method, certified as docs/semantics.md §10 asks of the games:

1. the states of value 0 by a graph fixed point: outside the set from which P1 can force a
   positive probability of reaching the goal (at each step some branch the adversary cannot
   empty leads closer), the adversary keeps P1 away from the goal forever;
2. strategy iteration for P1: P1's strategy is evaluated exactly by the adversary's best
   response — itself a policy iteration over the adversary's resolutions, each evaluated by a
   sparse linear solve on the states where the adversary cannot avoid the goal surely (there
   every resolution leaves the states with probability 1, so the system is regular) — and
   P1 switches to a choice whose worst case is better by more than 1e-11, until none is,
   keeping only switches under which every positive state stays positive (otherwise
   simultaneous switches can close a loop the adversary holds P1 in, and the iteration cycles);
3. certificate: the values are those of a P1 strategy against the adversary's best response
   (so at most R), and a fixed point of the operator above to within 1e-10 (so, being 0
   exactly where R is 0, at least R up to that residual). Failing either is a SolverError.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hg2prism.engines.engine import Transitions
from hg2prism.errors import PROBABILITY_SLACK, SolverError
from hg2prism.numeric import ExplicitModel, argmax_by_group, first_best, solve_m_matrix
from hg2prism.numeric.graph import stable_order
from hg2prism.numeric.fastest import (DISCOUNT, MAX_SCORE_SWEEPS, RELATIVE_TIE, SCORE_STOP,
                                      STORM_SLACK)
from hg2prism.numeric.tables import ranges

SWITCH = 1e-12          # the adversary switches only on an improvement above this
P1_SWITCH = 1e-11       # P1 too (above the solves' rounding on models of 1e5 states)
MAX_P1_ROUNDS = 500
RESIDUAL = 1e-10        # the certified fixed point's largest residual
MAX_ROUNDS = 10_000
# as the deceptive strategy: the fastest-first rule's constants (numeric/fastest.py)
OPTIMAL_SLACK, DISCOUNT_STOP, MAX_DISCOUNT_SWEEPS = STORM_SLACK, SCORE_STOP, MAX_SCORE_SWEEPS


@dataclass(frozen=True, eq=False)
class _Uncertain:
    """The choices that leave the adversary some mass and room to place it, one row each (in
    choice order), and their branches in branch order, padded to the widest: branch[g, j] the
    j-th branch of the g-th such choice where valid[g, j] (0 in the padding), room[g, j] its
    upper minus lower bound (0 in the padding), slack[g] the choice's mass to place."""

    branch: np.ndarray
    valid: np.ndarray
    room: np.ndarray
    slack: np.ndarray


@dataclass(frozen=True, eq=False)
class IntervalGame:
    """An interval MDP: the explicit model of its lower bounds (numeric.ExplicitModel: the
    choices of state s are choice_start[s]:choice_start[s+1], the branches of choice c are
    row_start[c]:row_start[c+1]) and the upper bound of every branch. Absorbing states (`stop`)
    keep their choices but are never solved: goal states have value 1, the others 0."""

    model: ExplicitModel      # the structure, with the lower bounds as its probabilities
    upper: np.ndarray         # [branches] the upper bounds, in the model's branch order
    goal: np.ndarray          # bool per state
    stop: np.ndarray          # bool per state: goal or failure
    initial: int
    # states that are pure chance (one choice of point intervals) and lead to no such state:
    # the intermediate states of the robust model. Linear solves eliminate them first.
    chance: np.ndarray | None = None

    @classmethod
    def build(cls, choice_start: np.ndarray, row_start: np.ndarray, target: np.ndarray,
              lower: np.ndarray, upper: np.ndarray, **rest) -> "IntervalGame":
        """From flat arrays: choices, their branches' targets and lower and upper bounds."""
        model = ExplicitModel.from_arrays(np.asarray(row_start), np.asarray(target),
                                          np.asarray(lower, dtype=float),
                                          np.asarray(choice_start))
        return cls(model=model, upper=np.asarray(upper, dtype=float), **rest)

    # the model's arrays, by the names the algorithms below read
    @property
    def choice_start(self) -> np.ndarray:
        return self.model.group_start

    @property
    def row_start(self) -> np.ndarray:
        return self.model.matrix.indptr

    @property
    def target(self) -> np.ndarray:
        return self.model.matrix.indices

    @property
    def lower(self) -> np.ndarray:
        return self.model.matrix.data

    @property
    def n_states(self) -> int:
        return self.model.n_states

    @property
    def n_choices(self) -> int:
        return self.model.n_choices

    @classmethod
    def of(cls, moves: Transitions, goal: np.ndarray, fail: np.ndarray, initial: int,
           chance: np.ndarray | None = None) -> "IntervalGame":
        """Storm's model (storm.read_structure) with its goal and failure states; a model without
        intervals is the game whose intervals are points. `chance`: see the field."""
        n_states = len(goal)
        choice_start = np.searchsorted(moves.source, np.arange(n_states + 1))
        upper = moves.probability if moves.upper is None else moves.upper
        return cls.build(choice_start=choice_start, row_start=np.asarray(moves.row_start),
                   target=np.asarray(moves.target), lower=np.asarray(moves.probability),
                   upper=np.asarray(upper), goal=np.asarray(goal, dtype=bool),
                   stop=np.asarray(goal, dtype=bool) | np.asarray(fail, dtype=bool),
                   initial=int(initial), chance=chance)

    def keeping(self, choices: np.ndarray) -> "IntervalGame":
        """The game with only the choices `choices` (increasing indices; a state may be left
        with none), their branches in the same order: worst_case gives each of them the same
        numbers as on the whole game."""
        first = self.row_start[choices]
        counts = self.row_start[choices + 1] - first
        branches = ranges(first, counts)
        per_state = np.bincount(self.choice_state[choices], minlength=self.n_states)
        return IntervalGame.build(choice_start=np.r_[0, np.cumsum(per_state)],
                                  row_start=np.r_[0, np.cumsum(counts)],
                                  target=self.target[branches], lower=self.lower[branches],
                                  upper=self.upper[branches], goal=self.goal, stop=self.stop,
                                  initial=self.initial)

    # -- derived arrays, computed once -----------------------------------------------------
    def _cached(self, name: str, make) -> np.ndarray:
        cache = self.__dict__.setdefault("_cache", {})
        if name not in cache:
            cache[name] = make()
        return cache[name]

    @property
    def choice_state(self) -> np.ndarray:
        return self._cached("choice_state", lambda: np.repeat(
            np.arange(self.n_states), np.diff(self.choice_start)))

    @property
    def branch_choice(self) -> np.ndarray:
        return self._cached("branch_choice", lambda: np.repeat(
            np.arange(self.n_choices), np.diff(self.row_start)))

    @property
    def uncertain(self) -> _Uncertain:
        """The branches of the choices that leave the adversary some mass and room to place it
        (`_Uncertain`). (Most choices of the robust model are P1's moves with point intervals:
        their lower bounds sum to 1 up to rounding, a slack of 1e-16 with no room, where the
        adversary places nothing.)"""
        def make():
            room = np.bincount(self.branch_choice, weights=self.upper - self.lower,
                               minlength=self.n_choices)
            choices = (self.slack > 0) & (room > 0)
            branches = np.flatnonzero(choices[self.branch_choice])
            if not branches.size:
                return _Uncertain(branch=np.zeros((0, 0), dtype=np.int64),
                                  valid=np.zeros((0, 0), dtype=bool), room=np.zeros((0, 0)),
                                  slack=np.zeros(0))
            choice = self.branch_choice[branches]
            first = np.flatnonzero(np.r_[True, choice[1:] != choice[:-1]])
            sizes = np.diff(np.r_[first, branches.size])
            width = int(sizes.max(initial=0))
            index = np.int32 if self.target.size < 2**31 else np.int64
            valid = np.arange(width) < sizes[:, None]
            branch = np.where(valid, branches[np.minimum(first[:, None] + np.arange(width),
                                                         max(branches.size - 1, 0))], 0)
            room = np.where(valid, self.upper[branch] - self.lower[branch], 0.0)
            return _Uncertain(branch=branch.astype(index), valid=valid, room=room,
                              slack=self.slack[choice[first]])
        return self._cached("uncertain", make)

    @property
    def entering(self) -> tuple[np.ndarray, np.ndarray]:
        """The branches into each state: entering[start[t]:start[t + 1]] enter state t, in
        branch order."""
        def make():
            order = stable_order(self.target, self.n_states)
            return order, np.r_[0, np.cumsum(np.bincount(self.target, minlength=self.n_states))]
        return self._cached("entering", make)

    @property
    def slack(self) -> np.ndarray:
        """1 - sum of the lower bounds of each choice: the mass the adversary places."""
        return self._cached("slack", lambda: np.clip(1.0 - np.bincount(
            self.branch_choice, weights=self.lower, minlength=self.n_choices), 0.0, None))


def worst_case(game: IntervalGame, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per choice, the adversary's minimum of the expected value over its intervals, and the
    minimising probability of every branch: lower bounds first, then the remaining mass to the
    branches of smallest value (ties in branch order), each up to its upper bound."""
    branch_value = values[game.target]
    probability = game.lower.copy()
    uncertain = game.uncertain
    if uncertain.branch.size:
        keys = np.where(uncertain.valid, branch_value[uncertain.branch], np.inf)   # padding last
        # Where the cheapest branch (the first of least value) has room for all the mass, it
        # takes it all and the order of the others does not matter (their share is 0).
        rows = np.arange(keys.shape[0])
        cheapest = keys.argmin(axis=1)
        whole = uncertain.room[rows, cheapest] >= uncertain.slack
        probability[uncertain.branch[rows[whole], cheapest[whole]]] += uncertain.slack[whole]
        rest = np.flatnonzero(~whole)
        if rest.size:
            _place_in_order(probability, keys[rest], uncertain.branch[rest], uncertain.room[rest],
                            uncertain.valid[rest], uncertain.slack[rest])
    expected = np.bincount(game.branch_choice, weights=probability * branch_value,
                           minlength=game.n_choices)
    return expected, probability


def _place_in_order(probability: np.ndarray, keys: np.ndarray, branch: np.ndarray,
                    room: np.ndarray, valid: np.ndarray, slack: np.ndarray) -> None:
    """Each row's mass `slack` to its branches by increasing key (ties in branch order), each
    up to its room: the rows are choices, padded to the widest (`_Uncertain`)."""
    # a stable sort of each choice's few branches: several times faster than one lexsort of
    # all of them, the same order
    within = np.argsort(keys, axis=1, kind="stable")
    ordered = np.take_along_axis(branch, within, axis=1)
    room = np.take_along_axis(room, within, axis=1)
    # the room of the cheaper branches of the same choice, added branch by branch within the
    # choice (a running sum over all choices would cancel catastrophically: 1e-11 off on a
    # model of 4e5 states, which put rows above 1 and values above 1)
    before = np.zeros_like(room)
    np.cumsum(room[:, :-1], axis=1, out=before[:, 1:])
    give = np.clip(slack[:, None] - before, 0.0, room)
    probability[ordered[valid]] += give[valid]


def positive_states(game: IntervalGame, fixed: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The states from which P1 (playing the choices `fixed`, one per state, or any) reaches
    the goal with positive probability whatever the adversary does, and for each of them a
    choice that moves closer to the goal (-1 elsewhere). Least fixed point: a choice makes
    progress when a branch into the set has a positive lower bound, or the upper bounds of the
    branches outside the set sum to less than 1."""
    positive = game.goal.copy()
    progress = np.full(game.n_states, -1, dtype=np.int64)
    allowed = np.zeros(game.n_choices, dtype=bool)
    if fixed is None:
        allowed[:] = True
    else:
        allowed[fixed[~game.stop]] = True
    allowed &= ~game.stop[game.choice_state]
    # Breadth-first: the first round looks at every allowed choice, each later one only at the
    # choices with a branch into the states the round before added (no other choice's test
    # changed), with the same sums in the same order, so the same sets and progress choices
    # as testing every choice every round.
    entering, start = game.entering
    candidates = np.flatnonzero(allowed)
    while True:
        candidates = candidates[~positive[game.choice_state[candidates]]]
        first_branch = game.row_start[candidates]
        counts = game.row_start[candidates + 1] - first_branch
        owner = np.repeat(np.arange(candidates.size), counts)
        branches = ranges(first_branch, counts)
        inside = positive[game.target[branches]]
        forced = np.bincount(owner, weights=(inside & (game.lower[branches] > 0)).astype(float),
                             minlength=candidates.size) > 0
        outside = np.bincount(owner, weights=np.where(inside, 0.0, game.upper[branches]),
                              minlength=candidates.size)
        chosen = candidates[forced | (outside < 1.0 - 1e-12)]
        if not chosen.size:
            return positive, progress
        states = game.choice_state[chosen]
        first = np.r_[True, states[1:] != states[:-1]]
        progress[states[first]] = chosen[first]
        positive[states] = True
        added = states[first]
        lengths = start[added + 1] - start[added]
        into = entering[ranges(start[added], lengths)]
        touched = np.zeros(game.n_choices, dtype=bool)
        touched[game.branch_choice[into]] = True
        candidates = np.flatnonzero(touched & allowed)


def adversary_response(game: IntervalGame, strategy: np.ndarray,
                       start: np.ndarray | None = None) -> np.ndarray:
    """The probability of reaching the goal when P1 plays `strategy` (a choice per state) and the
    adversary best responds: exact, by policy iteration over resolutions with sparse solves."""
    positive, _ = positive_states(game, strategy)
    live = np.flatnonzero(positive & ~game.stop)
    values = game.goal.astype(float)
    if live.size == 0:
        return values
    values[live] = 0.0 if start is None else start[live]
    rows = strategy[live]
    first, last = game.row_start[rows], game.row_start[rows + 1]
    counts = last - first
    row_of = np.repeat(np.arange(live.size), counts)
    branches = ranges(first, counts)
    position = np.full(game.n_states, -1, dtype=np.int64)
    position[live] = np.arange(live.size)
    targets = game.target[branches]
    into_live = position[targets] >= 0
    into_goal = game.goal[targets]
    eliminate = _chance_elimination(game, live, strategy)
    _, resolution = worst_case(game, values)
    chosen = resolution[branches]
    for _ in range(MAX_ROUNDS):
        matrix = sp.csr_matrix((chosen[into_live], (row_of[into_live], position[targets[into_live]])),
                               shape=(live.size, live.size))
        reach = np.bincount(row_of, weights=chosen * into_goal, minlength=live.size)
        values = game.goal.astype(float)
        values[live] = _solve_chain(matrix, reach, eliminate)
        expected, resolution = worst_case(game, values)
        current = np.bincount(row_of, weights=chosen * values[targets], minlength=live.size)
        better = expected[rows] < current - SWITCH
        if not better.any():
            return values
        switch = better[row_of]
        chosen = np.where(switch, resolution[branches], chosen)
    raise SolverError("the adversary's policy iteration did not converge")


def _chance_elimination(game: IntervalGame, live: np.ndarray, strategy: np.ndarray
                        ) -> np.ndarray | None:
    """Positions (among `live`) of the chance states to eliminate before solving, when no
    chance state leads to another; None when there are none (or they do)."""
    if game.chance is None:
        return None
    chance = game.chance[live]
    if not chance.any():
        return None
    rows = strategy[live[chance]]
    first, last = game.row_start[rows], game.row_start[rows + 1]
    counts = last - first
    branches = ranges(first, counts)
    if game.chance[game.target[branches]].any():
        return None
    return np.flatnonzero(chance)


def _solve_chain(matrix: sp.csr_matrix, reach: np.ndarray, eliminate: np.ndarray | None
                 ) -> np.ndarray:
    """x = matrix x + reach, exactly (`numeric.solve_m_matrix`: sparse LU and a step of
    refinement). The states `eliminate` (no edge among themselves) are substituted out first:
    x_C = P_CK x_K + r_C, so the system shrinks to (I - P_KK - P_KC P_CK) x_K = r_K + P_KC r_C."""
    n = matrix.shape[0]
    if eliminate is None:
        return solve_m_matrix(sp.identity(n, format="csc") - matrix, reach)[0]
    keep = np.ones(n, dtype=bool)
    keep[eliminate] = False
    kept = np.flatnonzero(keep)
    p_kk, p_kc = matrix[kept][:, kept], matrix[kept][:, eliminate]
    p_ck = matrix[eliminate][:, kept]
    reduced = (p_kk + p_kc @ p_ck).tocsc()
    rhs = reach[kept] + p_kc @ reach[eliminate]
    x = np.empty(n)
    x[kept] = solve_m_matrix(sp.identity(kept.size, format="csc") - reduced, rhs)[0]
    x[eliminate] = p_ck @ x[kept] + reach[eliminate]
    return x


@dataclass(frozen=True, eq=False)
class RobustSolution:
    values: np.ndarray         # R at every state of the interval model
    strategy: np.ndarray       # an optimal choice per state (P1's, from strategy iteration)
    q_values: np.ndarray       # worst case of every choice under `values`
    rounds: int                # P1's strategy-iteration rounds
    residual: float            # largest |max_c Q(c) - R(s)| over the non-absorbing states

    def value(self, state: int) -> float:
        return float(self.values[state])


def solve_robust(game: IntervalGame) -> RobustSolution:
    """R at every state, certified (module docstring)."""
    positive, progress = positive_states(game)
    strategy = game.choice_start[:-1].copy()
    strategy[progress >= 0] = progress[progress >= 0]
    free = positive & ~game.stop
    values = None
    for rounds in range(1, MAX_P1_ROUNDS + 1):
        values = adversary_response(game, strategy, values)
        q_values, _ = worst_case(game, values)
        best = np.maximum.reduceat(q_values, game.choice_start[:-1])
        better = free & (best > q_values[strategy] + P1_SWITCH)
        if not better.any():
            break
        improved = _improve_keeping_positive(game, strategy, q_values, better, free)
        if np.array_equal(improved, strategy):
            break       # every remaining switch would stall P1: the certificate decides
        strategy = improved
    else:
        raise SolverError("P1's strategy iteration on the interval model did not converge")
    running = ~game.stop
    residual = float(np.abs(best - values)[running].max(initial=0.0))
    if residual > RESIDUAL:
        raise SolverError(f"robust values are not a fixed point: residual {residual:.2e}")
    if (values[~positive] != 0.0).any():
        raise SolverError("robust values are positive where the adversary avoids the goal")
    outside = np.abs(values - np.clip(values, 0.0, 1.0)).max(initial=0.0)
    if outside > PROBABILITY_SLACK:
        raise SolverError(f"robust values are not probabilities: {outside:.2e} outside [0, 1]")
    return RobustSolution(values=values, strategy=strategy, q_values=q_values, rounds=rounds,
                          residual=residual)


def _improve_keeping_positive(game: IntervalGame, strategy: np.ndarray, q_values: np.ndarray,
                              better: np.ndarray, free: np.ndarray) -> np.ndarray:
    """P1's next strategy: each state in `better` switches to its best choice, except where the
    switches together would let the adversary hold a positive state away from the goal forever.

    Switches that are each an improvement can jointly close a loop of choices the adversary can
    keep P1 in; the values of such a strategy drop to 0 there and the iteration cycles. So the
    switched states that are no longer positive under the new strategy go back to their old
    choice, until every state of `free` is positive again (it is once all switches are undone).
    With every free state positive the adversary cannot stall P1, so each accepted round does
    not decrease the values, and one with a switch increases one."""
    proposed = strategy.copy()
    switched = np.flatnonzero(better)
    among = ranges(game.choice_start[switched], np.diff(game.choice_start)[switched])
    proposed[switched] = among[first_best(q_values[among], game.choice_state[among])]
    while True:
        positive, _ = positive_states(game, proposed)
        lost = free & ~positive & (proposed != strategy)
        if not lost.any():
            return proposed
        proposed[lost] = strategy[lost]


def fastest_choices(game: IntervalGame, solution: RobustSolution, decides: np.ndarray,
                    action: np.ndarray) -> np.ndarray:
    """Per state, P1's choice among the value-optimal ones (worst case within OPTIMAL_SLACK of
    R): the one maximising the worst-case discounted probability of reaching the goal, as the
    deceptive strategy chooses (docs/semantics.md §6), ties to the first in choice order.

    `decides` marks the states where P1 chooses a move (the others are the intermediate states
    of a step, with one choice each); `action` is each choice's move (-1 for none). The discount
    applies once per step, when an intermediate state moves on."""
    optimal = (solution.q_values >= solution.values[game.choice_state] - OPTIMAL_SLACK)
    optimal &= (action >= 0) | ~decides[game.choice_state]
    # Only the optimal choices are ever read (_best and the score mask the others), and each
    # stage reads those of one kind of state (intermediate, then deciding), so the adversary's
    # worst case is computed on those alone (the same numbers there).
    intermediate = ~decides & ~game.stop
    stages = [np.flatnonzero(optimal & intermediate[game.choice_state]),
              np.flatnonzero(optimal & ~intermediate[game.choice_state])]
    among = [game.keeping(kept) for kept in stages]

    def worst(values: np.ndarray, *which: int) -> np.ndarray:
        expected = np.zeros(game.n_choices)
        for stage in which:
            expected[stages[stage]] = worst_case(among[stage], values)[0]
        return expected

    speed = np.zeros(game.n_states)
    for _ in range(MAX_DISCOUNT_SWEEPS):
        onward = np.where(game.goal, 1.0, np.where(decides & ~game.stop, DISCOUNT * speed, 0.0))
        later = np.where(intermediate, _best(game, worst(onward, 0), optimal), 0.0)
        new = np.where(decides & ~game.stop,
                       _best(game, worst(np.where(game.goal, 1.0, later), 1), optimal), 0.0)
        done = np.abs(new - speed).max(initial=0.0) < DISCOUNT_STOP
        speed = new
        if done:
            break
    onward = np.where(game.goal, 1.0, np.where(decides & ~game.stop, DISCOUNT * speed, 0.0))
    later = np.where(intermediate, _best(game, worst(onward, 0), optimal), 0.0)
    score = worst(np.where(game.goal, 1.0, later), 0, 1)
    score = np.where(optimal, score, -1.0)
    score[action < 0] = np.where(decides[game.choice_state], -2.0, score)[action < 0]
    return argmax_by_group(score, game.choice_state, game.n_states, relative_tie=RELATIVE_TIE)


def move_values(game: IntervalGame, solution: RobustSolution, states: np.ndarray,
                action: np.ndarray, n_actions: int = 0) -> np.ndarray:
    """[len(states), action slots]: the worst case under the budget of each move (action[choice],
    P1's action slot) of each of `states`, R's one-step values (NaN for a move a state lacks):
    why the robust strategy moves as it does, as strategy.json's ``values``. `n_actions`: the
    slots per state (the TS's A1max; at least one more than the largest action)."""
    n_actions = max(int(n_actions), int(action.max(initial=-1)) + 1)
    values = np.full((len(states), n_actions), np.nan)
    row = np.full(game.n_states, -1, dtype=np.int64)
    row[states] = np.arange(len(states))
    choices = np.flatnonzero((row[game.choice_state] >= 0) & (action >= 0))   # not `[] stop`
    values[row[game.choice_state[choices]], action[choices]] = solution.q_values[choices]
    return values


def _best(game: IntervalGame, per_choice: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    masked = np.where(allowed, per_choice, -np.inf)
    best = np.maximum.reduceat(masked, game.choice_start[:-1])
    return np.where(np.isfinite(best), best, 0.0)
