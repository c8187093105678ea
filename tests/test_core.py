"""The core pipeline against an independent explicit solver (tests/reference.py), on world1 and
a seeded family of small generated worlds (tests/worldgen.py)."""

from __future__ import annotations

import dataclasses
import functools
import json
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import pytest

import reference
import worldgen
from conftest import MODELS
import gridview
from hg2prism import pipeline
from hg2prism.engines import storm
from hg2prism.prism.decoding import DecodedStates
from hg2prism.frontends.grid import ACTIONS
from hg2prism.opponent.inference import Memory
from hg2prism.worldfile import load_world
from hg2prism.strategy.canonical import canonical_mdp, canonical_values
from conftest import share

FAMILY = dict(worldgen.world_family())
CASES = ["world1"] + share(sorted(FAMILY))        # every fourth under `make test`
TOL = 1e-6


@functools.cache
def world_path(name: str, folder: str) -> Path:
    if name == "world1":
        return MODELS / "world1.toml"
    path = Path(folder) / f"{name}.toml"
    path.write_text(FAMILY[name])
    return path


@functools.cache
def run(name: str, folder: str) -> tuple[pipeline.CheckResult, reference.Reference]:
    path = world_path(name, folder)
    result = pipeline.check(load_world(path), Path(folder) / name)
    return result, reference.solve(path)


@pytest.fixture(params=CASES)
def case(request: pytest.FixtureRequest, world_dir: Path):
    return run(request.param, str(world_dir))


def test_family_covers_the_required_variety() -> None:
    worlds = [load_world_text(text) for text in FAMILY.values()]
    assert len(worlds) >= 30
    assert {w["adversary"].get("delay", 0) > 0 for w in worlds} == {True, False}
    assert {w["adversary"]["traps"] for w in worlds} >= {1, 2}
    assert {w["inference"]["window"] for w in worlds} >= {1, 2, 3}
    assert {w["robot"]["slip"] == 0 for w in worlds} == {True, False}
    assert {len(w["adversary"]["hypotheses"]) == 1 for w in worlds} == {True, False}
    # the delay encoding (docs/semantics.md §6) is checked on 30+ worlds with delay 1-3
    delayed = [w["adversary"] for w in worlds if w["adversary"].get("delay", 0) > 0]
    assert len(delayed) >= 30
    assert {a["delay"] for a in delayed} == {1, 2, 3}
    assert {a["traps"] for a in delayed} == {1, 2}


def load_world_text(text: str) -> dict:
    import tomllib
    return tomllib.loads(text)


def test_deceptive_value_matches_reference(case) -> None:
    result, ref = case
    assert result.results.deceptive_value == pytest.approx(ref.value, abs=TOL)


def test_leader_value_matches_reference_and_bounds_deception(case) -> None:
    result, ref = case
    assert result.results.v_lead == pytest.approx(ref.v_lead, abs=TOL)
    assert result.results.v_lead <= result.results.deceptive_value + TOL


def test_canonical_size_matches_reference(case) -> None:
    result, ref = case
    assert (result.results.states, result.results.transitions) == (ref.states, ref.transitions)


def test_trap_strategy_matches_reference(case) -> None:
    result, ref = case
    assert _trap_strategies_compared(result, ref) > 0


def _trap_strategies_compared(result, ref) -> int:
    """P2's trap set under each hypothesis at every TS state the reference solved, asserted
    equal to the reference's; how many were compared."""
    ts = gridview.view(result.analysis)
    compared = 0
    for h, game in enumerate(result.analysis.games):
        for state in range(ts.n_states - 1):
            try:  # the reference solves P2's games on the TS states reachable from the start
                theirs = ref.trap_strategy(h, _reference_state(ts, state))
            except KeyError:
                continue
            assert set(ts.trap_cells(int(game.trap_choice[state]))) == set(theirs), (h, state)
            compared += 1
    return compared


def test_exported_strategy_is_optimal(case) -> None:
    result, ref = case
    value = result.results.deceptive_value
    # The DTMC Storm's scheduler induces, checked by Storm ...
    assert result.engine.induced_probability(result.checked, result.strategy.choice) == pytest.approx(value, abs=TOL)
    # ... and the exported JSON strategy, evaluated by the independent solver.
    assert ref.strategy_value(result.records) == pytest.approx(value, abs=TOL)


def test_strategy_file_holds_the_records(case) -> None:
    """strategy.json is written column-wise (strategy/columns.py), not from the records: same
    content."""
    result, _ = case
    written = json.loads((result.out / "strategy.json").read_text())
    assert written == list(result.records)
    absorbing = int(result.decoded.goal.any()) + int(result.decoded.fail.any())
    assert len(written) == result.results.states - absorbing   # one per canonical state


