"""Reported numbers are what they claim (docs/semantics.md §7 and §10).

* V_NE's bracket [lower, upper]: each end is recomputed here by plain value iteration written in
  this file (lower: P2 minimising against P1's extracted mixed strategy; upper: P1 maximising
  against P2's), run until the change is below 1e-14; the ends agree within 1e-9, the bracket is
  at most 1e-6 wide, and value iteration's own V_NE (from below) is not above the upper end.
* Every probability is in [0, 1]: a value a few ulps above 1 is clamped, more is an error.
* The invariants V_NE <= V_lead <= deceptive value hold within 1e-6.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import worldgen
from conftest import MODELS, share
from hg2prism import pipeline
from hg2prism.analyses import baselines
from hg2prism.errors import SolverError, probability
from hg2prism.worldfile import load_world

FAMILY = dict(worldgen.world_family())
NAMES = ["world1", "world2", "fam00_d0_l1_w1_x2", "fam04_d1_l1_w2_x2", "fam09_d0_l2_w1_x3",
         "fam13_d1_l2_w2_x2", "fam20_d2_l1_w1_x3", "fam27_d0_l2_w1_x2"]


def _world(name: str, folder: Path):
    if name in ("world1", "world2"):
        return load_world(MODELS / f"{name}.toml")
    path = folder / f"{name}.toml"
    path.write_text(FAMILY[name])
    return load_world(path)


def _plain_iteration(game: baselines.ConcurrentGame, p1: np.ndarray | None,
                     p2: np.ndarray | None) -> np.ndarray:
    """Reach probability with one player's mixed strategy fixed and the other optimising
    (P2 minimising when p1 is given, P1 maximising when p2 is given), by value iteration."""
    v = game.goal.astype(float)
    for _ in range(2_000_000):
        m = (game.prob * v[game.next]).sum(axis=-1)                   # [G, A1, A2]
        if p1 is not None:
            per_a2 = np.einsum("ga,gab->gb", p1, m)
            new = np.where(game.allowed, per_a2, np.inf).min(axis=1)
        else:
            new = np.einsum("gb,gab->ga", np.where(game.allowed, p2, 0.0), m).max(axis=1)
        new = np.where(game.free, new, game.goal.astype(float))
        if np.abs(new - v).max() < 1e-14:
            return new
        v = new
    raise AssertionError("plain value iteration did not converge")


@pytest.mark.parametrize("name", share(NAMES))       # every fourth under `make test`
def test_nash_bracket(name: str, tmp_path: Path) -> None:
    analysis = pipeline.analyse(_world(name, tmp_path))
    nash = baselines.nash_baseline(analysis.ts, analysis.task)
    low, high = nash.v_ne_bounds
    n_q = analysis.task.n_states
    g0 = nash.initial[0] * n_q + nash.initial[1]
    game, solution = nash.game, nash.solution
    assert abs(_plain_iteration(game, solution.p1, None)[g0] - low) <= 1e-9
    assert abs(_plain_iteration(game, None, solution.p2)[g0] - high) <= 1e-9
    assert 0.0 <= low <= nash.v_ne <= high <= 1.0
    assert high - low <= 1e-6
    assert solution.values[g0] <= high + 1e-12          # value iteration stays below V_NE
    assert nash.v_ne <= analysis.v_lead + 1e-6
    assert 0.0 <= analysis.v_lead <= 1.0


@pytest.mark.parametrize("name", NAMES[:4])
def test_deceptive_value_invariants(name: str, tmp_path: Path) -> None:
    checked = pipeline.check(_world(name, tmp_path), tmp_path / "out")
    results = checked.results
    assert 0.0 <= results.deceptive_value <= 1.0
    assert results.v_lead <= results.deceptive_value + 1e-6
    assert results.sound is True
    # results.json (from check) is the typed results' to_json(), keys in the same order
    saved = json.loads((tmp_path / "out" / "results.json").read_text())
    assert saved == results.to_json() and list(saved) == list(results.to_json())


def test_probability_clamps_rounding_and_refuses_the_rest() -> None:
    assert probability(1.0000000000000353, "v") == 1.0
    assert probability(-1e-17, "v") == 0.0
    assert probability(0.25, "v") == 0.25
    with pytest.raises(SolverError, match="not a probability"):
        probability(1.001, "V_lead")
