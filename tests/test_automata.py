"""docs/semantics.md §3: Spot's DFAs over the world's label classes."""

from __future__ import annotations

import pytest
import spot

from hg2prism.model.automata import to_hoa, translate

LABELS = ("", "obs", "A", "B", "C")
TASK = "(!obs U A) & (!(B | obs) U C)"


def is_cosafe(formula: str) -> bool:
    return spot.formula(formula).is_syntactic_guarantee()


def test_paper_task_has_five_states_as_in_the_paper() -> None:
    dfa = translate(TASK, LABELS)
    assert dfa.n_states == 5
    assert len(dfa.accepting) == 1 and len(dfa.sink) == 1


def test_paper_task_transitions_match_the_paper_figure() -> None:
    """Fig. 3 of the paper: q0 -A-> q2, q0 -C-> q1, q0 -obs|B-> sink, q2 -C-> final,
    q1 -A-> final, q2 -obs|B-> sink, q1 -obs-> sink; staying on the empty label."""
    dfa = translate(TASK, LABELS)
    none, obs, a, b, c = range(5)
    q0 = dfa.initial
    (final,), (sink,) = dfa.accepting, dfa.sink
    seen_a, seen_c = dfa.read(q0, a), dfa.read(q0, c)
    assert len({q0, seen_a, seen_c, final, sink}) == 5
    assert dfa.read(q0, none) == q0
    assert dfa.read(q0, obs) == dfa.read(q0, b) == sink
    assert dfa.read(seen_a, c) == final and dfa.read(seen_a, a) == seen_a
    assert dfa.read(seen_a, obs) == dfa.read(seen_a, b) == sink
    assert dfa.read(seen_c, a) == final and dfa.read(seen_c, b) == seen_c == dfa.read(seen_c, c)
    assert dfa.read(seen_c, obs) == sink
    for label in range(5):
        assert dfa.read(final, label) == final and dfa.read(sink, label) == sink


@pytest.mark.parametrize("formula", ["G A", "F G A", "!(F A)", "A U G B", "G F A"])
def test_formulas_that_are_not_cosafe_are_refused(formula: str) -> None:
    assert not is_cosafe(formula)
    with pytest.raises(ValueError, match="co-safe"):
        translate(formula, LABELS)


def test_a_subgoal_hypothesis_has_three_states() -> None:
    dfa = translate("!obs U A", LABELS)
    assert dfa.n_states == 3
    (final,), (sink,) = dfa.accepting, dfa.sink
    assert dfa.read(dfa.initial, 2) == final and dfa.read(dfa.initial, 1) == sink
    assert dfa.read(dfa.initial, 3) == dfa.read(dfa.initial, 0) == dfa.initial


# ------------------------------------------------------------------ final states = good prefixes
# docs/semantics.md §3: a DFA state is final exactly when every infinite continuation over the world's letters
# is accepted. These tests ask Spot directly (language containment and satisfiability), without
# the package's rule, on random syntactically co-safe formulas.

import random

PROPS = ("obs", "A", "B", "C")


def _letter_formula(letter: str, props: tuple[str, ...]) -> str:
    """The Spot formula of one world letter: no proposition ("") or exactly one."""
    return " & ".join(p if p == letter else f"!{p}" for p in props)


def _only_world_letters(letters: list[str], props: tuple[str, ...]) -> spot.formula:
    return spot.formula("G(" + " | ".join(f"({_letter_formula(x, props)})" for x in letters) + ")")


