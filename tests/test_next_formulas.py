"""Formulas with X (next): the DFA's final states are good prefixes (docs/semantics.md §3), so the world values
are the hand-computed probabilities of reading the right letters at the right steps.

Every world here is a corridor walled above and below, so a slip (probability 0.1 to each side)
bumps into a wall and leaves the robot where it is: a move succeeds with probability 0.8.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import reference
from conftest import MODELS
from hg2prism import pipeline
from hg2prism.worldfile import load_world

SLIP = 0.1
MOVE = 1 - 2 * SLIP          # the chosen move happens


def world_text(rows: list[str], formula: str, hypotheses: list[str] | None = None) -> str:
    hypotheses = hypotheses or [formula]
    grid = "\n".join(rows)
    return f'''name = "next"
[grid]
map = """
{grid}
"""
[robot]
slip = {SLIP}
[task]
formula = "{formula}"
[adversary]
traps = 1
delay = 0
hypotheses = {hypotheses!r}
initial_hypothesis = 0
[inference]
window = 2
threshold = 1.5
rationality = 10.0
'''.replace("'", '"')


CASES = {
    # X A with A three moves east: after one step the robot cannot stand on A.
    "x_a_far": (["######", "#@..A#", "#t####", "######"], "X A", 0.0),
    # X A with A next door: the first move must succeed.
    "x_a_near": (["#####", "#t@A#", "#####"], "X A", MOVE),
    # X X A, A two moves east: both moves must succeed (the paper-world case of the issue).
    "x_x_a_two": (["#######", "#@.A.t#", "#######"], "X X A", MOVE * MOVE),
    # X X A, A next door with a wall behind it: succeed at once and stay (bumping into the wall
    # east of A keeps the robot on A with probability 1), or fail once and succeed then.
    "x_x_a_stay": (["#####", "#t@A#", "#####"], "X X A", MOVE * 1.0 + (1 - MOVE) * MOVE),
    # A | X B, starting off A: B must be the next cell.
    "a_or_x_b": (["######", "#A@Bt#", "######"], "A | X B", MOVE),
    # A | X B with B two moves away: impossible.
    "a_or_x_b_far": (["#######", "#A@.Bt#", "#######"], "A | X B", 0.0),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_next_formula_values_are_the_hand_computed_ones(name: str, tmp_path: Path) -> None:
    rows, formula, expected = CASES[name]
    path = tmp_path / f"{name}.toml"
    path.write_text(world_text(rows, formula))
    result = pipeline.check(load_world(path), tmp_path / name)
    assert result.results.deceptive_value == pytest.approx(expected, abs=1e-9)
    assert result.results.v_lead == pytest.approx(expected, abs=1e-9)
    assert reference.solve(path).value == pytest.approx(expected, abs=1e-9)
    if expected == 0.0:
        # every move from the start leads to failure: the start and the merged failure state
        assert result.results.states == 2


def test_world1_map_with_a_next_task(tmp_path: Path) -> None:
    """world1's map, task X X A: from the start (2,4) the robot reaches A (3,5) in two steps only by
    moving east then north, both without slipping: 0.8 x 0.8 (P2, guessing C, B or the task,
    never traps the cell east of the start in time to matter)."""
    text = (MODELS / "world1.toml").read_text()
    text = text.replace('formula = "(!obs U A) & (!(B | obs) U C)"', 'formula = "X X A"')
    text = text.replace('hypotheses = ["!obs U A", "!obs U B", "!obs U C"]',
                        'hypotheses = ["!obs U C", "!obs U B", "X X A"]')
    assert '"X X A"' in text
    path = tmp_path / "world1_xxa.toml"
    path.write_text(text)
    result = pipeline.check(load_world(path), tmp_path / "out")
    assert result.results.deceptive_value == pytest.approx(MOVE * MOVE, abs=1e-9)
    assert reference.solve(path).value == pytest.approx(MOVE * MOVE, abs=1e-9)
