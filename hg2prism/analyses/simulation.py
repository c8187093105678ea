"""Online simulation of the interaction on TS (docs/semantics.md §8).

Deceptive runs: P1 follows its exported deceptive strategy (the records of strategy.json),
tracking the hypergame state ``(v, q, M)`` exactly: ``q`` is its task DFA's state after reading
the current state's label and ``M`` its model of P2's memory, which evolves by docs/semantics.md §5 with
``a2 = pi2_xh(v)`` (docs/semantics.md §9). P2 runs the inference of docs/semantics.md §5 on the actual history and plays
``pi2_xh(v)`` for the hypothesis ``xh`` of her real memory, unless an experiment gives her
another policy (``p2_policy``) or another inference model (``p2_inference``). The successor is
sampled from the TS tables for the actions actually played.

Nash runs: both players sample their stationary mixed strategies over the game states
``g = s * n_q + q`` of TS x DFA(phi) (the convention of ``hg2prism.model.product``).

An episode ends in goal (``q`` in F and not trapped), in failure (trapped, or ``q`` in Sink) or
after ``horizon`` transitions (truncated: not completed, reported). The completion rate thus
estimates ``P(F<=horizon goal)``; it is reported with a Wilson score interval.

The exported records cover only the states reachable when P2 behaves as modelled. When an
experiment makes P2 deviate, P1 can reach other states (e.g. a trap candidate on which the
model would have trapped it): `Strategy.action` then raises StrategyError unless the strategy was
given a fallback (`leader_fallback`); the summary counts such steps (`off_record_steps`).

Runs are reproducible: every random number comes from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.stats import norm

from hg2prism.analyses.successor import (FAIL, GOAL, Hypergame, HypergameState,
                                         TrackedObserver)
from hg2prism.model.automata import DFA
from hg2prism.model.product import product
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.numeric import bounded_reach
from hg2prism.progress import Bar, warn
from hg2prism.strategy.policy import Policy, ProductPolicy
from hg2prism.strategy.records import Fallback, StrategyError
from hg2prism.opponent.observer import Memory
from hg2prism.opponent.observer import Observer

if TYPE_CHECKING:
    from hg2prism.results import Analysis

__all__ = [
    "FAIL", "GOAL", "TRUNCATED",
    "StepRecord",
    "SimulationSummary",
    "wilson_interval",
    "simulate_deceptive",
    "simulate_nash",
    "leader_fallback",
    "LeaderStrategy",
    "Replanning",
    "deviating_policy",
]

# Episode outcome codes (SimulationSummary.outcomes): FAIL and GOAL are the hypergame states'
# status codes (analyses.successor).
TRUNCATED = 2

# (rng, step number n >= 1, TS state v, the trap set P2's model plays at v, P2's real memory)
# -> the trap set P2 plays.
P2Policy = Callable[[np.random.Generator, int, int, int, Memory], int]
StepCallback = Callable[["StepRecord"], object]   # sees every step of every episode

_RANDOM_BLOCK = 8192


# ---------------------------------------------------------------------------------------------
# Wilson interval and the summary
# ---------------------------------------------------------------------------------------------

# a simulated count this improbable under its exact value (the two-sided p-value of the exact
# binomial test) means the two were computed on different processes, not sampling noise
AGREEMENT_P_VALUE = 1e-6


def warn_if_implausible(what: str, count: int, episodes: int, exact: float,
                        advice: str = "") -> bool:
    """A warning when `count` of `episodes` is implausible under the exact within-horizon
    probability `exact` (the exact binomial test's p-value below AGREEMENT_P_VALUE, so about
    one false warning in a million): the episodes and the model then play different games.
    (A Wilson interval at the same confidence covers badly where only a few episodes fail: it
    warned falsely 3.6 % of the time at n - 1 of n.) Returns whether it warned."""
    from scipy.stats import binomtest

    p = binomtest(count, episodes, min(max(exact, 0.0), 1.0)).pvalue
    if p >= AGREEMENT_P_VALUE:
        return False
    warn(f"simulated {what} is {count / episodes:.6f} ({count} of {episodes} episodes), far "
         f"from its exact within-horizon probability {exact:.6f} (exact binomial test: "
         f"p = {p:.1e}): the simulation and the model disagree{advice}")
    return True


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval (no continuity correction) of a binomial proportion.

    With p = successes / n and z = norm.ppf(1 - (1 - confidence) / 2):
    ``(p + z^2/(2n) -+ z sqrt(p(1-p)/n + z^2/(4n^2))) / (1 + z^2/n)``.
    """
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not 0 <= successes <= n:
        raise ValueError(f"successes must lie in 0..{n}, got {successes}")
    low, high = wilson_band(np.array([successes]), n, confidence)
    return float(low[0]), float(high[0])


