"""Adaptive deception (docs/semantics.md §16) against the independent reference
(tests/reference.py: TypedWorld, written from the semantics alone): V_adapt from Storm on the
adaptive hypergame's PRISM model, and every V_commit(j), within 1e-6 on generated grid and
arena worlds with 2-3 types (CUSUM and Bayesian "map", delay 0-2); V_commit(j) <= V_adapt <=
V_oracle; the canonical size and the exported adaptive strategy's value, on arena worlds too
(records read through a pairing of the two numberings of the task DFA); Storm's adaptive
transitions against the Python successor function, choice by choice; PRISM's POMDP bounds
as `run --prism-pomdp` reports them; and the boundary cases (one type carries all the weight;
two identical types)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import reference
import typegen
from hg2prism.experiments.adaptive import check_adaptive
from hg2prism.model import sizeguard
from hg2prism.worldfile.loader import load_world
from conftest import share

TOL = 1e-6
# seeds of tests/typegen.py whose worlds check in under 3 s each (of the first 40; all 40 agree
# with the reference)
GRID_SEEDS = [2, 3, 6, 7, 8, 9, 12, 14, 15, 18, 19, 25, 27, 28, 29, 30, 31, 32, 36, 37, 39]
ARENA_SEEDS = list(range(10))
# arena seeds whose task DFA the reference numbers otherwise than the package (q_pairing is not
# the identity): their records are read through the pairing
ARENA_RENUMBERED = {3, 6, 7}


def solve(tmp_path, text: str, name: str = "typed"):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    out = tmp_path / f"{name}_out"
    return path, check_adaptive(load_world(path), out), out


def q_pairing(check, ref) -> dict[int, int]:
    """The package's task DFA states -> the reference's, pairing the two DFAs breadth-first
    from their initial states over the same letters (the world's label classes). Both are
    Spot's automaton of the task numbered differently (the reference orders an arena's
    multi-proposition letters its own way), so the pairing is an isomorphism on the states the
    letters reach: asserted."""
    task, ts, theirs = check.analysis.task, check.analysis.ts, ref.base.task_dfa
    letters = {frozenset(reference.true_props(lab)): lab for lab in theirs.delta[theirs.init]}
    ours = [(k, letters[frozenset(name.split("&")) - {""}])
            for k, name in enumerate(ts.label_names)
            if frozenset(name.split("&")) - {""} in letters]
    assert ours, "no common letter"
    pairing, queue = {task.initial: theirs.init}, [task.initial]
    while queue:
        q = queue.pop()
        for k, lab in ours:
            a, b = int(task.delta[q, k]), theirs.step(pairing[q], lab)
            if a in pairing:
                assert pairing[a] == b, (q, k)
            else:
                pairing[a] = b
                queue.append(a)
    assert len(set(pairing.values())) == len(pairing)
    return pairing


def with_their_q(records: list[dict], pairing: dict[int, int]) -> list[dict]:
    """Records whose `q` is the reference's numbering of the same DFA state."""
    return [dict(record, q=pairing[int(record["q"])]) for record in records]


