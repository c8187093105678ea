"""The product TS x DFA (docs/semantics.md §§2-4, 7): the arena of P2's perceptual games, of the
symmetric baselines and of their simulations.

A product state is g = s * n_q + q: TS state s, DFA state q after reading the label of s. Every
step both players choose (P1 a move, P2 a trap set), the TS moves to one of its outcomes v' and
the DFA reads L(v'). Goal states (q final, robot not trapped) and failure states (trapped, or q
a sink) are absorbing; their rows of `next`/`prob` are never used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.numeric.graph import backward_reach


@dataclass(frozen=True, eq=False)
class Product:
    """TS x DFA as arrays over product states g = s * n_q + q."""

    ts: TransitionSystem
    dfa: DFA
    next: np.ndarray          # [G, A1, A2, K] successor product state of each outcome
    prob: np.ndarray          # [G, A1, A2, K] its probability
    allowed: np.ndarray       # [G, A2] P2's available trap sets
    goal: np.ndarray          # [G] q final and the robot not trapped
    fail: np.ndarray          # [G] trapped, or q a sink (and not goal)
    start: int                # the initial product state: (start, delta(iota, L(start)))

    @property
    def size(self) -> int:
        return self.next.shape[0]

    @property
    def free(self) -> np.ndarray:
        """[G] the states where the game goes on."""
        return ~(self.goal | self.fail)

    def state(self, s: int, q: int) -> int:
        return product_state(s, q, self.dfa.n_states)


def product_state(s, q, n_q: int):
    """g = s * n_q + q: the product state of TS state s and DFA state q (numbers or arrays),
    the one numbering of TS x DFA every game, baseline and policy uses."""
    return s * n_q + q


def product(ts: TransitionSystem, dfa: DFA) -> Product:
    """TS x DFA: the one construction of the product every game, baseline and simulation
    plays on (each builds its own, in milliseconds on the TS's few thousand states)."""
    n_q = dfa.n_states
    label = ts.state_label()
    # The DFA reads the label of the state being entered: q' = delta(q, L(v')). Written one
    # DFA state at a time into [S, n_q, ...] (a transposed copy of the whole table was several
    # times slower).
    letter = label[ts.succ]                                           # [S, A1, A2, K]
    nxt = np.empty((ts.n_states, n_q) + ts.succ.shape[1:],
                   dtype=np.result_type(ts.succ, dfa.delta))
    for q in range(n_q):
        nxt[:, q] = product_state(ts.succ, dfa.delta[q][letter], n_q)
    nxt = nxt.reshape(ts.n_states * n_q, *ts.succ.shape[1:])
    q_of = np.tile(np.arange(n_q), ts.n_states)
    s_of = np.repeat(np.arange(ts.n_states), n_q)
    trapped = s_of == ts.trapped                     # tried first: trapped is a failure
    goal = np.isin(q_of, list(dfa.accepting)) & ~trapped
    # a terminal arena state ends the episode: a goal when q is final, else a failure
    fail = trapped | ((np.isin(q_of, list(dfa.sink)) | ts.terminal[s_of]) & ~goal)
    start = product_state(ts.start_state, int(dfa.delta[dfa.initial, label[ts.start_state]]), n_q)
    return Product(ts=ts, dfa=dfa, next=nxt, prob=np.repeat(ts.prob, n_q, axis=0),
                   allowed=np.repeat(ts.allowed, n_q, axis=0), goal=goal, fail=fail,
                   start=int(start))


def completable(ts: TransitionSystem, dfa: DFA) -> bool:
    """Whether some play completes `dfa`'s task from the start: some moves of both players and
    outcomes of positive probability that reach a goal state of TS x DFA. False means that
    nothing either player does matters: every value of the world is 0 (an unreachable region,
    an arena whose edges never lead to a labelled state)."""
    p = product(ts, dfa)
    step = (p.prob > 0) & p.allowed[:, None, :, None] & p.free[:, None, None, None]
    rows = np.broadcast_to(np.arange(p.size).reshape(-1, 1, 1, 1), step.shape)[step]
    return bool(backward_reach(rows, p.next[step], np.flatnonzero(p.goal), p.size)[p.start])