def wilson_band(successes: np.ndarray, n: int, confidence: float = 0.95
                ) -> tuple[np.ndarray, np.ndarray]:
    """`wilson_interval` of every count in `successes` (integers in 0..n) at once: the
    completion figure's band has one per step of the horizon, up to 100,000."""
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    z = float(norm.ppf(1.0 - (1.0 - confidence) / 2.0))
    p = np.asarray(successes) / n
    z2 = z * z
    denominator = 1.0 + z2 / n
    centre = (p + z2 / (2.0 * n)) / denominator
    half = z * np.sqrt(p * (1.0 - p) / n + z2 / (4.0 * n * n)) / denominator
    # The closed form gives exactly 0 (1) for 0 (n) successes up to rounding.
    low = np.where(successes == 0, 0.0, np.maximum(0.0, centre - half))
    high = np.where(successes == n, 1.0, np.minimum(1.0, centre + half))
    return low, high


@dataclass(frozen=True, eq=False)
class SimulationSummary:
    """Outcome of a batch of episodes.

    ``completed`` episodes reached the goal, ``failed`` ones were trapped or reached a DFA sink,
    ``truncated`` ones were still running after ``horizon`` transitions (not completed).
    ``lengths[i]`` is the number of transitions of episode i, ``outcomes[i]`` its outcome code
    (FAIL = 0, GOAL = 1, TRUNCATED = 2).
    """

    episodes: int
    completed: int
    failed: int
    truncated: int
    rate: float                      # completed / episodes
    ci95: tuple[float, float]        # Wilson score interval of rate
    horizon: int
    seed: int
    seconds: float
    lengths: np.ndarray = field(repr=False)
    outcomes: np.ndarray = field(repr=False)
    off_record_steps: int = 0        # deceptive runs: steps where P1 had no record (fallback)
    # Runs against P2's inference: episodes in which her hypothesis changed at least once, and
    # the number of changes over all episodes (docs/semantics.md §11). A change at an episode's
    # last step counts: P2 updates her memory from P1's move whatever the robot reached.
    # `p2_switched_in_play` counts the episodes with a change after which the episode went on
    # (neither the goal nor a failure reached; cut by the horizon counts): a change P2 could
    # act on.
    p2_switched: int = 0
    p2_switches: int = 0
    p2_switched_in_play: int = 0
    replanned: int = 0               # with re-planning: episodes in which P1 switched strategy

    def interval(self, confidence: float = 0.95) -> tuple[float, float]:
        """Wilson score interval of the completion rate at another confidence level."""
        return wilson_interval(self.completed, self.episodes, confidence)

    @property
    def mean_length(self) -> float:
        return float(self.lengths.mean()) if self.episodes else 0.0


def _summary(outcomes: np.ndarray, lengths: np.ndarray, horizon: int, seed: int,
             seconds: float, off_record_steps: int = 0, p2_switched: int = 0,
             p2_switches: int = 0, replanned: int = 0, p2_switched_in_play: int = 0
             ) -> SimulationSummary:
    episodes = len(outcomes)
    completed = int((outcomes == GOAL).sum())
    return SimulationSummary(
        episodes=episodes, completed=completed, failed=int((outcomes == FAIL).sum()),
        truncated=int((outcomes == TRUNCATED).sum()), rate=completed / episodes,
        ci95=wilson_interval(completed, episodes, 0.95), horizon=horizon, seed=seed,
        seconds=seconds, lengths=lengths, outcomes=outcomes, off_record_steps=off_record_steps,
        p2_switched=p2_switched, p2_switches=p2_switches, replanned=replanned,
        p2_switched_in_play=p2_switched_in_play)


def _check_run(episodes: int, horizon: int) -> None:
    if int(episodes) < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    if int(horizon) < 1:
        raise ValueError(f"horizon must be >= 1, got {horizon}")