def compare(tmp_path, text: str, renumbered: bool = False) -> dict:
    """The package's adaptive results against the reference: V_adapt, the canonical size, the
    value of the exported adaptive strategy and V_commit(j) of each type's exported strategy
    (records read with the reference's numbering of the task DFA: q_pairing, the identity on
    grid worlds), and Storm's transitions against the Python successor function."""
    path, result, out = solve(tmp_path, text)
    r = result.results
    assert same_transitions(result) > 0 or r["states"] == 1     # (or the start is absorbing)
    world = load_world(path)       # both of the size guard's bounds hold (each is rigorous)
    assert r["states"] <= sizeguard._shared_run(world)
    assert r["states"] <= sizeguard._independent_types(world)
    ref = reference.TypedWorld(path)
    pairing = q_pairing(result.checks[0], ref)
    assert any(a != b for a, b in pairing.items()) == renumbered, pairing
    v_adapt, states, transitions = ref.v_adapt()
    assert r["v_adapt"] == pytest.approx(v_adapt, abs=TOL)
    # the canonical adaptive hypergame (§16 states, goal and failure merged) has the
    # reference's size, and the exported adaptive strategy attains V_adapt
    assert (r["states"], r["transitions"]) == (states, transitions)
    exported = with_their_q(json.loads((out / "strategy.json").read_text()), pairing)
    assert ref.adaptive_strategy_value(exported) == pytest.approx(v_adapt, abs=TOL)
    for j, t in enumerate(r["types"]):
        exported = with_their_q(json.loads((out / t["folder"] / "strategy.json").read_text()),
                                pairing)
        assert t["v_commit"] == pytest.approx(ref.v_commit(j, exported), abs=TOL), t["name"]
        assert t["v_commit"] <= r["v_adapt"] + TOL
    assert r["v_adapt"] <= r["v_oracle"] + TOL
    # the POMDP form: Storm's belief unfolding gives V_adapt wherever its exploration completes
    pomdp = r["pomdp"]
    if pomdp["completed_exploration"]:
        assert pomdp["value"] == pytest.approx(v_adapt, abs=TOL)
        assert pomdp["equals_v_adapt"] and pomdp["in_range"]
    assert r["v_oracle"] == pytest.approx(
        sum(t["weight"] * t["deceptive_value"] for t in r["types"]), abs=1e-12)
    assert r["value_of_adaptivity"] >= -TOL and r["cost_of_not_knowing"] >= -TOL
    return r


@pytest.mark.parametrize("seed", share(GRID_SEEDS))     # every fourth under `make test`
def test_grid_worlds_against_reference(tmp_path, seed):
    compare(tmp_path, typegen.typed_world(seed))


@pytest.mark.parametrize("seed", ARENA_SEEDS)
def test_arena_worlds_against_reference(tmp_path, seed):
    compare(tmp_path, typegen.typed_world(seed, arena=True), renumbered=seed in ARENA_RENUMBERED)


def _types(text: str) -> list[str]:
    return re.findall(r"\[\[type\]\]\n(?:[^\[]|\[type\.inference\])*", text)


THREE_TYPES = """
name = "three_types"
[grid]
map = \"\"\"
######
#DtBt#
#Aot@#
#EDt.#
######
\"\"\"
[robot]
slip = 0.05
[task]
formula = "(!obs U B) & F E"
[adversary]
traps = 1
delay = 1
initial_traps = [[3, 1]]
hypotheses = ["!obs U D", "F (D & F B)"]
[[type]]
weight = 0.47
initial_hypothesis = 1
[type.inference]
window = 1
rationality = 3.9
threshold = 0.11
[[type]]
weight = 0.31
initial_hypothesis = 0
[type.inference]
window = 2
rationality = 3.3
threshold = 0.75
[[type]]
weight = 0.89
initial_hypothesis = 0
[type.inference]
window = 1
rationality = 4.7
threshold = 1.72
"""


def test_three_types_sharing_one_run(tmp_path):
    """Three types with short windows (found by a stress test): counting each type's memory on
    its own bounded the adaptive hypergame by 13.8e6 states and the default size guard refused
    it; the types watch one run, and counting that run once bounds it far below the limit. It
    then solves like the reference, with 2,331 canonical states."""
    path = tmp_path / "three.toml"
    path.write_text(THREE_TYPES)
    world = load_world(path)
    assert sizeguard._independent_types(world) > sizeguard.DEFAULT_LIMIT
    assert sizeguard.check_size(world) == sizeguard._shared_run(world) < 10 ** 6
    assert compare(tmp_path, THREE_TYPES)["states"] == 2331


def test_one_type_with_all_the_weight(tmp_path):
    """V_adapt is that type's deceptive value (the other type, of weight 0, is never drawn)."""
    text = typegen.typed_world(3)
    first = text.index("[[type]]")
    types = _types(text)
    zero = re.sub(r"weight = [0-9.]+", "weight = 0", types[1])
    r = compare(tmp_path, text[:first] + types[0] + zero)
    assert r["v_adapt"] == pytest.approx(r["types"][0]["deceptive_value"], abs=TOL)
    assert r["cost_of_not_knowing"] == pytest.approx(0.0, abs=TOL)


