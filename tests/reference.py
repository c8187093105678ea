"""Independent reference implementation of the hg2prism semantics (docs/semantics.md §§1-6, and
§15 for arena worlds).

Written directly from the semantics (docs/semantics.md), deliberately without importing anything from
``hg2prism`` (and without stormpy), so that the test suite can use it to catch bugs in the
package.  Everything is explicit: the world is read with ``tomllib`` and compiled to an
explicit arena (``arena_of``: a grid world to one state per free cell with the actions N E S W
and their slip outcomes, an arena world as written); the transition system, the perceptual
games, the inference machine and the hypergame MDP are then explored on that arena with
dictionaries and breadth-first search, and the games/MDP are solved *exactly* (to
floating-point accuracy) by strategy iteration with exact policy evaluation (sparse linear
solves).

Conventions (the contract with the package under test):

* cells are ``(x, y)``: x = column from the left, y = row from the bottom, of the map as
  written (border included);
* a TS state is ``"trapped"``, ``(x, y)`` when delay == 0, or ``(x, y, T, c)`` when delay > 0
  with ``T`` the tuple of trap cells in candidate numbering (map reading order);
* for an arena world a TS state is ``"trapped"``, the state's name when delay == 0, or
  ``(name, standing, c)`` when delay > 0, ``standing`` the trap set as a tuple of candidate
  names in the order of ``trap_candidates`` or P2's general action (its name);
* DFA states are those of ``spot.translate(formula, "deterministic", "complete", "sbacc")``,
  renumbered breadth-first from the initial state over the label classes (semantics §3).

Choices where the semantics are silent (kept deliberately simple):

* the DFA's final states are those from which every infinite continuation over the world's
  letters is accepted (asked of Spot as a language containment, state by state), and ``Sink``
  the states from which no final state can be reached over those letters;
* with a single hypothesis no change can happen, but B still records the last w-1
  observations (semantics §5 step 3 read literally), so such states are distinct in the count;
* ``trap_strategy`` returns ``tuple(sorted(cells))`` (plain Python order of (x, y)); for an
  arena, the trap set in candidate order or the action name;
* the games G(x) are solved on the TS states reachable from the initial state; asking for
  P2's strategy or the inference at another TS state raises KeyError;
* blank lines of the map string (e.g. after the opening triple quote) are ignored.

Arena worlds (§15), choices where §15 is silent:

* the DFA letters are the label sets the arena's states carry (all listed states, reachable
  or not), plus the empty set in trap mode (``trapped`` carries no label); a grid's are its
  label classes as before.  The label classes of an arena, which only number the DFA states
  (§3), are these sets ordered by size, then by their propositions' indices in AP order; AP is
  ``arena.propositions`` as listed, else the propositions of the labels sorted by name;
* a terminal state v (no transition entry) has V_x(v, q) = 1 if q in F_x else 0; P2's
  strategy there ties every action (like F and Sink), and P2's model of P1 is empty;
* outcomes of probability 0 in ``to`` are dropped (they reach nothing); the trap rule applies
  to terminal states too (a terminal successor in the set in force is ``trapped``);
* the initial state is never trapped, even when it is a candidate in ``initial_traps``
  (the rule applies to successors only);
* records of an arena's strategy name the state as ``cell`` and its standing action as
  ``traps`` (a list of candidate names, or the action name).
"""

from __future__ import annotations

import itertools
import math
import re
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
NOISE_TOL = 1e-8    # rounding noise tolerated on rows the noise guard left out


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
       SWITCH_TOL) are switched in, until none is; a switch that would let P2 avoid the
       goal from a state where she could not (impossible in exact arithmetic: it is a tie
       that rounding makes look better, and it closes a loop) is undone and its row left out;
    4. certificate: the result is the value of a P1 strategy against P2's best response
       (<= game value) and a fixed point of the game operator (>= the least fixed point,
       i.e. the game value); the fixed-point residual is checked (< 1e-11; rows left out
       by the guard may exceed the value by rounding noise, < NOISE_TOL).
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
    # Rows a switch into which turned out to stall (see below); they stay out of the
    # improvement step. Never happens in exact arithmetic.
    allowed = np.ones(nrows, dtype=bool)
    for _outer in range(1000):
        x, attr = _best_response_min(n, state_pairs, pair_state, sigma1, row_targets, g, P,
                                     state_start)
        q, pv, _ = game_op(x)
        if not allowed.all():
            pv = np.maximum.reduceat(np.where(allowed, q, -np.inf), pair_start)
        better = np.nonzero(pv > q[sigma1] + SWITCH_TOL)[0]
        if len(better) == 0:
            break
        old = sigma1.copy()
        for p in better:
            sigma1[p] = max((r for r in pair_rows[p] if allowed[r]), key=lambda r: q[r])
        # Noise guard. In exact arithmetic a strict improvement keeps every state of the
        # attractor in it (a closed class without the goal cannot contain a strictly improved
        # state: its stationary distribution pi has pi (P x - x) = 0). With rounded
        # probabilities (rows summing to 1 only within an ulp, amplified by near-closed
        # loops, e.g. a 1e-8 chance of leaving) a tie can look like an improvement of ~1e-9
        # and the switch closes a loop that never reaches the goal. Such switches are undone
        # and their rows left out from then on.
        switched = set(better.tolist())
        while switched:
            lost = attr & ~_attractor(n, state_pairs, pair_state, sigma1, row_targets, g)[0]
            if not lost.any():
                break
            undo = [p for p in switched if lost[pair_state[p]]] or sorted(switched)
            for p in undo:
                allowed[sigma1[p]] = False
                sigma1[p] = old[p]
                switched.discard(p)
    else:
        raise RuntimeError("strategy iteration did not converge")
    # certificate: x is the exact value of P1's strategy sigma1 against P2's best response
    # (a lower bound of the game value) and a fixed point of the game operator (an upper
    # bound: the value is its least fixed point); rows left out by the noise guard may
    # exceed it by rounding noise only (NOISE_TOL)
    q, _, fx = game_op(x)
    if not allowed.all():
        pva = np.maximum.reduceat(np.where(allowed, q, -np.inf), pair_start)
        fxa = pva if npairs == n else np.minimum.reduceat(pva, state_start)
        noise = float(np.max(np.abs(fx - x)))
        if noise > NOISE_TOL:
            raise RuntimeError(f"game solution residual {noise} on rows left out as noise")
        fx = fxa
    res = float(np.max(np.abs(fx - x)))
    if res > 1e-11:
        raise RuntimeError(f"game solution residual {res}")
    return (x, sigma1) if return_strategy else x


