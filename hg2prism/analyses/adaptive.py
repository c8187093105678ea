"""Adaptive deception in Python (docs/semantics.md §16): the adaptive hypergame's successor
function, and what a committed strategy is worth when P2's type is drawn from the prior.

The adaptive hypergame's states are (v, q, C, memories): C the consistent types (a tuple of
type indices, increasing) and their memories in the same order. From a running state under
P1's move a1, the consistent types are grouped by the action they play (pi2 of their
hypothesis at v); the group of alpha has probability w(C_alpha) / w(C), then v' follows
P(. | v, a1, alpha), q' = delta(q, L(v')), C' = C_alpha and every type of C_alpha updates its
memory with (v, a1, alpha). Each type's part is its `analyses.successor.Hypergame` (its update,
its prediction, the status of a state), so nothing here re-implements an observer.

V_commit(j): P1 plays type j's deceptive strategy on (v, q, M_j), with M_j the memory type j
would have after what P1 observed (the actions P2 played), and the leader-game move where the
strategy has no record (§11); P2 plays with her type k's memory. `Committed` is that pair of
memories as one observer, so the induced chain is analyses/deception_value.induced_chain's.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hg2prism import numeric
from hg2prism.analyses.successor import GOAL, RUNNING, Hypergame, explore_chain
from hg2prism.opponent.observer import Observation, Observer
from hg2prism.strategy.policy import Policy

__all__ = ["AdaptiveState", "AdaptiveKey", "AdaptiveGame", "Committed", "CommittedPolicy", "committed_game",
           "adaptive_policy", "AdaptiveChain", "adaptive_chain", "AdaptiveRun",
           "simulate_adaptive", "play_episode", "belief"]

AdaptiveState = tuple[int, int, tuple[int, ...], tuple[Hashable, ...]]   # (v, q, C, memories)


class AdaptiveGame:
    """The adaptive hypergame over the types' hypergames `games` (one per type, on the same TS,
    task and trap policies) with the prior `weights`."""

    def __init__(self, games: Sequence[Hypergame], weights: Sequence[float]) -> None:
        self.games, self.weights = list(games), [float(w) for w in weights]

    def status(self, state: AdaptiveState) -> int:
        return self.games[0].status(state[0], state[1])

    def initial(self) -> AdaptiveState:
        """(v0, q0, the types of positive weight, their initial memories)."""
        v0, q0, _ = self.games[0].initial()
        types = tuple(k for k, w in enumerate(self.weights) if w > 0)
        return v0, q0, types, tuple(self.games[k].observer.initial_memory() for k in types)

    def groups(self, state: AdaptiveState) -> list[tuple[int, float, tuple[int, ...]]]:
        """(alpha, probability, C_alpha): the consistent types grouped by the action they
        play, in the order of their first type."""
        v, _, types, memories = state
        members: dict[int, list[int]] = {}
        for k, memory in zip(types, memories):
            members.setdefault(self.games[k].predicted(v, memory), []).append(k)
        total = sum(self.weights[k] for k in types)
        return [(alpha, sum(self.weights[k] for k in group) / total, tuple(group))
                for alpha, group in members.items()]

    def successors(self, state: AdaptiveState, a1: int
                   ) -> Iterator[tuple[AdaptiveState, float]]:
        """(successor, probability > 0) pairs under P1's move a1, by group then TS outcome (not
        merged)."""
        for alpha, share, group in self.groups(state):
            for successor, p in self.after(state, a1, alpha, group):
                if share * p > 0.0:
                    yield successor, share * p

    def after(self, state: AdaptiveState, a1: int, alpha: int, group: tuple[int, ...]
              ) -> Iterator[tuple[AdaptiveState, float]]:
        """The successors when P2 plays alpha (the types `group` play it), with their
        probabilities P(v' | v, a1, alpha) > 0."""
        v, q, types, memories = state
        memory_of = dict(zip(types, memories))
        first = self.games[group[0]]
        updated = tuple(self.games[k].update(memory_of[k], (v, a1, alpha)) for k in group)
        for (w, q2, _), p in first.after((v, q, memory_of[group[0]]), a1, alpha):
            yield (w, q2, group, updated), p

    def running(self, state: AdaptiveState) -> bool:
        return self.status(state) == RUNNING

    def key(self, state: AdaptiveState) -> AdaptiveKey:
        """The canonical key of a state: the state while it runs, else "goal" or "fail" (the
        absorbing states merged, docs/semantics.md §16)."""
        status = self.status(state)
        return state if status == RUNNING else ("goal" if status == GOAL else "fail")


AdaptiveKey = AdaptiveState | str       # a running state, or "goal" / "fail"


@dataclass(frozen=True, eq=False)
class Committed:
    """P1's model of type j and P2's real type k run side by side as one observer: the memory
    is (M_j, M_k), both updated with what was observed (v, a1, the action P2 played); P2 plays
    from M_k. (successor.TrackedObserver pairs memories too, for detection's mismatches: there
    P1's model records the set it predicted wherever it takes P2 to be deterministic, §9; here
    it records the set played, which P1 sees, §16.)"""

    model: Observer
    real: Observer

    def initial_memory(self) -> tuple[Hashable, Hashable]:
        return self.model.initial_memory(), self.real.initial_memory()

    def hypothesis(self, memory: tuple[Hashable, Hashable]) -> int:
        return self.real.hypothesis(memory[1])

    def hypothesis_distribution(self, memory: tuple[Hashable, Hashable]
                                ) -> tuple[tuple[int, float], ...]:
        return self.real.hypothesis_distribution(memory[1])

    def update(self, memory: tuple[Hashable, Hashable], observation: Observation
               ) -> tuple[Hashable, Hashable]:
        return (self.model.update(memory[0], observation),
                self.real.update(memory[1], observation))


@dataclass(frozen=True, eq=False)
class CommittedPolicy:
    """Type j's strategy read on the model's memory of a Committed pair."""

    strategy: Policy

    def action(self, ts_state: int, q: int, memory: tuple[Hashable, Hashable]) -> int:
        return self.strategy.action(ts_state, q, memory[0])


def committed_game(model: Hypergame, real: Hypergame) -> Hypergame:
    """The hypergame in which P2 infers as `real` while P1 tracks `model`'s memory."""
    return Hypergame(model.ts, model.task, [_Choices(c) for c in real.trap_choice],
                     Committed(model.observer, real.observer))


@dataclass(frozen=True)
class _Choices:
    trap_choice: Sequence[int]


# ---------------------------------------------------------------------------------------------
# The adaptive strategy played: its chain, exact within-horizon numbers, simulation
# ---------------------------------------------------------------------------------------------

AdaptivePolicy = Callable[[AdaptiveState], int]


def adaptive_policy(records: Sequence[Mapping], game: AdaptiveGame, names: Sequence[str]
                    ) -> AdaptivePolicy:
    """P1's adaptive strategy from its strategy.json records (strategy/adaptive.py): each
    consistent type's memory read as that type's records are (strategy/records.py)."""
    from hg2prism.strategy.records import StrategyError, read_record

    ts = game.games[0].ts
    index = {name: k for k, name in enumerate(names)}
    table: dict[AdaptiveState, int] = {}
    for i, record in enumerate(records):
        where = f"adaptive strategy record {i}"
        try:
            types = tuple(sorted(index[name] for name in record["types"]))
            read = [read_record(ts, {**record, "hypothesis": record["types"][names[k]][
                "hypothesis"], "window": record["types"][names[k]]["window"]}, where)
                for k in types]
        except (KeyError, TypeError) as err:
            raise StrategyError(f"{where}: bad or missing field ({err})") from None
        if not read:
            raise StrategyError(f"{where}: no consistent type")
        (v, q, _), action = read[0]
        key = (v, q, types, tuple(m for (_, _, m), _ in read))
        if table.setdefault(key, action) != action:
            raise StrategyError(f"{where}: conflicting actions for the same state")

    def policy(state: AdaptiveState) -> int:
        try:
            return table[state]
        except KeyError:
            raise StrategyError(f"no adaptive strategy record for state {state}") from None

    return policy


@dataclass(frozen=True, eq=False)
class AdaptiveChain:
    """The Markov chain P1's adaptive strategy induces on the adaptive hypergame, over the states
    reachable from the initial one (absorbing ones kept apart, so that C is known in each)."""

    states: list[AdaptiveState]
    matrix: sp.csr_matrix
    goal: np.ndarray          # absorbing goal states
    stop: np.ndarray          # absorbing states
    identified: np.ndarray    # one consistent type: P1's belief singles out P2's type

    def within(self, horizon: int) -> float:
        """P(goal within `horizon` steps) from the initial state (state 0)."""
        return numeric.bounded_reach(self.matrix, self.goal, self.stop, 0, horizon)

    def identified_within(self, horizon: int) -> float:
        """P(P1's belief singles out P2's type within `horizon` steps)."""
        return numeric.bounded_reach(self.matrix, self.identified, self.stop | self.identified,
                                     0, horizon)

    def identified_in_play_within(self, horizon: int) -> float:
        """P(P1's belief singles out P2's type within `horizon` - 1 steps, at a state where the
        episode goes on: a step after which P1 can act on it within the horizon)."""
        return numeric.bounded_reach(self.matrix, self.identified & ~self.stop,
                                     self.stop | self.identified, 0, max(horizon - 1, 0))


def adaptive_chain(game: AdaptiveGame, policy: AdaptivePolicy) -> AdaptiveChain:
    explored = explore_chain(game.initial(), lambda state: game.successors(state, policy(state))
                             if game.running(state) else None)
    states = explored.states
    status = np.array([game.status(s) for s in states])
    return AdaptiveChain(states, explored.matrix,
                         goal=status == GOAL, stop=status != RUNNING,
                         identified=np.array([len(s[2]) == 1 for s in states]))


@dataclass(frozen=True)
class AdaptiveRun:
    """Simulated episodes of the adaptive strategy, P2's type drawn from the prior in each."""

    episodes: int
    completed: int                  # reached the goal within the horizon
    identified: int                 # P1's belief singled out the true type within the horizon
    identification_steps: tuple[int, ...]   # the step at which it did, per identified episode
    by_type: tuple[tuple[int, int], ...]    # per type: (episodes drawn, completed)
    identified_in_play: int         # identified at a step after which the episode went on


def play_episode(game: AdaptiveGame, policy: AdaptivePolicy, k: int, horizon: int,
                 rng: np.random.Generator) -> list[AdaptiveState]:
    """The states of one episode against P2 of type k (at most `horizon` steps): P1 plays
    `policy`, P2 her type's action (that of k's group: k stays consistent), the TS moves."""
    state = game.initial()
    trace = [state]
    for _ in range(horizon):
        if not game.running(state):
            break
        alpha, _, group = next(g for g in game.groups(state) if k in g[2])
        u, total = rng.random(), 0.0
        for successor, p in game.after(state, policy(state), alpha, group):
            total += p
            if u < total:
                break
        state = successor
        trace.append(state)
    return trace


def belief(game: AdaptiveGame, state: AdaptiveState) -> list[float]:
    """P1's belief over the types in `state`: the prior restricted to C, normalised."""
    total = sum(game.weights[k] for k in state[2])
    return [game.weights[k] / total if k in state[2] else 0.0
            for k in range(len(game.weights))]


def simulate_adaptive(game: AdaptiveGame, policy: AdaptivePolicy, episodes: int, horizon: int,
                      seed: int) -> AdaptiveRun:
    """Each episode draws P2's type k from the prior; P1 plays `policy` on the adaptive state,
    P2 plays type k's action (always that of k's group: k stays consistent) and the TS moves."""
    rng = np.random.default_rng(seed)
    weights = np.array(game.weights) / sum(game.weights)
    drawn = rng.choice(len(weights), size=episodes, p=weights)
    completed = identified = in_play = 0
    steps: list[int] = []
    by_type = [[0, 0] for _ in weights]
    for k in drawn.tolist():
        trace = play_episode(game, policy, k, horizon, rng)
        state, found = trace[-1], next((i for i, s in enumerate(trace) if len(s[2]) == 1), None)
        by_type[k][0] += 1
        if game.status(state) == GOAL:
            completed += 1
            by_type[k][1] += 1
        if found is not None:
            identified += 1
            steps.append(found)
            in_play += found < len(trace) - 1       # P1 played on, knowing
    return AdaptiveRun(episodes, completed, identified, tuple(steps),
                       tuple(tuple(t) for t in by_type), in_play)
