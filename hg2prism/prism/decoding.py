"""The engine's states read as hypergame states (docs/semantics.md §6), by the layout of
prism/hypergame.py: which PRISM variable holds what.

The model encodes (v, q_prev, M) with the DFA one step behind, so several of its states can be
one canonical state (v, q, M) of docs/semantics.md §6; `DecodedStates.canonical` maps each to
its canonical id, and `canonical_size` counts canonical states and transitions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from hg2prism.engines.engine import BuiltModel, Transitions
from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.opponent.observer import Memory
from hg2prism.prism.hypergame import Layout


@dataclass(frozen=True, eq=False)
class DecodedStates:
    """A model checker's states as docs/semantics.md §6 hypergame states."""

    place: np.ndarray         # arena state index (the number of arena states once trapped)
    traps: np.ndarray         # P2's standing action (0 when delay is 0)
    countdown: np.ndarray
    q: np.ndarray             # DFA state after reading the current state's label
    hypothesis: np.ndarray
    window: np.ndarray        # [n, slots, 2] (TS state, action slot), or [n, slots, 3] with P2's
                              # action in force (Bayesian observer); -1 for empty slots
    goal: np.ndarray          # bool
    fail: np.ndarray          # bool
    canonical: np.ndarray     # canonical id; goal states share one id, failure states another
    n_canonical: int

    def ts_states(self, ts: TransitionSystem, rows: np.ndarray | None = None) -> np.ndarray:
        """The TS state of each state (of `rows`), meaningful where it is not trapped."""
        at = slice(None) if rows is None else rows
        return ts.state(self.place[at], self.traps[at], self.countdown[at])

    def memories(self, rows: np.ndarray | None = None) -> list[Memory]:
        """P2's memory in each state (of `rows`): her hypothesis and her window, empty slots
        left out (the key strategy.json's records are read back to, strategy/records.py)."""
        at = slice(None) if rows is None else rows
        return [Memory(h, tuple(tuple(entry) for entry in window if entry[0] >= 0))
                for h, window in zip(self.hypothesis[at].tolist(), self.window[at].tolist())]


def decode_states(model: BuiltModel, layout: Layout, ts: TransitionSystem, task: DFA,
                  window_hypotheses: Callable[[np.ndarray], np.ndarray] | None = None
                  ) -> DecodedStates:
    """The engine's states as hypergame states, read off their PRISM variables and labels.
    When the layout has no `hyp` variable, P2's hypothesis is derived from each state's window
    by `window_hypotheses`."""
    def column(name: str) -> np.ndarray:
        return _narrow(model.variable(name, layout.initial_value(name)))

    place = column("place")
    label = np.append(ts.place_label, 0)[place]
    q = _narrow(task.delta[column("q"), label])
    width = 3 if layout.slot_sets else 2
    window = np.stack([np.stack([column(name) for name in names], axis=1)
                       for names in (layout.slot_variables(i) for i in range(1, layout.slots + 1))],
                      axis=1) if layout.slots else np.zeros((model.n_states, 0, width), dtype=np.int64)
    goal = model.transitions.labels["goal"]
    fail = model.transitions.labels["fail"]
    if layout.delay:
        traps, countdown = column("traps"), column("countdown")
    else:       # no standing traps without delay (docs/semantics.md §2): both are 0
        traps, countdown = (np.zeros(model.n_states, dtype=np.int32) for _ in range(2))
    if layout.hypothesis_variable:
        hypothesis = column("hyp")
    else:
        if window_hypotheses is None:
            raise ValueError("decoding this model needs the observer's window_hypotheses")
        hypothesis = _narrow(np.asarray(window_hypotheses(window), dtype=np.int64))
    key = np.column_stack([place, traps, countdown, q, hypothesis, window.reshape(model.n_states, -1)])
    key[goal] = -2
    key[fail] = -3
    canonical = _dense_ids(_row_keys(key))
    return DecodedStates(place=place, traps=traps, countdown=countdown, q=q, hypothesis=hypothesis,
                         window=window, goal=goal, fail=fail, canonical=canonical,
                         n_canonical=int(canonical.max()) + 1 if canonical.size else 0)


def _narrow(values: np.ndarray) -> np.ndarray:
    """Integer columns as int32 when they fit (a state's variables are small numbers: half
    the memory of the decoded states of a large model)."""
    values = np.asarray(values)
    if values.size and (values.min() < -2 ** 31 or values.max() >= 2 ** 31):
        return values
    return values.astype(np.int32, copy=False)


def row_keys(rows: np.ndarray) -> np.ndarray:
    """One integer per row of `rows`, equal exactly when the rows are equal, numbered 0..n-1
    in key order: how canonical states are numbered."""
    return _dense_ids(_row_keys(rows))


def _row_keys(rows: np.ndarray) -> np.ndarray:
    """One integer per row, equal exactly when the rows are equal: sorting one column is far
    faster than np.unique(axis=0) on millions of rows."""
    shifted = rows - rows.min(axis=0)
    radix = shifted.max(axis=0) + 1
    if np.sum(np.log2(radix.astype(float))) < 62:
        key = np.zeros(len(rows), dtype=np.int64)
        for column, base in zip(shifted.T, radix):
            key = key * int(base) + column
        return key
    _, inverse = np.unique(rows, axis=0, return_inverse=True)   # keys too wide for int64
    return inverse.reshape(-1)


def _dense_ids(keys: np.ndarray) -> np.ndarray:
    """0..n-1 numbering of the distinct keys, in key order (np.unique's inverse, by sorting:
    numpy 2.4's np.unique is many times slower on millions of keys)."""
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    ids = np.empty(len(keys), dtype=np.int64)
    ids[order] = np.cumsum(np.r_[True, ordered[1:] != ordered[:-1]]) - 1
    return ids


def canonical_size(decoded: DecodedStates, moves: Transitions) -> tuple[int, int]:
    """docs/semantics.md §6: canonical states, and (state, action, successor) triples after merging."""
    absorbing = decoded.goal | decoded.fail
    n = decoded.n_canonical   # one integer per (state, action, successor): n*n*5 < 2**63
    # one key per entry of a non-absorbing state's choice with positive probability, written
    # block of choices by block into one array (the blocks' temporaries stay small)
    counts = np.diff(moves.row_start)
    live = ~absorbing[moves.source]
    key = np.empty(int(counts[live].sum()), dtype=np.int64)
    filled = 0
    for low in range(0, len(counts), SIZE_BLOCK):
        high = min(len(counts), low + SIZE_BLOCK)
        first, last = int(moves.row_start[low]), int(moves.row_start[high])
        block = np.repeat((decoded.canonical[moves.source[low:high]] * 5
                           + moves.action[low:high] + 1) * n, counts[low:high])
        block += decoded.canonical[moves.target[first:last]]
        keep = np.repeat(live[low:high], counts[low:high])
        keep &= moves.probability[first:last] > 0
        kept = np.count_nonzero(keep)
        key[filled:filled + kept] = block[keep]
        filled += kept
    n_triples = _count_distinct_in_place(key[:filled])
    loops = int(decoded.goal.any()) + int(decoded.fail.any())
    return decoded.n_canonical, n_triples + loops


SIZE_BLOCK = 1 << 20      # choices per block of canonical_size's keys


def _count_distinct_in_place(keys: np.ndarray) -> int:
    """The number of distinct keys (sorts `keys`)."""
    keys.sort()
    return int(len(keys) > 0) + int(np.count_nonzero(keys[1:] != keys[:-1]))