def _attractor(n, state_pairs, pair_state, sigma1, row_targets, g):
    """(inattr, hit) when P1 plays sigma1: inattr[s] when P2 cannot avoid reaching the goal
    with positive probability from s; hit[p] when pair p leads there."""
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
    return np.array(inattr, dtype=bool), hit


def _best_response_min(n, state_pairs, pair_state, sigma1, row_targets, g, P, state_start):
    """Minimum reachability probability for P2 when P1 plays sigma1 (pair -> row), and the
    attractor of the goal (see _attractor)."""
    # 1. attractor of the goal: states from which P2 cannot avoid reaching the goal with
    #    positive probability; outside it (set Z) P2 avoids the goal forever (value 0).
    inattr, hit = _attractor(n, state_pairs, pair_state, sigma1, row_targets, g)
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
        return x, inattr
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
            return x, inattr
        for s in worse:
            tau[s] = min(state_pairs[s], key=lambda p: qp[p])
    raise RuntimeError("policy iteration (min) did not converge")


# --------------------------------------------------------------------------------------
# automata
# --------------------------------------------------------------------------------------

def true_props(letter):
    """The propositions that hold in a letter: None (none), one proposition name (a grid's
    label class), or a set of proposition names (an arena's label: a full valuation)."""
    if letter is None:
        return frozenset()
    if isinstance(letter, str):
        return frozenset((letter,))
    return frozenset(letter)


def _one_of(letters, aps):
    """Spot formula: the letter is one of `letters` (each a valuation of `aps`, see true_props)."""
    terms = []
    for lab in letters:
        true = true_props(lab)
        terms.append("(" + " & ".join(
            (ap if ap in true else f"!{ap}") for ap in aps) + ")" if aps else "1")
    return " | ".join(terms) if terms else "0"