def test_two_identical_types(tmp_path):
    """V_adapt is their common deceptive value."""
    text = typegen.typed_world(5)
    first = text.index("[[type]]")
    one = _types(text)[0]
    twin = one.replace('name = "t0"', 'name = "twin"').replace("weight = ", "weight = 1")
    r = compare(tmp_path, text[:first] + one + twin)
    v = r["types"][0]["deceptive_value"]
    assert r["types"][1]["deceptive_value"] == pytest.approx(v, abs=TOL)
    assert r["v_adapt"] == pytest.approx(v, abs=TOL)
    assert r["value_of_adaptivity"] == pytest.approx(0.0, abs=TOL)


def reachable(game) -> tuple[list, dict]:
    """The adaptive hypergame's states reachable from the initial one (breadth-first, by the
    package's successor function AdaptiveGame.successors) and, for each running state and each
    action P1 has there, the distribution over the successors' keys (equal keys merged)."""
    ts = game.games[0].ts
    start = game.key(game.initial())
    order, seen, moves = [start], {start}, {}
    for state in order:              # grows while it is read
        if isinstance(state, str):
            continue
        moves[state] = {}
        for a1 in np.flatnonzero(ts.enabled[state[0]]).tolist():
            merged: dict = {}
            for successor, p in game.successors(state, a1):
                key = game.key(successor)
                merged[key] = merged.get(key, 0.0) + p
                if key not in seen:
                    seen.add(key)
                    order.append(key)
            moves[state][a1] = merged
    return order, moves


def same_transitions(result) -> int:
    """Storm's adaptive model equals the Python successor function (analyses/adaptive.py,
    AdaptiveGame.successors) transition by transition: every engine state decoded through its
    valuation as (v, q, C, memories) (strategy/adaptive.py), the running keys the engine
    reaches are the Python's reachable states (`reachable`), and every choice of every engine state has the
    Python's distribution over successor keys for its action, within 1e-12. Returns the
    number of (state, action) pairs compared."""
    from hg2prism.analyses.adaptive import AdaptiveGame
    from hg2prism.analyses.successor import Hypergame

    games = [Hypergame(c.analysis.ts, c.analysis.task, c.analysis.games, c.analysis.inference)
             for c in result.checks]
    states, by_state = reachable(AdaptiveGame(games, [t["weight"] for t in result.results["types"]]))
    ts = result.checks[0].analysis.ts
    keys = result.strategy.states.keys(ts)
    moves = result.built.transitions
    engine: dict = {}
    for c, (s, a1) in enumerate(zip(moves.source.tolist(), moves.action.tolist())):
        if isinstance(keys[s], str):
            continue
        dist: dict = {}
        for e in range(moves.row_start[c], moves.row_start[c + 1]):
            if moves.probability[e] > 0:
                t = keys[moves.target[e]]
                dist[t] = dist.get(t, 0.0) + float(moves.probability[e])
        engine.setdefault(keys[s], {}).setdefault(a1, []).append(dist)
    assert keys[result.built.initial] == states[0]
    assert set(engine) == set(by_state)
    compared = 0
    for state, by_action in by_state.items():
        assert set(engine[state]) == set(by_action), state
        for a1, expected in by_action.items():
            for found in engine[state][a1]:        # several engine states may be one key
                assert set(found) == set(expected), (state, a1)
                for t, p in expected.items():
                    assert abs(found[t] - p) <= 1e-12, (state, a1, t, found[t], p)
                compared += 1
    # the canonical size counts the same triples
    triples = sum(len(d) for by_action in by_state.values() for d in by_action.values())
    ended = sum(1 for s in states if isinstance(s, str))
    assert (len(states), triples + ended) == (result.results["states"],
                                                  result.results["transitions"])
    return compared


