"""Independent reference for what the deception is worth (docs/semantics.md §11).

Written from the semantics alone, importing nothing from ``hg2prism``: it builds on the explicit
world, games, inference and hypergame of ``tests/reference.py`` (itself written from the
semantics; ``tests/reference_bayes.py`` for the Bayesian observer of §12, "map" decision) and
computes, with dictionaries and breadth-first search,

* V_static: the MDP on (v, q) (task DFA state tracked) in which P2 plays pi2 of her initial
  hypothesis at every step, solved exactly by ``reference.solve_reach_game``;
* V_naive: P1 answers the trap set in force with its leader-game move (the maximisers of
  Q_phi(v, q, ., a2) within 1e-9, then the largest discounted score under the leader pair,
  relative ties of 1e-12, then N, E, S, W), P2 runs her inference; the value of the chain this
  pair induces on the hypergame, by ``reference.dtmc_reach``;
* the probability that P2 changes her hypothesis at least once within a horizon when P1 plays a
  given strategy (records in the strategy.json format).
"""

from __future__ import annotations

import tomllib
from collections import deque

import numpy as np
import scipy.sparse as sp

from reference import (ACTIONS, TIE_P2, TRAPPED, World, dtmc_reach, grid_record,
                       solve_reach_game)
from reference_bayes import BayesWorld

ANSWER_TIE = 1e-9
DISCOUNT = 0.9
SCORE_TIE = 1e-12


