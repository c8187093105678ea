"""Playing a step-dependent strategy (the bounded objective, docs/semantics.md §6) with the
machinery built for memoryless ones: P1's model of P2's memory is extended with the number of
steps taken, so that the hypergame state P1 tracks, ``(v, q, (M, t))``, determines its move."""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from hg2prism.model.dynamics import TransitionSystem
from hg2prism.opponent.observer import Observation, Observer
from hg2prism.strategy.records import Strategy, StrategyError


@dataclass(frozen=True)
class TimedMemory:
    """P2's memory and the number of steps taken so far (capped, see `StepCounter`)."""

    memory: Hashable
    step: int

    @property
    def hypothesis(self) -> int:
        return self.memory.hypothesis

    @property
    def window(self) -> tuple:
        return self.memory.window


class StepCounter:
    """An observer that behaves exactly like `inner` and also counts the steps, up to `cap`."""

    def __init__(self, inner: Observer, cap: int) -> None:
        self.inner = inner
        self.cap = cap
        self.kind = inner.kind
        self.draws = inner.draws
        self.window = inner.window
        self.initial_hypothesis = inner.initial_hypothesis

    @property
    def n_hypotheses(self) -> int:
        return self.inner.n_hypotheses

    def initial_memory(self) -> TimedMemory:
        return TimedMemory(self.inner.initial_memory(), 0)

    def update(self, memory: TimedMemory, observation: Observation) -> TimedMemory:
        return TimedMemory(self.inner.update(memory.memory, observation),
                           min(memory.step + 1, self.cap))

    def hypothesis(self, memory: TimedMemory) -> int:
        return self.inner.hypothesis(memory.memory)

    def hypothesis_distribution(self, memory: TimedMemory) -> tuple[tuple[int, float], ...]:
        return self.inner.hypothesis_distribution(memory.memory)


class SteppedStrategy:
    """P1's step-dependent strategy read from strategy.json's records with a ``schedule``
    (runs ``[first step, last step, move]`` over the steps taken 0..bound-1)."""

    def __init__(self, records: Iterable[Mapping], ts: TransitionSystem, bound: int) -> None:
        records = tuple(records)
        base = Strategy.from_records(records, ts)
        if len(base.table) != len(records):
            raise StrategyError("strategy records repeat a state")
        self.bound = bound
        self.base = base        # the records as a Strategy (their values, for the explorer)
        self.row = {key: i for i, key in enumerate(base.table)}
        self.actions = np.full((len(records), bound), -1, dtype=np.int8)
        for i, (record, key) in enumerate(zip(records, base.table)):
            names = ts.action_names(key[0])
            for first, last, move in record.get("schedule", ()):
                if move not in names:
                    raise StrategyError(f"strategy record {i}: action {move!r} in its schedule "
                                        f"is not one of {', '.join(names)}")
                self.actions[i, int(first):int(last) + 1] = names.index(move)
        if (self.actions < 0).any():
            raise StrategyError("a strategy record's schedule does not cover every step")

    def action(self, ts_state: int, q: int, memory: TimedMemory) -> int:
        row = self.row.get((ts_state, q, memory.memory))
        if row is None:
            raise StrategyError(f"the strategy has no record for TS state {ts_state}, q={q}, "
                                f"{memory.memory}")
        return int(self.actions[row, min(memory.step, self.bound - 1)])
