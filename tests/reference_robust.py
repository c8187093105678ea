"""Independent robust value iteration (docs/semantics.md §13) on the explicit hypergame of
tests/reference.py. Imports nothing from hg2prism.

With a deviation budget delta, at every step where P2 may play several trap sets she plays the
predicted one, pi2_xh(v), with probability at least 1 - delta, and an adversary who sees P1's
move spreads the rest to minimise P1's value:

    R(s) = max_a1 [ (1 - delta) * E[R | a1, pred] + delta * min_{a2 in A2(v)} E[R | a1, a2] ]

(the plain expectation under pred where |A2(v)| = 1), goal 1, failure 0, least fixed point.
P2's memory evolves by the observation (v, a1) whatever she plays (section 5); a Bayesian
observer (tests/reference_bayes.py, decision "map") records (v, a1, a2) with a2 the set she
played (section 13). Value iteration
from 0 converges to the least fixed point from below; it stops when a sweep changes no value by
more than STOP.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import scipy.sparse as sp

from reference import ACTIONS, TRAPPED, World, grid_record

STOP = 1e-12
MAX_SWEEPS = 500_000


class RobustHypergame:
    """The hypergame states reachable when P2 may play any available trap set, and for each
    (state, move, trap set) the successor distribution."""

    def __init__(self, path, world: World | None = None) -> None:
        self.world = World(path) if world is None else world
        w = self.world
        bayes = hasattr(w, "log_posterior")      # a reference_bayes.BayesWorld
        dfa = w.task_dfa
        s0 = w.initial()
        self.initial = s0
        self.index: dict = {}
        self.states: list = []
        # rows[(i, a1)] = (predicted set, [(trap set, {successor: probability})])
        self.rows: dict = {}
        if s0 in ("goal", "fail"):
            return
        self.index[s0] = 0
        self.states.append(s0)
        queue = deque([s0])
        while queue:
            s = queue.popleft()
            v, q, M = s
            if bayes:
                (x, _), = w.draw(M).items()
                pred = w.pi2(x, v)
            else:
                pred = w.pi2(M[0], v)
            for a1 in ACTIONS:
                if not bayes:
                    M2 = w.eta(M, (v, a1))
                per_set = []
                for a2 in w.A2(v):
                    if bayes:
                        M2 = (tuple(M) + ((v, a1, a2),))[-w.window:]
                    succ: dict = {}
                    for v2, pr in w.outcomes(v, a1, a2).items():
                        if v2 == TRAPPED:
                            t = "fail"
                        else:
                            t = w.classify((v2, dfa.step(q, w.label(v2)), M2))
                        succ[t] = succ.get(t, 0.0) + pr
                        if t not in ("goal", "fail") and t not in self.index:
                            self.index[t] = len(self.states)
                            self.states.append(t)
                            queue.append(t)
                    per_set.append((a2, succ))
                self.rows[(self.index[s], a1)] = (pred, per_set)

    def _matrices(self, moves):
        """Sparse [rows, states] matrix and goal vector for the (state, move, set) rows of
        `moves` (state index -> list of moves); per (state, move): its pred row and its rows."""
        ri, ci, vals, goal = [], [], [], []
        pairs = []   # (state, a1, pred row, first row, number of rows)
        for i in range(len(self.states)):
            for a1 in moves(i):
                pred, per_set = self.rows[(i, a1)]
                first = len(goal)
                pred_row = None
                for a2, succ in per_set:
                    r = len(goal)
                    if a2 == pred:
                        pred_row = r
                    g = 0.0
                    for t, pr in succ.items():
                        if t == "goal":
                            g += pr
                        elif t != "fail":
                            ri.append(r)
                            ci.append(self.index[t])
                            vals.append(pr)
                    goal.append(g)
                pairs.append((i, a1, pred_row, first, len(per_set)))
        P = sp.csr_matrix((vals, (ri, ci)), shape=(len(goal), len(self.states)))
        return P, np.array(goal), pairs

    def _iterate(self, moves, deltas) -> np.ndarray:
        """Value iteration for several budgets at once: column k is delta = deltas[k]."""
        P, goal, pairs = self._matrices(moves)
        pred_rows = np.array([p[2] for p in pairs])
        firsts = np.array([p[3] for p in pairs])
        several = np.array([p[4] > 1 for p in pairs])[:, None]
        pair_state = np.array([p[0] for p in pairs])
        state_first = np.flatnonzero(np.r_[True, pair_state[1:] != pair_state[:-1]])
        delta = np.asarray(deltas, dtype=float)[None, :]
        x = np.zeros((len(self.states), delta.shape[1]))
        for _ in range(MAX_SWEEPS):
            e = goal[:, None] + P @ x
            worst = np.minimum.reduceat(e, firsts, axis=0)
            step = np.where(several, (1 - delta) * e[pred_rows] + delta * worst, e[pred_rows])
            y = np.maximum.reduceat(step, state_first, axis=0)
            change = float(np.max(np.abs(y - x)))
            x = y
            if change < STOP:
                return x
        raise RuntimeError("robust value iteration did not converge")

    def robust_values(self, deltas) -> list[float]:
        """R_delta at the initial state for each budget."""
        if self.initial in ("goal", "fail"):
            return [1.0 if self.initial == "goal" else 0.0] * len(deltas)
        return [float(v) for v in self._iterate(lambda i: ACTIONS, deltas)[0]]

    def robust_value(self, delta: float) -> float:
        """R_delta at the initial state."""
        return self.robust_values([delta])[0]

    def worst_case(self, records, delta: float) -> float:
        """The value P1's strategy `records` (strategy.json's records) guarantees against the
        adversary with budget delta: P1's moves fixed, the adversary minimising."""
        w = self.world
        table = {}
        for rec in map(grid_record, records):
            v = w.record_ts_state(rec["cell"], rec.get("traps"), rec.get("countdown"))
            B = tuple((w.record_ts_state(o["cell"], o.get("traps"), o.get("countdown")),
                       o["action"]) for o in rec["window"])
            table[(v, int(rec["q"]), (int(rec["hypothesis"]), B))] = rec["action"]
        if self.initial in ("goal", "fail"):
            return 1.0 if self.initial == "goal" else 0.0
        # the states reachable under the strategy and any deviation must all have a record
        seen = {0}
        queue = deque([0])
        while queue:
            i = queue.popleft()
            s = self.states[i]
            if s not in table:
                raise KeyError(f"no record for the reachable state {s}")
            pred, per_set = self.rows[(i, table[s])]
            for a2, succ in per_set:
                if delta == 0 and a2 != pred:
                    continue
                for t in succ:
                    if t not in ("goal", "fail") and self.index[t] not in seen:
                        seen.add(self.index[t])
                        queue.append(self.index[t])
        return float(self._iterate(
            lambda i: [table[self.states[i]]] if i in seen else ACTIONS[:1], [delta])[0, 0])
