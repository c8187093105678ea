"""Independent reference for the Nash baseline V_NE (docs/semantics.md §7, SPEC §7, §10).

Written from the semantics alone, importing nothing from ``hg2prism``: the transition system,
the task DFA and the product come from ``tests/reference.py`` (explicit dictionaries and
breadth-first search); this module adds the concurrent game on TS x DFA(phi)

    V(v, q) = val(M),   M[a1][a2] = sum_{v'} P(v' | v, a1, a2) V(v', delta(q, L(v')))

(P1 maximises over its actions at v, P2 minimises over A2(v); goal = 1, failure = 0, the
least fixed point) and brackets it soundly, by strategy improvement for both players (as for the turn-based
games; for concurrent games see Chatterjee, de Alfaro and Henzinger's strategy improvement for
concurrent reachability and safety games):

* **below**: P1's stationary mixed strategy x is evaluated exactly: P2's best response to it,
  a minimising MDP solved by ``reference.solve_reach_game`` (strategy iteration, exact policy
  evaluation). What x guarantees is below V_NE. x is then switched, at the states whose matrix
  game on those values beats it by more than IMPROVE, to that game's optimal strategy;
* **above**: likewise P1's best response to P2's stationary y (an MDP value above V_NE: P2
  guarantees it), y improved where the matrix games on those values are lower; and P1's best
  response to P2's optimal strategies in the matrix games on the lower values (as these
  approach V_NE, those strategies approach P2's locally optimal ones, which are optimal for
  the minimiser: V_NE is a supermartingale under them);
* both start from the optimal strategies of SEED_SWEEPS sweeps of value iteration from below
  (lower ends of the matrix games) and from above (upper ends; from 1 on the states from which
  P2 cannot surely keep P1 from the goal, 0 elsewhere), which are sound bounds themselves.

It stops when the bracket at the start is narrower than ``GAP`` (1e-7), or when neither
strategy improves (then the bracket is as found: the tests check its width). Plain value
iteration needs up to 10^5 sweeps on some mazes; this needs a few rounds on most. Strategy
weights below TINY are dropped before an evaluation (still a strategy of that player, so the
bounds stay sound); an evaluation the exact solver gives up on (its strategy iteration cycling
on rounding noise) is not used.

Matrix games are solved exactly, all states of one shape (|A1(v)|, |A2(v)|) at once: the
value max_x min_j (x^T M)_j of the LP is attained at a vertex, i.e. at a strategy x whose
support S and a set J of |S| columns make the system ``x_S^T M[S, J] = v 1, sum x_S = 1``
non-singular. Every such x (that is a probability vector) is a candidate; the largest
guaranteed payoff min_j (x^T M)_j over the candidates is the value (and each candidate's is
a lower bound, whatever rounding did to x). The same on -M^T gives P2's side, so the value
comes with a certificate (upper - lower); where it is wider than ``CERT`` (never seen), the
state's game is solved by ``scipy.optimize.linprog`` instead.
"""

from __future__ import annotations

import itertools
from collections import deque

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from reference import TRAPPED, World, solve_reach_game

GAP = 1e-7             # stop when the bracket at the start is below this
CERT = 1e-11           # accepted width of a matrix game's [lower, upper]
SEED_SWEEPS = 10       # value-iteration sweeps that give P1's first strategy
IMPROVE = 1e-12        # a strategy switches only where the matrix game beats it by more
MAX_ITERATIONS = 100
TINY = 1e-9            # mixed-strategy weights below this are dropped


# --------------------------------------------------------------------------------------
# small zero-sum matrix games, batched
# --------------------------------------------------------------------------------------

def _candidates(m: np.ndarray):
    """P1's vertex candidates for the games m [n, k1, k2]: yields x [n, k1] (NaN rows where
    the candidate does not exist: singular system or negative weights)."""
    n, k1, k2 = m.shape
    for i in range(k1):                                  # pure strategies
        x = np.zeros((n, k1))
        x[:, i] = 1.0
        yield x
    for k in range(2, min(k1, k2) + 1):
        for rows in itertools.combinations(range(k1), k):
            for cols in itertools.combinations(range(k2), k):
                sub = m[:, rows][:, :, cols]             # [n, k, k]
                if k == 2:
                    # equalise the two columns: x1 (a - b) = x2 (d - c)
                    d1 = sub[:, 0, 0] - sub[:, 0, 1]
                    d2 = sub[:, 1, 1] - sub[:, 1, 0]
                    den = d1 + d2
                    ok = np.abs(den) > 1e-300
                    x1 = np.divide(d2, den, out=np.full(n, np.nan), where=ok)
                    xs = np.stack([x1, 1.0 - x1], axis=1)
                else:
                    a = np.zeros((n, k + 1, k + 1))
                    a[:, :k, :k] = np.swapaxes(sub, 1, 2)    # row r: column cols[r]
                    a[:, :k, k] = -1.0
                    a[:, k, :k] = 1.0
                    det = np.linalg.det(a)
                    ok = np.abs(det) > 1e-14
                    a[~ok] = np.eye(k + 1)
                    b = np.zeros((n, k + 1))
                    b[:, k] = 1.0
                    xs = np.linalg.solve(a, b[..., None])[..., 0][:, :k]
                    xs[~ok] = np.nan
                bad = ~(xs >= -1e-12).all(axis=1)
                xs = np.clip(xs, 0.0, None)
                xs = xs / xs.sum(axis=1, keepdims=True)
                xs[bad] = np.nan
                x = np.zeros((n, k1))
                x[:, rows] = xs
                yield x