def test_world4(tmp_path):
    """models/world4.toml: adaptivity is worth at least 0.1 there, and every value agrees
    with the reference (V_adapt, V_commit of both types, the adaptive strategy's value)."""
    from pathlib import Path

    text = (Path(__file__).resolve().parent.parent / "models" / "world4.toml").read_text()
    r = compare(tmp_path, text)
    assert r["value_of_adaptivity"] >= 0.1
    jumpy, stubborn = r["types"]
    assert jumpy["deceptive_value"] == pytest.approx(1.0, abs=TOL)
    assert stubborn["deceptive_value"] == pytest.approx(0.75, abs=TOL)
    # the feint that deceives jumpy gets P1 trapped by stubborn
    assert jumpy["committed_against"]["stubborn"] == pytest.approx(0.0, abs=TOL)
    # the model's commands grow with the types, not with the product: one robot command per
    # action slot (and the absorbing one), each type's module as in its own hypergame
    commands = r["model_commands"]
    assert commands["robot"] == 5 and commands["task"] == 4
    for k in range(2):
        own = json.loads((tmp_path / "typed_out" / f"type{k}" / "results.json").read_text())
        assert commands[f"p2_inference_t{k}"] == own["model_commands"]["p2_inference"]
        # its model's header names the type (it named the world alone, as if P2 had no types)
        header = (tmp_path / "typed_out" / f"type{k}" / "hypergame.prism").read_text()
        lines = header.splitlines()
        start = next(i for i, line in enumerate(lines) if line.startswith("// world "))
        entry = [lines[start]] + [line[2:] for line in lines[start + 1:]
                                  if line.startswith("//" + " " * 14)][:3]
        world_entry = " ".join(" ".join(entry).split())       # wrapped at 100 columns
        name = ("jumpy", "stubborn")[k]
        assert world_entry.endswith(f"here P2 of type '{name}' (type {k} of 2)"), world_entry
    # each file's header gives the command that re-checks it, and names only its own variables
    # (the POMDP's header was the MDP's: no re-check line, alive_t<k> that it does not have)
    from hg2prism.prism.adaptive import PRISM_RESOLUTION

    mdp, pomdp = ((tmp_path / "typed_out" / name).read_text().split("\nmdp\n")[0].split(
        "\npomdp\n")[0] for name in ("adaptive.prism", "adaptive_pomdp.prism"))
    assert "prism adaptive.prism adaptive.props -ex" in mdp and "alive_t<k>" in mdp
    assert (f"prism adaptive_pomdp.prism -pf 'Pmax=? [F \"goal\"]' -gridresolution "
            f"{PRISM_RESOLUTION}") in pomdp
    assert "alive_t" not in pomdp and "hidden variable `type`" in pomdp


def _prism():
    import os
    import shutil

    return os.environ.get("PRISM") or shutil.which("prism")


def test_run_reports_prism_pomdp_bounds(tmp_path):
    """`hg2prism run --prism-pomdp` runs PRISM's POMDP engine (where installed: $PRISM or the
    PATH) on the POMDP form of a small generated typed world and reports its bounds in
    results.json and the printed table: they hold V_adapt within PRISM's precision (value
    iterations stopped at a relative 1e-6: not certified); and PRISM's value of the MDP form
    is V_adapt."""
    import subprocess
    import sys

    prism = _prism()
    if not prism:
        pytest.skip("PRISM is not installed (set PRISM=/path/to/prism)")
    path = tmp_path / "typed.toml"
    path.write_text(typegen.typed_world(3))
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "hg2prism", "run", str(path), "--prism-pomdp",
                           "--episodes", "100", "--out", str(out)], capture_output=True,
                          text=True, timeout=300, env={**__import__("os").environ,
                                                       "PRISM": prism})
    assert done.returncode == 0, done.stderr
    r = json.loads((out / "results.json").read_text())
    found = r["prism_pomdp"]
    assert found["status"] == "run", found
    v = r["v_adapt"]
    assert found["lower"] <= found["upper"]
    assert found["lower"] - 1e-6 * v <= v <= found["upper"] + 1e-6 * v
    assert found["within_prism_precision"] and found["seconds"] > 0
    assert found["outside_by"] == pytest.approx(max(found["lower"] - v, v - found["upper"], 0))
    assert found["brackets_v_adapt"] == (found["outside_by"] == 0)
    # which PRISM gave the bounds, as its banner says ("PRISM-games" and "Version: ...")
    banner = subprocess.run([prism, "-version"], capture_output=True, text=True, timeout=120)
    assert r["software"]["prism"].split()[0] == banner.stdout.split()[0]
    assert r["software"]["prism"].split()[1] in banner.stdout and "prism_version" not in found
    row = f"[{found['lower']:.6f}, {found['upper']:.6f}]"
    assert row in done.stdout and row in (out / "table.md").read_text()
    assert "PRISM's POMDP engine on adaptive_pomdp.prism" in done.stderr
    # PRISM reads the MDP form too (it checks every state a guard allows, reachable or not)
    import re

    done = subprocess.run([prism, str(out / "adaptive.prism"), str(out / "adaptive.props")],
                          capture_output=True, text=True, timeout=300)
    value = re.search(r"^Result: ([0-9.eE-]+)", done.stdout, re.MULTILINE)
    assert value, done.stdout[-2000:]
    assert float(value[1]) == pytest.approx(v, abs=1e-6)


