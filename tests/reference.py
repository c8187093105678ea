"""Independent reference implementation of the hg2prism semantics (docs/semantics.md §§1-6).

Written directly from the semantics (docs/semantics.md), deliberately without importing anything from
``hg2prism`` (and without stormpy), so that the test suite can use it to catch bugs in the
package.  Everything is explicit: the world is read with ``tomllib``, the transition system,
the perceptual games, the inference machine and the hypergame MDP are explored with
dictionaries and breadth-first search, and the games/MDP are solved *exactly* (to
floating-point accuracy) by strategy iteration with exact policy evaluation (sparse linear
solves).

Conventions (the contract with the package under test):

* cells are ``(x, y)``: x = column from the left, y = row from the bottom, of the map as
  written (border included);
* a TS state is ``"trapped"``, ``(x, y)`` when delay == 0, or ``(x, y, T, c)`` when delay > 0
  with ``T`` the tuple of trap cells in candidate numbering (map reading order);
* DFA states are those of ``spot.translate(formula, "deterministic", "complete", "sbacc")``,
  renumbered breadth-first from the initial state over the label classes (semantics §3).

Choices where the semantics are silent (kept deliberately simple):

* the DFA's final states are those from which every infinite continuation over the world's
  letters is accepted (asked of Spot as a language containment, state by state), and ``Sink``
  the states from which no final state can be reached over those letters;
* with a single hypothesis no change can happen, but B still records the last w-1
  observations (semantics §5 step 3 read literally), so such states are distinct in the count;
* ``trap_strategy`` returns ``tuple(sorted(cells))`` (plain Python order of (x, y));
* the games G(x) are solved on the TS states reachable from the initial state; asking for
  P2's strategy or the inference at another TS state raises KeyError;
* blank lines of the map string (e.g. after the opening triple quote) are ignored.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import spot
from spot import buddy

TRAPPED = "trapped"
ACTIONS = ("N", "E", "S", "W")
DELTA = {"N": (0, 1), "E": (1, 0), "S": (0, -1), "W": (-1, 0)}
PERP = {"N": ("E", "W"), "S": ("E", "W"), "E": ("N", "S"), "W": ("N", "S")}

TIE_P2 = 1e-6        # semantics §4: tie tolerance of P2's strategy
TOL_CUSUM = 1e-9     # semantics §5: threshold / argmax tolerance
SWITCH_TOL = 1e-12   # strategy iteration: switch only on a strict improvement
VI_STOP = 1e-9      # value iteration only seeds the strategy iteration
VI_MAX_SWEEPS = 1500
TIE_EXTRACT = 1e-7  # near-optimal rows when extracting the first strategy


# --------------------------------------------------------------------------------------
# exact solver for turn-based reachability games (P2 moves first, then P1, then chance)
# --------------------------------------------------------------------------------------

def solve_reach_game(state_pairs, pair_rows, row_succ, return_strategy=False):
    """Least fixed point of  V(s) = min_{p in pairs(s)} max_{r in rows(p)} sum_t P_r(t) V(t).

    ``state_pairs[s]``: list of pair ids (P2 choices) of non-terminal state s;
    ``pair_rows[p]``:   list of row ids (P1 choices) of pair p;
    ``row_succ[r]``:    list of (target, prob), target an int state id, "goal" (value 1) or
                        "fail" (value 0).
    Pair ids must be numbered consecutively state by state, row ids pair by pair.
    An MDP for a maximiser is the special case of one pair per state.

    Method (exact up to floating point):
    1. a bounded number of value-iteration sweeps gives approximate values;
    2. P1's strategy is extracted from them: among the rows within TIE_EXTRACT of the best,
       each pair takes one that makes progress towards the goal (layered attractor, largest
       probability of progress), so that P1 never stalls in a tie (which would give a
       badly conditioned, even wrong, evaluation);
    3. strategy iteration for the maximiser: the P1 strategy is evaluated exactly by P2's
       best response (graph analysis of the states where P2 avoids the goal forever, then
       policy iteration with sparse linear solves), and rows that are strictly better (by
       SWITCH_TOL) are switched in, until none is;
    4. certificate: the result is the value of a P1 strategy against P2's best response
       (<= game value) and a fixed point of the game operator (>= the least fixed point,
       i.e. the game value); the fixed-point residual is checked (< 1e-11).
    """
    n = len(state_pairs)
    npairs = len(pair_rows)
    nrows = len(row_succ)
    if n == 0:
        return (np.zeros(0), np.zeros(0, dtype=np.int64)) if return_strategy else np.zeros(0)
    # consecutive numbering (lets us use segment reductions)
    assert [p for ps in state_pairs for p in ps] == list(range(npairs))
    assert [r for rs in pair_rows for r in rs] == list(range(nrows))
    state_start = np.array([ps[0] for ps in state_pairs], dtype=np.int64)
    pair_start = np.array([rs[0] for rs in pair_rows], dtype=np.int64)
    pair_state = np.repeat(np.arange(n), [len(ps) for ps in state_pairs])

    # sparse transition matrix to non-terminal states, and the one-step goal probability
    ri, ci, vals = [], [], []
    g = np.zeros(nrows)
    row_targets = []  # non-terminal successors with positive probability (graph searches)
    for r, succ in enumerate(row_succ):
        ts = []
        for t, pr in succ:
            if pr <= 0:
                continue
            if t == "goal":
                g[r] += pr
            elif t == "fail":
                pass
            else:
                ri.append(r)
                ci.append(t)
                vals.append(pr)
                ts.append(t)
        row_targets.append(ts)
    P = sp.csr_matrix((vals, (ri, ci)), shape=(nrows, n))

    uniform4 = all(len(rs) == 4 for rs in pair_rows)

    def game_op(x):
        q = g + P @ x
        pv = q.reshape(-1, 4).max(axis=1) if uniform4 else np.maximum.reduceat(q, pair_start)
        return q, pv, (pv if npairs == n else np.minimum.reduceat(pv, state_start))

    row_pair = np.repeat(np.arange(npairs), [len(rs) for rs in pair_rows])
    row_nt = [[(t, pr) for t, pr in succ if pr > 0 and t not in ("goal", "fail")]
              for succ in row_succ]
    preds = [[] for _ in range(n)]          # state -> rows that can move into it
    for r, ts in enumerate(row_targets):
        for t in ts:
            preds[t].append(r)

    def extract(x, tol):
        """P1 strategy, greedy w.r.t. x among rows within tol of the best, with progress:
        pairs are ranked in layers (a state is ranked once all its pairs are); a pair picks,
        among its near-optimal rows, the one with the largest probability of moving into the
        goal or an already ranked state.  Unranked pairs (value 0) take a best row."""
        q = g + P @ x
        pv = np.maximum.reduceat(q, pair_start)
        near = q >= pv[row_pair] - tol
        choice = np.full(npairs, -1, dtype=np.int64)
        ranked = np.zeros(n, dtype=bool)
        left = np.array([len(ps) for ps in state_pairs])
        frontier = sorted({int(row_pair[r]) for r in range(nrows) if near[r] and g[r] > 0})
        while frontier:
            newly = []
            for p in frontier:
                if choice[p] >= 0:
                    continue
                best, bestm = -1, 0.0
                for r in pair_rows[p]:
                    if not near[r]:
                        continue
                    m = g[r] + sum(pr for t, pr in row_nt[r] if ranked[t])
                    if m > bestm + 1e-15:
                        best, bestm = r, m
                if best < 0:
                    continue
                choice[p] = best
                s = pair_state[p]
                left[s] -= 1
                if left[s] == 0:
                    newly.append(s)
            for s in newly:
                ranked[s] = True
            frontier = sorted({int(row_pair[r]) for s in newly for r in preds[s]
                               if near[r] and choice[row_pair[r]] < 0})
        for p in np.nonzero(choice < 0)[0]:
            choice[p] = max(pair_rows[p], key=lambda r: q[r])
        return choice

    # 1. value iteration (approximate values, only used to pick a good first strategy)
    x = np.zeros(n)
    for _ in range(VI_MAX_SWEEPS):
        _, _, y = game_op(x)
        d = float(np.max(np.abs(y - x)))
        x = y
        if d < VI_STOP:
            break
    # 2. optimal-looking strategy with progress, evaluated exactly; then strategy
    #    iteration (strict improvements only) until no row improves on the exact values
    sigma1 = extract(x, TIE_EXTRACT)
    for _outer in range(1000):
        x = _best_response_min(n, state_pairs, pair_state, sigma1, row_targets, g, P,
                               state_start)
        q, pv, _ = game_op(x)
        better = np.nonzero(pv > q[sigma1] + SWITCH_TOL)[0]
        if len(better) == 0:
            break
        for p in better:
            sigma1[p] = max(pair_rows[p], key=lambda r: q[r])
    else:
        raise RuntimeError("strategy iteration did not converge")
    # certificate: x is the exact value of P1's strategy sigma1 against P2's best response
    # (a lower bound of the game value) and a fixed point of the game operator (an upper
    # bound: the value is its least fixed point)
    _, _, fx = game_op(x)
    res = float(np.max(np.abs(fx - x)))
    if res > 1e-11:
        raise RuntimeError(f"game solution residual {res}")
    return (x, sigma1) if return_strategy else x


def _best_response_min(n, state_pairs, pair_state, sigma1, row_targets, g, P, state_start):
    """Minimum reachability probability for P2 when P1 plays sigma1 (pair -> row)."""
    # 1. attractor of the goal: states from which P2 cannot avoid reaching the goal with
    #    positive probability; outside it (set Z) P2 avoids the goal forever (value 0).
    preds = [[] for _ in range(n)]
    for p, r in enumerate(sigma1):
        for t in row_targets[r]:
            preds[t].append(p)
    hit = [False] * len(sigma1)
    left = [len(ps) for ps in state_pairs]
    inattr = [False] * n
    queue = deque()

    def mark(p):
        if hit[p]:
            return
        hit[p] = True
        s = pair_state[p]
        left[s] -= 1
        if left[s] == 0:
            inattr[s] = True
            queue.append(s)

    for p, r in enumerate(sigma1):
        if g[r] > 0:
            mark(p)
    while queue:
        t = queue.popleft()
        for p in preds[t]:
            mark(p)
    # 2. P2's policy: on Z an avoiding pair (value 0); on the rest policy iteration, each
    #    policy evaluated exactly (the system is non-singular there)
    tau = np.empty(n, dtype=np.int64)
    for s in range(n):
        if inattr[s]:
            tau[s] = state_pairs[s][0]
        else:
            tau[s] = next(p for p in state_pairs[s] if not hit[p])
    live = np.array([s for s in range(n) if inattr[s]], dtype=np.int64)
    x = np.zeros(n)
    if len(live) == 0:
        return x
    eye = sp.identity(len(live), format="csc")
    for _ in range(10000):
        rows = sigma1[tau[live]]
        A = P[rows][:, live]
        sol = np.atleast_1d(spla.spsolve((eye - A).tocsc(), g[rows]))
        x = np.zeros(n)
        x[live] = sol
        qp = (g + P @ x)[sigma1]             # value of each pair under sigma1
        best = np.minimum.reduceat(qp, state_start)
        worse = [s for s in live if best[s] < qp[tau[s]] - SWITCH_TOL]
        if not worse:
            return x
        for s in worse:
            tau[s] = min(state_pairs[s], key=lambda p: qp[p])
    raise RuntimeError("policy iteration (min) did not converge")


# --------------------------------------------------------------------------------------
# automata
# --------------------------------------------------------------------------------------

def _one_of(letters, aps):
    """Spot formula: the letter is one of `letters` (None = no proposition, else exactly that one)."""
    terms = []
    for lab in letters:
        terms.append("(" + " & ".join(
            (ap if ap == lab else f"!{ap}") for ap in aps) + ")" if aps else "1")
    return " | ".join(terms) if terms else "0"


class DFA:
    def __init__(self, formula: str, labels, world_letters=None):
        self.formula = formula
        f = spot.formula(formula)
        if not f.is_syntactic_guarantee():
            raise ValueError(f"not syntactically co-safe: {formula}")
        aut = spot.translate(f, "deterministic", "complete", "sbacc")
        self.aut = aut
        self.n = aut.num_states()
        self.init = aut.get_init_state_number()
        aps = [str(a) for a in aut.ap()]
        aps_all = sorted({lab for lab in labels if lab is not None} | set(aps))
        # delta[q][label] for label in labels (None or a proposition name)
        self.delta = {}
        for q in range(self.n):
            row = {}
            for lab in labels:
                assign = buddy.bddtrue
                for ap in aps:
                    var = aut.register_ap(ap)
                    lit = buddy.bdd_ithvar(var) if ap == lab else buddy.bdd_nithvar(var)
                    assign = buddy.bdd_and(assign, lit)
                dsts = [e.dst for e in aut.out(q)
                        if buddy.bdd_and(e.cond, assign) != buddy.bddfalse]
                if len(dsts) != 1:
                    raise RuntimeError(f"DFA of {formula} not deterministic/complete on {lab}")
                row[lab] = dsts[0]
            self.delta[q] = row
        # Final states (semantics §3): a good prefix has been read, i.e. every infinite continuation
        # over the world's letters is accepted. Asked of Spot as a language containment: the
        # automaton started in q contains every word over the world's letters.
        letters = labels if world_letters is None else world_letters
        universe = spot.translate(spot.formula(f"G({_one_of(letters, aps_all)})"))
        self.acc = set()
        for q in range(self.n):
            from_q = spot.make_twa_graph(aut, spot.twa_prop_set.all())
            from_q.set_init_state(q)
            if spot.contains(from_q, universe):
                self.acc.add(q)
        # Sink: states from which no final state is reachable reading the world's letters.
        good = set(self.acc)
        changed = True
        while changed:
            changed = False
            for q in range(self.n):
                if q not in good and any(self.delta[q][lab] in good for lab in letters):
                    good.add(q)
                    changed = True
        self.sink = set(range(self.n)) - good
        self._renumber(aut, labels)

    def _renumber(self, aut, labels):
        """Semantics §3: states numbered breadth-first from the initial state, successors in
        label-class order (none, obs, the region letters sorted); states no word of classes
        reaches follow, breadth-first over every valuation of the automaton's propositions
        (in class order, then by name; binary order, the last varying fastest)."""
        classes = [None] + [lab for lab in ("obs",) if lab in labels] + sorted(
            lab for lab in labels if lab not in (None, "obs"))
        aps = [str(a) for a in aut.ap()]
        aps = [lab for lab in classes if lab in aps] + sorted(set(aps) - set(classes))

        def successor(q, true_aps):
            assign = buddy.bddtrue
            for ap in aps:
                var = aut.register_ap(ap)
                assign = buddy.bdd_and(assign, buddy.bdd_ithvar(var) if ap in true_aps
                                       else buddy.bdd_nithvar(var))
            return next(e.dst for e in aut.out(q) if buddy.bdd_and(e.cond, assign) != buddy.bddfalse)

        valuations = [{ap for ap, bit in zip(aps, bits) if bit}
                      for bits in itertools.product((False, True), repeat=len(aps))]
        order = [self.init]
        for letters in ([{lab} if lab else set() for lab in classes], valuations):
            for q in order:          # grows while walked: a queue
                for true_aps in letters:
                    target = successor(q, true_aps)
                    if target not in order:
                        order.append(target)
        new = {old: i for i, old in enumerate(order)}
        self.delta = {new[q]: {lab: new[d] for lab, d in row.items()} for q, row in self.delta.items()}
        self.init, self.acc, self.sink = new[self.init], {new[q] for q in self.acc}, {new[q] for q in self.sink}
        self.aut = None     # Spot's numbering no longer applies

    def step(self, q, lab):
        return self.delta[q][lab]


# --------------------------------------------------------------------------------------
# the reference model
# --------------------------------------------------------------------------------------

@dataclass
class Reference:
    value: float
    v_lead: float
    states: int
    transitions: int
    world: "World" = field(repr=False, default=None)

    def strategy_value(self, records):
        return self.world.strategy_value(records)

    def optimal_records(self):
        """An optimal strategy of the reference, in the exported record format."""
        return self.world.optimal_records()

    def infer(self, hypothesis, window, observation):
        w = self.world
        B = tuple((w.norm_ts(v), a) for v, a in window)
        obs = (w.norm_ts(observation[0]), observation[1])
        return w.eta((int(hypothesis), B), obs)

    def trap_strategy(self, hypothesis, ts_state):
        """pi2_x(v) as tuple(sorted(cells)) (plain Python sort of (x, y) pairs)."""
        w = self.world
        return tuple(sorted(w.pi2(int(hypothesis), w.norm_ts(ts_state))))


class World:
    def __init__(self, path):
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
        self.doc = doc
        rows = [ln.rstrip("\r") for ln in doc["grid"]["map"].split("\n")]
        rows = [ln for ln in rows if ln.strip() != ""]
        self.rows = rows
        self.H = len(rows)
        self.W = len(rows[0])
        self.slip = float(doc["robot"]["slip"])
        self.task = doc["task"]["formula"]
        adv = doc["adversary"]
        self.ntraps = int(adv["traps"])
        self.delay = int(adv.get("delay", 0))
        self.hyps = list(adv["hypotheses"])
        self.h0 = int(adv.get("initial_hypothesis", 0))
        inf = doc["inference"]
        self.window = int(inf["window"])
        self.threshold = float(inf["threshold"]) if "threshold" in inf else None   # none for "bayes"
        self.beta = float(inf["rationality"])

        self.cands = []
        self.start = None
        self.props = {"obs"}
        for i, row in enumerate(rows):
            y = self.H - 1 - i
            for x, ch in enumerate(row):
                if ch == "t":
                    self.cands.append((x, y))
                elif ch == "@":
                    self.start = (x, y)
                elif "A" <= ch <= "Z":
                    self.props.add(ch)
        self.cand_index = {c: i for i, c in enumerate(self.cands)}
        self.sets = [tuple(self.cands[i] for i in comb)
                     for comb in itertools.combinations(range(len(self.cands)), self.ntraps)]
        if self.delay > 0:
            T0 = self.norm_traps(adv.get("initial_traps", []))
            self.v0 = (self.start[0], self.start[1], T0, 0)
        else:
            self.v0 = self.start
        labels = [None] + sorted(self.props)
        # the letters the world's states produce: none (free cells, trapped), obs where the map
        # has an obstacle, and each region letter on the map
        self.world_letters = [None] + sorted(
            p for p in self.props
            if p != "obs" or any("o" in row for row in self.rows))
        self.dfa_cache = {}
        self.task_dfa = self.dfa(self.task, labels)
        self.hyp_dfas = [self.dfa(h, labels) for h in self.hyps]
        self._out_cache = {}
        self._ts_states = self._explore_ts()
        self._games = {}
        self._pi2_cache = {}
        self._logpi_cache = {}
        self._eta_cache = {}

    # ----- helpers -----
    def dfa(self, formula, labels):
        if formula not in self.dfa_cache:
            self.dfa_cache[formula] = DFA(formula, labels, self.world_letters)
        return self.dfa_cache[formula]

    def char(self, x, y):
        return self.rows[self.H - 1 - y][x]

    def label(self, v):
        if v == TRAPPED:
            return None
        ch = self.char(v[0], v[1])
        if ch == "o":
            return "obs"
        if "A" <= ch <= "Z":
            return ch
        return None

    def norm_traps(self, T):
        cells = {(int(c[0]), int(c[1])) for c in T}
        return tuple(sorted(cells, key=lambda c: self.cand_index[c]))

    def norm_ts(self, v):
        if isinstance(v, str):
            assert v == TRAPPED
            return TRAPPED
        v = tuple(v)
        if len(v) == 2:
            return (int(v[0]), int(v[1]))
        return (int(v[0]), int(v[1]), self.norm_traps(v[2]), int(v[3]))

    # ----- TS (semantics §2) -----
    def move(self, cell, d):
        dx, dy = DELTA[d]
        nx, ny = cell[0] + dx, cell[1] + dy
        if 0 <= nx < self.W and 0 <= ny < self.H and self.char(nx, ny) != "#":
            return (nx, ny)
        return cell

    def A2(self, v):
        if self.delay == 0:
            return self.sets
        T, c = v[2], v[3]
        return [T] if c > 0 else self.sets

    def outcomes(self, v, a1, a2):
        """P(. | v, a1, a2) as a dict (merged, zero-probability outcomes dropped)."""
        key = (v, a1, a2)
        res = self._out_cache.get(key)
        if res is not None:
            return res
        cell = (v[0], v[1])
        res = {}
        p_main = 1.0 - 2.0 * self.slip
        for d, p in ((a1, p_main), (PERP[a1][0], self.slip), (PERP[a1][1], self.slip)):
            if p <= 0:
                continue
            c2 = self.move(cell, d)
            if c2 in a2:
                s = TRAPPED
            elif self.delay == 0:
                s = c2
            else:
                T, c = v[2], v[3]
                s = (c2[0], c2[1], a2, self.delay if a2 != T else max(c - 1, 0))
            res[s] = res.get(s, 0.0) + p
        self._out_cache[key] = res
        return res

    def _explore_ts(self):
        seen = {self.v0}
        order = [self.v0]
        queue = deque([self.v0])
        while queue:
            v = queue.popleft()
            for a2 in self.A2(v):
                for a1 in ACTIONS:
                    for s in self.outcomes(v, a1, a2):
                        if s != TRAPPED and s not in seen:
                            seen.add(s)
                            order.append(s)
                            queue.append(s)
        return order

    # ----- perceptual games (semantics §4) -----
    def game_values(self, formula):
        """V_x as a dict {(v, q): value} over TS-reachable v (non-trapped) and all q."""
        if formula in self._games:
            return self._games[formula]
        dfa = self.dfa_cache[formula]
        idx = {}
        nodes = []
        for v in self._ts_states:
            for q in range(dfa.n):
                if q in dfa.acc or q in dfa.sink:
                    continue
                idx[(v, q)] = len(nodes)
                nodes.append((v, q))
        state_pairs, pair_rows, row_succ = [], [], []
        for (v, q) in nodes:
            ps = []
            for a2 in self.A2(v):
                rows = []
                for a1 in ACTIONS:
                    succ = []
                    for v2, pr in self.outcomes(v, a1, a2).items():
                        if v2 == TRAPPED:
                            succ.append(("fail", pr))
                            continue
                        q2 = dfa.step(q, self.label(v2))
                        if q2 in dfa.acc:
                            succ.append(("goal", pr))
                        elif q2 in dfa.sink:
                            succ.append(("fail", pr))
                        else:
                            succ.append((idx[(v2, q2)], pr))
                    rows.append(len(row_succ))
                    row_succ.append(succ)
                ps.append(len(pair_rows))
                pair_rows.append(rows)
            state_pairs.append(ps)
        x = solve_reach_game(state_pairs, pair_rows, row_succ)
        vals = {nodes[i]: float(x[i]) for i in range(len(nodes))}
        self._games[formula] = (dfa, vals)
        return self._games[formula]

    def V(self, formula, v, q):
        dfa, vals = self.game_values(formula)
        if v == TRAPPED:
            return 0.0
        if q in dfa.acc:
            return 1.0
        if q in dfa.sink:
            return 0.0
        try:
            return vals[(v, q)]
        except KeyError:
            raise KeyError(f"TS state {v!r} is not reachable from the initial state") from None

    def Q(self, formula, v, q, a1, a2):
        dfa, _ = self.game_values(formula)
        if q in dfa.acc or q in dfa.sink:
            return self.V(formula, v, q)
        tot = 0.0
        for v2, pr in self.outcomes(v, a1, a2).items():
            if v2 == TRAPPED:
                continue
            tot += pr * self.V(formula, v2, dfa.step(q, self.label(v2)))
        return tot

    def pi2(self, x, v):
        """P2's strategy pi2_x(v) (semantics §4): a trap set (tuple in candidate order)."""
        key = (x, v)
        if key in self._pi2_cache:
            return self._pi2_cache[key]
        formula = self.hyps[x]
        dfa, _ = self.game_values(formula)
        q0 = dfa.step(dfa.init, self.label(v))
        acts = self.A2(v)
        if q0 in dfa.acc or q0 in dfa.sink:
            tied = list(acts)
        else:
            m = [max(self.Q(formula, v, q0, a1, a2) for a1 in ACTIONS) for a2 in acts]
            mn = min(m)
            tied = [a2 for a2, mv in zip(acts, m) if mv <= mn + TIE_P2]
        if self.delay > 0 and v[2] in tied:
            res = v[2]
        else:
            res = tied[0]   # self.sets / A2 are already in itertools.combinations order
        self._pi2_cache[key] = res
        return res

    def logpi1(self, x, v, a2):
        """P2's softmax model of P1 under hypothesis x: {a1: ln pi1_x(a1 | v, a2)}."""
        key = (x, v, a2)
        if key in self._logpi_cache:
            return self._logpi_cache[key]
        formula = self.hyps[x]
        dfa, _ = self.game_values(formula)
        q0 = dfa.step(dfa.init, self.label(v))
        z = [self.beta * self.Q(formula, v, q0, a1, a2) for a1 in ACTIONS]
        mx = max(z)
        lse = mx + math.log(sum(math.exp(zi - mx) for zi in z))
        res = {a1: zi - lse for a1, zi in zip(ACTIONS, z)}
        self._logpi_cache[key] = res
        return res

    def r(self, x, xh, v, a1):
        a2 = self.pi2(xh, v)
        return self.logpi1(x, v, a2)[a1] - self.logpi1(xh, v, a2)[a1]

    # ----- inference (semantics §5) -----
    def eta(self, M, obs):
        key = (M, obs)
        if key in self._eta_cache:
            return self._eta_cache[key]
        xh, B = M
        w = self.window
        Wn = (tuple(B) + (obs,))[-w:]
        Z = {}
        for x in range(len(self.hyps)):
            if x == xh:
                continue
            z = 0.0
            for (vi, ai) in Wn:
                z = max(0.0, z + self.r(x, xh, vi, ai))
            Z[x] = z
        if any(z >= self.threshold - TOL_CUSUM for z in Z.values()):
            mz = max(Z.values())
            xs = next(x for x in range(len(self.hyps)) if x != xh and Z[x] >= mz - TOL_CUSUM)
            res = (xs, ())
        else:
            res = (xh, tuple(Wn[-(w - 1):]) if w > 1 else ())
        self._eta_cache[key] = res
        return res

    # ----- hypergame MDP (semantics §6) -----
    def hyper_successors(self, s, a1):
        """dict canonical successor -> probability; successors are "goal", "fail" or (v,q,M)."""
        v, q, M = s
        dfa = self.task_dfa
        a2 = self.pi2(M[0], v)
        M2 = self.eta(M, (v, a1))
        res = {}
        for v2, pr in self.outcomes(v, a1, a2).items():
            if v2 == TRAPPED:
                t = "fail"
            else:
                q2 = dfa.step(q, self.label(v2))
                if q2 in dfa.acc:
                    t = "goal"
                elif q2 in dfa.sink:
                    t = "fail"
                else:
                    t = (v2, q2, M2)
            res[t] = res.get(t, 0.0) + pr
        return res

    def classify(self, s):
        v, q, _ = s
        if v == TRAPPED:
            return "fail"
        if q in self.task_dfa.acc:
            return "goal"
        if q in self.task_dfa.sink:
            return "fail"
        return s

    def initial(self):
        dfa = self.task_dfa
        return self.classify((self.v0, dfa.step(dfa.init, self.label(self.v0)), (self.h0, ())))

    def explore_hypergame(self):
        s0 = self.initial()
        seen = {}
        order = []
        reached = set()
        if s0 in ("goal", "fail"):
            reached.add(s0)
            return s0, order, seen, {}, reached
        seen[s0] = 0
        order.append(s0)
        trans = {}
        queue = deque([s0])
        while queue:
            s = queue.popleft()
            for a1 in ACTIONS:
                succ = self.hyper_successors(s, a1)
                trans[(s, a1)] = succ
                for t in succ:
                    if t in ("goal", "fail"):
                        reached.add(t)
                    elif t not in seen:
                        seen[t] = len(order)
                        order.append(t)
                        queue.append(t)
        return s0, order, seen, trans, reached

    def solve(self):
        self._policy = {}
        s0, order, idx, trans, reached = self.explore_hypergame()
        dfa = self.task_dfa
        # leader game G(phi) at (v0, delta(iota, L(v0)))
        self.game_values(self.task)
        v_lead = self.V(self.task, self.v0, dfa.step(dfa.init, self.label(self.v0)))
        ntrans = sum(len(succ) for succ in trans.values()) + len(reached)
        nstates = len(order) + len(reached)
        if s0 in ("goal", "fail"):
            value = 1.0 if s0 == "goal" else 0.0
        else:
            state_pairs, pair_rows, row_succ = [], [], []
            for i, s in enumerate(order):
                rows = []
                for a1 in ACTIONS:
                    succ = [(t if t in ("goal", "fail") else idx[t], pr)
                            for t, pr in trans[(s, a1)].items()]
                    rows.append(len(row_succ))
                    row_succ.append(succ)
                state_pairs.append([i])
                pair_rows.append(rows)
            x, sigma1 = solve_reach_game(state_pairs, pair_rows, row_succ,
                                         return_strategy=True)
            value = float(x[0])
            self._policy = {s: ACTIONS[sigma1[i] - pair_rows[i][0]] for i, s in enumerate(order)}
        self._hyper = (s0, order, idx, trans, reached)
        value = min(1.0, max(0.0, value))               # clip floating-point noise
        v_lead = min(1.0, max(0.0, float(v_lead)))
        return Reference(value=value, v_lead=v_lead, states=nstates,
                         transitions=ntrans, world=self)

    # ----- strategy evaluation -----
    def _ts_record(self, v):
        if self.delay == 0:
            return {"cell": [v[0], v[1]], "traps": None, "countdown": None}
        return {"cell": [v[0], v[1]], "traps": [list(c) for c in v[2]], "countdown": v[3]}

    def optimal_records(self):
        recs = []
        for (v, q, (xh, B)), a in self._policy.items():
            rec = self._ts_record(v)
            rec.update(q=q, hypothesis=xh,
                       window=[dict(self._ts_record(vi), action=ai) for vi, ai in B],
                       action=a)
            recs.append(rec)
        return recs

    def record_ts_state(self, cell, traps, countdown):
        if self.delay == 0:
            return (int(cell[0]), int(cell[1]))
        return (int(cell[0]), int(cell[1]), self.norm_traps(traps), int(countdown))

    def strategy_value(self, records):
        table = {}
        for rec in map(grid_record, records):
            v = self.record_ts_state(rec["cell"], rec.get("traps"), rec.get("countdown"))
            B = tuple((self.record_ts_state(o["cell"], o.get("traps"), o.get("countdown")), o["action"])
                      for o in rec["window"])
            key = (v, int(rec["q"]), (int(rec["hypothesis"]), B))
            a = rec["action"]
            if a not in ACTIONS:
                raise ValueError(f"bad action {a!r} in record {rec}")
            if key in table and table[key] != a:
                raise ValueError(f"conflicting records for state {key}")
            table[key] = a
        s0 = self.initial()
        if s0 in ("goal", "fail"):
            return 1.0 if s0 == "goal" else 0.0
        idx = {s0: 0}
        order = [s0]
        queue = deque([s0])
        succs = []
        while queue:
            s = queue.popleft()
            if s not in table:
                raise KeyError(f"no strategy record for reachable state {s}")
            succ = self.hyper_successors(s, table[s])
            for t in succ:
                if t not in ("goal", "fail") and t not in idx:
                    idx[t] = len(order)
                    order.append(t)
                    queue.append(t)
        succs = []
        for s in order:
            succ = self.hyper_successors(s, table[s])
            succs.append([(t if t in ("goal", "fail") else idx[t], pr) for t, pr in succ.items()])
        x = dtmc_reach(succs)
        return min(1.0, max(0.0, float(x[0])))