class DFA:
    """``labels``: the letters delta is defined on (see true_props). Grid letters (None or one
    proposition) are numbered by the grid's label classes (none, obs, letters sorted); with
    ``ap_order`` (arenas) the letters are the label classes in the order given and the
    propositions are ordered by ``ap_order`` for the numbering of unreachable states."""

    def __init__(self, formula: str, labels, world_letters=None, ap_order=None):
        self.formula = formula
        self.ap_order = ap_order
        f = spot.formula(formula)
        if not f.is_syntactic_guarantee():
            raise ValueError(f"not syntactically co-safe: {formula}")
        aut = spot.translate(f, "deterministic", "complete", "sbacc")
        self.aut = aut
        self.n = aut.num_states()
        self.init = aut.get_init_state_number()
        aps = [str(a) for a in aut.ap()]
        aps_all = sorted(set().union(*map(true_props, labels)) | set(aps))
        # delta[q][label] for label in labels (None, a proposition name or a set of them)
        self.delta = {}
        for q in range(self.n):
            row = {}
            for lab in labels:
                true = true_props(lab)
                assign = buddy.bddtrue
                for ap in aps:
                    var = aut.register_ap(ap)
                    lit = buddy.bdd_ithvar(var) if ap in true else buddy.bdd_nithvar(var)
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
        (in class order, then by name; binary order, the last varying fastest).
        Arenas (``ap_order`` given): the classes are ``labels`` in the order given, the
        propositions in ``ap_order``, then any other by name."""
        aps = [str(a) for a in aut.ap()]
        if self.ap_order is None:
            classes = [None] + [lab for lab in ("obs",) if lab in labels] + sorted(
                lab for lab in labels if lab not in (None, "obs"))
            aps = [lab for lab in classes if lab in aps] + sorted(set(aps) - set(classes))
        else:
            classes = list(labels)
            aps = [ap for ap in self.ap_order if ap in aps] + sorted(set(aps) - set(self.ap_order))

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
        for letters in ([true_props(lab) for lab in classes], valuations):
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
# explicit arenas (semantics §15): a grid world compiles to one, an arena world is one
# --------------------------------------------------------------------------------------

IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
NOT_PROPOSITIONS = {"F", "G", "M", "R", "U", "V", "W", "X", "true", "false"}   # Spot reads these


def arena_of(doc: dict) -> dict:
    """The explicit arena of a parsed world file, grid (§§1-2) or arena (§15) alike:

    * ``kind``: "grid" or "arena";
    * ``states``: the names, in the state numbering (a grid's are its free cells ``(x, y)``
      in map reading order); ``initial``: s0;
    * ``propositions``: AP, in order; ``label``: name -> letter (a grid's: None or its one
      proposition; an arena's: the frozenset of its propositions); ``classes``: the letters
      the DFAs read, in label-class order; ``letters``: those the world produces (§3);
    * ``actions``: name -> P1's actions in order (empty: a terminal state);
    * ``moves``: (name, a1) -> {a2 or None: {successor name: probability}}, None for the
      entry without ``p2`` (every P2 action not named), before the trap rule;
    * ``p2``: "traps" or "general"; ``a2``: A2 in order (trap sets as tuples of candidates in
      candidate order, or action names); ``candidates``: the trap candidates (or []);
    * ``delay`` and ``initial_action`` (the standing action at the start, None when delay 0).
    """
    if ("grid" in doc) == ("arena" in doc):
        raise ValueError("a world has exactly one of [grid] and [arena]")
    return grid_arena(doc) if "grid" in doc else parse_arena(doc)


def grid_arena(doc: dict) -> dict:
    """§15 last item: one state per free cell, N E S W with §2's slip outcomes (merged in the
    order intended, first perpendicular, second perpendicular; probability 0 dropped)."""
    rows = [ln.rstrip("\r") for ln in doc["grid"]["map"].split("\n")]
    rows = [ln for ln in rows if ln.strip() != ""]
    H, W = len(rows), len(rows[0])
    slip = float(doc["robot"]["slip"])

    def char(x, y):
        return rows[H - 1 - y][x]

    def move(cell, d):
        dx, dy = DELTA[d]
        nx, ny = cell[0] + dx, cell[1] + dy
        if 0 <= nx < W and 0 <= ny < H and char(nx, ny) != "#":
            return (nx, ny)
        return cell

    states, cands, label, start = [], [], {}, None
    props = {"obs"}
    for i, row in enumerate(rows):
        y = H - 1 - i
        for x, ch in enumerate(row):
            if ch == "#":
                continue
            states.append((x, y))
            label[(x, y)] = "obs" if ch == "o" else ch if "A" <= ch <= "Z" else None
            if ch == "t":
                cands.append((x, y))
            elif ch == "@":
                start = (x, y)
            elif "A" <= ch <= "Z":
                props.add(ch)
    moves = {}
    for cell in states:
        for a1 in ACTIONS:
            dist = {}
            for d, p in ((a1, 1.0 - 2.0 * slip), (PERP[a1][0], slip), (PERP[a1][1], slip)):
                if p > 0:
                    c2 = move(cell, d)
                    dist[c2] = dist.get(c2, 0.0) + p
            moves[(cell, a1)] = {None: dist}
    adv = doc["adversary"]
    ntraps = int(adv["traps"])
    delay = int(adv.get("delay", 0))
    cand_index = {c: i for i, c in enumerate(cands)}
    a2 = [tuple(cands[i] for i in comb)
          for comb in itertools.combinations(range(len(cands)), ntraps)]
    init_action = None
    if delay > 0:
        init_action = tuple(sorted({(int(c[0]), int(c[1])) for c in adv.get("initial_traps", [])},
                                   key=lambda c: cand_index[c]))
    return dict(kind="grid", states=states, initial=start, propositions=sorted(props),
                label=label, classes=[None] + sorted(props),
                # none (the start cell, trapped), obs where the map has an obstacle, and each
                # region letter on the map
                letters=[None] + sorted(p for p in props
                                        if p != "obs" or any("o" in row for row in rows)),
                actions={c: list(ACTIONS) for c in states}, moves=moves, p2="traps", a2=a2,
                candidates=cands, delay=delay, initial_action=init_action,
                grid=dict(rows=rows, H=H, W=W, slip=slip, char=char, move=move,
                          props=props))


def parse_arena(doc: dict) -> dict:
    """An arena world's [arena] and [adversary] tables as an explicit arena, checked against
    §15 (ValueError naming the problem)."""
    ar = doc["arena"]
    states = list(ar["states"])
    known = set(states)
    for name in states:
        if not isinstance(name, str) or not IDENT.match(name):
            raise ValueError(f"state name {name!r} is not an identifier")
    if len(known) != len(states) or TRAPPED in known:
        raise ValueError("state names repeated (or 'trapped')")
    initial = ar["initial"]
    if initial not in known:
        raise ValueError(f"unknown initial state {initial!r}")
    labels_doc = dict(ar.get("labels", {}))
    for name, props in labels_doc.items():
        if name not in known:
            raise ValueError(f"label of unknown state {name!r}")
    occurring = []
    for name in states:
        for p in labels_doc.get(name, []):
            if p not in occurring:
                occurring.append(p)
    # AP: as listed, else those that occur in the labels, by name
    propositions = list(ar["propositions"]) if "propositions" in ar else sorted(occurring)
    for p in propositions:
        if not isinstance(p, str) or not IDENT.match(p) or p in NOT_PROPOSITIONS:
            raise ValueError(f"{p!r} is not an atomic proposition Spot reads as such")
    if len(set(propositions)) != len(propositions):
        raise ValueError("propositions repeated")
    if set(occurring) - set(propositions):
        raise ValueError(f"labels use unknown propositions {set(occurring) - set(propositions)}")
    label = {name: frozenset(labels_doc.get(name, [])) for name in states}

    adv = doc["adversary"]
    delay = int(adv.get("delay", 0))
    if "actions" in adv:
        if "traps" in adv or "trap_candidates" in adv or "initial_traps" in adv:
            raise ValueError("adversary: general actions and traps together")
        mode, cands = "general", []
        a2 = list(adv["actions"])
        if not a2 or len(set(a2)) != len(a2) or not all(
                isinstance(a, str) and IDENT.match(a) for a in a2):
            raise ValueError("adversary.actions: distinct identifiers, at least one")
        init_action = None
        if delay > 0:
            init_action = adv["initial_action"]
            if init_action not in a2:
                raise ValueError(f"unknown initial_action {init_action!r}")
    else:
        mode = "traps"
        ntraps = int(adv["traps"])
        cands = list(adv["trap_candidates"])
        if len(set(cands)) != len(cands) or set(cands) - known or not 1 <= ntraps <= len(cands):
            raise ValueError("adversary.trap_candidates: distinct states, at least `traps`")
        cand_index = {c: i for i, c in enumerate(cands)}
        a2 = [tuple(cands[i] for i in comb)
              for comb in itertools.combinations(range(len(cands)), ntraps)]
        init_action = None
        if delay > 0:
            init = list(adv["initial_traps"])
            if len(set(init)) != ntraps or set(init) - set(cands):
                raise ValueError("adversary.initial_traps: `traps` distinct candidates")
            init_action = tuple(sorted(set(init), key=lambda c: cand_index[c]))

    actions = {name: [] for name in states}
    moves = {}
    for entry in ar.get("transition", []):
        s, a1, to = entry["state"], entry["action"], dict(entry["to"])
        if s not in known:
            raise ValueError(f"transition from unknown state {s!r}")
        if not isinstance(a1, str) or not IDENT.match(a1):
            raise ValueError(f"action {a1!r} is not an identifier")
        if set(to) - known:
            raise ValueError(f"transition to unknown states {set(to) - known}")
        if any(p < 0 for p in to.values()) or abs(math.fsum(to.values()) - 1.0) > 1e-9:
            raise ValueError(f"probabilities of ({s}, {a1}) do not sum to 1: {to}")
        if a1 not in actions[s]:
            actions[s].append(a1)
        row = moves.setdefault((s, a1), {})
        if "p2" in entry:
            if mode != "general":
                raise ValueError("p2 is only allowed with general P2 actions")
            named = [entry["p2"]] if isinstance(entry["p2"], str) else list(entry["p2"])
            for b in named:
                if b not in a2:
                    raise ValueError(f"unknown P2 action {b!r}")
                if b in row:
                    raise ValueError(f"two entries for ({s}, {a1}, {b})")
                row[b] = {t: float(p) for t, p in to.items()}
        else:
            if None in row:
                raise ValueError(f"two entries without p2 for ({s}, {a1})")
            row[None] = {t: float(p) for t, p in to.items()}
    for (s, a1), row in moves.items():
        if None not in row and set(a2) - set(row):
            raise ValueError(f"({s}, {a1}) not covered for P2 actions {set(a2) - set(row)}")

    # the letters: the label sets the states carry (and the empty one of `trapped`)
    letters = set(label.values()) | ({frozenset()} if mode == "traps" else set())
    order = {p: i for i, p in enumerate(propositions)}
    classes = sorted(letters, key=lambda lab: (len(lab), sorted(order[p] for p in lab)))
    return dict(kind="arena", states=states, initial=initial, propositions=propositions,
                label=label, classes=classes, letters=list(classes), actions=actions,
                moves=moves, p2=mode, a2=a2, candidates=cands, delay=delay,
                initial_action=init_action)


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
        """pi2_x(v): for a grid, tuple(sorted(cells)) (plain Python sort of (x, y) pairs); for
        an arena, the trap set as a tuple of candidates in candidate order, or the action name."""
        w = self.world
        a2 = w.pi2(int(hypothesis), w.norm_ts(ts_state))
        return tuple(sorted(a2)) if w.kind == "grid" else a2


class World:
    """The world of a grid or arena file, everything computed on its explicit arena
    (``self.arena``, see arena_of). TS states (§2, §15): ``"trapped"``; a grid's ``(x, y)`` or
    ``(x, y, T, c)``; an arena's ``name`` or ``(name, standing, c)`` (standing: the trap set as
    a tuple of candidates in candidate order, or P2's action name)."""

    def __init__(self, path, doc=None):
        if doc is None:
            with open(path, "rb") as fh:
                doc = tomllib.load(fh)
        self.doc = doc
        self.arena = arena = arena_of(doc)
        self.kind = arena["kind"]
        self.mode = arena["p2"]
        self.task = doc["task"]["formula"]
        adv = doc["adversary"]
        self.delay = arena["delay"]
        self.hyps = list(adv["hypotheses"])
        self.h0 = int(adv.get("initial_hypothesis", 0))
        # which tied action P2 takes where the standing one is not tied: the first (the
        # rule) or, with [adversary] tie_break = "last", the last
        self.tie_last = adv.get("tie_break", "first") == "last"
        inf = doc["inference"]
        self.window = int(inf["window"])
        self.threshold = float(inf["threshold"]) if "threshold" in inf else None   # none for "bayes"
        self.beta = float(inf["rationality"])

        self.sets = arena["a2"]                 # A2 in order (trap sets or action names)
        self.cands = arena["candidates"]
        self.cand_index = {c: i for i, c in enumerate(self.cands)}
        self._trapset = {a2: frozenset(a2) for a2 in self.sets} if self.mode == "traps" else None
        self._label = arena["label"]
        self._actions = arena["actions"]
        self._moves = arena["moves"]
        self.empty_letter = None if self.kind == "grid" else frozenset()
        if self.kind == "grid":
            g = arena["grid"]
            self.rows, self.H, self.W, self.slip = g["rows"], g["H"], g["W"], g["slip"]
            self.char, self.move, self.props = g["char"], g["move"], g["props"]
            self.ntraps = int(adv["traps"])
            self.start = arena["initial"]
            self.place = (lambda v: v) if self.delay == 0 else (lambda v: v[:2])
        else:
            self.props = set(arena["propositions"])
            self.place = (lambda v: v) if self.delay == 0 else (lambda v: v[0])
            for formula in [self.task, *self.hyps]:
                unknown = {str(a) for a in spot.atomic_prop_collect(spot.formula(formula))} \
                    - self.props
                if unknown:
                    raise ValueError(f"{formula!r} uses unknown propositions {sorted(unknown)}")
        self.v0 = self.make(arena["initial"], arena["initial_action"], 0)
        self.world_letters = arena["letters"]
        self.dfa_cache = {}
        self._ap_order = None if self.kind == "grid" else arena["propositions"]
        labels = arena["classes"]
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
            self.dfa_cache[formula] = DFA(formula, labels, self.world_letters, self._ap_order)
        return self.dfa_cache[formula]

    def make(self, name, standing, countdown):
        """The TS state of the arena state `name` with the standing action and countdown."""
        if self.delay == 0:
            return name
        if self.kind == "grid":
            return (name[0], name[1], standing, countdown)
        return (name, standing, countdown)

    def standing(self, v):
        return v[-2]

    def countdown(self, v):
        return v[-1]

    def label(self, v):
        if v == TRAPPED:
            return self.empty_letter
        return self._label[self.place(v)]

    def actions(self, v):
        """P1's actions at TS state v, in order (none at `trapped` and at terminal states)."""
        if v == TRAPPED:
            return []
        return self._actions[self.place(v)]

    def terminal(self, v):
        """A state without P1 actions (not `trapped`): reaching it ends the episode (§15)."""
        return v != TRAPPED and not self._actions[self.place(v)]

    def norm_traps(self, T):
        """The standing P2 action of a record or a caller: a trap set (any iterable of
        candidates: cells [x, y] for a grid, names for an arena) as a tuple in candidate
        order, or a general action's name."""
        if self.mode == "general":
            return str(T)
        if self.kind == "grid":
            items = {(int(c[0]), int(c[1])) for c in T}
        else:
            items = {str(c) for c in T}
        return tuple(sorted(items, key=lambda c: self.cand_index[c]))

    def norm_ts(self, v):
        if isinstance(v, str) and v == TRAPPED:
            return TRAPPED
        if self.kind == "arena":
            if isinstance(v, str):
                return v
            v = tuple(v)
            return (str(v[0]), self.norm_traps(v[1]), int(v[2]))
        v = tuple(v)
        if len(v) == 2:
            return (int(v[0]), int(v[1]))
        return (int(v[0]), int(v[1]), self.norm_traps(v[2]), int(v[3]))

    # ----- TS (semantics §2, §15) -----
    def A2(self, v):
        if self.delay == 0:
            return self.sets
        T, c = v[-2], v[-1]
        return [T] if c > 0 else self.sets

    def outcomes(self, v, a1, a2):
        """P(. | v, a1, a2) as a dict (merged, zero-probability outcomes dropped)."""
        key = (v, a1, a2)
        res = self._out_cache.get(key)
        if res is not None:
            return res
        row = self._moves[(self.place(v), a1)]
        dist = row.get(a2) if a2 in row else row[None]
        traps = self._trapset[a2] if self._trapset is not None else ()
        res = {}
        for s2, p in dist.items():
            if p <= 0:
                continue
            if s2 in traps:
                s = TRAPPED
            elif self.delay == 0:
                s = s2
            else:
                T, c = v[-2], v[-1]
                s = self.make(s2, a2, self.delay if a2 != T else max(c - 1, 0))
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
                for a1 in self.actions(v):
                    for s in self.outcomes(v, a1, a2):
                        if s != TRAPPED and s not in seen:
                            seen.add(s)
                            order.append(s)
                            queue.append(s)
        return order

    # ----- perceptual games (semantics §4) -----
    def _target(self, dfa, q, v2):
        """"goal", "fail" or (v2, q2) after moving to v2 from DFA state q (§4, §15)."""
        if v2 == TRAPPED:
            return "fail"
        q2 = dfa.step(q, self.label(v2))
        if q2 in dfa.acc:
            return "goal"
        if q2 in dfa.sink or self.terminal(v2):
            return "fail"
        return (v2, q2)

    def game_values(self, formula):
        """V_x as a dict {(v, q): value} over TS-reachable non-terminal v (not trapped) and
        the q outside F and Sink."""
        if formula in self._games:
            return self._games[formula]
        dfa = self.dfa_cache[formula]
        idx = {}
        nodes = []
        for v in self._ts_states:
            if self.terminal(v):
                continue
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
                for a1 in self.actions(v):
                    succ = []
                    for v2, pr in self.outcomes(v, a1, a2).items():
                        t = self._target(dfa, q, v2)
                        succ.append((t if t in ("goal", "fail") else idx[t], pr))
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
        if q in dfa.sink or self.terminal(v):
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
        """P2's strategy pi2_x(v) (semantics §4): a trap set (tuple in candidate order) or a
        general action. Where q_x0(v) is in F or Sink, or v is terminal, every action ties."""
        key = (x, v)
        if key in self._pi2_cache:
            return self._pi2_cache[key]
        formula = self.hyps[x]
        dfa, _ = self.game_values(formula)
        q0 = dfa.step(dfa.init, self.label(v))
        acts = self.A2(v)
        if q0 in dfa.acc or q0 in dfa.sink or self.terminal(v):
            tied = list(acts)
        else:
            m = [max(self.Q(formula, v, q0, a1, a2) for a1 in self.actions(v)) for a2 in acts]
            mn = min(m)
            tied = [a2 for a2, mv in zip(acts, m) if mv <= mn + TIE_P2]
        if self.delay > 0 and self.standing(v) in tied:
            res = self.standing(v)
        else:
            # A2 is in its order: as listed, or itertools.combinations order
            res = tied[-1] if self.tie_last else tied[0]
        self._pi2_cache[key] = res
        return res

    def logpi1(self, x, v, a2):
        """P2's softmax model of P1 under hypothesis x: {a1: ln pi1_x(a1 | v, a2)} over the
        actions available at v."""
        key = (x, v, a2)
        if key in self._logpi_cache:
            return self._logpi_cache[key]
        formula = self.hyps[x]
        dfa, _ = self.game_values(formula)
        q0 = dfa.step(dfa.init, self.label(v))
        acts = self.actions(v)
        z = [self.beta * self.Q(formula, v, q0, a1, a2) for a1 in acts]
        res = {}
        if z:
            mx = max(z)
            lse = mx + math.log(sum(math.exp(zi - mx) for zi in z))
            res = {a1: zi - lse for a1, zi in zip(acts, z)}
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
            t = self._target(dfa, q, v2)
            if t not in ("goal", "fail"):
                t = (v2, t[1], M2)
            res[t] = res.get(t, 0.0) + pr
        return res

    def classify(self, s):
        v, q, _ = s
        if v == TRAPPED:
            return "fail"
        if q in self.task_dfa.acc:
            return "goal"
        if q in self.task_dfa.sink or self.terminal(v):
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
            for a1 in self.actions(s[0]):
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
                for a1 in self.actions(s[0]):
                    succ = [(t if t in ("goal", "fail") else idx[t], pr)
                            for t, pr in trans[(s, a1)].items()]
                    rows.append(len(row_succ))
                    row_succ.append(succ)
                state_pairs.append([i])
                pair_rows.append(rows)
            x, sigma1 = solve_reach_game(state_pairs, pair_rows, row_succ,
                                         return_strategy=True)
            value = float(x[0])
            self._policy = {s: self.actions(s[0])[sigma1[i] - pair_rows[i][0]]
                            for i, s in enumerate(order)}
        self._hyper = (s0, order, idx, trans, reached)
        value = min(1.0, max(0.0, value))               # clip floating-point noise
        v_lead = min(1.0, max(0.0, float(v_lead)))
        return Reference(value=value, v_lead=v_lead, states=nstates,
                         transitions=ntrans, world=self)

    # ----- strategy evaluation -----
    def _ts_record(self, v):
        """An arena state is recorded by name as its "cell", its standing action as "traps"
        (a list of candidate names, or P2's action name)."""
        if self.kind == "arena":
            if self.delay == 0:
                return {"cell": v, "traps": None, "countdown": None}
            T = list(v[1]) if self.mode == "traps" else v[1]
            return {"cell": v[0], "traps": T, "countdown": v[2]}
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
        if self.kind == "arena":
            return self.make(str(cell), None if self.delay == 0 else self.norm_traps(traps),
                             None if self.delay == 0 else int(countdown))
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
            if a not in self.actions(v):
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
    """A grid arena state's name x{x}_y{y} as the cell [x, y] (another name as it is)."""
    import re

    match = re.fullmatch(r"x(\d+)_y(\d+)", name)
    return [int(match[1]), int(match[2])] if match else name