def test_prism_pomdp_not_asked_or_not_found(tmp_path, monkeypatch):
    """Without --prism-pomdp, results.json and the table say PRISM was not asked; asked where
    there is no PRISM, they say it was not found; either way the rest is computed. A world
    without types refuses --prism-pomdp with one line."""
    import subprocess
    import sys

    from hg2prism.experiments import adaptive

    path = tmp_path / "typed.toml"
    path.write_text(typegen.typed_world(3))
    world = load_world(path)
    r = check_adaptive(world, tmp_path / "a")
    assert r.results["prism_pomdp"] == {"status": adaptive.NOT_ASKED}
    assert adaptive.NOT_ASKED in r.table
    monkeypatch.delenv("PRISM", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path / "nowhere"))
    assert adaptive.find_prism() is None
    r = check_adaptive(world, tmp_path / "b", prism=True)
    assert r.results["prism_pomdp"] == {"status": adaptive.NOT_FOUND}
    assert adaptive.NOT_FOUND in r.table and "v_adapt" in r.results
    # $PRISM naming no executable (it was "error: [Errno 2] No such file or directory")
    monkeypatch.setenv("PRISM", str(tmp_path / "nowhere" / "prism"))
    r = check_adaptive(world, tmp_path / "c", prism=True, storm_method="fast")
    assert r.results["prism_pomdp"]["status"].startswith(
        f"not run: PRISM not found: {tmp_path / 'nowhere' / 'prism'} is not an executable")
    monkeypatch.undo()
    # --episode picks the figures' episode of a world with one [inference]; a world with types
    # ignored it silently
    done = subprocess.run([sys.executable, "-m", "hg2prism", "run", str(path), "--episode",
                           "seed=3", "--out", str(tmp_path / "e")], capture_output=True, text=True)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert ": --episode: " in done.stderr and not (tmp_path / "e").exists()
    plain = tmp_path / "plain.toml"
    plain.write_text(typegen.worldgen.make_world(3, window=1, traps=1))
    done = subprocess.run([sys.executable, "-m", "hg2prism", "run", str(plain), "--prism-pomdp",
                           "--out", str(tmp_path / "r")], capture_output=True, text=True)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert ": --prism-pomdp: " in done.stderr and not (tmp_path / "r").exists()


def test_prism_pomdp_bounds_that_come_out_inverted(tmp_path, monkeypatch, caplog):
    """PRISM's two uncertified iterations can give a 'lower' bound above the 'upper' one (a
    roboticist saw [0.794950204, 0.794950079]): results.json says `inverted` and the warning
    says why they are no bracket, even when V_adapt is within PRISM's precision of them."""
    import logging

    from hg2prism.experiments import adaptive

    executable = tmp_path / "prism"
    executable.write_text("#!/bin/sh\n")
    executable.chmod(0o755)
    for lower, upper, v in ((0.794950204, 0.794950079, 0.7949501), (0.5, 0.6, 0.55)):
        monkeypatch.setattr(adaptive, "prism_pomdp_bounds", lambda *a, **k: {
            "lower": lower, "upper": upper, "seconds": 1.0})
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="hg2prism"):
            found = adaptive.prism_pomdp(str(executable), tmp_path / "m.prism", v)
        assert found["inverted"] == (lower > upper)
        assert found["brackets_v_adapt"] == (lower <= v <= upper)
        said = [r.getMessage() for r in caplog.records]
        if lower > upper:
            assert found["within_prism_precision"]
            (line,) = said
            assert f"its lower bound above its upper one by {lower - upper:.2g}:" in line, line
        else:
            assert said == []