def test_storm_inference_transitions_are_those_of_section_5(case) -> None:
    """Every transition Storm built moves P2's memory exactly as inference.update does."""
    result, _ = case
    decoded, inference, ts = result.decoded, result.analysis.inference, result.analysis.ts
    moves = result.engine.explicit(result.checked.model).transitions
    memories = [_memory(decoded, s) for s in range(len(decoded.place))]
    updates: dict[tuple, Memory] = {}         # inference.update is a function of its arguments
    checked = 0
    for choice in range(len(moves.source)):
        s = int(moves.source[choice])
        if decoded.goal[s] or decoded.fail[s]:
            continue
        state = ts.state(int(decoded.place[s]), int(decoded.traps[s]), int(decoded.countdown[s]))
        key = (memories[s], state, int(moves.action[choice]))
        expected = updates.get(key)
        if expected is None:
            expected = updates[key] = inference.update(key[0], key[1:])
        for t in moves.target[moves.row_start[choice]:moves.row_start[choice + 1]].tolist():
            assert memories[t] == expected
            checked += 1
    assert checked > 0


def test_tables_are_exact_wherever_storm_goes(case) -> None:
    """The model's tables over TS states are exact only on ts.reachable (rendering.lookup's
    `care`): every TS state Storm reached, in a state or in a window slot, is among them."""
    result, _ = case
    decoded, ts = result.decoded, result.analysis.ts
    reachable = ts.reachable(np.array([g.trap_choice for g in result.analysis.games]))
    live = ~(decoded.goal | decoded.fail) & (decoded.place < ts.n_places)
    states = (decoded.place * ts.n_sets + decoded.traps) * ts.phases + decoded.countdown \
        if ts.delay else decoded.place
    assert reachable[states[live]].all()
    slots = decoded.window[..., 0]
    assert reachable[slots[slots >= 0]].all()


def test_python_inference_matches_reference(case) -> None:
    """inference.update against the reference's eta on every memory Storm reached."""
    result, ref = case
    decoded, inference = result.decoded, result.analysis.inference
    ts = gridview.view(result.analysis)
    seen = set()
    for s in range(len(decoded.place)):
        if decoded.goal[s] or decoded.fail[s]:
            continue
        memory = _memory(decoded, s)
        state = ts.state(int(decoded.place[s]), int(decoded.traps[s]), int(decoded.countdown[s]))
        for a in range(4):
            if (memory, state, a) in seen:
                continue
            seen.add((memory, state, a))
            ours = inference.update(memory, (state, a))
            theirs = ref.infer(memory.hypothesis, _reference_window(ts, memory.window),
                               (_reference_state(ts, state), ACTIONS[a]))
            assert (ours.hypothesis, _reference_window(ts, ours.window)) == theirs


def _memory(decoded: DecodedStates, s: int) -> Memory:
    return Memory(int(decoded.hypothesis[s]),
                  tuple((int(v), int(a)) for v, a in decoded.window[s] if v >= 0))


def _reference_state(ts, state: int):
    if state == ts.trapped:
        return "trapped"
    cell, traps, countdown = ts.decode(state)
    if ts.delay == 0:
        return ts.cells[cell]
    return (*ts.cells[cell], ts.trap_cells(traps), countdown)


def _reference_window(ts, window) -> tuple:
    return tuple((_reference_state(ts, v), ACTIONS[a]) for v, a in window)


def test_single_hypothesis_equal_to_a_one_step_task_gives_v_lead(world_dir: Path) -> None:
    """docs/semantics.md §7: X = {phi}, phi = "!obs U A": deceptive value equals V_lead."""
    world = load_world(MODELS / "world1.toml")
    for window in (1, 2):
        single = dataclasses.replace(world, formula="!obs U A", hypotheses=("!obs U A",),
                                     initial_hypothesis=0, window=window)
        result = pipeline.check(single, world_dir / f"single_w{window}")
        assert result.results.deceptive_value == pytest.approx(result.results.v_lead, abs=TOL)
        assert 0 < result.results.v_lead < 1


def test_command_count_does_not_grow_with_the_product(world_dir: Path) -> None:
    world = load_world(MODELS / "world1.toml")
    variants = {
        "w1": dataclasses.replace(world, window=1),
        "w3": dataclasses.replace(world, window=3),
        "x2": dataclasses.replace(world, hypotheses=world.hypotheses[:2]),
        "x5": dataclasses.replace(world, hypotheses=world.hypotheses + ("F A", "!obs U (A & X C)")),
        "t2": dataclasses.replace(world, traps=2),
    }
    counts = {}
    for name, variant in variants.items():
        model = pipeline.emit(variant, world_dir / f"cmd_{name}")
        counts[name] = model.commands
    # One command per move and one for the absorbing states, whatever the trap sets.
    assert {c["robot"] for c in counts.values()} == {5}
    assert {c["task"] for c in counts.values()} == {4}
    # The inference module grows with the hypotheses (8 commands each; 4 with window 1, where
    # the hypothesis after each move is a table), not with the window.
    for name, variant in variants.items():
        per_hypothesis = 4 if variant.window == 1 else 8
        assert counts[name]["p2_inference"] == per_hypothesis * len(variant.hypotheses), name
    assert counts["w3"]["p2_inference"] == counts["x5"]["p2_inference"] * 3 // 5
    model = pipeline.emit(world, world_dir / "cmd_world1")
    assert sum(model.commands.values()) < 100
    assert len(model.text) < 200_000


