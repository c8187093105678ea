"""Spot: syntactically co-safe LTL -> complete DFA over the world's label classes (docs/semantics.md §3)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np
import spot
import buddy


@dataclass(frozen=True, eq=False)
class DFA:
    formula: str
    n_states: int
    initial: int
    accepting: frozenset[int]     # final states: a good prefix has been read (docs/semantics.md §3)
    sink: frozenset[int]          # states from which no final state is reachable
    delta: np.ndarray             # [n_states, n_labels] successor on each label class
    automaton: spot.twa_graph | None = None   # Spot's automaton: its state numbers are the q's

    def read(self, q: int, label: int) -> int:
        return int(self.delta[q, label])


def is_cosafe(formula: str) -> bool:
    return spot.formula(formula).is_syntactic_guarantee()


def translate(formula: str, label_names: tuple[str, ...],
              occurring: Iterable[int] | None = None) -> DFA:
    """DFA of a syntactically co-safe formula, its letters being the label classes of the world.

    label_names[0] is the empty label; every other class sets exactly one proposition.
    occurring: the label classes the world's states actually produce (default: all of them).
    The final states and the sink are computed over these letters only (docs/semantics.md §3): a final
    state is one from which every continuation over them is accepted (a good prefix has been
    read), a sink one from which no final state can be reached.
    """
    f = spot.formula(formula)
    if not f.is_syntactic_guarantee():
        raise ValueError(f"{formula!r} is not syntactically co-safe")
    aut = spot.translate(f, "deterministic", "complete", "sbacc")
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
    for q in range(n):
        for edge in aut.out(q):
            for k, bdd in enumerate(letters):
                if (edge.cond & bdd) != buddy.bddfalse:
                    delta[q, k] = edge.dst
    if (delta < 0).any():
        raise AssertionError("Spot returned an incomplete automaton")
    used = sorted(set(range(len(label_names)) if occurring is None else occurring))
    buchi = [aut.state_is_accepting(q) for q in range(n)]
    final = good_prefix_states(delta[:, used], buchi)
    sink = frozenset(range(n)) - _can_reach(delta[:, used], final)
    return DFA(formula=formula, n_states=n, initial=aut.get_init_state_number(),
               accepting=frozenset(final), sink=sink, delta=delta, automaton=aut)


def good_prefix_states(delta: np.ndarray, buchi: list[bool]) -> frozenset[int]:
    """The states from which every infinite run over delta's letters is Büchi-accepted.

    A run is rejected exactly when it ends up looping in non-accepting states forever, so a
    state is *not* final when it can reach a state with an infinite path through non-accepting
    states only. Spot's Büchi marks alone are not final states: for `X A` it marks the transient
    initial states accepting, which would declare the goal reached before anything was read.
    """
    n = delta.shape[0]
    looping = {q for q in range(n) if not buchi[q]}     # greatest fixed point: can stay outside
    changed = True
    while changed:
        changed = False
        for q in list(looping):
            if not any(int(d) in looping for d in delta[q]):
                looping.discard(q)
                changed = True
    return frozenset(range(n)) - _can_reach(delta, frozenset(looping))


def _can_reach(delta: np.ndarray, targets: frozenset[int]) -> frozenset[int]:
    """States with a path (of length >= 0) into targets."""
    predecessors: list[set[int]] = [set() for _ in range(delta.shape[0])]
    for q in range(delta.shape[0]):
        for d in delta[q]:
            predecessors[int(d)].add(q)
    reached, stack = set(targets), list(targets)
    while stack:
        for p in predecessors[stack.pop()]:
            if p not in reached:
                reached.add(p)
                stack.append(p)
    return frozenset(reached)


# ---------------------------------------------------------------------------------------------
# Exports: the DFA as HOA (for Spot and other omega-automata tools) and as DOT (for Graphviz)
# ---------------------------------------------------------------------------------------------

def to_hoa(dfa: DFA, label_names: tuple[str, ...]) -> str:
    """The DFA in the Hanoi Omega-Automata format, states numbered as hg2prism numbers them.

    The edges are Spot's (complete and deterministic over every valuation of the formula's
    propositions); the acceptance set is the DFA's final states F instead of Spot's Büchi marks
    (docs/semantics.md §3): F is closed under the world's letters, so over them a run is
    Büchi-accepted exactly when it reaches F. A comment in the header names the sink states and
    the transition table over the world's label classes, which is what hg2prism reads.
    """
    if dfa.automaton is None:
        raise ValueError("the DFA has no Spot automaton to export")
    copy = spot.make_twa_graph(dfa.automaton, spot.twa_prop_set.all())
    copy.set_buchi()
    copy.prop_state_acc(True)
    # The edges (hence determinism and completeness) are Spot's; properties that depend on the
    # acceptance marks are no longer known.
    for prop in (copy.prop_terminal, copy.prop_weak, copy.prop_very_weak,
                 copy.prop_inherently_weak, copy.prop_stutter_invariant):
        prop(spot.trival_maybe())
    final = spot.mark_t([0])
    for edge in copy.edges():
        edge.acc = final if edge.src in dfa.accepting else spot.mark_t([])
    copy.set_name(f"DFA of {dfa.formula}")
    text = copy.to_str("hoa")
    # Spot writes the numbering it holds (make_twa_graph copies without renumbering); a
    # renumbered export would no longer match the q of strategy.json and of the PRISM model.
    if copy.num_states() != dfa.n_states or copy.get_init_state_number() != dfa.initial:
        raise AssertionError("Spot renumbered the DFA's states")
    def name(k: int) -> str:
        return label_names[k] or "{}"

    table = "; ".join(f"{q}: " + ", ".join(f"{name(k)}->{int(dfa.delta[q, k])}"
                                           for k in range(len(label_names)))
                      for q in range(dfa.n_states))
    comment = (f"hg2prism DFA of {dfa.formula!r}. States are the q of strategy.json and of "
               f"the PRISM models. Final (good-prefix) states: {sorted(dfa.accepting)}; sink "
               f"states: {sorted(dfa.sink)}. On the world's label classes: {table}.")
    comment = "/* " + comment.replace("*/", "* /") + " */"
    return text.replace("HOA: v1\n", f"HOA: v1\n{comment}\n", 1) + "\n"


def to_dot(dfa: DFA, label_names: tuple[str, ...]) -> str:
    """The DFA as a Graphviz digraph over the world's label classes: one edge per (state,
    successor) labelled with the classes leading there ("{}" = no proposition), final states
    double-circled, sink states grey, the initial state pointed at."""
    def quoted(text: str) -> str:
        return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'

    lines = [f"digraph {quoted('DFA of ' + dfa.formula)} {{", "  rankdir=LR",
             f"  label={quoted(dfa.formula + ' (states = q of strategy.json)')}",
             '  labelloc="t"', '  node [shape="circle"]',
             '  init [label="", shape=none, width=0]', f"  init -> {dfa.initial}"]
    for q in range(dfa.n_states):
        style = []
        if q in dfa.accepting:
            style.append("peripheries=2")
        if q in dfa.sink:
            style.append('style=filled, fillcolor="lightgrey"')
        kind = " (final)" if q in dfa.accepting else " (sink)" if q in dfa.sink else ""
        lines.append(f"  {q} [label={quoted(f'{q}{kind}')}{''.join(', ' + s for s in style)}]")
        by_target: dict[int, list[str]] = {}
        for k, name in enumerate(label_names):
            by_target.setdefault(int(dfa.delta[q, k]), []).append(name or "{}")
        for target, names in by_target.items():
            lines.append(f"  {q} -> {target} [label={quoted(', '.join(names))}]")
    lines.append("}")
    return "\n".join(lines) + "\n"
