"""Issue 22, item 9: `run` stopped with "policy iteration for P1's best response did not
converge" on small worlds that `check` solves. Now

* `run` completes on the issue's world (deceptive value 0.9, V_lead 0), on maze 113, where
  P2's Nash strategy plays a trap set with probability 2e-9 and the old solve cycled, and on
  every fifth of the 200 random mazes (tests/mazegen.py; `make test`: every fortieth) and
  maze 3 (`make mazes`, or HG2PRISM_ALL_MAZES=1, runs all 200, each with its figures; by
  default 11 of the 41 draw theirs: every twentieth and maze 3; under `make test` all six);
  on those, where PRISM is installed, PRISM-games' csg
  engine computes V_NE from the exported symmetric.prism, an engine independent of ours, and
  it lies in our bracket (within 1e-6, as in tests/test_prism.py);
* on 200 random small mazes (walls at random, trap candidates on the shortest paths to the
  regions, delay 0-2, CUSUM and Bayesian observers) the baselines complete, computed in this
  process: V_lead, V_static and V_naive equal the independent reference
  (tests/reference.py, tests/reference_deception.py), and the bracket of V_NE holds (the
  guaranteed value of P1's strategy and value iteration's value, both below V_NE, are at most
  P1's best response to P2's strategy and the reference's V_lead); value iteration stops here
  at a change of 1e-6 instead of 1e-10, as a few mazes need 10^5 sweeps to reach 1e-10;
* on the mazes `run` runs, `results.json`'s V_NE lies (within 1e-6) in the bracket of the
  independent V_NE reference (tests/reference_nash.py: strategy improvement for both players
  with exact matrix games and exact MDP evaluations), itself narrower than 1e-6 (except on
  the five mazes of LIMIT_SURE, none in the default selection).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

import mazegen
import reference_deception
import reference_nash
from hg2prism import pipeline, progress
from hg2prism.analyses import baselines, deception_value
from hg2prism.cli import main
from hg2prism.worldfile import load_world
from test_prism import PRISM, TOL as PRISM_TOL, prism_value
from conftest import QUICK, share

TOL = 1e-9
NASH_TOLERANCE = 1e-6
RUNS = {"issue": mazegen.ISSUE_WORLD, "maze113": mazegen.maze_world(113),
        "maze8": mazegen.maze_world(8)}


# Every fifth maze through the whole `run` as well (all 200 take about 330 s of CPU, mostly
# figures and a few slow Nash iterations: `make mazes` runs them all). Maze 3 stopped `run`
# with a StrategyError until Storm's dropped constant variables were decoded (test_engine).
RUN_SEEDS = (list(range(200)) if os.environ.get("HG2PRISM_ALL_MAZES")
             else [3] + list(range(0, 200, 40 if QUICK else 5)))   # every fortieth: `make test`


# Mazes (not in the default selection) where the reference's bracket stays wider than 1e-6
# after its 100 rounds: P1 wins only in the limit there (its stationary strategies guarantee
# 1 - 1/k after k rounds, e.g. 0.99524 on maze 21, while P2's best strategy concedes 1; maze 18
# 0.8834 against 0.88892): only containment is checked.
LIMIT_SURE = {18, 21, 31, 37, 71}


# Of those, the figures, the replay and the explorer are drawn on every twentieth and maze 3
# (they are half of a maze's `run`, and what they draw is tested on the shipped worlds); the
# others stop after choosing the episode (`_without_drawings`).
DRAWN_SEEDS = {3} | set(range(0, 200, 20))


def _without_drawings(monkeypatch) -> None:
    """`run` with its figures, replay and explorer left out (the episode is still chosen)."""
    from hg2prism.report import explorer, plots, replay

    for module, name in ((plots, "world_figure"), (plots, "belief_figure"),
                         (plots, "completion_figure"), (explorer, "write_explorer")):
        monkeypatch.setattr(module, name, lambda *args, **kwargs: None)
    monkeypatch.setattr(replay, "replay_gif", lambda *args, **kwargs: 0)


@pytest.mark.parametrize("seed", RUN_SEEDS)
def test_run_completes_on_mazes(seed: int, tmp_path: Path, monkeypatch) -> None:
    path = tmp_path / f"maze{seed}.toml"
    path.write_text(mazegen.maze_world(seed))
    if seed not in DRAWN_SEEDS and not os.environ.get("HG2PRISM_ALL_MAZES"):
        _without_drawings(monkeypatch)
    with progress.quiet():
        assert main(["run", str(path), "--out", str(tmp_path / "out"), "--episodes", "20"]) == 0
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    drawn = seed in DRAWN_SEEDS or bool(os.environ.get("HG2PRISM_ALL_MAZES"))
    assert (tmp_path / "out" / "replay.gif").exists() == drawn
    assert results["v_naive"] <= results["deceptive_value"] + TOL
    low, high = results["v_ne_bounds"]
    assert low - TOL <= results["v_ne"] <= high + TOL
    # V_NE by the independent reference (tests/reference_nash.py): a sound bracket
    ref = reference_nash.v_ne(path)
    assert seed in LIMIT_SURE or ref.upper - ref.lower <= NASH_TOLERANCE, ref
    assert ref.contains(results["v_ne"], NASH_TOLERANCE), (results["v_ne"], ref)
    if PRISM is not None and drawn:
        # V_NE by an independent engine: PRISM-games' csg engine on the exported game (on the
        # mazes that draw: a JVM each; the reference's bracket above holds V_NE on all)
        value = prism_value(tmp_path / "out" / "symmetric.prism", epsilon="1e-9")
        assert low - PRISM_TOL <= value <= high + PRISM_TOL, (value, low, high)


@pytest.mark.parametrize("name", list(RUNS))
def test_run_completes(name: str, tmp_path: Path) -> None:
    path = tmp_path / f"{name}.toml"
    path.write_text(RUNS[name])
    assert main(["run", str(path), "--out", str(tmp_path / name), "--episodes", "200"]) == 0
    results = json.loads((tmp_path / name / "results.json").read_text())
    ref = reference_deception.deception(path)
    assert results["v_static"] == pytest.approx(ref.v_static(), abs=TOL)
    assert results["v_naive"] == pytest.approx(ref.v_naive(), abs=TOL)
    low, high = results["v_ne_bounds"]
    assert low - TOL <= results["v_ne"] <= high + TOL
    nash = reference_nash.v_ne(path)
    assert nash.upper - nash.lower <= NASH_TOLERANCE, nash
    assert nash.contains(results["v_ne"], NASH_TOLERANCE), (results["v_ne"], nash)
    if name == "issue":
        assert results["deceptive_value"] == pytest.approx(0.9, abs=1e-9)
        assert results["v_lead"] == 0.0


def reference_v_lead(ref: reference_deception.Deception) -> float:
    """V_lead from the reference: the leader game G(phi) at (v0, delta(iota, L(v0)))."""
    w, dfa = ref.w, ref.w.task_dfa
    return w.V(w.task, w.v0, dfa.step(dfa.init, w.label(w.v0)))


@pytest.mark.parametrize("seed", share(range(200)))       # every fourth under `make test`
def test_maze_baselines_match_reference(seed: int, tmp_path: Path) -> None:
    path = tmp_path / f"maze{seed}.toml"
    path.write_text(mazegen.maze_world(seed))
    with progress.quiet():
        analysis = pipeline.analyse(load_world(path))
    worth = deception_value.deception_values(analysis, 0.0)
    game = baselines.concurrent_game(analysis.ts, analysis.task)
    nash = baselines.solve_nash(game, NASH_TOLERANCE)
    start = analysis.ts.start_state * analysis.task.n_states + int(
        analysis.task.delta[analysis.task.initial,
                            analysis.ts.place_label[analysis.ts.decode(analysis.ts.start_state)[0]]])
    guaranteed = baselines.guaranteed_value(game, nash.p1)[start]
    best = baselines.best_response_value(game, nash.p2)[start]
    ref = reference_deception.deception(path)
    v_lead = reference_v_lead(ref)
    assert analysis.v_lead == pytest.approx(v_lead, abs=TOL)
    assert worth.v_static == pytest.approx(ref.v_static(), abs=TOL)
    assert worth.v_naive == pytest.approx(ref.v_naive(), abs=TOL)
    # both are below V_NE, itself below the best response to P2's strategy and below V_lead
    lower = max(guaranteed, nash.values[start])
    assert lower <= best + TOL
    assert lower <= v_lead + TOL
