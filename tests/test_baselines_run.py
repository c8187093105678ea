"""docs/semantics.md §7 invariants and docs/semantics.md §8's statistical check on generated worlds, through `run`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import reference_nash
import worldgen
from conftest import MODELS, share
from hg2prism import pipeline
from hg2prism.analyses import baselines
from hg2prism.model.automata import translate
from hg2prism.frontends import transition_system as build_transition_system
from hg2prism.opponent.perceptual_games import solve_game
from hg2prism.analyses.simulation import wilson_interval
from hg2prism.worldfile import load_world

FAMILY = dict(worldgen.world_family())
# Non-trivial worlds: delay 0, 1 and 2, one and two traps, windows 1-3.
SAMPLE = ["fam04_d1_l1_w2_x2", "fam15_d0_l2_w3_x2", "fam20_d2_l1_w1_x3", "fam25_d1_l1_w3_x2",
          "fam28_d1_l2_w1_x4", "fam41_tx_d1_l1_w2"]


def _world(name: str, folder: Path):
    path = folder / f"{name}.toml"
    path.write_text(FAMILY[name])
    return load_world(path)


@pytest.mark.parametrize("name", share(SAMPLE) + ["world1"])      # every fourth under `make test`
def test_nash_below_leader_everywhere(name: str, tmp_path: Path) -> None:
    world = load_world(MODELS / "world1.toml") if name == "world1" else _world(name, tmp_path)
    ts = build_transition_system(world)
    task = translate(world.formula, ts.label_names, ts.letters)
    nash = baselines.nash_baseline(ts, task)
    lead = solve_game(ts, task).values
    assert (nash.values <= lead + 1e-6).all()
    assert (nash.guaranteed <= nash.values + 1e-6).all()


@pytest.mark.parametrize("name", SAMPLE[:3] + ["world1"])
def test_run_simulations_agree_with_exact_bounded_probabilities(name: str, tmp_path: Path) -> None:
    world = load_world(MODELS / "world1.toml") if name == "world1" else _world(name, tmp_path)
    out = tmp_path / "out"
    result = pipeline.run(world, out, episodes=3000, horizon=60, seed=7, show_progress=False)
    r = result.results
    assert r.v_ne <= r.v_lead + 1e-6 <= r.deceptive_value + 2e-6
    assert r.v_naive <= r.deceptive_value + 1e-6 and r.v_lead <= r.v_static + 1e-6
    assert r.value_of_deception == r.deceptive_value - r.v_naive
    for row in ("deceptive", "nash", "leader", "static", "naive"):
        sim = getattr(r.simulation, row)
        successes = round(sim.rate * sim.episodes)
        low, high = wilson_interval(successes, sim.episodes, 0.999)
        assert low <= sim.exact_within_horizon <= high, (row, sim)
        assert sim.exact_within_horizon <= {"deceptive": r.deceptive_value, "nash": 1.0,
                                            "leader": r.v_lead, "static": r.v_static,
                                            "naive": r.v_naive}[row] + 1e-6
    assert 0.0 <= r.simulation.deceptive.p2_switched <= 1.0
    assert r.simulation.deceptive.p2_switches_mean >= r.simulation.deceptive.p2_switched
    for row in (r.simulation.deceptive, r.simulation.naive):
        assert 0.0 <= row.p2_switched_in_play <= row.p2_switched
    saved = json.loads((out / "results.json").read_text())
    if name == "world1":
        # V_NE by the independent reference (tests/reference_nash.py): a sound bracket
        ref = reference_nash.v_ne(MODELS / "world1.toml")
        assert ref.upper - ref.lower <= 1e-6 and ref.contains(saved["v_ne"], 1e-6), ref
    for key in ("deceptive_value", "v_lead", "v_ne", "v_ne_p1_guaranteed", "states", "transitions",
                "storm_states", "storm_transitions", "storm_choices", "timings", "simulation",
                "v_static", "v_naive", "value_of_deception"):
        assert key in saved
    # results.json is the typed results' to_json(), keys in the same order
    assert saved == result.results.to_json()
    assert list(saved) == list(result.results.to_json())
    for name_ in ("table.md", "world.png", "symmetric.prism", "symmetric.props",
                  "perceptual_0.prism", "perceptual_0.props", "strategy.json", "hypergame.prism"):
        assert (out / name_).stat().st_size > 0
    assert (out / "world.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_run_is_reproducible(tmp_path: Path) -> None:
    world = load_world(MODELS / "world1.toml")
    a = pipeline.run(world, tmp_path / "a", episodes=500, horizon=50, seed=3, show_progress=False)
    b = pipeline.run(world, tmp_path / "b", episodes=500, horizon=50, seed=3, show_progress=False)
    assert a.results.simulation == b.results.simulation
    assert (tmp_path / "a" / "table.md").read_text() == (tmp_path / "b" / "table.md").read_text()


def test_timings_are_read_only_and_each_output_keeps_its_stages(tmp_path: Path) -> None:
    """Analysis.timings (and a check's or run's results' timings) are read-only: a stage adds
    its time by making new timings, so an Analysis never changes after it is built (generate
    once added its time to the Analysis it was given). results.json keeps every stage, in the
    order they ran, each time at most the wall time measured around the whole call."""
    import time

    world = _world(SAMPLE[0], tmp_path)
    analysis = pipeline.analyse(world)
    assert list(analysis.timings) == ["games"]
    pipeline.generate(analysis, tmp_path / "emitted")
    assert list(analysis.timings) == ["games"]
    with pytest.raises(TypeError):
        analysis.timings["generate"] = 0.0              # type: ignore[index]
    check_stages = ["games", "generate", "parse", "build", "check", "export"]
    start = time.perf_counter()
    checked = pipeline.check(world, tmp_path / "check")
    wall = time.perf_counter() - start
    saved = json.loads((tmp_path / "check" / "results.json").read_text())["timings"]
    assert list(saved) == list(checked.analysis.timings) == check_stages
    assert dict(checked.results.timings) == dict(checked.analysis.timings)
    assert all(0 <= seconds for seconds in saved.values()) and sum(saved.values()) <= wall
    start = time.perf_counter()
    ran = pipeline.run(world, tmp_path / "run", episodes=50, horizon=20, seed=1,
                       show_progress=False)
    wall = time.perf_counter() - start
    saved = json.loads((tmp_path / "run" / "results.json").read_text())["timings"]
    assert list(saved) == check_stages + ["exports", "nash", "deception", "simulation",
                                          "plots", "replay"]
    assert list(ran.check.analysis.timings) == check_stages     # the check's, unchanged
    assert all(0 <= seconds for seconds in saved.values()) and sum(saved.values()) <= wall
    with pytest.raises(TypeError):
        ran.results.timings["replay"] = 0.0             # type: ignore[index]