def test_storm_builds_more_states_with_longer_windows(world_dir: Path) -> None:
    """The product grows with the window while the command count above does not."""
    world = load_world(MODELS / "world1.toml")
    sizes = [pipeline.check(dataclasses.replace(world, window=w), world_dir / f"size_w{w}")
             .results.states for w in (1, 2, 3)]
    assert sizes[0] < sizes[1] < sizes[2]


@pytest.mark.parametrize("name", ["world1"] + sorted(FAMILY)[::9])
@pytest.mark.parametrize("method", ["storm-sound", "sound-ovi", "fast"])
def test_storm_methods_agree_with_the_sound_default(name: str, method: str, world_dir: Path) -> None:
    result, ref = run(name, str(world_dir))
    other = storm.check(result.out / "hypergame.prism", pipeline.PROPERTY, method)
    tolerance = 1e-9 if "sound" in method else TOL   # "fast" is not sound
    assert other.values == pytest.approx(result.checked.values, abs=tolerance)
    assert other.value == pytest.approx(ref.value, abs=TOL)


def test_deceptive_moves_are_the_fastest_optimal_ones(case) -> None:
    """docs/semantics.md §6: every state's exported move is, among the moves whose value is
    within 1e-8 of the state's, the first (in move order) maximising the discounted (0.9)
    probability W of reaching the goal; W iterated here by a plain Jacobi iteration over the
    optimal moves (a sparse matrix of this test's own, not the package's fastest-move code)."""
    result, _ = case
    moves = result.engine.explicit(result.checked.model).transitions
    mdp = canonical_mdp(result.decoded, moves)
    values = canonical_values(result.decoded, result.checked.values)
    n_choices = mdp.choice_state.size
    # each choice's one-step value, and which choices are optimal (within 1e-8)
    step = np.zeros(n_choices)
    np.add.at(step, mdp.entry_choice, mdp.entry_prob * values[mdp.entry_target])
    optimal = step >= values[mdp.choice_state] - 1e-8
    # score(c, w) = sum over c's entries of p * (1 if the target is a goal else 0.9 * w[target])
    goal = mdp.goal[mdp.entry_target]
    reward = np.zeros(n_choices)
    np.add.at(reward, mdp.entry_choice[goal], mdp.entry_prob[goal])
    onward = sp.csr_matrix((0.9 * mdp.entry_prob[~goal],
                            (mdp.entry_choice[~goal], mdp.entry_target[~goal])),
                           shape=(n_choices, mdp.n))
    states = mdp.choice_state[optimal]
    w = np.zeros(mdp.n)
    for _ in range(1000):
        best = np.full(mdp.n, -np.inf)
        np.maximum.at(best, states, (reward + onward @ w)[optimal])
        new = np.where(np.isfinite(best), best, 0.0)
        change = np.abs(new - w).max(initial=0.0)
        w = new
        if change < 1e-9:
            break
    scores = reward + onward @ w
    action = moves.action[result.strategy.choice[mdp.representative]]
    exported = action >= 0
    assert set(np.flatnonzero(exported).tolist()) == set(states.tolist())
    best = np.full(mdp.n, -np.inf)
    np.maximum.at(best, states, scores[optimal])
    at_best = optimal & (scores >= (best - 1e-12 * np.abs(best))[mdp.choice_state])
    first = np.full(mdp.n, n_choices)                 # choices are in state and move order
    np.minimum.at(first, mdp.choice_state[at_best], np.flatnonzero(at_best))
    wrong = np.flatnonzero(exported & (action != mdp.choice_action[np.minimum(first, n_choices - 1)]))
    assert wrong.size == 0, wrong[:10]


def _tie_break_cases() -> list[str]:
    """world1 and three generated worlds (delay 0 and positive, one and two traps) on which
    P2's tie break changes her play."""
    worlds = {name: load_world_text(text)["adversary"] for name, text in FAMILY.items()}
    picks = [next(n for n, a in sorted(worlds.items()) if a.get("delay", 0) == 0),
             next(n for n, a in sorted(worlds.items()) if a.get("delay", 0) > 0 and a["traps"] == 1),
             next(n for n, a in sorted(worlds.items()) if a.get("delay", 0) > 0 and a["traps"] == 2)]
    return ["world1"] + picks


