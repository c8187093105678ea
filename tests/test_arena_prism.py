"""The PRISM models of an arena (docs/semantics.md §15; hg2prism/prism/arena_tables.py): a grid
world and its arena form give the same model to Storm; a small attack graph with general P2
actions, a P2-dependent transition, terminal states and states with one to three actions
(tests/arenas.lateral) is accepted by PRISM with Storm's value, in every variant (delay 0-2,
CUSUM and Bayesian observers, trap mode); and the number of commands of a model grows with the
actions, outcomes and hypotheses, never with the number of states.
"""

from __future__ import annotations

import functools
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

import arenas
import worldgen
from conftest import MODELS, share
from hg2prism import pipeline, progress
from hg2prism.engines import storm
from hg2prism.model.arena import Arena
from hg2prism.prism.game_models import write_game_models
from hg2prism.prism.hypergame import PROPERTY
from hg2prism.worldfile import load_world, world_from_toml
from test_prism import PRISM, RESULT

TOL = 1e-6
LATERAL = [(delay, kind, traps) for delay in (0, 1, 2) for kind in ("cusum", "bayes")
           for traps in (False, True)]


def _emit(world, folder: Path) -> tuple[pipeline.PrismModel, object]:
    """The hypergame model of `world` written to `folder`, and Storm's check of it."""
    folder.mkdir(parents=True, exist_ok=True)
    with progress.quiet():
        model = pipeline.emit(world, folder)
    return model, storm.check(folder / "hypergame.prism", PROPERTY)


def _reachable(checked) -> int:
    """Storm's states reachable from its initial state by positive transitions."""
    moves = storm.read_structure(checked.model)
    choice = np.repeat(np.arange(len(moves.source)), np.diff(moves.row_start))
    source = moves.source[choice]
    seen = np.zeros(checked.model.nr_states, dtype=bool)
    seen[checked.model.initial_states[0]] = True
    while True:
        grown = seen.copy()
        grown[moves.target[seen[source] & (moves.probability > 0)]] = True
        if (grown == seen).all():
            return int(seen.sum())
        seen = grown


def test_a_grid_world_and_its_arena_form_give_storm_the_same_model(tmp_path: Path) -> None:
    world = load_world(MODELS / "world1.toml")
    grid_model, grid = _emit(world, tmp_path / "grid")
    arena_model, arena = _emit(arenas.arena_form(world), tmp_path / "arena")
    assert arena.value == grid.value
    assert arena.size == grid.size
    assert arena_model.commands == grid_model.commands
    # the same tables: the texts differ in the header only (the world's name and path)
    def body(text: str) -> str:
        return text[text.index("\nmdp\n"):]
    assert body(arena_model.text) == body(grid_model.text)


@functools.cache
def _lateral(delay: int, kind: str, traps: bool, folder: str):
    world = arenas.lateral(delay=delay, kind=kind, traps_mode=traps)
    out = Path(folder) / f"lateral_d{delay}_{kind}_{traps}"
    try:
        model, checked = _emit(world, out)
    except ValueError as error:     # pragma: no cover - until opponent/ handles any arena
        pytest.skip(f"the analysis of a non-grid arena fails outside prism/: {error}")
    return world, model, checked, out


@pytest.fixture(params=share(LATERAL), ids=lambda p: f"d{p[0]}-{p[1]}-{'traps' if p[2] else 'general'}")
def lateral(request, tmp_path_factory):
    return _lateral(*request.param, str(tmp_path_factory.getbasetemp() / "lateral"))


def test_lateral_models_use_the_arena_scheme(lateral) -> None:
    world, model, checked, _ = lateral
    text = model.text
    assert 0.0 <= checked.value <= 1.0
    # every Storm state is reachable (no outcome of probability 0 adds one)
    assert _reachable(checked) == checked.model.nr_states
    # one robot command per action slot (+ the absorbing one), guarded where a slot is missing
    assert model.commands["robot"] == 3 + 1
    assert "enabled_1" in text and "enabled_2" in text and "formula terminal" in text
    assert ("TRAPPED" in text) == world.arena.traps_mode
    assert 'label "ap_crown"' in text and 'label "ap_payroll"' in text
    # slot labels only: no action name and no state name is a PRISM identifier
    assert set(re.findall(r"^\s*\[(\w*)\]", text, re.M)) <= {"", "a0", "a1", "a2"}
    assert not re.search(r"\b(phish|pivot_db|watch_db|mail)\b", text.split("\nmdp\n")[1])
    # Storm's choice labels read back as the action slots
    moves = storm.read_structure(checked.model)
    assert set(moves.action.tolist()) <= {-1, 0, 1, 2}