def lower_value(m: np.ndarray):
    """(value, x): the largest payoff P1 guarantees over its vertex candidates, and the
    candidate, for the games m [n, k1, k2] (P1 maximises over rows)."""
    n, k1, _ = m.shape
    best = np.full(n, -np.inf)
    arg = np.full((n, k1), np.nan)
    for x in _candidates(m):
        g = np.einsum("ni,nij->nj", np.nan_to_num(x), m).min(axis=1)
        g[np.isnan(x).any(axis=1)] = -np.inf
        better = g > best
        best[better] = g[better]
        arg[better] = x[better]
    return best, arg


def upper_value(m: np.ndarray):
    """(value, y): the smallest payoff P2 concedes over her vertex candidates, and it."""
    v, y = lower_value(-np.swapaxes(m, 1, 2))
    return -v, y


def lp_value(m: np.ndarray) -> float:
    """The value of one game m [k1, k2] by linear programming (HiGHS)."""
    k1, k2 = m.shape
    # variables x (k1), v; maximise v: min -v; v - x^T M_j <= 0; sum x = 1
    c = np.zeros(k1 + 1)
    c[-1] = -1.0
    a_ub = np.hstack([-m.T, np.ones((k2, 1))])
    a_eq = np.hstack([np.ones((1, k1)), np.zeros((1, 1))])
    res = linprog(c, A_ub=a_ub, b_ub=np.zeros(k2), A_eq=a_eq, b_eq=[1.0],
                  bounds=[(0, None)] * k1 + [(None, None)], method="highs")
    if res.status != 0:
        raise RuntimeError(f"linprog failed: {res.message}")
    return float(-res.fun)


def game_values(m: np.ndarray):
    """(lower, upper, x, y) of the games m [n, k1, k2]; lower == upper within CERT (where the
    vertex enumeration is not certified, both are the LP's value)."""
    low, x = lower_value(m)
    high, y = upper_value(m)
    for s in np.flatnonzero(high - low > CERT):
        low[s] = high[s] = lp_value(m[s])
    return low, high, x, y


# --------------------------------------------------------------------------------------
# the concurrent game on TS x DFA(phi)
# --------------------------------------------------------------------------------------