class Deception:
    """The §11 values of one world file."""

    def __init__(self, path) -> None:
        self.w = World(path)
        self.dfa = self.w.task_dfa
        self._leader_a2 = {}
        self._speed = None

    def hypothesis(self, M) -> int:
        """The hypothesis P2 acts on with memory M (CUSUM, §5: the first entry)."""
        return M[0]

    # ----- helpers on the task's product -----
    def _step(self, q, v2):
        """'goal', 'fail' or the tracked (v2, q2) after entering v2 from DFA state q."""
        if v2 == TRAPPED:
            return "fail"
        q2 = self.dfa.step(q, self.w.label(v2))
        if q2 in self.dfa.acc:
            return "goal"
        if q2 in self.dfa.sink or self.w.terminal(v2):     # a terminal arena state ends it
            return "fail"
        return (v2, q2)

    def _start(self):
        w = self.w
        return self._step(self.dfa.init, w.v0) if w.v0 != TRAPPED else "fail"

    # ----- V_static -----
    def static_mdp(self):
        """(order, rows): the states (v, q) of the MDP where P2 plays pi2 of her initial
        hypothesis at every step, reachable from the start, and per state one successor
        dictionary {state index, "goal" or "fail": probability} per move of ACTIONS. None
        when the start is already "goal" or "fail"."""
        w = self.w
        s0 = self._start()
        if s0 in ("goal", "fail"):
            return None
        index = {s0: 0}
        order = [s0]
        queue = deque([s0])
        rows_of = []
        while queue:
            v, q = queue.popleft()
            a2 = w.pi2(w.h0, v)
            rows = []
            for a1 in ACTIONS:
                succ = {}
                for v2, p in w.outcomes(v, a1, a2).items():
                    t = self._step(q, v2)
                    if t not in ("goal", "fail") and t not in index:
                        index[t] = len(order)
                        order.append(t)
                        queue.append(t)
                    key = t if t in ("goal", "fail") else index[t]
                    succ[key] = succ.get(key, 0.0) + p
                rows.append(succ)
            rows_of.append(rows)
        return order, rows_of

    def v_static(self) -> float:
        mdp = self.static_mdp()
        if mdp is None:
            return 1.0 if self._start() == "goal" else 0.0
        _, rows_of = mdp
        state_pairs, pair_rows, row_succ = [], [], []
        for i, rows in enumerate(rows_of):
            ids = []
            for succ in rows:
                ids.append(len(row_succ))
                row_succ.append(list(succ.items()))
            state_pairs.append([i])
            pair_rows.append(ids)
        x = solve_reach_game(state_pairs, pair_rows, row_succ)
        return min(1.0, max(0.0, float(x[0])))

    # ----- the leader game's pair and its discounted scores -----
    def leader_a2(self, v, q):
        """P2's leader strategy at the tracked (v, q): §4's rule on Q_phi."""
        key = (v, q)
        if key not in self._leader_a2:
            w, task = self.w, self.w.task
            acts = w.A2(v)
            m = [max(w.Q(task, v, q, a1, a2) for a1 in w.actions(v)) for a2 in acts]
            tied = [a2 for a2, mv in zip(acts, m) if mv <= min(m) + TIE_P2]
            self._leader_a2[key] = (w.standing(v) if w.delay > 0 and w.standing(v) in tied
                                    else tied[-1] if w.tie_last else tied[0])
        return self._leader_a2[key]

    def _gain(self, v, q, a1, a2, scores):
        total = 0.0
        for v2, p in self.w.outcomes(v, a1, a2).items():
            t = self._step(q, v2)
            if t == "goal":
                total += p
            elif t != "fail":
                total += p * DISCOUNT * scores.get(t, 0.0)
        return total

    def speed(self):
        """W(v, q) of the leader pair: the largest discounted reach score over P1's moves
        within 1e-9 of V_lead against P2's leader set, iterated until the change is < 1e-12."""
        if self._speed is not None:
            return self._speed
        w, task = self.w, self.w.task
        _, values = w.game_values(task)
        nodes = list(values)
        index = {s: i for i, s in enumerate(nodes)}
        # One row per (node, optimal move): its chance of entering the goal now and its
        # outcomes' probabilities into other nodes.
        row_node, goal_now, ri, ci, vals = [], [], [], [], []
        for i, (v, q) in enumerate(nodes):
            a2 = self.leader_a2(v, q)
            for a1 in w.actions(v):
                if w.Q(task, v, q, a1, a2) < values[(v, q)] - 1e-9:
                    continue
                r = len(row_node)
                row_node.append(i)
                g = 0.0
                for v2, p in w.outcomes(v, a1, a2).items():
                    t = self._step(q, v2)
                    if t == "goal":
                        g += p
                    elif t != "fail":
                        ri.append(r)
                        ci.append(index[t])
                        vals.append(p)
                goal_now.append(g)
        row_node = np.array(row_node, dtype=np.int64)
        goal_now = np.array(goal_now)
        moves = sp.csr_matrix((vals, (ri, ci)), shape=(len(row_node), len(nodes)))
        x = np.zeros(len(nodes))
        for _ in range(100_000):
            gain = goal_now + DISCOUNT * (moves @ x)
            new = np.full(len(nodes), -np.inf)
            np.maximum.at(new, row_node, gain)
            new[np.isinf(new)] = 0.0
            if np.abs(new - x).max(initial=0.0) < 1e-12:
                break
            x = new
        scores = {s: float(x[i]) for i, s in enumerate(nodes)}
        self._speed = scores
        return scores

    def naive_move(self, v, q, a2):
        """P1's naive answer to the trap set a2 at the tracked (v, q)."""
        w, task = self.w, self.w.task
        qs = {a1: w.Q(task, v, q, a1, a2) for a1 in w.actions(v)}
        best = max(qs.values())
        candidates = [a1 for a1 in w.actions(v) if qs[a1] >= best - ANSWER_TIE]
        scores = self.speed()
        gain = {a1: self._gain(v, q, a1, a2, scores) for a1 in candidates}
        top = max(gain.values())
        return next(a1 for a1 in candidates if gain[a1] >= top - SCORE_TIE * abs(top))

    # ----- V_naive -----
    def naive_table(self):
        """{hypergame state: P1's move} over the states the naive pair reaches."""
        w = self.w
        s0 = w.initial()
        table = {}
        if s0 in ("goal", "fail"):
            return s0, table
        queue = deque([s0])
        seen = {s0}
        while queue:
            s = queue.popleft()
            v, q, M = s
            table[s] = self.naive_move(v, q, w.pi2(self.hypothesis(M), v))
            for t in w.hyper_successors(s, table[s]):
                if t not in ("goal", "fail") and t not in seen:
                    seen.add(t)
                    queue.append(t)
        return s0, table

    def v_naive(self) -> float:
        s0, table = self.naive_table()
        return chain_value(self.w, s0, table)


