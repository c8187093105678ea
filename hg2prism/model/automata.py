"""Spot: syntactically co-safe LTL -> complete DFA over the world's label classes (docs/semantics.md §3)."""

from __future__ import annotations

import itertools
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

    def __reduce__(self):
        # Spot's automaton does not pickle (a SWIG object): it travels as its HOA text, which
        # keeps its state numbers and its propositions' order (a Solution sent to another
        # process, copy.deepcopy).
        hoa = None if self.automaton is None else self.automaton.to_str("hoa")
        return _restored_dfa, (self.formula, self.n_states, self.initial, self.accepting,
                               self.sink, self.delta, hoa)


def _restored_dfa(formula: str, n_states: int, initial: int, accepting: frozenset[int],
                  sink: frozenset[int], delta: np.ndarray, hoa: str | None) -> DFA:
    return DFA(formula=formula, n_states=n_states, initial=initial, accepting=accepting,
               sink=sink, delta=delta, automaton=None if hoa is None else spot.automaton(hoa))


def translate(formula: str, label_names: tuple[str, ...],
              occurring: Iterable[int] | None = None) -> DFA:
    """DFA of a syntactically co-safe formula, its letters being the label classes of the world.

    label_names[0] is the empty label; every other class sets the propositions its name joins
    with '&' (a grid's each set one).
    occurring: the label classes the world's states actually produce (default: all of them).
    The final states and the sink are computed over these letters only (docs/semantics.md §3): a final
    state is one from which every continuation over them is accepted (a good prefix has been
    read), a sink one from which no final state can be reached.
    """
    f = spot.formula(formula)
    if not f.is_syntactic_guarantee():
        raise ValueError(f"{formula!r} is not syntactically co-safe")
    spot_aut = spot.translate(f, "deterministic", "complete", "sbacc")
    letters = _letters(spot_aut, label_names)
    aut = _renumbered(spot_aut, letters, label_names)
    n = aut.num_states()
    delta = np.array([[_successor(aut, q, bdd) for bdd in letters] for q in range(n)],
                     dtype=np.int64).reshape(n, len(label_names))
    used = sorted(set(range(len(label_names)) if occurring is None else occurring))
    buchi = [aut.state_is_accepting(q) for q in range(n)]
    final = good_prefix_states(delta[:, used], buchi)
    sink = frozenset(range(n)) - _can_reach(delta[:, used], final)
    return DFA(formula=formula, n_states=n, initial=aut.get_init_state_number(),
               accepting=frozenset(final), sink=sink, delta=delta, automaton=aut)


def _letters(aut: spot.twa_graph, label_names: tuple[str, ...]) -> list[object]:
    """The BDD of each label class over the automaton's propositions: the class's proposition
    true (if the automaton has it), every other one false."""
    return [_valuation(aut, set(name.split("&")) - {""}) for name in label_names]


def _valuation(aut: spot.twa_graph, true_aps: set[str]) -> object:
    """The BDD of the valuation of the automaton's propositions that sets exactly `true_aps`."""
    bdd = buddy.bddtrue
    for ap in aut.ap():
        var = aut.register_ap(ap)
        bdd = bdd & (buddy.bdd_ithvar(var) if str(ap) in true_aps else buddy.bdd_nithvar(var))
    return bdd


def _successor(aut: spot.twa_graph, q: int, letter: object) -> int:
    """The destination of q's edge on `letter` (a full valuation: deterministic and complete
    automata have exactly one)."""
    for edge in aut.out(q):
        if (edge.cond & letter) != buddy.bddfalse:
            return edge.dst
    raise AssertionError("Spot returned an incomplete automaton")


def _renumbered(aut: spot.twa_graph, letters: list[object],
                label_names: tuple[str, ...]) -> spot.twa_graph:
    """Spot's automaton with its states numbered canonically (docs/semantics.md §3).

    Spot numbers states by the process's history (the order in which propositions were met),
    so two translations of one formula may differ. Here the states are numbered breadth-first
    from the initial state, successors in label-class order; states that no sequence of label
    classes reaches follow, breadth-first over every valuation of the automaton's propositions
    (in the order below, in binary order, the last proposition varying fastest). The
    propositions are registered in label-class order (any the world lacks after them, by
    name), and each state's edges are listed in the new order.
    """
    present = {str(ap) for ap in aut.ap()}
    names = list(dict.fromkeys(p for n in label_names for p in n.split("&") if p in present))
    names += sorted(present - set(names))
    valuations = [_valuation(aut, {name for name, bit in zip(names, bits) if bit})
                  for bits in itertools.product((False, True), repeat=len(names))]
    order = _breadth_first(aut, [aut.get_init_state_number()], letters)
    order = _breadth_first(aut, order, valuations)
    if len(order) != aut.num_states():
        raise AssertionError("Spot returned states unreachable from the initial state")
    number = {old: new for new, old in enumerate(order)}
    copy = spot.make_twa_graph(aut.get_dict())
    for name in names:
        copy.register_ap(name)
    copy.copy_acceptance_of(aut)
    copy.prop_copy(aut, spot.twa_prop_set.all())
    copy.new_states(len(order))
    copy.set_init_state(number[aut.get_init_state_number()])
    for old in order:
        for edge in sorted(aut.out(old), key=lambda e: number[e.dst]):
            copy.new_edge(number[old], number[edge.dst], edge.cond, edge.acc)
    return copy