def _random_cosafe_formulas(count: int, seed: int) -> list[tuple[str, tuple[str, ...]]]:
    """(formula, propositions): seeded randltl, half over 3 and half over 4 propositions,
    syntactic guarantees only (constants left out), each formula once."""
    chosen: list[tuple[str, tuple[str, ...]]] = []
    seen: set[str] = set()
    for props, tree_size, part_seed, quota in ((PROPS[:3], 12, seed, count // 2),
                                               (PROPS, 15, seed + 1, count - count // 2)):
        taken = 0
        for f in spot.randltl(list(props), seed=part_seed, tree_size=tree_size, simplify=1):
            if taken == quota:
                break
            text = str(f)
            if f.is_syntactic_guarantee() and not f.is_constant() and text not in seen:
                seen.add(text)
                chosen.append((text, props))
                taken += 1
    return chosen


COSAFE_FORMULAS = _random_cosafe_formulas(220, seed=20261123)


def _world_letters(props: tuple[str, ...], rng: random.Random) -> list[str]:
    """A world's letters: always none and the regions; obs only when the map has an obstacle."""
    letters = [""] + [p for p in props if p != "obs"]
    if rng.random() < 0.7:
        letters.append("obs")
    return letters


def test_enough_random_cosafe_formulas() -> None:
    assert len(COSAFE_FORMULAS) >= 200
    assert sum(1 for f, _ in COSAFE_FORMULAS if "X" in f) >= 50


@pytest.mark.parametrize("index", range(0, 220, 20))
def test_final_states_are_the_good_prefix_states(index: int) -> None:
    rng = random.Random(index)
    for formula, props in COSAFE_FORMULAS[index:index + 20]:
        labels = ("",) + props
        letters = _world_letters(props, rng)
        occurring = [labels.index(x) for x in letters]
        dfa = translate(formula, labels, occurring)
        universe = spot.translate(_only_world_letters(letters, props))
        # Spot numbers states differently from one translation to the next (the order in which
        # propositions were registered), so the DFA's own automaton is asked.
        aut = dfa.automaton
        assert aut.num_states() == dfa.n_states and aut.is_deterministic()
        for q in range(dfa.n_states):
            from_q = spot.make_twa_graph(aut, spot.twa_prop_set.all())
            from_q.set_init_state(q)
            every_continuation_accepted = spot.contains(from_q, universe)
            assert (q in dfa.accepting) == every_continuation_accepted, (formula, letters, q)
        # Sink: no final state reachable over the world's letters (breadth-first, here).
        reach = {q: {q} for q in range(dfa.n_states)}
        for _ in range(dfa.n_states):
            for q in reach:
                reach[q] |= {int(dfa.delta[r, k]) for r in reach[q] for k in occurring}
        for q in range(dfa.n_states):
            assert (q in dfa.sink) == (not reach[q] & dfa.accepting), (formula, q)


@pytest.mark.parametrize("index", range(0, 220, 20))
def test_dfa_accepts_a_finite_word_exactly_when_it_is_a_good_prefix(index: int) -> None:
    rng = random.Random(1000 + index)
    for formula, props in COSAFE_FORMULAS[index:index + 20]:
        labels = ("",) + props
        letters = _world_letters(props, rng)
        occurring = [labels.index(x) for x in letters]
        dfa = translate(formula, labels, occurring)
        negation = spot.formula(f"!({formula})")
        world_only = _only_world_letters(letters, props)
        for _ in range(4):
            word = [rng.choice(letters) for _ in range(rng.randint(0, 4))]
            q = dfa.initial
            for x in word:
                q = dfa.read(q, labels.index(x))
            # u is a good prefix iff no infinite word over the world's letters extends u and
            # violates the formula.
            prefix = "1"
            for x in reversed(word):
                prefix = f"({_letter_formula(x, props)}) & X({prefix})"
            counterexample = spot.formula(f"({prefix}) & {world_only} & {negation}")
            is_good_prefix = spot.translate(counterexample).is_empty()
            assert (q in dfa.accepting) == is_good_prefix, (formula, word, letters)


# ------------------------------------------------------------------ canonical numbering
# docs/semantics.md §3: DFA states are numbered breadth-first from the initial state, so the
# numbering does not depend on what the process translated before (Spot's own does).

import json
import subprocess
import sys

# "F A & F B" first: in the fresh process nothing is translated before it.
NUMBERED = ["F A & F B", TASK, "!obs U (A & F B)", "(!obs U A) & F B", "F (A & F B)",
            "!B U A", "(!A U B) | F C", "F(A & X B)", "X (A U B)"]
# Twenty co-safe formulas (Spot's randltl, seed 5) after which Spot numbers "F A & F B"
# otherwise than a fresh process does.
UNRELATED = ["Xobs & (B U obs)", "XXD & FD", "D", "B | C", "((!A & !B) | (A & B)) & (B | XD)",
             "XF!C", "X((D & X((D & obs) | (!D & !obs))) | (!D & X((!D & obs) | (D & !obs))))",
             "F(C & XC)", "F!D", "FA", "(obs | X!C) & (B | FC)", "F(B | C | (!D U B))", "F!B",
             "X(XD | (C & F!B))", "(C & !D) | (!C & D)",
             "((D & X!A) | (!D & XA)) M X(!obs | FA)", "D M ((D & obs) | (!D & !obs))",
             "C | X(D M !A)", "XFC", "((A & obs) | (!A & !obs)) & (C | D | XD)"]
TRANSLATING = """
import json, sys
import spot
from hg2prism.model.automata import to_hoa, translate
before, targets, labels = json.loads(sys.argv[1])
for formula in before:
    translate(formula, tuple(labels))
result = {}
for formula in targets:
    spots = spot.translate(spot.formula(formula), "deterministic", "complete", "sbacc")
    dfa = translate(formula, tuple(labels))
    result[formula] = {"initial": dfa.initial, "delta": dfa.delta.tolist(),
                       "accepting": sorted(dfa.accepting), "sink": sorted(dfa.sink),
                       "hoa": to_hoa(dfa, tuple(labels)), "spot": spots.to_str("hoa")}
print(json.dumps(result))
"""


def _translated_in_a_process(before: list[str], labels: tuple[str, ...]) -> dict:
    """NUMBERED translated in a fresh interpreter after `before`."""
    done = subprocess.run([sys.executable, "-c", TRANSLATING,
                           json.dumps([before, NUMBERED, list(labels)])],
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def test_numbering_is_breadth_first_in_label_class_order() -> None:
    """The paper's task: q0 = 0, then its successors on {}, obs, A, B, C in that order."""
    dfa = translate(TASK, LABELS)
    assert dfa.initial == 0
    assert dfa.delta.tolist() == [[0, 1, 2, 1, 3], [1] * 5, [2, 1, 2, 1, 4], [3, 1, 4, 3, 3],
                                  [4] * 5]
    assert dfa.accepting == {4} and dfa.sink == {1}


def test_numbering_does_not_depend_on_what_was_translated_before() -> None:
    """Each formula translated after twenty unrelated ones is numbered as in a fresh process
    (same initial state, delta, final and sink states) and task.hoa's text is byte-identical,
    although Spot's own automaton differs for some of them (so the test can fail)."""
    labels = ("", "obs", "A", "B", "C", "D")
    fresh = _translated_in_a_process([], labels)
    after = _translated_in_a_process(UNRELATED, labels)
    assert any(fresh[f]["spot"] != after[f]["spot"] for f in NUMBERED)
    for formula in NUMBERED:
        assert fresh[formula] | {"spot": None} == after[formula] | {"spot": None}, formula
    here = translate(TASK, labels)     # and in this process, after whatever the suite ran
    assert here.delta.tolist() == fresh[TASK]["delta"] and here.initial == fresh[TASK]["initial"]
    assert to_hoa(here, labels) == fresh[TASK]["hoa"]


def test_renumbering_keeps_the_language() -> None:
    """The renumbered automaton is Spot's up to isomorphism: the two accept the same words."""
    for formula in NUMBERED + UNRELATED:
        dfa = translate(formula, ("", "obs", "A", "B", "C", "D"))
        original = spot.translate(spot.formula(formula), "deterministic", "complete", "sbacc")
        assert dfa.automaton.num_states() == original.num_states()
        assert spot.are_equivalent(dfa.automaton, original), formula
