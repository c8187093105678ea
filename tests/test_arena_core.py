"""The pipeline's consumers of the TS on arenas (issue 23, docs/semantics.md §15): a grid world
and its arena form (tests/arenas.py) give the same perceptual games, baselines and values of
deception; a non-grid arena (general P2 actions, a p2-dependent transition, a terminal state,
states with one to three actions) runs through the games, the observers, the baselines, the
value of deception, the simulation, the size guard and the sweep's parameters."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from arenas import arena_form, lateral
from hg2prism.analyses import simulation
from hg2prism.analyses.baselines import nash_baseline
from hg2prism.analyses.deception_value import deception_values
from hg2prism.errors import InputError
from hg2prism.experiments import sweep
from hg2prism.model import sizeguard
from hg2prism.pipeline import analyse
from hg2prism.worldfile import load_world

MODELS = Path(__file__).resolve().parent.parent / "models"


def _worlds() -> list[tuple[str, object]]:
    worlds = [(name, load_world(MODELS / f"{name}.toml"))
              for name in ("world1", "world2", "world3", "world3_bayes")]
    world2 = dict(worlds)["world2"]
    worlds.append(("world2_delay2", sweep.sweep_world(world2, "delay", 2)))
    return worlds


@pytest.mark.parametrize("name,world", _worlds(), ids=[n for n, _ in _worlds()])
def test_a_grid_world_and_its_arena_form_agree(name: str, world) -> None:
    grid, arena = analyse(world), analyse(arena_form(world))
    assert grid.v_lead == arena.v_lead
    for g, a in zip(grid.games, arena.games):
        assert np.array_equal(g.values, a.values)
        assert np.array_equal(g.trap_choice, a.trap_choice)       # P2's strategy tables
        assert np.array_equal(g.log_policy, a.log_policy)
    nash_g, nash_a = nash_baseline(grid.ts, grid.task), nash_baseline(arena.ts, arena.task)
    assert (nash_g.v_ne, nash_g.v_ne_bounds) == (nash_a.v_ne, nash_a.v_ne_bounds)
    worth_g, worth_a = deception_values(grid, 0.0), deception_values(arena, 0.0)
    assert (worth_g.v_static, worth_g.v_naive) == (worth_a.v_static, worth_a.v_naive)
    assert sizeguard.estimate_states(world) == sizeguard.estimate_states(arena_form(world))


@pytest.mark.parametrize("kwargs", [dict(), dict(delay=2), dict(kind="bayes"),
                                    dict(delay=1, traps_mode=True)],
                         ids=["cusum", "delay2", "bayes", "traps_delay1"])
def test_a_non_grid_arena_runs_through_the_consumers(kwargs) -> None:
    world = lateral(**kwargs)
    analysis = analyse(world)
    ts = analysis.ts
    enabled = ts.enabled
    for game in analysis.games:
        policy = np.exp(game.log_policy)                          # [S, A2, A1max]
        # the softmax ranges over the actions enabled at v: no mass on padded slots
        assert np.all(policy[~np.broadcast_to(enabled[:, None, :], policy.shape)] == 0.0)
        assert np.allclose(policy.sum(axis=2), 1.0)
        assert np.all(ts.allowed[np.arange(ts.n_states), game.trap_choice])
    observer = analysis.inference
    tables = observer.ratios if world.inference == "cusum" else observer.log_likelihood
    assert np.isfinite(tables).all()

    nash = nash_baseline(ts, analysis.task)
    assert 0.0 <= nash.v_ne_bounds[0] <= nash.v_ne <= nash.v_ne_bounds[1] <= 1.0
    padded = np.broadcast_to(~enabled[:, None, :], nash.p1.shape)
    assert np.all(nash.p1[padded] == 0.0)

    worth = deception_values(analysis, 0.0)
    assert 0.0 <= worth.v_naive <= 1.0 and 0.0 <= worth.v_static <= 1.0
    # P1's moves are always enabled actions
    assert np.all(enabled[np.arange(ts.n_states).repeat(analysis.task.n_states),
                          worth.static.p1])

    p1, p2 = worth.static.policy.mixed(), np.eye(ts.n_sets)[worth.static.p2]
    within = simulation.exact_completion(ts, analysis.task, p1, p2, 50)
    summary = simulation.simulate_nash(ts, analysis.task, p1, p2, 400, 50, 3, progress=False)
    assert 0.0 <= within <= worth.v_static + 1e-12
    assert summary.ci95[0] - 0.05 <= within <= summary.ci95[1] + 0.05
    naive = simulation.simulate_deceptive(analysis, worth.naive, 400, 50, 4, progress=False)
    assert naive.episodes == 400
    assert naive.ci95[0] - 0.05 <= worth.naive_chain.within(50) <= naive.ci95[1] + 0.05
    estimate = sizeguard.estimate_states(world)
    assert 2 < estimate < 10 ** 6


def test_v_lead_of_the_attack_graph() -> None:
    """From `out`: phish reaches mail (0.6 per try) or exploit reaches web (0.5) or the
    terminal `burnt` (0.2). P2 watches db whenever P1 is in mail, so pivot_db never works
    there; from web, scan reaches db or hr (0.3 each) whatever P2 does: V_lead = 5/14 (exploit,
    then scan: 0.5/0.7 * 0.3/0.6)."""
    analysis = analyse(lateral())
    assert analysis.v_lead == pytest.approx(0.5 / 0.7 * 0.3 / 0.6, abs=1e-12)


def test_sweep_parameters_on_an_arena_world() -> None:
    world = lateral()
    with pytest.raises(InputError, match="--param slip: applies to grid worlds only; lateral "
                                         "is an arena world"):
        sweep.check_grid(world, [("slip", [0.1])])
    with pytest.raises(InputError, match="--param traps: applies to worlds whose P2 sets traps"):
        sweep.check_grid(world, [("traps", [1])])
    point = sweep.sweep_point(world, {"delay": 2, "window": 1, "rationality": 2.0})
    assert (point.delay, point.window, point.rationality, point.initial_standing) == (2, 1, 2.0, 0)
    traps = lateral(traps_mode=True)
    point = sweep.sweep_point(traps, {"traps": 2, "delay": 1})
    assert point.traps == 2 and point.initial_standing == 0      # the one 2-set of {web, mail}
    assert sweep.sweep_point(traps, {"traps": 1, "delay": 0}).initial_standing == 0
    assert math.isfinite(sizeguard.estimate_states(point))


def test_a_sweep_over_delay_starts_from_the_standing_action_the_file_names(tmp_path) -> None:
    """With delay 0 an arena world's file may name the action (or trap set) standing at the
    start, for sweeps over delay, as a grid's initial_traps: the sweep's points start from it
    (they took P2's first action, and an unknown name was accepted); without it from the
    first. The world keeps it (World.initial_standing), so a variant keeps it too."""
    from hg2prism.frontends.arena import to_toml

    text = to_toml(lateral(delay=1).replace(initial_standing=2)).replace("delay = 1", "delay = 0")
    assert 'initial_action = "watch_hr"' in text
    path = tmp_path / "lateral.toml"
    path.write_text(text)
    world = load_world(path)
    assert (world.delay, world.initial_standing) == (0, 2)
    assert sweep.sweep_point(world, {"delay": 2}).initial_standing == 2
    assert sweep.sweep_point(world, {"delay": 0}) == world
    other = world.replace(front=lateral(traps_mode=False).front.__class__(
        **{**world.front.__dict__, "initial": 1}))
    assert sweep.sweep_point(other, {"delay": 2}).initial_standing == 2
    # convert keeps it (it wrote the standing action only with delay > 0): the arena form
    # sweeps as the world does, a grid world's arena form as the grid world
    again = tmp_path / "again.toml"
    again.write_text(to_toml(world))
    assert 'initial_action = "watch_hr"' in again.read_text()
    assert sweep.sweep_point(load_world(again), {"delay": 2}).initial_standing == 2
    (tmp_path / "world2.toml").write_text((MODELS / "world2.toml").read_text().replace(
        "initial_traps = [[2, 5]]", "initial_traps = [[5, 3]]"))     # not the first candidate
    grid = load_world(tmp_path / "world2.toml")        # delay 0
    assert sweep.sweep_point(grid, {"delay": 1}).initial_standing == 2
    (tmp_path / "world2_arena.toml").write_text(to_toml(grid))
    converted = load_world(tmp_path / "world2_arena.toml")
    assert (sweep.sweep_point(converted, {"delay": 1}).initial_standing
            == sweep.sweep_point(grid, {"delay": 1}).initial_standing)
    path.write_text(text.replace('initial_action = "watch_hr"\n', ""))
    assert sweep.sweep_point(load_world(path), {"delay": 2}).initial_standing == 0
    assert "initial_action" not in to_toml(load_world(path))

    text = to_toml(lateral(delay=1, traps_mode=True).replace(initial_standing=1))
    assert 'initial_traps = ["mail"]' in text
    path.write_text(text.replace("delay = 1", "delay = 0"))
    world = load_world(path)
    assert sweep.sweep_point(world, {"delay": 1}).initial_standing == 1       # {mail}
    path.write_text(text.replace("delay = 1", "delay = 0").replace('["mail"]', "[]"))
    assert sweep.sweep_point(load_world(path), {"delay": 1}).initial_standing == 0  # {web}


def test_strategy_records_name_states_and_actions_of_an_arena() -> None:
    """strategy.json on an arena: states and P1's actions by name, values over the actions
    available there, the initial state's record first; the file's text equals json.dumps of
    the records, and Strategy reads them back."""
    import json

    from hg2prism.engines.engine import Transitions
    from hg2prism.prism.decoding import DecodedStates
    from hg2prism.strategy.deceptive import StormChoices
    from hg2prism.strategy.records import RecordExtras, Strategy, strategy_json, strategy_records

    ts = analyse(lateral(delay=1)).ts
    web, mail = ts.arena.index("web"), ts.arena.index("mail")
    watch_db = ts.a2_names.index("watch_db")
    # engine states: 0 at web (one action), 1 at mail (three), 2 the goal; 1 is initial
    decoded = DecodedStates(
        place=np.array([web, mail, 0]), traps=np.array([watch_db, 0, 0]),
        countdown=np.array([1, 0, 0]), q=np.array([0, 0, 1]), hypothesis=np.array([1, 0, 0]),
        window=np.array([[[ts.state(mail, 0, 0), 2]], [[-1, -1]], [[-1, -1]]]),
        goal=np.array([False, False, True]), fail=np.zeros(3, dtype=bool),
        canonical=np.array([0, 1, 2]), n_canonical=3)
    moves = Transitions(source=np.array([0, 1, 1, 1]), action=np.array([0, 0, 1, 2]),
                        row_start=np.arange(5), target=np.array([2, 0, 2, 1]),
                        probability=np.ones(4), labels={})
    choices = StormChoices(representative=np.array([0, 1, 2]), choice=np.array([0, 3, -1]))
    values = np.array([[0.5, np.nan, np.nan], [0.1, 0.2, 0.3], [np.nan] * 3])
    extras = RecordExtras(values)
    records = strategy_records(decoded, choices, moves, ts, extras, initial=1)
    text = strategy_json(decoded, choices, moves, ts, extras, initial=1)
    assert json.loads(text) == records
    assert records[0] == {"initial": True, "state": "mail", "standing": "idle", "countdown": 0,
                          "q": 0, "hypothesis": 0, "window": [], "action": "wait",
                          "values": {"pivot_db": 0.1, "pivot_hr": 0.2, "wait": 0.3}}
    assert records[1] == {"state": "web", "standing": "watch_db", "countdown": 1, "q": 0,
                          "hypothesis": 1, "window": [{"state": "mail", "standing": "idle",
                                                       "countdown": 0, "action": "wait"}],
                          "action": "scan", "values": {"scan": 0.5}}
    strategy = Strategy.from_records(records, ts)
    assert strategy.move("web", 0, 1, [("mail", "wait", "idle", 0)], "watch_db", 1) == "scan"
    assert strategy.move("mail", 0, 0, (), "idle", 0) == "wait"


def test_trap_sets_are_numbered_without_listing_them() -> None:
    """trap_set_index / trap_set_at: the combinations order a2_actions lists, computed (a
    sweep over traps or World.replace(traps=k) listed every set: 30M for 10 of 30); and
    carried_standing, the sweep's rule for another number of traps."""
    import itertools
    import math

    from hg2prism.model.dynamics import carried_standing, trap_set_at, trap_set_index

    for n in range(1, 8):
        for k in range(1, n + 1):
            for i, members in enumerate(itertools.combinations(range(n), k)):
                assert trap_set_index(n, members) == i and trap_set_at(n, k, i) == members
    assert trap_set_at(30, 10, math.comb(30, 10) - 1) == tuple(range(20, 30))
    assert trap_set_index(30, range(20, 30)) == math.comb(30, 10) - 1
    assert trap_set_index(4, (3, 0)) == 2                  # {0, 3}: the order given is no matter
    assert carried_standing(4, (2,), 2) == trap_set_index(4, (0, 2))   # then the first other
    assert carried_standing(4, (1, 3), 1) == trap_set_index(4, (1,))   # the first of them
    assert carried_standing(4, (1, 3), 4) == 0                          # all four
