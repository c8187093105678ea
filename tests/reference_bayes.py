"""An independent explicit solver for the Bayesian observer (docs/semantics.md §12), written from
the specification alone: it imports nothing from hg2prism and builds on tests/reference.py (the
world, the DFAs, P2's games, her trap strategy pi2_x and her softmax model ln pi1_x, the
reachability game solver and the DTMC solver).

It works on grid and arena worlds alike (semantics §15: reference.World compiles either to an
explicit arena; observations are (v, a1, a2) with v a TS state of reference.World's naming).

P2's memory W is the tuple of the last at most w observations (v, a1, a2), oldest first, with a2
the P2 action in force (a trap set as a tuple of cells or candidate states, or an action
name). The posterior is ln p(x | W) = ln prior(x) + sum ln pi1_x(a1 | v, a2) - ln Z. "map": P2
plays the action of the first hypothesis within 1e-9 of the largest log-posterior; "sample":
she draws x with p(x | W).
The hypergame MDP has states (v, q, W); from (v, q, W) under a1 the successor
(v', delta(q, L(v')), W + (v, a1, pi2_x(v)) [last w]) gets p(x | W) * P(v' | v, a1, pi2_x(v)).

With `static=True` P2 never revises: she plays pi2_x0 for x0 the prior's most probable hypothesis
and her memory stays empty, which gives V_static (the value of a fixed misperception).
"""

from __future__ import annotations

import math
from collections import deque

import reference

TIE = 1e-9      # hypotheses within this of the largest log-posterior tie (first one wins)


class BayesWorld(reference.World):
    def __init__(self, path, static: bool = False, doc=None):
        super().__init__(path, doc)
        inf = self.doc["inference"]
        n = len(self.hyps)
        prior = [float(p) for p in inf.get("prior", [1.0] * n)]
        total = math.fsum(prior)
        self.prior = [p / total for p in prior]
        self.decision = inf.get("decision", "map")
        self.static = static
        logs = [math.log(p) for p in self.prior]
        self.h0 = next(x for x, l in enumerate(logs) if l >= max(logs) - TIE)

    def log_posterior(self, W):
        """ln prior(x) + sum of ln pi1_x over W, oldest first, for every x (unnormalised)."""
        scores = []
        for x in range(len(self.hyps)):
            s = math.log(self.prior[x])
            for v, a1, a2 in W:
                s += self.logpi1(x, v, a2)[a1]
            scores.append(s)
        return scores

    def draw(self, W):
        """{x: probability} P2 plays at this step."""
        if self.static:
            return {self.h0: 1.0}
        scores = self.log_posterior(W)
        top = max(scores)
        if self.decision == "map":
            return {next(x for x, s in enumerate(scores) if s >= top - TIE): 1.0}
        weights = [math.exp(s - top) for s in scores]
        z = sum(weights)
        return {x: w / z for x, w in enumerate(weights) if w > 0}

    def hyper_successors(self, s, a1):
        v, q, W = s
        dfa = self.task_dfa
        res = {}
        for x, px in self.draw(W).items():
            a2 = self.pi2(x, v)
            W2 = () if self.static else (tuple(W) + ((v, a1, a2),))[-self.window:]
            for v2, pr in self.outcomes(v, a1, a2).items():
                t = self._target(dfa, q, v2)     # "goal", "fail" (trapped, terminal) or (v2, q2)
                if t not in ("goal", "fail"):
                    t = (v2, t[1], W2)
                res[t] = res.get(t, 0.0) + px * pr
        return res

    def initial(self):
        dfa = self.task_dfa
        return self.classify((self.v0, dfa.step(dfa.init, self.label(self.v0)), ()))

    def _played_record(self, a2):
        """A P2 action as records write it: a list of cells or candidates, or an action name."""
        if self.mode == "general":
            return a2
        return [list(c) for c in a2] if self.kind == "grid" else list(a2)

    def optimal_records(self):
        """The reference's optimal strategy as records (see strategy_value); `hypothesis` is
        the posterior's first most probable hypothesis."""
        recs = []
        for (v, q, W), a in self._policy.items():
            scores = self.log_posterior(W)
            rec = self._ts_record(v)
            rec.update(q=q, hypothesis=next(x for x, l in enumerate(scores)
                                            if l >= max(scores) - TIE),
                       window=[dict(self._ts_record(vi), action=ai,
                                    played=self._played_record(a2)) for vi, ai, a2 in W],
                       action=a)
            recs.append(rec)
        return recs

    def strategy_value(self, records):
        """The value of exported records {cell, traps, countdown, q, hypothesis, window, action},
        window entries {cell, traps, countdown, action, played} (for an arena, as
        reference.World records them: cell = state name, traps/played = the P2 action)."""
        table = {}
        for rec in map(reference.grid_record, records):
            v = self.record_ts_state(rec["cell"], rec.get("traps"), rec.get("countdown"))
            W = tuple((self.record_ts_state(o["cell"], o.get("traps"), o.get("countdown")),
                       o["action"], self.norm_traps(o["played"])) for o in rec["window"])
            table[(v, int(rec["q"]), W)] = rec["action"]
        s0 = self.initial()
        if s0 in ("goal", "fail"):
            return 1.0 if s0 == "goal" else 0.0
        idx, order, queue = {s0: 0}, [s0], deque([s0])
        while queue:
            s = queue.popleft()
            for t in self.hyper_successors(s, table[s]):
                if t not in ("goal", "fail") and t not in idx:
                    idx[t] = len(order)
                    order.append(t)
                    queue.append(t)
        succs = [[(t if t in ("goal", "fail") else idx[t], pr)
                  for t, pr in self.hyper_successors(s, table[s]).items()] for s in order]
        return min(1.0, max(0.0, float(reference.dtmc_reach(succs)[0])))


def solve(path, static: bool = False) -> reference.Reference:
    """Deceptive value (or V_static with `static`), V_lead and the canonical size."""
    return BayesWorld(path, static=static).solve()
