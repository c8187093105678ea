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


def decode_states(model: BuiltModel, layout: Layout, ts: TransitionSystem, task: DFA,
                  window_hypotheses: Callable[[np.ndarray], np.ndarray] | None = None
                  ) -> DecodedStates:
    """The engine's states as hypergame states, read off their PRISM variables and labels.
    When the layout has no `hyp` variable, P2's hypothesis is derived from each state's window
    by `window_hypotheses`."""
    def column(name: str) -> np.ndarray:
        return model.variable(name, layout.initial_value(name))

    place = column("place")
    label = np.append(ts.place_label, 0)[place]
    q = task.delta[column("q"), label]
    width = 3 if layout.slot_sets else 2
    window = np.stack([np.stack([column(name) for name in names], axis=1)
                       for names in (layout.slot_variables(i) for i in range(1, layout.slots + 1))],
                      axis=1) if layout.slots else np.zeros((model.n_states, 0, width), dtype=np.int64)
    goal = model.transitions.labels["goal"]
    fail = model.transitions.labels["fail"]
    if layout.delay:
        traps, countdown = column("traps"), column("countdown")
    else:       # no standing traps without delay (docs/semantics.md §2): both are 0
        traps, countdown = (np.zeros(model.n_states, dtype=np.int64) for _ in range(2))
    if layout.hypothesis_variable:
        hypothesis = column("hyp")
    else:
        if window_hypotheses is None:
            raise ValueError("decoding this model needs the observer's window_hypotheses")
        hypothesis = np.asarray(window_hypotheses(window), dtype=np.int64)
    key = np.column_stack([place, traps, countdown, q, hypothesis, window.reshape(model.n_states, -1)])
    key[goal] = -2
    key[fail] = -3
    canonical = _dense_ids(_row_keys(key))
    return DecodedStates(place=place, traps=traps, countdown=countdown, q=q, hypothesis=hypothesis,
                         window=window, goal=goal, fail=fail, canonical=canonical,
                         n_canonical=int(canonical.max()) + 1 if canonical.size else 0)


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
    # the (state, action) part of each choice's key, repeated over its entries; the successor
    # added in place, and the entries of absorbing states or of probability 0 dropped
    counts = np.diff(moves.row_start)
    key = np.repeat((decoded.canonical[moves.source] * 5 + moves.action + 1) * n, counts)
    key += decoded.canonical[moves.target]
    keep = np.repeat(~absorbing[moves.source], counts)
    keep &= moves.probability > 0
    key = key[keep]
    n_triples = _count_distinct_in_place(key)
    loops = int(decoded.goal.any()) + int(decoded.fail.any())
    return decoded.n_canonical, n_triples + loops


def _count_distinct_in_place(keys: np.ndarray) -> int:
    """The number of distinct keys (sorts `keys`)."""
    keys.sort()
    return int(len(keys) > 0) + int(np.count_nonzero(keys[1:] != keys[:-1]))
