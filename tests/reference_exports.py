"""Independent readers and solvers for the exported files (written from the file formats and
docs/semantics.md alone; imports nothing from hg2prism): PRISM's explicit .tra/.sta/.lab,
the transition table of an HOA automaton over a world's label classes, and the numbers of a
DTMC (reachability, bounded reachability, expected steps to absorption)."""

from __future__ import annotations

from collections import deque
from pathlib import Path

import buddy
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import spot

import reference


class ExplicitDTMC:
    """A DTMC read from PRISM's explicit files."""

    def __init__(self, folder: Path, stem: str = "induced") -> None:
        tra = (folder / f"{stem}.tra").read_text().split("\n")
        n, m = map(int, tra[0].split())
        rows = [line.split() for line in tra[1:] if line.strip()]
        assert len(rows) == m
        self.n = n
        self.succ: list[list[tuple[int, float]]] = [[] for _ in range(n)]
        for s, t, p in rows:
            self.succ[int(s)].append((int(t), float(p)))
        lab = (folder / f"{stem}.lab").read_text().split("\n")
        names = {}
        for item in lab[0].split():
            k, name = item.split("=")
            names[int(k)] = name.strip('"')
        self.labels: dict[str, set[int]] = {name: set() for name in names.values()}
        for line in lab[1:]:
            if line.strip():
                state, members = line.split(":")
                for k in members.split():
                    self.labels[names[int(k)]].add(int(state))
        (self.initial,) = self.labels["init"]
        sta = (folder / f"{stem}.sta").read_text().split("\n")
        self.variables = sta[0].strip("()").split(",")
        self.valuations = {}
        for line in sta[1:]:
            if line.strip():
                state, values = line.split(":")
                self.valuations[int(state)] = tuple(int(v) for v in values.strip("()").split(","))

    def absorbing(self) -> set[int]:
        return {s for s in range(self.n) if self.succ[s] == [(s, 1.0)]}

    def rows_sum_to_one(self) -> bool:
        return all(abs(sum(p for _, p in succ) - 1.0) < 1e-9 for succ in self.succ)

    def reference_succs(self):
        """Successor lists in tests/reference.py's form: goal and every other absorbing state
        become "goal" / "fail"."""
        goal = self.labels["goal"]
        stop = self.absorbing()
        index = {s: i for i, s in enumerate(sorted(set(range(self.n)) - stop))}
        succs = [[("goal" if t in goal else "fail" if t in stop else index[t], p)
                  for t, p in self.succ[s]] for s in sorted(index)]
        return index, succs

    def reach_goal(self) -> float:
        """P(F "goal") from the initial state (tests/reference.py's linear solve)."""
        if self.initial in self.labels["goal"]:
            return 1.0
        index, succs = self.reference_succs()
        if self.initial not in index:
            return 0.0
        return float(reference.dtmc_reach(succs)[index[self.initial]])

    def bounded_goal(self, horizon: int) -> float:
        """P(F<=horizon "goal") from the initial state: x_k = [goal] + P x_{k-1} off the goal."""
        goal = np.zeros(self.n)
        goal[list(self.labels["goal"])] = 1.0
        rows, cols, vals = [], [], []
        for s, succ in enumerate(self.succ):
            if s in self.labels["goal"]:
                continue
            for t, p in succ:
                rows.append(s)
                cols.append(t)
                vals.append(p)
        matrix = sp.csr_matrix((vals, (rows, cols)), shape=(self.n, self.n))
        x = goal.copy()
        for _ in range(horizon):
            x = np.maximum(goal, matrix @ x)
        return float(x[self.initial])

    def expected_steps_to_absorption(self) -> float:
        """E[steps until an absorbing state] from the initial state; inf when some state with a
        positive chance of being reached never gets absorbed."""
        stop = self.absorbing()
        if self.initial in stop:
            return 0.0
        # forward-reachable states from the initial one
        seen, queue = {self.initial}, deque([self.initial])
        while queue:
            s = queue.popleft()
            for t, p in self.succ[s]:
                if p > 0 and t not in seen:
                    seen.add(t)
                    queue.append(t)
        # states of `seen` that can reach an absorbing state
        preds: dict[int, list[int]] = {s: [] for s in seen}
        for s in seen:
            for t, p in self.succ[s]:
                if p > 0:
                    preds[t].append(s)
        can = set(stop & seen)
        queue = deque(can)
        while queue:
            t = queue.popleft()
            for s in preds[t]:
                if s not in can:
                    can.add(s)
                    queue.append(s)
        if can != seen:
            return float("inf")
        live = sorted(seen - stop)
        pos = {s: i for i, s in enumerate(live)}
        rows, cols, vals = [], [], []
        for s in live:
            rows.append(pos[s])
            cols.append(pos[s])
            vals.append(1.0)
            for t, p in self.succ[s]:
                if t in pos:
                    rows.append(pos[s])
                    cols.append(pos[t])
                    vals.append(-p)
        matrix = sp.csc_matrix((vals, (rows, cols)), shape=(len(live), len(live)))
        return float(np.atleast_1d(spla.spsolve(matrix, np.ones(len(live))))[pos[self.initial]])


def hoa_table(text: str, labels: list[str | None]) -> tuple[int, dict[int, dict]]:
    """Read an HOA automaton with Spot and return (initial state, {q: {label: successor}}),
    a label being None (no proposition) or the one proposition that holds."""
    aut = spot.automaton(text)
    aps = [str(a) for a in aut.ap()]
    table = {}
    for q in range(aut.num_states()):
        row = {}
        for lab in labels:
            assign = buddy.bddtrue
            for ap in aps:
                var = aut.register_ap(ap)
                assign = buddy.bdd_and(assign, buddy.bdd_ithvar(var) if ap == lab
                                       else buddy.bdd_nithvar(var))
            targets = [e.dst for e in aut.out(q) if buddy.bdd_and(e.cond, assign) != buddy.bddfalse]
            assert len(targets) == 1, (q, lab, targets)
            row[lab] = targets[0]
        table[q] = row
    return aut.get_init_state_number(), table


def hoa_marked_states(text: str) -> set[int]:
    """States whose outgoing edges carry an acceptance mark."""
    aut = spot.automaton(text)
    return {e.src for e in aut.edges() if e.acc != spot.mark_t([])}