def _cell_of(name):
    """A grid arena state's name x{x}_y{y} as the cell [x, y]."""
    x, y = name[1:].split("_y")
    return [int(x), int(y)]


def grid_record(rec):
    """A strategy.json record (or window entry) of a grid world, {state, standing, countdown,
    ..., played}, in the grid form this reference reads: {cell, traps, countdown, ...,
    played} with cells [x, y] (state names x{x}_y{y}, trap sets their members joined by '+')."""
    out = dict(rec)
    out["cell"] = _cell_of(out.pop("state"))
    standing = out.pop("standing", None)
    out["traps"] = None if standing is None else [_cell_of(c) for c in standing.split("+")]
    if "played" in out:
        out["played"] = [_cell_of(c) for c in out["played"].split("+")]
    if "window" in out:
        out["window"] = [grid_record(o) for o in out["window"]]
    return out


def dtmc_reach(succs):
    """Exact P(F goal) in a DTMC: graph search for probability-0 states, then a linear solve."""
    n = len(succs)
    preds = [[] for _ in range(n)]
    can = [False] * n
    queue = deque()
    for i, succ in enumerate(succs):
        for t, pr in succ:
            if pr <= 0:
                continue
            if t == "goal":
                if not can[i]:
                    can[i] = True
                    queue.append(i)
            elif t != "fail":
                preds[t].append(i)
    while queue:
        t = queue.popleft()
        for i in preds[t]:
            if not can[i]:
                can[i] = True
                queue.append(i)
    live = [i for i in range(n) if can[i]]
    pos = {i: k for k, i in enumerate(live)}
    x = np.zeros(n)
    if not live:
        return x
    ri, ci, vals = [], [], []
    b = np.zeros(len(live))
    for k, i in enumerate(live):
        ri.append(k)
        ci.append(k)
        vals.append(1.0)
        for t, pr in succs[i]:
            if t == "goal":
                b[k] += pr
            elif t != "fail" and can[t]:
                ri.append(k)
                ci.append(pos[t])
                vals.append(-pr)
    A = sp.csc_matrix((vals, (ri, ci)), shape=(len(live), len(live)))
    sol = np.atleast_1d(spla.spsolve(A, b))
    x[live] = sol
    return x


def solve(path) -> Reference:
    return World(path).solve()
