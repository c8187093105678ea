"""Spot: syntactically co-safe LTL -> complete DFA over the world's label classes (SPEC §3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import spot
import buddy


@dataclass(frozen=True, eq=False)
class DFA:
    formula: str
    n_states: int
    initial: int
    accepting: frozenset[int]
    sink: frozenset[int]          # states from which no accepting state is reachable
    delta: np.ndarray             # [n_states, n_labels] successor on each label class

    def is_absorbing(self, q: int) -> bool:
        return q in self.accepting or q in self.sink

    def read(self, q: int, label: int) -> int:
        return int(self.delta[q, label])


def is_cosafe(formula: str) -> bool:
    return spot.formula(formula).is_syntactic_guarantee()


def translate(formula: str, label_names: tuple[str, ...]) -> DFA:
    """DFA of a syntactically co-safe formula, its letters being the label classes of the world.

    label_names[0] is the empty label; every other class sets exactly one proposition.
    """
    f = spot.formula(formula)
    if not f.is_syntactic_guarantee():
        raise ValueError(f"{formula!r} is not syntactically co-safe")
    aut = spot.translate(f, "deterministic", "complete", "sbacc")
    bdict = aut.get_dict()
    aps = [str(ap) for ap in aut.ap()]
    ap_vars = {ap: aut.register_ap(ap) for ap in aps}

    def letter(true_ap: str) -> object:
        bdd = buddy.bddtrue
        for ap, var in ap_vars.items():
            bdd = bdd & (buddy.bdd_ithvar(var) if ap == true_ap else buddy.bdd_nithvar(var))
        return bdd

    letters = [letter(name) for name in label_names]
    n = aut.num_states()
    delta = np.full((n, len(label_names)), -1, dtype=np.int64)
    accepting = set()
    graph: list[set[int]] = [set() for _ in range(n)]
    for q in range(n):
        if aut.state_is_accepting(q):
            accepting.add(q)
        for edge in aut.out(q):
            graph[q].add(edge.dst)
            for k, bdd in enumerate(letters):
                if (edge.cond & bdd) != buddy.bddfalse:
                    delta[q, k] = edge.dst
    if (delta < 0).any():
        raise AssertionError("Spot returned an incomplete automaton")
    del bdict

    # Sink: F unreachable in the automaton's graph (over the full alphabet 2^AP).
    can_accept = set(accepting)
    changed = True
    while changed:
        changed = False
        for q in range(n):
            if q not in can_accept and graph[q] & can_accept:
                can_accept.add(q)
                changed = True
    sink = frozenset(q for q in range(n) if q not in can_accept)
    return DFA(formula=formula, n_states=n, initial=aut.get_init_state_number(),
               accepting=frozenset(accepting), sink=sink, delta=delta)