# ---------------------------------------------------------------------------------------------
# Progress bar and random numbers
# ---------------------------------------------------------------------------------------------

class _Uniforms:
    """Uniform [0, 1) numbers drawn from the generator in blocks (deterministic for a seed)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.block: list[float] = []
        self.pos = _RANDOM_BLOCK          # the block is used up: the first number draws one

    def next(self) -> float:
        if self.pos >= len(self.block):
            self.block = self.rng.random(_RANDOM_BLOCK).tolist()
            self.pos = 0
        u = self.block[self.pos]
        self.pos += 1
        return u


# ---------------------------------------------------------------------------------------------
# P1's strategy
# ---------------------------------------------------------------------------------------------

def leader_fallback(analysis: Analysis, model: Hypergame | None = None) -> Fallback:
    """A fallback for states the records do not cover: P1 answers the trap set its model
    predicts (pi2_xh(v)) with its naive answer (docs/semantics.md §11): the move optimal in the
    leader game G(phi) of §7 against that set, the fastest of them (`NaiveStrategy`, which
    adaptive deception's committed strategies fall back on too).

    It is a heuristic for off-model experiments only; simulations report how many steps used it
    (SimulationSummary.off_record_steps)."""
    from hg2prism.analyses.deception_value import NaiveStrategy, naive_answers

    if model is None:       # the hypergame P1's model of P2 predicts with (given: shared)
        model = Hypergame(analysis.ts, analysis.task, analysis.games, analysis.inference)
    return NaiveStrategy(naive_answers(analysis.ts, analysis.task, analysis.leader),
                         model).action


class LeaderStrategy(ProductPolicy):
    """P1's leader-game strategy on (v, q) (docs/semantics.md §14's "leader" fallback): P1 assumes
    P2 knows its task and plays the leader game's trap set pi2_lead(v, q); P1 answers with its
    fastest optimal move of that game (the leader baseline's P1, docs/semantics.md §7)."""

    def __init__(self, analysis: Analysis) -> None:
        from hg2prism.opponent.perceptual_games import fastest_answers

        super().__init__(fastest_answers(analysis.ts, analysis.task, analysis.leader),
                         analysis.task.n_states, analysis.ts.n_actions)


@dataclass(frozen=True)
class Replanning:
    """Re-planning (docs/semantics.md §14): P1 runs the mismatch detector of docs/semantics.md §9
    on its own augmented states and, from the step after its first rejection to the end of the
    episode, plays the Policy `fallback` instead."""

    fallback: Policy
    alpha: float
    epsilon: float


# ---------------------------------------------------------------------------------------------
# Deceptive runs
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class StepRecord:
    """One transition of an episode, as passed to the observer.

    ``(ts_state, q, memory)`` is P1's augmented state before the step (``memory`` = P1's model
    of P2's memory, docs/semantics.md §9); ``a2`` the trap set P2 actually played, ``predicted_a2`` the one
    P1's model predicts (``pi2_xh(v)`` with ``xh = memory.hypothesis``), ``n_a2 = |A2(v)|``.
    ``p2_memory`` is P2's real memory before the step (equal to ``memory`` unless P2 runs another
    inference model). ``next_state``/``next_q`` is where the step led (``next_state`` may be
    ``ts.trapped``). P2's actions are indices into ``ts.a2_names`` (in trap mode the states a
    trap set covers: ``ts.trap_places(a2)``).
    """

    episode: int
    n: int
    ts_state: int
    q: int
    memory: Memory
    a1: int
    a2: int
    predicted_a2: int
    n_a2: int
    p2_memory: Memory
    next_state: int
    next_q: int
    # the trap sets P1's model predicts with their probabilities: one pair unless P2 draws
    # her hypothesis (Bayesian "sample", docs/semantics.md §12), then the posterior mixture
    prediction: tuple[tuple[int, float], ...] = ()
    # the hypothesis whose trap set P2 played: the one she drew when she draws it, else (None)
    # her memory's
    p2_drawn: int | None = None

    @property
    def acted(self) -> int:
        """The hypothesis P2 acted on at this step (whose trap set she played)."""
        return self.p2_memory.hypothesis if self.p2_drawn is None else self.p2_drawn

    @property
    def augmented_state(self) -> tuple[int, int, Memory]:
        """s~_n = (v_n, q_n, M_n): the key the mismatch detector counts on."""
        return (self.ts_state, self.q, self.memory)

    @property
    def observation(self) -> tuple[int, int, int]:
        """What P2's inference reads at this step (observer.Observation): the TS state, P1's
        move and the trap set she played."""
        return (self.ts_state, self.a1, self.a2)


def deviating_policy(ts: TransitionSystem, deviate_after: int) -> P2Policy:
    """docs/semantics.md §9's experiment: P2 follows the model for n <= deviate_after, then plays uniformly
    at random over A2(v)."""
    allowed = [np.flatnonzero(row) for row in ts.allowed]

    def policy(rng: np.random.Generator, n: int, ts_state: int, predicted: int,
               memory: Memory) -> int:
        if n <= deviate_after:
            return predicted
        choices = allowed[ts_state]
        return int(choices[rng.integers(len(choices))])

    return policy


class _Chain:
    """The hypergame states an online simulation has met so far, numbered, with what the
    episodes ask of them memoised. A node is (v, q, (M1, M2)): TS state, task DFA state, P1's
    model of P2's memory and P2's real memory; `game` is the successor function over them
    (its observer a successor.TrackedObserver of `model`, the hypergame as P1 models it)."""

    def __init__(self, game: Hypergame, model: Hypergame) -> None:
        self.game, self.model = game, model
        self.index: dict[HypergameState, int] = {}
        self.nodes: list[HypergameState] = []
        self.status: list[int] = []          # RUNNING, GOAL or FAIL
        self.p2_hypothesis: list[int] = []   # the hypothesis of P2's real memory
        self.p2_sets: list[list[tuple[int, float]]] = []   # the trap sets P2 plays from
        self.p2_draws: list[tuple[int, ...]] = []   # the hypothesis of each of those sets
        self.predicted: list[int] = []       # the trap set P1's model predicts
        self.a1: list[int] = []              # P1's move, -1 until first asked
        self.moves: dict[tuple[int, int, int], tuple[list[float], list[int]]] = {}

    def node(self, state: HypergameState) -> int:
        """The number of `state`, given when first met."""
        i = self.index.get(state)
        if i is None:
            i = self.index[state] = len(self.nodes)
            self.nodes.append(state)
            v, q, memory = state
            self.status.append(self.game.status(v, q))
            self.p2_hypothesis.append(self.game.observer.hypothesis(memory))
            self.p2_sets.append(self.game.trap_sets(v, memory))
            self.p2_draws.append(tuple(x for x, _ in
                                       self.game.observer.hypothesis_distribution(memory)))
            self.predicted.append(self.model.predicted(v, memory[0]))
            self.a1.append(-1)
        return i

    def transitions(self, i: int, a1: int, a2: int) -> tuple[list[float], list[int]]:
        """Cumulative probabilities and successor nodes of node i when P1 plays a1 and P2
        the trap set a2 (`Hypergame.after`)."""
        key = (i, a1, a2)
        move = self.moves.get(key)
        if move is None:
            merged: dict[int, float] = {}
            for successor, p in self.game.after(self.nodes[i], a1, a2):
                j = self.node(successor)
                merged[j] = merged.get(j, 0.0) + p
            cumulative, targets, total = [], [], 0.0
            for j, p in merged.items():
                total += p
                cumulative.append(total)
                targets.append(j)
            cumulative[-1] = 1.0 + 1e-12      # guards against rounding in the sum
            move = self.moves[key] = (cumulative, targets)
        return move


class _DeceptiveRun:
    """What the episodes of one `simulate_deceptive` call share: the chain of hypergame states
    met, P1's policies and their memoised moves, P2's deviation, the step observer, and the
    counters of the summary (off-record steps, P2's switches, re-planned episodes)."""

    def __init__(self, analysis: Analysis, strategy: Policy, p2_policy: P2Policy | None,
                 observer: StepCallback | None, p2_inference: Observer | None,
                 replanning: Replanning | None) -> None:
        ts, task, games = analysis.ts, analysis.task, analysis.games
        self.ts = ts
        self.model = Hypergame(ts, task, games, analysis.inference)
        real = None if p2_inference is None else Hypergame(ts, task, games, p2_inference)
        self.chain = _Chain(Hypergame(ts, task, games, TrackedObserver(self.model, real)),
                            self.model)
        self.root = self.chain.node(self.chain.game.initial())
        self.n_allowed = ts.allowed.sum(axis=1).tolist()
        self.strategy, self.p2_policy, self.observer = strategy, p2_policy, observer
        self.replanning = replanning
        self.recorded = getattr(strategy, "table", None)
        self.off_record: set[int] = set()
        self.fallback_a1: dict[int, int] = {}
        self.fallback_recorded = (None if replanning is None
                                  else getattr(replanning.fallback, "table", None))
        self.off_record_steps = self.p2_switched = self.p2_switches = self.replanned = 0
        self.p2_switched_in_play = 0
        # Without an observer, a detector or a deviating P2 (what `run` plays), each node's step
        # is memoised whole: (the one successor or -1, cumulative probabilities, successors,
        # off the records), or
        # _DRAWS where P2 draws her hypothesis (each step then draws its own trap set).
        self.plain = observer is None and replanning is None and p2_policy is None
        self.steps: dict[int, tuple[int, list[float], list[int], bool] | tuple[()]] = {}

    def episode(self, episode: int, horizon: int, rng: np.random.Generator,
                uniforms: _Uniforms) -> tuple[int, int]:
        """Play episode number `episode`: (its outcome code, its number of transitions)."""
        from hg2prism.analyses.detection import MismatchDetector, Mixture

        if self.plain:
            return self._plain_episode(episode, horizon, rng, uniforms)
        chain, plan = self.chain, self.replanning
        node, steps, switches, switched, in_play = self.root, 0, 0, False, False
        outcome = chain.status[node]
        detector = MismatchDetector(plan.alpha, plan.epsilon) if plan is not None else None
        while outcome < 0 and steps < horizon:
            steps += 1
            v, q, (m1, _) = chain.nodes[node]
            a1 = self._p1_move(node, switched, episode, steps)
            predicted = chain.predicted[node]
            a2, drawn = self._p2_move(rng, uniforms, steps, node)
            nxt = self._next(node, a1, a2, uniforms)
            if self.observer is not None:
                self._report(episode, steps, node, nxt, a1, a2, predicted, drawn)
            if chain.p2_hypothesis[nxt] != chain.p2_hypothesis[node]:
                switches += 1
                in_play |= bool(chain.status[nxt] < 0)       # the episode goes on
            if detector is not None and not switched:
                # as the detection experiment predicts her: by the posterior mixture when
                # she draws her hypothesis (docs/semantics.md §12)
                expected = (Mixture(self._prediction(node)) if self.model.observer.draws
                            else predicted)
                if detector.observe((v, q, m1), expected, a2, self.n_allowed[v]).rejected:
                    switched = True
                    self.replanned += 1
            node = nxt
            outcome = chain.status[node]
        self.p2_switches += switches
        self.p2_switched += switches > 0
        self.p2_switched_in_play += in_play
        return (TRUNCATED if outcome < 0 else outcome), steps

    def _plain_episode(self, episode: int, horizon: int, rng: np.random.Generator,
                       uniforms: _Uniforms) -> tuple[int, int]:
        """`episode` when the run is plain: the same steps, counts and random numbers (drawn
        from `uniforms`' block in the same order), each node's step looked up once."""
        chain, memo = self.chain, self.steps
        status, hypothesis = chain.status, chain.p2_hypothesis
        node, steps, switches, in_play, off = self.root, 0, 0, False, 0
        outcome = status[node]
        block, pos = uniforms.block, uniforms.pos
        while outcome < 0 and steps < horizon:
            steps += 1
            step = memo.get(node)
            if step is None:
                step = memo[node] = self._plain_step(node, episode, steps)
            if step:
                nxt, cumulative, targets, off_record = step
                off += off_record
                if nxt < 0:
                    if pos == _RANDOM_BLOCK:
                        block, pos = uniforms.rng.random(_RANDOM_BLOCK).tolist(), 0
                    u = block[pos]
                    pos += 1
                    k = 0
                    while u >= cumulative[k]:
                        k += 1
                    nxt = targets[k]
            else:       # P2 draws her hypothesis: her trap set, then the successor
                uniforms.block, uniforms.pos = block, pos
                a1 = self._p1_move(node, False, episode, steps)
                a2, _ = self._p2_move(rng, uniforms, steps, node)
                nxt = self._next(node, a1, a2, uniforms)
                block, pos = uniforms.block, uniforms.pos
            if hypothesis[nxt] != hypothesis[node]:
                switches += 1
                in_play |= bool(status[nxt] < 0)       # the episode goes on
            node = nxt
            outcome = status[node]
        uniforms.block, uniforms.pos = block, pos
        self.off_record_steps += off
        self.p2_switches += switches
        self.p2_switched += switches > 0
        self.p2_switched_in_play += in_play
        return (TRUNCATED if outcome < 0 else outcome), steps

    def _plain_step(self, node: int, episode: int, steps: int
                    ) -> tuple[int, list[float], list[int], bool] | tuple[()]:
        """A plain run's step from `node`, memoised by `_plain_episode`: the one successor (-1
        when there are several) and the successor table of P1's move and P2's one trap set,
        and whether the move is off the records; () when P2 draws her trap set."""
        if len(self.chain.p2_sets[node]) > 1:
            return ()
        a1 = self._p1_action(node, episode, steps)
        cumulative, targets = self.chain.transitions(node, a1, self.chain.p2_sets[node][0][0])
        single = targets[0] if len(targets) == 1 else -1
        return single, cumulative, targets, node in self.off_record

    def _p1_action(self, node: int, episode: int, steps: int) -> int:
        """P1's strategy's move at `node`, memoised (a node off the records is noted)."""
        a1 = self.chain.a1[node]
        if a1 < 0:
            v, q, (m1, _) = self.chain.nodes[node]
            try:
                a1 = self.chain.a1[node] = int(self.strategy.action(v, q, m1))
            except StrategyError as err:
                raise StrategyError(f"episode {episode}, step {steps}: {err}") from None
            if self.recorded is not None and (v, q, m1) not in self.recorded:
                self.off_record.add(node)
        return a1

    def _p1_move(self, node: int, switched: bool, episode: int, steps: int) -> int:
        """P1's move at `node`: the strategy's, or after a re-planning switch the fallback's
        (both memoised per node); steps off the strategy's records are counted."""
        if switched:
            v, q, (m1, _) = self.chain.nodes[node]
            a1 = self.fallback_a1.get(node, -1)
            if a1 < 0:
                try:
                    a1 = self.fallback_a1[node] = int(self.replanning.fallback.action(v, q, m1))
                except StrategyError as err:
                    raise StrategyError(f"episode {episode}, step {steps}: {err}") from None
            if self.fallback_recorded is not None and (v, q, m1) not in self.fallback_recorded:
                self.off_record_steps += 1
            return a1
        a1 = self._p1_action(node, episode, steps)
        if node in self.off_record:
            self.off_record_steps += 1
        return a1

    def _p2_move(self, rng: np.random.Generator, uniforms: _Uniforms, n: int,
                 node: int) -> tuple[int, int | None]:
        """The trap set P2 plays at `node`: pi2 of her real hypothesis (drawn with one uniform
        when she draws it), or what `p2_policy` makes of it; and the hypothesis she drew (None
        when she does not draw)."""
        drawn = self.chain.p2_sets[node]
        if len(drawn) == 1:
            own, hypothesis = drawn[0][0], None
        else:       # P2 draws her hypothesis (Bayesian "sample"): one uniform
            u, k, total = uniforms.next(), 0, drawn[0][1]
            while u >= total and k + 1 < len(drawn):
                k += 1
                total += drawn[k][1]
            own, hypothesis = drawn[k][0], self.chain.p2_draws[node][k]
        if self.p2_policy is None:
            return own, hypothesis
        v, _, (_, m2) = self.chain.nodes[node]
        a2 = int(self.p2_policy(rng, n, v, own, m2))
        if not (0 <= a2 < self.ts.n_sets and self.ts.allowed[v, a2]):
            raise ValueError(f"p2_policy returned trap set {a2}, which is not "
                             f"available in TS state {v}")
        return a2, hypothesis

    def _next(self, node: int, a1: int, a2: int, uniforms: _Uniforms) -> int:
        """The node the step leads to, drawn with one uniform when there are several."""
        cumulative, targets = self.chain.transitions(node, a1, a2)
        if len(targets) == 1:
            return targets[0]
        u = uniforms.next()
        k = 0
        while u >= cumulative[k]:
            k += 1
        return targets[k]

    def _report(self, episode: int, steps: int, node: int, nxt: int, a1: int, a2: int,
                predicted: int, drawn: int | None) -> None:
        """Pass the step to the observer, with P1's model's prediction as a mixture."""
        v, q, (m1, m2) = self.chain.nodes[node]
        w, q2, _ = self.chain.nodes[nxt]
        self.observer(StepRecord(episode=episode, n=steps, ts_state=v, q=q, memory=m1, a1=a1,
                                 a2=a2, predicted_a2=predicted, n_a2=self.n_allowed[v],
                                 p2_memory=m2, next_state=w, next_q=q2,
                                 prediction=self._prediction(node), p2_drawn=drawn))

    def _prediction(self, node: int) -> tuple[tuple[int, float], ...]:
        """The trap sets P1's model predicts at `node` with their probabilities (one pair
        unless P2 draws her hypothesis), sorted by set."""
        v, _, (m1, _) = self.chain.nodes[node]
        mixture: dict[int, float] = {}
        for a, p in self.model.trap_sets(v, m1):
            mixture[a] = mixture.get(a, 0.0) + p
        return tuple(sorted(mixture.items()))


def simulate_deceptive(analysis: Analysis, strategy: Policy, episodes: int, horizon: int, seed: int,
                       p2_policy: P2Policy | None = None, observer: StepCallback | None = None,
                       progress: bool = True,
                       p2_inference: Observer | None = None,
                       label: str = "simulate deceptive",
                       replanning: Replanning | None = None,
                       episode_streams: bool = False) -> SimulationSummary:
    """Play `episodes` episodes of P1's deceptive strategy against P2's inference (docs/semantics.md §8).

    `analysis` is a results.Analysis (its ts, task, games and inference are used).
    `strategy` is P1's Policy (deterministic: its moves are memoised per state), e.g. a
    Strategy.
    `p2_policy(rng, n, ts_state, predicted, memory) -> a2` replaces P2's model behaviour; there
    ``predicted`` = pi2_xh(v) for P2's real hypothesis and ``memory`` is P2's real memory
    (n = 1, 2, ... within each episode). It must return an allowed trap set of v.
    `p2_inference` runs P2's real inference with another model than P1's (analysis.inference);
    P1 still tracks its own model's memory to choose actions and predict traps.
    `observer(StepRecord)` is called once per transition; `label` names the progress bar.
    With `replanning`, P1 switches to its fallback after the detector's first rejection
    (SimulationSummary.replanned counts the episodes that switched).
    With `episode_streams` episode e draws its random numbers from its own generator,
    ``default_rng([seed, e])``, instead of one stream for the batch: two runs that differ in
    P1's play (re-planning or not) then play every episode identically up to where P1's moves
    differ, and episodes after it are not shifted (common random numbers).
    """
    _check_run(episodes, horizon)
    start_time = time.perf_counter()
    run = _DeceptiveRun(analysis, strategy, p2_policy, observer, p2_inference, replanning)
    rng = np.random.default_rng(seed)
    uniforms = _Uniforms(rng)
    outcomes = np.empty(episodes, dtype=np.int8)
    lengths = np.empty(episodes, dtype=np.int64)
    bar = Bar(label, episodes, progress)
    for episode in range(episodes):
        if episode_streams:
            rng = np.random.default_rng([seed, episode])
            uniforms = _Uniforms(rng)
        outcomes[episode], lengths[episode] = run.episode(episode, horizon, rng, uniforms)
        bar.update(episode + 1)
    seconds = time.perf_counter() - start_time
    bar.close(seconds)
    return _summary(outcomes, lengths, horizon, seed, seconds, run.off_record_steps,
                    run.p2_switched, run.p2_switches, run.replanned, run.p2_switched_in_play)


# ---------------------------------------------------------------------------------------------
# Nash runs
# ---------------------------------------------------------------------------------------------

def _cumulative(policy: np.ndarray, rows: np.ndarray, name: str) -> np.ndarray:
    """Row-wise cumulative sums of a mixed strategy, checked on the rows that are played."""
    if (policy[rows] < -1e-9).any():
        raise ValueError(f"{name} has negative probabilities")
    sums = policy[rows].sum(axis=1)
    if rows.any() and np.abs(sums - 1.0).max() > 1e-6:
        raise ValueError(f"{name}: the rows of non-absorbing game states must sum to 1 "
                         f"(found sums between {sums.min():.6g} and {sums.max():.6g})")
    cumulative = np.cumsum(np.clip(policy, 0.0, None), axis=1)
    cumulative /= np.where(cumulative[:, -1:] > 0, cumulative[:, -1:], 1.0)
    cumulative[:, -1] = 1.0 + 1e-12
    return cumulative


def _sample(cumulative: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Index of the first cumulative entry above u, row by row."""
    return (u[:, None] >= cumulative).sum(axis=1)


def exact_completion(ts: TransitionSystem, dfa: DFA, p1: np.ndarray, p2: np.ndarray,
                     horizon: int) -> float:
    """P(goal within `horizon` steps) when both players play the stationary mixed strategies
    p1 [G, A1max] and p2 [G, n_a2] over g = s * n_q + q: the number a simulation estimates."""
    arena = product(ts, dfa)
    weight = arena.prob * p1[:, :, None, None] * p2[:, None, :, None]       # [G, A1, A2, K]
    stop = ~arena.free
    rows = np.repeat(np.arange(arena.size), weight[0].size)
    matrix = sp.csr_matrix((weight.reshape(-1), (rows, arena.next.reshape(-1))),
                           shape=(arena.size, arena.size))
    matrix = sp.diags((~stop).astype(float)) @ matrix
    return bounded_reach(matrix, arena.goal, stop, arena.start, horizon)


def simulate_nash(ts: TransitionSystem, dfa: DFA, nash_p1: np.ndarray, nash_p2: np.ndarray,
                  episodes: int, horizon: int, seed: int,
                  progress: bool = True, label: str = "simulate nash") -> SimulationSummary:
    """Both players sample stationary mixed strategies over g = s * n_q + q (docs/semantics.md §7/§8).

    `nash_p1` is [G, ts.n_actions] (P1's distribution over action slots), `nash_p2` is [G, n_sets] (only trap sets
    allowed at s may have positive probability); rows of absorbing game states are ignored.
    Episodes run side by side (vectorised over episodes).
    """
    _check_run(episodes, horizon)
    start_time = time.perf_counter()
    n_q = dfa.n_states
    size = ts.n_states * n_q
    nash_p1 = np.asarray(nash_p1, dtype=float)
    nash_p2 = np.asarray(nash_p2, dtype=float)
    if nash_p1.shape != (size, ts.n_actions):
        raise ValueError(f"nash_p1 must have shape {(size, ts.n_actions)}, got {nash_p1.shape}")
    if nash_p2.shape != (size, ts.n_sets):
        raise ValueError(f"nash_p2 must have shape {(size, ts.n_sets)}, got {nash_p2.shape}")

    arena = product(ts, dfa)
    goal, fail, running, allowed = arena.goal, arena.fail, arena.free, arena.allowed
    if (nash_p2[running] > 1e-9)[~allowed[running]].any():
        raise ValueError("nash_p2 gives positive probability to a trap set that is not available")
    cum1 = _cumulative(nash_p1, running, "nash_p1")
    cum2 = _cumulative(np.where(allowed, nash_p2, 0.0), running, "nash_p2")
    nxt = arena.next
    cum_outcome = np.cumsum(arena.prob, axis=-1)
    cum_outcome[..., -1] = 1.0 + 1e-12

    rng = np.random.default_rng(seed)
    start = arena.start
    state = np.full(episodes, start, dtype=np.int64)
    lengths = np.zeros(episodes, dtype=np.int64)
    active = np.flatnonzero(running[state])
    bar = Bar(label, episodes, progress)
    bar.update(episodes - len(active))
    for _ in range(horizon):
        if not len(active):
            break
        g = state[active]
        u = rng.random((3, len(active)))
        a1 = _sample(cum1[g], u[0])
        a2 = _sample(cum2[g], u[1])
        k = _sample(cum_outcome[g, a1, a2], u[2])
        state[active] = nxt[g, a1, a2, k]
        lengths[active] += 1
        active = active[running[state[active]]]
        bar.update(episodes - len(active))
    outcomes = np.where(goal[state], GOAL, np.where(fail[state], FAIL, TRUNCATED)).astype(np.int8)
    seconds = time.perf_counter() - start_time
    bar.close(seconds)
    return _summary(outcomes, lengths, horizon, seed, seconds)