@pytest.mark.parametrize("seed", [None, 7, 9])
def test_simulation_agrees_with_exact(tmp_path, seed):
    """The adaptive strategy simulated (P2's type drawn from the prior in each episode): the
    completion rate and the share of episodes in which P1's belief singles out P2's type lie in
    the 99.9 % Wilson intervals of the exact within-horizon probabilities."""
    from pathlib import Path

    from hg2prism.analyses.adaptive import (AdaptiveGame, adaptive_chain, adaptive_policy,
                                            simulate_adaptive)
    from hg2prism.analyses.simulation import wilson_interval
    from hg2prism.analyses.successor import Hypergame

    text = ((Path(__file__).resolve().parent.parent / "models" / "world4.toml").read_text()
            if seed is None else typegen.typed_world(seed))
    path, result, out = solve(tmp_path, text)
    games = [Hypergame(c.analysis.ts, c.analysis.task, c.analysis.games, c.analysis.inference)
             for c in result.checks]
    weights = [t["weight"] for t in result.results["types"]]
    game = AdaptiveGame(games, weights)
    records = json.loads((out / "strategy.json").read_text())
    policy = adaptive_policy(records, game, [t["name"] for t in result.results["types"]])
    chain = adaptive_chain(game, policy)
    horizon, episodes = 30, 3000
    run = simulate_adaptive(game, policy, episodes, horizon, seed=1)
    for count, exact in ((run.completed, chain.within(horizon)),
                         (run.identified, chain.identified_within(horizon)),
                         (run.identified_in_play, chain.identified_in_play_within(horizon))):
        low, high = wilson_interval(count, episodes, 0.999)
        assert low <= exact <= high, (count, exact)
    assert run.identified_in_play <= run.identified
    assert chain.identified_in_play_within(horizon) <= chain.identified_within(horizon)
    assert sum(n for n, _ in run.by_type) == episodes
    # an identified episode is identified at some step within the horizon
    assert all(0 <= step <= horizon for step in run.identification_steps)
    # unbounded, the chain's completion is V_adapt
    assert chain.within(100_000) == pytest.approx(result.results["v_adapt"], abs=1e-6)
    if seed is None:
        _bad_adaptive_records_are_strategy_errors(records, game, result)


FORK = """name = "fork"
description = "two doors; P2's trap on her first step says which type she is, as P1 walks in"
[arena]
states = ["s", "L", "R"]
initial = "s"
[arena.labels]
L = ["gl"]
R = ["gr"]
[[arena.transition]]
state = "s"
action = "goL"
to = { L = 1.0 }
[[arena.transition]]
state = "s"
action = "goR"
to = { R = 1.0 }
[task]
formula = "F gl | F gr"
[adversary]
traps = 1
trap_candidates = ["L", "R"]
hypotheses = ["F gl", "F gr"]
[[type]]
name = "left"
weight = 0.3
initial_hypothesis = 0
[type.inference]
window = 1
threshold = 0.5
rationality = 1.0
[[type]]
name = "right"
weight = 0.7
initial_hypothesis = 1
[type.inference]
window = 1
threshold = 0.5
rationality = 1.0
"""