class BayesDeception(Deception):
    """The §11 values against the Bayesian observer of §12 with the "map" decision (her memory
    is the window W; she acts on the posterior's first most probable hypothesis; V_static's
    first guess is the prior's)."""

    def __init__(self, path) -> None:
        super().__init__(path)
        self.w = BayesWorld(path)
        self.dfa = self.w.task_dfa
        if self.w.decision != "map":
            raise ValueError("the naive value here needs the 'map' decision")

    def hypothesis(self, M) -> int:
        (x,) = self.w.draw(M)
        return x


def deception(path) -> Deception:
    """The §11 reference of a world file, for its observer (`[inference] kind`)."""
    with open(path, "rb") as fh:
        kind = tomllib.load(fh)["inference"].get("kind", "cusum")
    return BayesDeception(path) if kind == "bayes" else Deception(path)


def chain_successors(w: World, table) -> list:
    """The chain the move table {state: move} induces on the hypergame, states numbered in
    the table's order: per state its [(state index, "goal" or "fail", probability)]."""
    index = {s: i for i, s in enumerate(table)}
    return [[(t if t in ("goal", "fail") else index[t], p)
             for t, p in w.hyper_successors(s, table[s]).items()] for s in table]


def chain_value(w: World, s0, table) -> float:
    """P(F goal) from s0 in the chain the move table induces on the hypergame."""
    if s0 in ("goal", "fail"):
        return 1.0 if s0 == "goal" else 0.0
    index = {s: i for i, s in enumerate(table)}
    x = dtmc_reach(chain_successors(w, table))
    return min(1.0, max(0.0, float(x[index[s0]])))


def record_table(w: World, records) -> dict:
    """{hypergame state: move} from strategy.json records."""
    table = {}
    for rec in map(grid_record, records):
        v = w.record_ts_state(rec["cell"], rec.get("traps"), rec.get("countdown"))
        window = tuple((w.record_ts_state(o["cell"], o.get("traps"), o.get("countdown")),
                        o["action"]) for o in rec["window"])
        table[(v, int(rec["q"]), (int(rec["hypothesis"]), window))] = rec["action"]
    return table


def switch_probability(w: World, records, horizon: int, in_play: bool = False) -> float:
    """P(P2's hypothesis changes at least once within `horizon` steps) when P1 plays the
    records: a step from (v, q, M) with move a changes it when eta(M, (v, a)) holds another
    hypothesis than M (the episode's last step included). `in_play`: only a change after which
    the episode goes on counts, a step into a state that is neither the goal nor a failure."""
    table = record_table(w, records)
    s0 = w.initial()
    if s0 in ("goal", "fail"):
        return 0.0
    order, index, queue = [s0], {s0: 0}, deque([s0])
    while queue:
        s = queue.popleft()
        for t in w.hyper_successors(s, table[s]):
            if t not in ("goal", "fail") and t not in index:
                index[t] = len(order)
                order.append(t)
                queue.append(t)
    switches = np.array([w.eta(M, (v, table[(v, q, M)]))[0] != M[0] for v, q, M in order])
    succs = [[(index[t], p) for t, p in w.hyper_successors(s, table[s]).items()
              if t not in ("goal", "fail")] for s in order]
    # f_k(s): probability of a change within k steps from s; goal and failure end the episode.
    # A change counts on every successor, or (in_play) on those where the episode goes on.
    f = np.zeros(len(order))
    for _ in range(horizon):
        f = np.array([(sum(p for _, p in succs[i]) if in_play else 1.0) if switches[i]
                      else sum(p * f[j] for j, p in succs[i]) for i in range(len(order))])
    return float(f[0])
