"""The hypergame's successor function in Python (docs/semantics.md §6, §9, §12): the one place
that says where a hypergame state (v, q, M) goes when P1 plays a move.

From (v, q, M) under P1's move a1, P2 plays a2 = pi2_x(v) for the hypothesis x she acts on
(`Observer.hypothesis_distribution(M)`: one hypothesis for a deterministic observer, each
hypothesis with its posterior probability for a Bayesian "sample" one), the robot moves to
v' with probability P(v' | v, a1, a2), the task DFA reads the label of v',
q' = delta(q, L(v')), and P2's memory becomes M' = update(M, (v, a1, a2)). A state is a goal
when q is final and the robot is not trapped, a failure when it is trapped or q is a sink
(`status`).

Everything that plays P1's policy against P2 in Python uses it: the Markov chain a strategy
induces (analyses/deception_value.induced_chain: V_naive), the online simulation
(analyses/simulation, and with it the detection experiment and re-planning). The simulation
runs P2's real inference beside P1's model of it; `TrackedObserver` is that pair seen as one
observer, so that the same successor function serves it.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable, Iterator, Sequence
from dataclasses import dataclass

import scipy.sparse as sp

from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.opponent.observer import Observation, Observer

__all__ = ["FAIL", "GOAL", "RUNNING", "HypergameState", "Hypergame", "TrackedObserver",
           "ExploredChain", "explore_chain"]

# The status of a hypergame state (the simulation's episode outcome codes share them).
FAIL, GOAL, RUNNING = 0, 1, -1

HypergameState = tuple[int, int, Hashable]     # (v, q, M)


class Hypergame:
    """The hypergame over `ts` x DFA(`task`) with P2's inference `observer` and her trap
    policies pi2_x (`games[x].trap_choice`), as a successor function. Of the observer only
    `initial_memory`, `update`, `hypothesis` and `hypothesis_distribution` are used (all a
    TrackedObserver has). Memory updates are memoised (an update is a function of its
    arguments)."""

    def __init__(self, ts: TransitionSystem, task: DFA, games: list,
                 observer: Observer) -> None:
        self.ts, self.task, self.observer = ts, task, observer
        self.trap_choice = [[int(a) for a in g.trap_choice] for g in games]
        self._label = ts.state_label().tolist()
        self._delta = task.delta.tolist()
        self._succ, self._prob = ts.succ, ts.prob
        self._outcomes = range(ts.succ.shape[-1])
        self._updates: dict[tuple[Hashable, Observation], Hashable] = {}

    def status(self, v: int, q: int) -> int:
        """GOAL, FAIL or RUNNING: trapped is a failure; then a final q is a goal, a sink q a
        failure, and so is a terminal arena state."""
        if v == self.ts.trapped:
            return FAIL
        if q in self.task.accepting:
            return GOAL
        if q in self.task.sink or self.ts.terminal[v]:
            return FAIL
        return RUNNING

    def initial(self) -> HypergameState:
        """(v0, delta(q_init, L(v0)), the observer's initial memory)."""
        v0 = self.ts.start_state
        return v0, self._delta[self.task.initial][self._label[v0]], self.observer.initial_memory()

    def predicted(self, v: int, memory: Hashable) -> int:
        """pi2_xh(v): the trap set of the hypothesis P2 acts on (`observer.hypothesis`)."""
        return self.trap_choice[self.observer.hypothesis(memory)][v]

    def trap_sets(self, v: int, memory: Hashable) -> list[tuple[int, float]]:
        """(a2, probability) pairs P2 plays from at v: pi2_x(v) for each (x, p) of
        `observer.hypothesis_distribution(memory)`, in its order and not merged."""
        return [(self.trap_choice[x][v], p)
                for x, p in self.observer.hypothesis_distribution(memory)]

    def update(self, memory: Hashable, observation: Observation) -> Hashable:
        """P2's memory after `observation` (v, a1, a2), memoised."""
        key = (memory, observation)
        new = self._updates.get(key)
        if new is None:
            new = self._updates[key] = self.observer.update(memory, observation)
        return new

    def after(self, state: HypergameState, a1: int, a2: int
              ) -> Iterator[tuple[HypergameState, float]]:
        """The successors of `state` when P1 plays a1 and P2 the trap set a2, with their
        probabilities P(v' | v, a1, a2) > 0, one per TS outcome in the TS's order (not
        merged: callers number and merge states their own way)."""
        v, q, memory = state
        new_memory = self.update(memory, (v, a1, a2))
        delta_q, label = self._delta[q], self._label
        for k in self._outcomes:
            p = float(self._prob[v, a1, a2, k])
            if p > 0.0:
                w = int(self._succ[v, a1, a2, k])
                yield (w, delta_q[label[w]], new_memory), p

    def successors(self, state: HypergameState, a1: int
                   ) -> Iterator[tuple[HypergameState, float]]:
        """The distribution over the successors of `state` under P1's move a1, P2 playing
        from `trap_sets`: pairs (successor, p_x * P(v' | v, a1, a2)) with positive
        probability, by hypothesis then TS outcome, not merged."""
        v, _, memory = state
        for a2, px in self.trap_sets(v, memory):
            for successor, p in self.after(state, a1, a2):
                p = px * p
                if p > 0.0:
                    yield successor, p


@dataclass(frozen=True, eq=False)
class TrackedObserver:
    """P1's model of P2's inference and P2's real inference, run side by side as one observer
    whose memory is the pair (M1, M2) (docs/semantics.md §9): `model` is the hypergame as P1
    models it, `real` the one with P2's real inference when it differs (else P2 runs the model).

    P2 plays from her real memory M2, which records the set she played. P1's model M1 records
    the set the model predicts when it says P2 is deterministic, and the set played when it
    says she draws her hypothesis (any set of the mixture is consistent with the model)."""

    model: Hypergame
    real: Hypergame | None = None

    @property
    def p2(self) -> Hypergame:
        """The hypergame with the inference P2 really runs."""
        return self.model if self.real is None else self.real

    def initial_memory(self) -> tuple[Hashable, Hashable]:
        return self.model.observer.initial_memory(), self.p2.observer.initial_memory()

    def hypothesis(self, memory: tuple[Hashable, Hashable]) -> int:
        """The hypothesis of P2's real memory."""
        return self.p2.observer.hypothesis(memory[1])

    def hypothesis_distribution(self, memory: tuple[Hashable, Hashable]
                                ) -> tuple[tuple[int, float], ...]:
        return self.p2.observer.hypothesis_distribution(memory[1])

    def update(self, memory: tuple[Hashable, Hashable], observation: Observation
               ) -> tuple[Hashable, Hashable]:
        """Both memories after (v, a1, a2). Without a separate real inference, P2's memory is
        taken to be the model's whenever the model records the set played: the two memories
        are assumed equal there, as they are until P2 plays an unpredicted set. (With an
        observer whose memory holds the sets, the Bayesian one, they differ after such a set,
        and this puts P2's memory back to the model's: the simulation has always done so, and
        the outputs of its deviation experiments depend on it.)"""
        m1, m2 = memory
        v, a1, a2 = observation
        drawn = self.model.trap_sets(v, m1)
        modelled = a2 if len(drawn) > 1 else drawn[0][0]
        n1 = self.model.update(m1, (v, a1, modelled))
        if self.real is None and modelled == a2:
            return n1, n1
        return n1, self.p2.update(m2, observation)


# ---------------------------------------------------------------------------------------------
# The Markov chain a strategy induces, explored
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ExploredChain:
    """A Markov chain explored breadth-first (`explore_chain`)."""

    states: list[Hashable]      # in the order found: `fixed` first, then from the start
    matrix: sp.csr_matrix       # one-step probabilities, those into one state summed
    start: int                  # the start's index


def explore_chain(start: Hashable, moves: Callable[[Hashable], Iterable[tuple[Hashable, float]]
                                                   | None],
                  fixed: Sequence[Hashable] = ()) -> ExploredChain:
    """The chain reachable from `start`, breadth-first: `moves(state)` gives its (successor,
    probability) pairs, or None for a state that stays (absorbing); `fixed` states come first
    in that order (the induced chain's merged failure and goal). moves is called once per
    state, in the states' order (a caller may record what it decided beside them)."""
    states = list(fixed)
    index = {state: i for i, state in enumerate(states)}

    def node(state: Hashable) -> int:
        i = index.get(state)
        if i is None:
            i = index[state] = len(states)
            states.append(state)
        return i

    first = node(start)
    rows: list[int] = []
    cols: list[int] = []
    values: list[float] = []
    i = 0
    while i < len(states):          # states grows as successors are found
        out = moves(states[i]) if i >= len(fixed) else None
        if out is not None:
            merged: dict[int, float] = {}
            for successor, p in out:
                j = node(successor)
                merged[j] = merged.get(j, 0.0) + p
            rows += [i] * len(merged)
            cols += list(merged)
            values += list(merged.values())
        i += 1
    n = len(states)
    return ExploredChain(states, sp.csr_matrix((values, (rows, cols)), shape=(n, n)), first)

