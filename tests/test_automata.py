"""SPEC §3: Spot's DFAs over the world's label classes."""

from __future__ import annotations

import pytest

from hg2prism.automata import is_cosafe, translate

LABELS = ("", "obs", "A", "B", "C")
TASK = "(!obs U A) & (!(B | obs) U C)"


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