def test_lateral_game_exports_build(lateral) -> None:
    """The perceptual games (smg) of the arena build in Storm."""
    import stormpy

    world, _, _, out = lateral
    with progress.quiet():
        analysis = pipeline.analyse(world)
    write_game_models(analysis, out)
    for i in range(len(analysis.games)):
        program = stormpy.parse_prism_program(str(out / f"perceptual_{i}.prism"))
        assert stormpy.build_model(program).nr_states > 0


@pytest.mark.skipif(PRISM is None, reason="PRISM is not installed (set PRISM=/path/to/prism)")
def test_prism_accepts_the_lateral_models_with_storms_value(lateral) -> None:
    """PRISM's default (symbolic) engine checks every command's probabilities in every state
    its guard allows, reachable or not. The Bayesian window's tables make its symbolic build
    explode (minutes on delay 2), so those run on PRISM's explicit engine."""
    world, _, checked, out = lateral
    command = [PRISM, str(out / "hypergame.prism"), str(out / "hypergame.props"),
               "-epsilon", "1e-12", "-maxiters", "10000000"]
    if world.inference == "bayes":
        command.append("-explicit")
    done = subprocess.run(command, capture_output=True, text=True, timeout=600)
    output = done.stdout + done.stderr
    assert done.returncode == 0 and "Error" not in output, output[-3000:]
    (value,) = RESULT.findall(output)
    assert abs(float(value) - checked.value) <= TOL


# ------------------------------------------------------------------------ commands vs states

def chain(n: int, kind: str = "cusum", delay: int = 1):
    """A lateral-like arena of n + 3 states: a chain s0 .. s<n-1> that P1 walks forward (or
    burns), with
    pivots to db (blocked while P2 watches db) and hr from each state (every third state has
    no pivot to hr), db, hr and `burnt` terminal."""
    states = tuple(f"s{i}" for i in range(n)) + ("db", "hr", "burnt")
    db, hr, burnt = n, n + 1, n + 2
    actions = tuple(("fwd", "pivot_db") if i % 3 == 2 else ("fwd", "pivot_db", "pivot_hr")
                    for i in range(n)) + ((), (), ())
    entries = {}
    for s in range(n):
        for j in range(3):
            entries[(s, 0, j)] = {s + 1: 0.5, s: 0.3, burnt: 0.2} if s + 1 < n else {burnt: 0.2, s: 0.8}
            entries[(s, 1, j)] = {s: 1.0} if j == 1 else {db: 0.5, s: 0.5}
            if len(actions[s]) == 3:
                entries[(s, 2, j)] = {s: 1.0} if j == 2 else {hr: 0.5, s: 0.5}
    dest, prob = arenas.tables(len(states), entries, 3, 3)
    arena = Arena(states=states, initial=0, propositions=("crown", "payroll"),
                  labels=tuple(frozenset({"crown"}) if s == db else frozenset({"payroll"})
                               if s == hr else frozenset() for s in range(len(states))),
                  actions=actions, dest=dest, prob=prob, p2_actions=("idle", "watch_db", "watch_hr"))
    world = arenas.lateral(delay=delay, kind=kind)
    import dataclasses

    return dataclasses.replace(world, front=arena, name=f"chain{n}")


@pytest.mark.parametrize("kind", ["cusum", "bayes"])
def test_commands_do_not_grow_with_the_states(kind: str, tmp_path: Path) -> None:
    try:
        with progress.quiet():
            small = pipeline.emit(arenas.lateral(delay=1, kind=kind), tmp_path / "lateral")
            large = pipeline.emit(chain(30, kind), tmp_path / "chain")
    except ValueError as error:     # pragma: no cover - until opponent/ handles any arena
        pytest.skip(f"the analysis of a non-grid arena fails outside prism/: {error}")
    assert large.commands == small.commands
    # a grid: world1 (31 cells) and a 14 x 14 generated world with the same settings
    settings = dict(delay=0, traps=1, window=2, nhyp=3, slip=0.1)
    worlds = [world_from_toml(worldgen.make_world(7, size=size, **settings), f"w{size[0]}.toml")
              for size in ((4, 4), (14, 14))]
    with progress.quiet():
        counts = [pipeline.emit(w, tmp_path / w.name).commands for w in worlds]
    assert counts[0] == counts[1]