class NashGame:
    """The concurrent game of §7 on the product of the reference's TS and task DFA, over the
    product states reachable from the start (absorbing goal and fail merged away)."""

    def __init__(self, path) -> None:
        self.w = w = World(path)
        self.dfa = w.task_dfa
        self.start = self._target(self.dfa.init, w.v0)
        self.states, self.shape, self.a2 = [], [], []
        index = {}
        if self.start in ("goal", "fail"):
            self._tables(index, [], [], [], [])
            return
        index[self.start] = 0
        self.states.append(self.start)
        queue = deque([self.start])
        goal_now, ri, ci, vals = [], [], [], []
        row = 0
        while queue:
            v, q = queue.popleft()
            acts, a2s = w.actions(v), w.A2(v)
            self.shape.append((len(acts), len(a2s)))
            self.a2.append(a2s)
            for a1 in acts:
                for a2 in a2s:
                    g = 0.0
                    for v2, p in w.outcomes(v, a1, a2).items():
                        t = self._target(q, v2)
                        if t == "goal":
                            g += p
                        elif t != "fail":
                            if t not in index:
                                index[t] = len(self.states)
                                self.states.append(t)
                                queue.append(t)
                            ri.append(row)
                            ci.append(index[t])
                            vals.append(p)
                    goal_now.append(g)
                    row += 1
        self._tables(index, goal_now, ri, ci, vals)

    def _target(self, q, v2):
        """"goal", "fail" or (v2, q2) after entering v2 from task DFA state q (§6, §15)."""
        if v2 == TRAPPED:
            return "fail"
        q2 = self.dfa.step(q, self.w.label(v2))
        if q2 in self.dfa.acc:
            return "goal"
        if q2 in self.dfa.sink or self.w.terminal(v2):
            return "fail"
        return (v2, q2)

    def _tables(self, index, goal_now, ri, ci, vals) -> None:
        n = len(self.states)
        self.n = n
        self.index = index
        self.goal_now = np.array(goal_now, dtype=float)
        self.P = sp.csr_matrix((vals, (ri, ci)), shape=(len(goal_now), n))
        self._csr = self.P
        sizes = [k1 * k2 for k1, k2 in self.shape]
        self.first = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        # states grouped by the shape of their matrix game
        self.groups = {}
        for s, shape in enumerate(self.shape):
            self.groups.setdefault(shape, []).append(s)
        self.group_rows = {shape: (np.array(ss), self.first[ss][:, None, None]
                                   + np.arange(shape[0] * shape[1]).reshape(shape)[None])
                           for shape, ss in self.groups.items()}

    # ----- one sweep -----
    def sweep(self, v: np.ndarray, side: str):
        """(new values, strategies per group) of one Jacobi sweep from v; side "lower" uses
        the lower ends of the matrix games (and P1's strategies), "upper" the upper ends (and
        P2's)."""
        flat = self.goal_now + self.P @ v
        new = np.empty(self.n)
        strategies = {}
        for shape, (ss, rows) in self.group_rows.items():
            value, strategies[shape] = (lower_value if side == "lower" else upper_value)(flat[rows])
            new[ss] = value
        return new, strategies

    def avoid_set(self) -> np.ndarray:
        """States from which P2 can keep P1 away from the goal surely: the greatest set Z
        in which some a2 keeps every a1's outcomes in Z (or failure)."""
        inside = np.ones(self.n, dtype=bool)
        succ = [[] for _ in range(len(self.goal_now))]
        coo = self.P.tocoo()
        for r, c in zip(coo.row, coo.col):
            succ[r].append(c)
        changed = True
        while changed:
            changed = False
            for s in np.flatnonzero(inside):
                k1, k2 = self.shape[s]
                base = self.first[s]
                keeps = any(all(self.goal_now[base + a1 * k2 + a2] == 0
                                and all(inside[t] for t in succ[base + a1 * k2 + a2])
                                for a1 in range(k1)) for a2 in range(k2))
                if not keeps:
                    inside[s] = False
                    changed = True
        return inside

    def strategies(self, v: np.ndarray) -> dict:
        """Both players' optimal mixed strategies in the matrix games of v {shape: (x, y)}."""
        flat = self.goal_now + self.P @ v
        return {shape: game_values(flat[rows])[2:] for shape, (ss, rows) in
                self.group_rows.items()}

    def _per_state(self, of: dict) -> list:
        """Per state the mixed strategy of `of` {shape: [states of the group, actions]}, its
        weights below TINY dropped (still a strategy of that player: the bounds stay sound,
        and the exact solver is not fed near-zero leaks it cannot tell from rounding)."""
        mix = [None] * self.n
        for shape, (ss, _) in self.group_rows.items():
            m = np.where(of[shape] < TINY, 0.0, of[shape])
            m /= m.sum(axis=1, keepdims=True)
            for i, s in enumerate(ss):
                mix[s] = m[i]
        return mix

    def _mixture(self, s: int, a1s, a2s, weight) -> list:
        """[(target, probability)] of state s when the rows (a1, a2) are mixed with
        weight(a1, a2) (targets: state indices, "goal")."""
        k2 = self.shape[s][1]
        acc = {}
        for a1 in a1s:
            for a2 in a2s:
                w = weight(a1, a2)
                if w <= 0:
                    continue
                r = self.first[s] + a1 * k2 + a2
                if self.goal_now[r] > 0:
                    acc["goal"] = acc.get("goal", 0.0) + w * self.goal_now[r]
                lo, hi = self._csr.indptr[r], self._csr.indptr[r + 1]
                for t, p in zip(self._csr.indices[lo:hi], self._csr.data[lo:hi]):
                    acc[int(t)] = acc.get(int(t), 0.0) + w * p
        return list(acc.items())

    def best_response(self, y_of: dict) -> np.ndarray:
        """P1's best-response values (an MDP, solved exactly) to P2's stationary strategy
        (the y of both {shape: (x, y)}): an upper bound of V_NE."""
        y = self._per_state(y_of)
        state_pairs, pair_rows, row_succ = [], [], []
        for s in range(self.n):
            k1, k2 = self.shape[s]
            state_pairs.append([s])
            pair_rows.append(list(range(len(row_succ), len(row_succ) + k1)))
            for a1 in range(k1):
                row_succ.append(self._mixture(s, [a1], range(k2), lambda a1, a2: y[s][a2]))
        return solve_reach_game(state_pairs, pair_rows, row_succ)

    def guaranteed(self, x_of: dict) -> np.ndarray:
        """What P1's stationary strategy (the x of both) guarantees against P2's best
        response (an MDP, solved exactly): a lower bound of V_NE."""
        x = self._per_state(x_of)
        state_pairs, pair_rows, row_succ = [], [], []
        for s in range(self.n):
            k1, k2 = self.shape[s]
            state_pairs.append(list(range(len(pair_rows), len(pair_rows) + k2)))
            for a2 in range(k2):
                pair_rows.append([len(row_succ)])
                row_succ.append(self._mixture(s, range(k1), [a2], lambda a1, a2: x[s][a1]))
        return solve_reach_game(state_pairs, pair_rows, row_succ)