def test_identified_only_as_the_episode_ends_is_not_in_play(tmp_path):
    """On a world where P2's first trap tells her type as P1 steps into a door (a user review:
    "P1's belief singles out P2's type" was 1.0 there, though P1 never acts on it), every
    episode is identified, at step 1, its last: the share in play is 0, simulated and exact,
    With P1 committed to the likelier type's door, V_adapt is 0.7."""
    from hg2prism.analyses.adaptive import (AdaptiveGame, adaptive_chain, adaptive_policy,
                                            simulate_adaptive)
    from hg2prism.analyses.successor import Hypergame

    path, result, out = solve(tmp_path, FORK)
    assert result.results["v_adapt"] == pytest.approx(0.7, abs=1e-12)
    games = [Hypergame(c.analysis.ts, c.analysis.task, c.analysis.games, c.analysis.inference)
             for c in result.checks]
    game = AdaptiveGame(games, [t["weight"] for t in result.results["types"]])
    records = json.loads((out / "strategy.json").read_text())
    policy = adaptive_policy(records, game, [t["name"] for t in result.results["types"]])
    chain = adaptive_chain(game, policy)
    run = simulate_adaptive(game, policy, 200, 10, seed=3)
    assert run.identified == 200 and set(run.identification_steps) == {1}
    assert run.identified_in_play == 0
    assert chain.identified_within(10) == pytest.approx(1.0, abs=1e-12)
    assert chain.identified_in_play_within(10) == 0.0
    assert chain.identified_in_play_within(1) == 0.0 == chain.identified_in_play_within(0)


def _bad_adaptive_records_are_strategy_errors(records, game, result) -> None:
    """A bad strategy.json record of the adaptive strategy is a StrategyError naming the
    record (an unknown action name was a ValueError from list.index, an unknown type a
    KeyError)."""
    from hg2prism.analyses.adaptive import adaptive_policy
    from hg2prism.strategy.records import StrategyError

    names = [t["name"] for t in result.results["types"]]
    one = records[0]
    some_type = next(iter(one["types"]))
    for bad, word in (({**one, "action": "fly"}, "action 'fly'"),
                      ({**one, "types": {"nobody": one["types"][some_type]}}, "nobody"),
                      ({**one, "types": {some_type: {"window": []}}}, "hypothesis")):
        with pytest.raises(StrategyError, match="adaptive strategy record 0") as err:
            adaptive_policy([bad, *records[1:]], game, names)
        assert word in str(err.value)


def test_a_warning_every_type_gives_is_shown_once(tmp_path, caplog):
    """`check --storm-method fast` on a world with two types warned "not sound" once per type:
    a warning repeated word for word within one adaptive check is shown once (others are not
    merged)."""
    import logging

    from hg2prism import progress

    path = tmp_path / "typed.toml"
    path.write_text(typegen.typed_world(3))
    with caplog.at_level(logging.WARNING, logger="hg2prism"):
        check_adaptive(load_world(path), tmp_path / "a", storm_method="fast")
        with progress.each_warning_once():
            progress.warn("one")
            progress.warn("two")
            progress.warn("one")
        progress.warn("one")            # outside: shown again
    unsound = [r for r in caplog.records if "is not sound" in r.getMessage()]
    assert len(unsound) == 1
    assert [r.getMessage() for r in caplog.records if "sound" not in r.getMessage()
            ][-3:] == ["warning: one", "warning: two", "warning: one"]


def test_the_adaptive_simulation_is_checked_against_its_exact_values(tmp_path, monkeypatch,
                                                                     caplog):
    """`run` on a world with types warns, as on any world (semantics §8), when a simulated
    count is implausible under its exact within-horizon probability: completion, identification
    and identification in play (it had no such check: a statistics review). On world4 nothing
    is said; with the exact completion made wrong, one line names the row."""
    import logging
    from pathlib import Path

    from hg2prism.analyses import adaptive as analyses_adaptive
    from hg2prism.experiments import adaptive as experiments_adaptive
    from hg2prism.worldfile import load_world

    world = load_world(Path(__file__).resolve().parent.parent / "models" / "world4.toml")
    simulation = (400, 60, 0)

    runs = iter(range(10))

    def messages() -> list[str]:
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="hg2prism"):
            experiments_adaptive.check_adaptive(world, tmp_path / f"out{next(runs)}",
                                                simulation=simulation)
        return [r.getMessage() for r in caplog.records if "simulated" in r.getMessage()]

    assert messages() == []
    monkeypatch.setattr(analyses_adaptive.AdaptiveChain, "within", lambda self, horizon: 0.2)
    (line,) = messages()
    assert line.startswith("warning: simulated completion of the adaptive strategy is ") and \
        "far from its exact within-horizon probability 0.200000" in line, line