def _set_of(name):
    """A trap set's name (its members joined by '+') as a list of cells."""
    cells = [_cell_of(c) for c in name.split("+")]
    return cells if all(isinstance(c, list) for c in cells) else name


def grid_record(rec):
    """A strategy.json record (or window entry) of the package, {state, standing, countdown,
    ..., played}, in the form this reference reads: {cell, traps, countdown, ..., played}, a
    grid's cells as [x, y] (state names x{x}_y{y}, trap sets their members joined by '+').
    A record already in that form (this reference's own) is returned as it is."""
    if "state" not in rec:
        return rec
    out = dict(rec)
    out["cell"] = _cell_of(out.pop("state"))
    standing = out.pop("standing", None)
    out["traps"] = None if standing is None else _set_of(standing)
    if "played" in out:
        out["played"] = _set_of(out["played"])
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


# --------------------------------------------------------------------------------------
# adaptive deception (semantics §16): P2's type is unknown to P1
# --------------------------------------------------------------------------------------

class TypedWorld:
    """A world with P2's types ([[type]]): one World per type (its [inference] and first
    guess; the Bayesian ones from reference_bayes), sharing the arena and hypotheses.

    A type's memory: (hypothesis, window) for CUSUM (§5), the window W for the Bayesian "map"
    observer (§12). What it plays at v: pi2 of its hypothesis. Its update after P1 plays a1 at
    v and P2 plays a2: eta for CUSUM (a2 not used), W + (v, a1, a2) (last w) for Bayes."""

    def __init__(self, path):
        import copy

        import reference_bayes

        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
        types = doc["type"]
        total = math.fsum(float(t["weight"]) for t in types)
        self.weights = [float(t["weight"]) / total for t in types]
        self.names = [t.get("name", f"type{i}") for i, t in enumerate(types)]
        self.worlds = []
        for t in types:
            one = copy.deepcopy(doc)
            del one["type"]
            one["inference"] = dict(t["inference"])
            one["adversary"]["initial_hypothesis"] = int(t.get("initial_hypothesis", 0))
            if one["inference"].get("kind", "cusum") == "bayes":
                self.worlds.append(reference_bayes.BayesWorld(path, doc=one))
            else:
                self.worlds.append(World(path, doc=one))
        self.base = self.worlds[0]

    # ----- one type's memory -----
    def _bayes(self, k):
        return hasattr(self.worlds[k], "log_posterior")

    def memory0(self, k):
        return () if self._bayes(k) else (self.worlds[k].h0, ())

    def plays(self, k, M, v):
        w = self.worlds[k]
        if self._bayes(k):
            (x,) = w.draw(M)
            return w.pi2(x, v)
        return w.pi2(M[0], v)

    def update(self, k, M, v, a1, a2):
        w = self.worlds[k]
        if self._bayes(k):
            return (tuple(M) + ((v, a1, a2),))[-w.window:]
        return w.eta(M, (v, a1))

    # ----- the adaptive hypergame: states (v, q, C, memories of C) -----
    def classify(self, v, q, rest):
        w = self.base
        if v == TRAPPED:
            return "fail"
        if q in w.task_dfa.acc:
            return "goal"
        if q in w.task_dfa.sink or w.terminal(v):
            return "fail"
        return (v, q) + rest

    def adaptive_initial(self):
        w = self.base
        C = tuple(k for k in range(len(self.worlds)) if self.weights[k] > 0)
        q0 = w.task_dfa.step(w.task_dfa.init, w.label(w.v0))
        return self.classify(w.v0, q0, (C, tuple(self.memory0(k) for k in C)))

    def adaptive_successors(self, s, a1):
        """{successor: probability}: the consistent types grouped by the action they play,
        the group of alpha with its share of the weight, then P(v' | v, a1, alpha)."""
        v, q, C, Ms = s
        w = self.base
        groups = {}
        for k, M in zip(C, Ms):
            groups.setdefault(self.plays(k, M, v), []).append((k, M))
        total = math.fsum(self.weights[k] for k in C)
        res = {}
        for alpha, members in groups.items():
            share = math.fsum(self.weights[k] for k, _ in members) / total
            C2 = tuple(k for k, _ in members)
            Ms2 = tuple(self.update(k, M, v, a1, alpha) for k, M in members)
            for v2, pr in w.outcomes(v, a1, alpha).items():
                t = w._target(w.task_dfa, q, v2)
                if t not in ("goal", "fail"):
                    t = (v2, t[1], C2, Ms2)
                res[t] = res.get(t, 0.0) + share * pr
        return res

    def v_adapt(self):
        """Pmax F goal of the adaptive hypergame, its canonical size (states, transitions)."""
        s0 = self.adaptive_initial()
        if s0 in ("goal", "fail"):
            return (1.0 if s0 == "goal" else 0.0), 1, 1
        idx, order, queue, trans = {s0: 0}, [s0], deque([s0]), {}
        reached = set()
        while queue:
            s = queue.popleft()
            for a1 in self.base.actions(s[0]):
                succ = trans[(s, a1)] = self.adaptive_successors(s, a1)
                for t in succ:
                    if t in ("goal", "fail"):
                        reached.add(t)
                    elif t not in idx:
                        idx[t] = len(order)
                        order.append(t)
                        queue.append(t)
        state_pairs, pair_rows, row_succ = [], [], []
        for i, s in enumerate(order):
            rows = []
            for a1 in self.base.actions(s[0]):
                rows.append(len(row_succ))
                row_succ.append([(t if t in ("goal", "fail") else idx[t], pr)
                                 for t, pr in trans[(s, a1)].items()])
            state_pairs.append([i])
            pair_rows.append(rows)
        x = solve_reach_game(state_pairs, pair_rows, row_succ)
        ntrans = sum(len(succ) for succ in trans.values()) + len(reached)
        return min(1.0, max(0.0, float(x[0]))), len(order) + len(reached), ntrans

    # ----- a committed strategy against each type -----
    def _records(self, j, records):
        """The records of type j's deceptive strategy as {(v, q, M_j): action}."""
        w = self.worlds[j]
        set_of = lambda name: self._played(w, name)       # noqa: E731

        def state(o):
            return w.record_ts_state(o["cell"], set_of(o.get("traps")), o.get("countdown"))

        table = {}
        for rec in map(grid_record, records):
            if self._bayes(j):
                M = tuple((state(o), o["action"], w.norm_traps(set_of(o["played"])))
                          for o in rec["window"])
            else:
                M = (int(rec["hypothesis"]), tuple((state(o), o["action"])
                                                   for o in rec["window"]))
            table[(state(rec), int(rec["q"]), M)] = rec["action"]
        return table

    @staticmethod
    def _played(w, played):
        """A record's played trap set of an arena (its candidates joined by '+')."""
        if isinstance(played, str) and w.kind == "arena" and w.mode == "traps":
            return played.split("+")
        return played

    def leader_move(self, v, q, a2):
        """The leader game's move against a2 (§11: the naive answer, with its tie rules),
        from tests/reference_deception.py on the types' common arena and task."""
        if getattr(self, "_naive", None) is None:
            import reference_deception

            naive = reference_deception.Deception.__new__(reference_deception.Deception)
            naive.w, naive.dfa = self.base, self.base.task_dfa
            naive._leader_a2, naive._speed = {}, None
            self._naive = naive
        return self._naive.naive_move(v, q, a2)

    def committed_value(self, j, records, k):
        """The value of type j's deceptive strategy (records; the leader move where it has
        none) when P2 is of type k. P1 tracks type j's memory from what it observes (the
        actions P2 plays); P2 plays with type k's."""
        table = self._records(j, records)
        w = self.base
        q0 = w.task_dfa.step(w.task_dfa.init, w.label(w.v0))
        s0 = self.classify(w.v0, q0, (self.memory0(j), self.memory0(k)))
        if s0 in ("goal", "fail"):
            return 1.0 if s0 == "goal" else 0.0

        def move(s):
            v, q, Mj, Mk = s
            a = table.get((v, q, Mj))
            return a if a is not None else self.leader_move(v, q, self.plays(j, Mj, v))

        def successors(s):
            v, q, Mj, Mk = s
            a1 = move(s)
            a2 = self.plays(k, Mk, v)
            Mj2 = self.update(j, Mj, v, a1, a2)
            Mk2 = self.update(k, Mk, v, a1, a2)
            res = {}
            for v2, pr in w.outcomes(v, a1, a2).items():
                t = w._target(w.task_dfa, q, v2)
                if t not in ("goal", "fail"):
                    t = (v2, t[1], Mj2, Mk2)
                res[t] = res.get(t, 0.0) + pr
            return res

        idx, order, queue, succs = {s0: 0}, [s0], deque([s0]), []
        while queue:
            s = queue.popleft()
            succ = successors(s)
            for t in succ:
                if t not in ("goal", "fail") and t not in idx:
                    idx[t] = len(order)
                    order.append(t)
                    queue.append(t)
            succs.append(succ)
        rows = [[(t if t in ("goal", "fail") else idx[t], pr) for t, pr in succ.items()]
                for succ in succs]
        return min(1.0, max(0.0, float(dtmc_reach(rows)[0])))

    def v_commit(self, j, records):
        """sum_k w_k (value of type j's strategy against type k)."""
        return math.fsum(self.weights[k] * self.committed_value(j, records, k)
                         for k in range(len(self.worlds)) if self.weights[k] > 0)

    def adaptive_strategy_value(self, records):
        """The value of an exported adaptive strategy (records {state, standing, countdown, q,
        types: {name: {hypothesis, window}}, action}) on the adaptive hypergame."""
        index = {name: k for k, name in enumerate(self.names)}
        table = {}
        for rec in records:
            v = self._records(0, [dict(rec, hypothesis=0, window=[])])
            ((v, q, _),) = v.keys()
            C = tuple(sorted(index[name] for name in rec["types"]))
            Ms = tuple(next(iter(self._records(k, [dict(
                rec, hypothesis=rec["types"][self.names[k]]["hypothesis"],
                window=rec["types"][self.names[k]]["window"])])))[2] for k in C)
            table[(v, q, C, Ms)] = rec["action"]
        s0 = self.adaptive_initial()
        if s0 in ("goal", "fail"):
            return 1.0 if s0 == "goal" else 0.0
        idx, order, queue, succs = {s0: 0}, [s0], deque([s0]), []
        while queue:
            s = queue.popleft()
            succ = self.adaptive_successors(s, table[s])
            succs.append(succ)
            for t in succ:
                if t not in ("goal", "fail") and t not in idx:
                    idx[t] = len(order)
                    order.append(t)
                    queue.append(t)
        rows = [[(t if t in ("goal", "fail") else idx[t], pr) for t, pr in succ.items()]
                for succ in succs]
        return min(1.0, max(0.0, float(dtmc_reach(rows)[0])))
