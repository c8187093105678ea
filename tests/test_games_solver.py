"""The games' graph searches (breadth-first over predecessor moves) against the plain
level-by-level fixed points they replace, on world1 and generated worlds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import worldgen
from conftest import MODELS
from hg2prism.automata import translate
from hg2prism.dynamics import build_transition_system
from hg2prism.games import _certified, _Game
from hg2prism.world import load_world

FAMILY = dict(worldgen.world_family())
CASES = ["world1"] + sorted(FAMILY)[::5]


def level_by_level_attractor(game: _Game, actions: np.ndarray | None) -> np.ndarray:
    """Rank in P1's positive attractor, one full pass over every move per level."""
    rank = np.where(game.goal, 0, -1)
    level = 0
    while True:
        level += 1
        inside = rank >= 0
        reach = ((game.prob > 0) & inside[game.next]).any(axis=-1)            # [G, 4, A2]
        if actions is not None:
            reach &= actions
        ok = (reach.any(axis=1) | ~game.allowed).all(axis=1) & game.free & ~inside
        if not ok.any():
            return rank
        rank[ok] = level


def avoid_forever(game: _Game, p1: np.ndarray) -> np.ndarray:
    """States from which P2 keeps P1 (answering p1) away from the goal: greatest fixed point."""
    rows = np.arange(game.size)[:, None]
    sets = np.arange(game.ts.n_sets)[None, :]
    nxt, prob = game.next[rows, p1, sets], game.prob[rows, p1, sets]          # [G, A2, 3]
    avoid = ~game.goal
    while True:
        stays = (((prob == 0) | avoid[nxt]).all(axis=-1) & game.allowed).any(axis=1)
        new = avoid & (stays | game.zero_fixed)
        if (new == avoid).all():
            return avoid
        avoid = new


@pytest.fixture(params=CASES)
def games(request: pytest.FixtureRequest, world_dir: Path) -> list[_Game]:
    if request.param == "world1":
        path = MODELS / "world1.toml"
    else:
        path = world_dir / f"{request.param}.toml"
        path.write_text(FAMILY[request.param])
    world = load_world(path)
    ts = build_transition_system(world)
    return [_Game(ts, translate(f, ts.label_names)) for f in (world.formula,) + world.hypotheses]


def test_attractor_ranks_match_the_level_by_level_search(games: list[_Game]) -> None:
    rng = np.random.default_rng(0)
    for game in games:
        assert (game.positive_attractor() == level_by_level_attractor(game, None)).all()
        for _ in range(3):
            actions = rng.random((game.size, 4, game.ts.n_sets)) < 0.5
            assert (game.positive_attractor(actions) == level_by_level_attractor(game, actions)).all()


def test_certificate_zero_region_matches_the_greatest_fixed_point(games: list[_Game]) -> None:
    rng = np.random.default_rng(1)
    for game in games:
        for _ in range(3):
            p1 = rng.integers(0, 4, size=(game.size, game.ts.n_sets))
            avoid = avoid_forever(game, p1)
            inside = np.zeros(game.size)
            inside[~avoid] = 1.0                       # certified iff x vanishes on `avoid`
            assert _certified(game, p1, inside)
            assert avoid.any()                         # the trapped state at least
            spoiled = inside.copy()
            spoiled[np.flatnonzero(avoid)[-1]] = 1e-6
            assert not _certified(game, p1, spoiled)