@pytest.mark.parametrize("name", _tie_break_cases())
def test_the_last_tie_break_against_the_reference(name: str, world_dir: Path) -> None:
    """[adversary] tie_break = "last" (docs/semantics.md §4): P2 takes the last of her tied
    sets where the standing one is not tied. Values, canonical sizes and her strategies agree
    with the independent reference reading the same key, and the strategies differ from the
    rule's (first) somewhere, so the key does something."""
    text = world_path(name, str(world_dir)).read_text()
    last = world_dir / f"{name}_last.toml"
    last.write_text(text.replace("[adversary]\n", '[adversary]\ntie_break = "last"\n', 1))
    result = pipeline.check(load_world(last), world_dir / f"{name}_last")
    ref = reference.solve(last)
    assert result.results.deceptive_value == pytest.approx(ref.value, abs=TOL)
    assert result.results.v_lead == pytest.approx(ref.v_lead, abs=TOL)
    assert (result.results.states, result.results.transitions) == (ref.states, ref.transitions)
    assert _trap_strategies_compared(result, ref) > 0
    first, _ = run(name, str(world_dir))
    assert any((game.trap_choice != rule.trap_choice).any()
               for game, rule in zip(result.analysis.games, first.analysis.games))


def test_the_last_tie_break_is_the_first_with_the_candidates_reversed(tmp_path: Path) -> None:
    """With one trap, P2 taking the last of her tied sets is P2 taking the first with the
    trap candidates listed in reverse (world1's arena form, `convert`): the same deceptive
    value (0.9636 against the rule's 0.9498: the tie decides part of world1's value) and
    sizes; and `convert` writes the key."""
    from hg2prism.frontends.arena import to_toml

    world = load_world(MODELS / "world1.toml")
    last = world.replace(tie_break="last")
    arena = to_toml(world)
    assert 'tie_break = "last"' in to_toml(last) and "tie_break" not in arena
    assert last.digest() != world.digest()      # another world (the rule's keeps its digest)
    start = arena.index("trap_candidates = [")
    end = arena.index("]", start)
    names = [n.strip() for n in arena[start + len("trap_candidates = ["):end].split(",")]
    reversed_text = arena[:start] + "trap_candidates = [" + ", ".join(names[::-1]) + arena[end:]
    (tmp_path / "world1_reversed.toml").write_text(reversed_text)
    reversed_world = load_world(tmp_path / "world1_reversed.toml")
    ours = pipeline.check(last, tmp_path / "last").results
    theirs = pipeline.check(reversed_world, tmp_path / "reversed").results
    rule = pipeline.check(world, tmp_path / "first").results
    assert ours.deceptive_value == pytest.approx(theirs.deceptive_value, abs=1e-9)
    assert (ours.states, ours.transitions) == (theirs.states, theirs.transitions)
    # the numbers docs/semantics.md §4 gives (the reference computes both in the test above)
    assert (round(rule.deceptive_value, 4), round(ours.deceptive_value, 4)) == (0.9498, 0.9636)


CORRIDORS = '''name = "corridors"
description = "A and B at the ends of two corridors, the first candidate A's chokepoint"

[grid]
map = """
#########
#A#...#B#
#t#...#t#
#.#.o.#.#
#.......#
#...t...#
#.......#
#...@...#
#########
"""

[robot]
slip = 0.1

[task]
formula = "!obs U A"

[adversary]
traps = 1
hypotheses = ["!obs U A", "!obs U B"]
initial_hypothesis = 1

[inference]
window = 2
threshold = 1.5
rationality = 5.0
'''


@pytest.mark.parametrize("tie_break, value", [("first", 0.0), ("last", 1.0)])
def test_the_tie_decides_everything_in_the_corridors(tie_break: str, value: float,
                                                     tmp_path: Path) -> None:
    """docs/semantics.md §4, "What the tie decides": P2, believing B, is indifferent between
    her three candidates while P1 walks up A's corridor; by the rule she takes the first, A's
    chokepoint, and P1 never arrives (0); taking the last (the middle cell) she lets him pass
    (1). The reference agrees both ways."""
    path = tmp_path / f"corridors_{tie_break}.toml"
    path.write_text(CORRIDORS.replace("initial_hypothesis = 1\n",
                                      f'initial_hypothesis = 1\ntie_break = "{tie_break}"\n'))
    result = pipeline.check(load_world(path), tmp_path / "out")
    assert result.results.deceptive_value == pytest.approx(value, abs=1e-9)
    assert reference.solve(path).value == pytest.approx(value, abs=TOL)