class Bracket:
    """The result: lower <= V_NE <= upper at the start, after `iterations` rounds of
    strategy improvement, on the product's `states` non-absorbing states."""

    def __init__(self, lower: float, upper: float, iterations: int, states: int) -> None:
        self.lower, self.upper, self.iterations, self.states = lower, upper, iterations, states

    def contains(self, value: float, tol: float) -> bool:
        return self.lower - tol <= value <= self.upper + tol

    def __repr__(self) -> str:
        return (f"Bracket(lower={self.lower!r}, upper={self.upper!r}, iterations={self.iterations}, "
                f"states={self.states})")


def _or_none(solve, strategy):
    """solve(strategy), or None where the exact MDP solver (reference.solve_reach_game) gives
    up (its strategy iteration cycling on rounding noise): that bound is then not used."""
    try:
        return solve(strategy)
    except RuntimeError:
        return None


def v_ne(path, gap: float = GAP, max_iterations: int = MAX_ITERATIONS) -> Bracket:
    """A sound bracket of V_NE at the start of the world file `path`, narrower than `gap`
    unless `max_iterations` rounds of strategy improvement did not get there (then as found).

    Strategy improvement on both sides (the turn-based games' method, for concurrent games as
    in Chatterjee, de Alfaro and Henzinger's strategy improvement for concurrent reachability
    and safety games): P1's stationary strategy x is evaluated exactly (P2's best response,
    ``guaranteed``: a lower bound), and switched, at the states whose matrix game on those
    values beats it by more than IMPROVE, to the game's optimal strategy; likewise P2's y
    against P1's best response (an upper bound). Both start from the optimal strategies of
    SEED_SWEEPS value-iteration sweeps from below and from above."""
    game = NashGame(path)
    if game.start in ("goal", "fail"):
        value = 1.0 if game.start == "goal" else 0.0
        return Bracket(value, value, 0, 0)
    low = np.zeros(game.n)
    high = np.where(game.avoid_set(), 0.0, 1.0)
    for _ in range(SEED_SWEEPS):
        low = np.maximum(low, game.sweep(low, "lower")[0])
        high = np.minimum(high, game.sweep(high, "upper")[0])
    x_of = {shape: xy[0] for shape, xy in game.strategies(low).items()}
    y_of = {shape: xy[1] for shape, xy in game.strategies(high).items()}
    lower, upper = 0.0, 1.0
    for it in range(1, max_iterations + 1):
        v = game.guaranteed(x_of)
        w = _or_none(game.best_response, y_of)
        if w is None:           # P2's improvement stops where its evaluation failed
            w = high
        else:
            high = np.minimum(high, w)
        lower, upper = max(lower, float(v[0])), min(upper, float(high[0]))
        if upper - lower < gap:
            break
        improved = 0
        on_v, on_w = game.goal_now + game.P @ v, game.goal_now + game.P @ w
        y_on_v = {}
        for shape, (ss, rows) in game.group_rows.items():
            val, _, better, y_on_v[shape] = game_values(on_v[rows])
            switch = val > v[ss] + IMPROVE
            x_of[shape][switch] = better[switch]
            _, val, _, better = game_values(on_w[rows])
            switch2 = val < w[ss] - IMPROVE
            y_of[shape][switch2] = better[switch2]
            improved += int(switch.sum() + switch2.sum())
        # P2's optimal strategies in the games on P1's values: as these approach V_NE, they
        # approach P2's locally optimal strategies for V_NE, which are optimal (for the
        # minimiser, V_NE is a supermartingale under them): an upper bound that often
        # converges faster than P2's own improvement
        extra = _or_none(game.best_response, y_on_v)
        if extra is not None:
            high = np.minimum(high, extra)
            upper = min(upper, float(high[0]))
        if upper - lower < gap or not improved:
            break
    return Bracket(max(0.0, lower), min(1.0, upper), it, game.n)