def _breadth_first(aut: spot.twa_graph, seeds: list[int], letters: list[object]) -> list[int]:
    """`seeds` followed by the states first reached from them breadth-first, successors in the
    order of `letters`."""
    order, seen = list(seeds), set(seeds)
    for q in order:      # grows while it is walked: the queue
        for letter in letters:
            target = _successor(aut, q, letter)
            if target not in seen:
                seen.add(target)
                order.append(target)
    return order


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

    The edges are those of Spot's automaton (complete and deterministic over every valuation of
    the formula's propositions); the acceptance set is the DFA's final states F instead of
    Spot's Büchi marks (docs/semantics.md §3): F is closed under the world's letters, so over
    them a run is Büchi-accepted exactly when it reaches F. A comment in the header names the
    sink states and the transition table over the world's label classes, which is what
    hg2prism reads. The text is written here rather than by Spot, whose printer orders the
    propositions and the terms of each label by BDD variable, that is by the process's
    history: this one depends on the DFA alone (one edge per destination, in state order, its
    label a cover of its valuations by prime implicants).
    """
    if dfa.automaton is None:
        raise ValueError("the DFA has no Spot automaton to export")
    aut = dfa.automaton
    names = [str(ap) for ap in aut.ap()]
    valuations = list(itertools.product((0, 1), repeat=len(names)))
    letters = [_valuation(aut, {n for n, bit in zip(names, bits) if bit}) for bits in valuations]

    def name(k: int) -> str:
        return label_names[k] or "{}"

    table = "; ".join(f"{q}: " + ", ".join(f"{name(k)}->{int(dfa.delta[q, k])}"
                                           for k in range(len(label_names)))
                      for q in range(dfa.n_states))
    comment = (f"hg2prism DFA of {dfa.formula!r}. States are the q of strategy.json and of "
               f"the PRISM models. Final (good-prefix) states: {sorted(dfa.accepting)}; sink "
               f"states: {sorted(dfa.sink)}. On the world's label classes: {table}.")
    lines = ["HOA: v1", "/* " + comment.replace("*/", "* /") + " */",
             "name: " + _hoa_string(f"DFA of {dfa.formula}"), f"States: {dfa.n_states}",
             f"Start: {dfa.initial}", " ".join([f"AP: {len(names)}"] + [_hoa_string(n) for n in names]),
             "acc-name: Buchi", "Acceptance: 1 Inf(0)",
             "properties: trans-labels explicit-labels state-acc complete",
             "properties: deterministic", "--BODY--"]
    for q in range(dfa.n_states):
        lines.append(f"State: {q}" + (" {0}" if q in dfa.accepting else ""))
        by_target: dict[int, list[tuple[int, ...]]] = {}
        for bits, letter in zip(valuations, letters):
            by_target.setdefault(_successor(aut, q, letter), []).append(bits)
        for target in sorted(by_target):
            lines.append(f"[{_hoa_label(_prime_cover(by_target[target]))}] {target}")
    return "\n".join(lines + ["--END--"]) + "\n"


def _hoa_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _hoa_label(cubes: list[tuple[int | None, ...]]) -> str:
    """A HOA label: the disjunction of the cubes (None: the proposition does not matter)."""
    terms = ["&".join(("" if bit else "!") + str(i) for i, bit in enumerate(cube)
                      if bit is not None) or "t" for cube in cubes]
    return " | ".join(terms)


def _prime_cover(minterms: list[tuple[int, ...]]) -> list[tuple[int | None, ...]]:
    """A small set of cubes whose union is exactly `minterms` (valuations as 0/1 tuples): the
    prime implicants (Quine-McCluskey), then greedily the one covering most of what is left
    (ties: the first in sorted order). Deterministic: it depends on the set alone."""
    def key(cube: tuple[int | None, ...]) -> tuple[int, ...]:
        return tuple(2 if bit is None else bit for bit in cube)

    def covers(cube: tuple[int | None, ...], minterm: tuple[int, ...]) -> bool:
        return all(bit is None or bit == m for bit, m in zip(cube, minterm))

    cubes: set[tuple[int | None, ...]] = set(minterms)
    primes: set[tuple[int | None, ...]] = set()
    while cubes:
        merged, used = set(), set()
        for cube in cubes:
            for i, bit in enumerate(cube):
                other = cube[:i] + (None if bit is None else 1 - bit,) + cube[i + 1:]
                if bit is not None and other in cubes:
                    merged.add(cube[:i] + (None,) + cube[i + 1:])
                    used |= {cube, other}
        primes |= cubes - used
        cubes = merged
    candidates, left, chosen = sorted(primes, key=key), set(minterms), []
    while left:
        best = max(candidates, key=lambda c: sum(covers(c, m) for m in left))
        chosen.append(best)
        left = {m for m in left if not covers(best, m)}
    return sorted(chosen, key=key)


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
