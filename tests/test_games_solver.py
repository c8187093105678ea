"""The games' graph searches (breadth-first over predecessor moves) against the plain
level-by-level fixed points they replace, on world1 and generated worlds; the solved strategies'
optimality; strategy iteration alone on the generated delay worlds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import worldgen
from conftest import MODELS
from hg2prism.model.automata import translate
from hg2prism.frontends import transition_system as build_transition_system
from hg2prism.errors import SolverError
from hg2prism.opponent.perceptual_games import is_certified, TurnBasedGame
from hg2prism.worldfile import load_world, world_from_toml

FAMILY = dict(worldgen.world_family())
CASES = ["world1"] + sorted(FAMILY)[::5]


def level_by_level_attractor(game: TurnBasedGame, actions: np.ndarray | None) -> np.ndarray:
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


def avoid_forever(game: TurnBasedGame, p1: np.ndarray) -> np.ndarray:
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
def games(request: pytest.FixtureRequest, world_dir: Path) -> list[TurnBasedGame]:
    if request.param == "world1":
        path = MODELS / "world1.toml"
    else:
        path = world_dir / f"{request.param}.toml"
        path.write_text(FAMILY[request.param])
    world = load_world(path)
    ts = build_transition_system(world)
    return [TurnBasedGame(ts, translate(f, ts.label_names, ts.letters)) for f in (world.formula,) + world.hypotheses]


def test_attractor_ranks_match_the_level_by_level_search(games: list[TurnBasedGame]) -> None:
    rng = np.random.default_rng(0)
    for game in games:
        assert (game.positive_attractor() == level_by_level_attractor(game, None)).all()
        for _ in range(3):
            actions = rng.random((game.size, 4, game.ts.n_sets)) < 0.5
            assert (game.positive_attractor(actions) == level_by_level_attractor(game, actions)).all()
        # the game keeps the last masks' ranks (read-only): a mask its caller changes after
        # asking is another mask, and every move allowed is no restriction
        actions = rng.random((game.size, 4, game.ts.n_sets)) < 0.5
        kept = game.positive_attractor(actions)
        assert not kept.flags.writeable
        actions[:] = rng.random(actions.shape) < 0.3
        assert (game.positive_attractor(actions) == level_by_level_attractor(game, actions)).all()
        actions[:] = True
        assert (game.positive_attractor(actions) == level_by_level_attractor(game, None)).all()


def test_moves_index_the_tables_like_three_index_arrays(games: list[TurnBasedGame]) -> None:
    """TurnBasedGame.moves (np.take on the flat tables, used by every strategy evaluation)
    returns exactly next[g, a1, a2] and prob[g, a1, a2], for one move per state and for P1's
    answers to every trap set."""
    rng = np.random.default_rng(2)
    for game in games:
        _, n_a1, n_a2, _ = game.next.shape
        g = np.arange(game.size)
        a1, a2 = rng.integers(0, n_a1, game.size), rng.integers(0, n_a2, game.size)
        nxt, prob = game.moves((g * n_a1 + a1) * n_a2 + a2)
        assert nxt.shape == (game.size, game.next.shape[-1])
        assert (nxt == game.next[g, a1, a2]).all() and (prob == game.prob[g, a1, a2]).all()
        p1 = rng.integers(0, n_a1, (game.size, n_a2))
        sets = np.arange(n_a2)[None, :]
        nxt, prob = game.moves((g[:, None] * n_a1 + p1) * n_a2 + sets)
        assert (nxt == game.next[g[:, None], p1, sets]).all()
        assert (prob == game.prob[g[:, None], p1, sets]).all()


def test_product_successors_follow_the_definition(games: list[TurnBasedGame]) -> None:
    """next[s * n_q + q, a1, a2, k] = succ[s, a1, a2, k] * n_q + delta(q, L(succ[s, a1, a2, k]))
    and prob, allowed repeat the TS's rows (model/product.py)."""
    for game in games:
        ts, dfa = game.ts, game.dfa
        n_q = dfa.n_states
        label = ts.state_label()
        for q in range(n_q):
            rows = np.arange(ts.n_states) * n_q + q
            assert (game.next[rows] == ts.succ * n_q + dfa.delta[q, label[ts.succ]]).all()
            assert (game.prob[rows] == ts.prob).all() and (game.allowed[rows] == ts.allowed).all()


def test_bellman_is_the_operator_of_the_allowed_q_values(games: list[TurnBasedGame]) -> None:
    """The sweep of value iteration (TurnBasedGame.bellman) gives operator(allowed_q(v)) bit
    for bit, absorbing states and states without a set included."""
    rng = np.random.default_rng(3)
    for game in games:
        for v in (game.goal.astype(float), rng.random(game.size)):
            assert np.array_equal(game.bellman(v), game.operator(game.allowed_q(v)))
            assert np.array_equal(game.operator(game.allowed_q(v)),
                                  np.where(game.allowed, game.q_values(v).max(axis=1),
                                           np.inf).min(axis=1))


def greedy_by_definition(game: TurnBasedGame, q: np.ndarray, slack: float
                         ) -> tuple[np.ndarray, np.ndarray]:
    """_greedy's rule over the whole [G, A1, A2] table: P2 the first least best answer among
    her allowed sets; P1, among answers within `slack` of the best, the first that maximises
    the chance of entering a state of lower rank in the attractor of his optimal answers
    (-1 for the other answers and at the sets P2 may not play)."""
    best = q.max(axis=1)
    p2 = np.where(game.allowed, best, np.inf).argmin(axis=1)
    optimal = q >= best[:, None, :] - slack
    rank = game.positive_attractor(optimal)
    lower = np.where(rank >= 0, rank, np.iinfo(np.int64).max)
    nearer = lower[game.next] < lower[:, None, None, None]
    gain = (game.prob * nearer).sum(-1)
    closer = np.where(optimal & game.allowed[:, None, :], gain, -1.0)
    return closer.argmax(axis=1), p2


def test_greedy_strategies_follow_the_definition(games: list[TurnBasedGame]) -> None:
    from hg2prism.opponent.perceptual_games import _greedy

    rng = np.random.default_rng(4)
    for game in games:
        for v in (game.goal.astype(float), rng.random(game.size), rng.random(game.size).round(1)):
            q = game.allowed_q(v)
            for slack in (1e-12, 0.3):
                p1, p2 = _greedy(game, q, slack)
                want_p1, want_p2 = greedy_by_definition(game, q, slack)
                assert (p2 == want_p2).all() and (p1 == want_p1).all()


def test_certificate_zero_region_matches_the_greatest_fixed_point(games: list[TurnBasedGame]) -> None:
    rng = np.random.default_rng(1)
    for game in games:
        for _ in range(3):
            p1 = rng.integers(0, 4, size=(game.size, game.ts.n_sets))
            avoid = avoid_forever(game, p1)
            inside = np.zeros(game.size)
            inside[~avoid] = 1.0                       # certified iff x vanishes on `avoid`
            assert is_certified(game, p1, inside)
            assert avoid.any()                         # the trapped state at least
            spoiled = inside.copy()
            spoiled[np.flatnonzero(avoid)[-1]] = 1e-6
            assert not is_certified(game, p1, spoiled)


def best_response_lower_bound(game: TurnBasedGame, pick, sweeps: int = 5_000) -> np.ndarray:
    """Value iteration from 0 for v = pick(Q_v) (a one-player game): every iterate is a lower
    bound of that player's value. These games converge slowly (slip loops), so no more."""
    v = game.goal.astype(float)
    for _ in range(sweeps):
        new = np.where(game.free, pick(game.q_values(v)), v)
        if np.abs(new - v).max() < 1e-13:
            return new
        v = new
    return v


def test_solved_strategies_are_optimal(games: list[TurnBasedGame]) -> None:
    """P2's returned trap sets hold P1 to V (up to docs/semantics.md §4's 1e-6 ties), and P1's returned
    answers are greedy for V."""
    from hg2prism.opponent.perceptual_games import solve_game

    for game in games:
        solution = solve_game(game.ts, game.dfa)
        value = solution.values.reshape(-1)
        rows = np.arange(game.size)
        p2, p1 = solution.p2_strategy, solution.p1_strategy
        against_p2 = best_response_lower_bound(game, lambda q: q[rows, :, p2].max(axis=1))
        assert (against_p2 <= value + 1e-4).all(), (against_p2 - value).max()
        q = game.q_values(value)
        answered = q[rows[:, None], p1, np.arange(game.ts.n_sets)[None, :]]       # [G, A2]
        assert (~game.allowed | (answered >= q.max(axis=1) - 1e-9)).all()


def first_seed_sweeps(game: TurnBasedGame, tolerance: float) -> int:
    """Sweeps of value iteration from below (goal 1, P1's attractor complement fixed at 0) until
    the change is below `tolerance`: docs/semantics.md §10's step 2, counted independently."""
    outside = ~game.goal & (game.positive_attractor() < 0)
    fixed = ~game.free | outside
    v = game.terminal.copy()
    for sweep in range(1, 100_000):
        new = np.where(fixed, v, game.operator(game.q_values(v)))
        change = np.abs(new - v).max()
        v = new
        if change < tolerance:
            return sweep
    raise AssertionError("value iteration did not settle")


def test_strategy_iteration_certifies_the_same_solution_on_delay_worlds(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """With a single polishing round, Hoffman-Karp strategy iteration (docs/semantics.md §10,
    step 3a) solves most games of the generated delay worlds: its values must be certified from
    the first value-iteration seed (a wrong fixed point would fail the certificate and make value
    iteration resume, adding sweeps) and give the strategies of the default path, whose values
    tests/test_core.py checks against the independent reference."""
    import hg2prism.opponent.perceptual_games as perceptual_games

    compared = 0
    for name, text in sorted(FAMILY.items()):
        world = world_from_toml(text, name)
        if not world.delay:
            continue
        ts = build_transition_system(world)
        for formula in (world.formula,) + world.hypotheses:
            dfa = translate(formula, ts.label_names, ts.letters)
            default = perceptual_games.solve_game(ts, dfa)
            with monkeypatch.context() as patch:
                patch.setattr(perceptual_games, "POLISH_ROUNDS", 1)
                alone = perceptual_games.solve_game(ts, dfa)
            game = TurnBasedGame(ts, dfa)
            # each part of the game is solved from its own first seed, its exits at their values
            values = alone.values.reshape(-1)
            seeds = sum(first_seed_sweeps(game.restricted(part, values), perceptual_games.VI_TOLERANCE)
                        for part in game.parts())
            assert alone.sweeps == seeds, (name, formula)
            assert (alone.p2_strategy == default.p2_strategy).all(), (name, formula)
            assert (alone.p1_strategy == default.p1_strategy).all(), (name, formula)
            assert np.abs(alone.values - default.values).max() <= 1e-12, (name, formula)
            compared += 1
    assert compared >= 50


def delay_games() -> list[tuple[str, str, TurnBasedGame]]:
    games = []
    for name, text in sorted(FAMILY.items()):
        world = world_from_toml(text, name)
        if world.delay:
            ts = build_transition_system(world)
            games += [(name, f, TurnBasedGame(ts, translate(f, ts.label_names, ts.letters)))
                      for f in (world.formula,) + world.hypotheses]
    return games


def test_parts_are_solved_downstream_first_and_like_the_whole_game() -> None:
    """Solving the game one part (TS x a strongly connected set of DFA states) at a time gives
    the values of solving it whole, within the certificate's 1e-10; a part's moves enter only
    itself, the parts before it and absorbing states; and the generated delay worlds have
    games of several parts (else this compares nothing)."""
    from hg2prism.opponent import perceptual_games

    several = 0
    for name, formula, game in delay_games():
        parts = game.parts()
        done = ~game.free
        for part in parts:
            inside = np.zeros(game.size, dtype=bool)
            inside[part] = True
            entered = game.next[part][game.prob[part] > 0]
            assert (done[entered] | inside[entered]).all(), (name, formula)
            done |= inside
        assert done.all(), (name, formula)
        if len(parts) > 1:
            several += 1
            composed = perceptual_games.solve_game(game.ts, game.dfa).values.reshape(-1)
            whole = perceptual_games._solve_whole(game)[0]
            assert np.abs(composed - whole).max() <= 1e-10, (name, formula)
    assert several >= 10


def test_shared_parts_are_solved_once_and_change_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """The games of one world share their common parts (SharedParts: on these worlds the
    task's last obligation is often a hypothesis): solved with one SharedParts, on two threads
    as the pipeline does, every game has the values and strategies, bit for bit, of the game
    solved alone; each distinct part is solved once (fewer part solves than parts asked for,
    else this compares nothing); and a part whose solve fails fails every game that asks."""
    from concurrent.futures import ThreadPoolExecutor

    from hg2prism.opponent import perceptual_games

    solved: list[int] = []
    whole = perceptual_games._solve_whole

    def counted(game: TurnBasedGame):
        solved.append(int(game.free.sum()))
        return whole(game)

    asked = 0
    for name, text in sorted(FAMILY.items()):
        world = world_from_toml(text, name)
        ts = build_transition_system(world)
        dfas = [translate(f, ts.label_names, ts.letters) for f in (world.formula,) + world.hypotheses]
        alone = [perceptual_games.solve_game(ts, dfa) for dfa in dfas]
        asked += sum(len(TurnBasedGame(ts, dfa).parts()) for dfa in dfas)
        shared = perceptual_games.SharedParts()
        with monkeypatch.context() as patch:
            patch.setattr(perceptual_games, "_solve_whole", counted)
            with ThreadPoolExecutor(max_workers=2) as pool:
                together = list(pool.map(lambda dfa: perceptual_games.solve_game(ts, dfa, shared),
                                         dfas))
        for a, b in zip(alone, together):
            assert np.array_equal(a.values, b.values), name
            assert np.array_equal(a.p1_strategy, b.p1_strategy), name
            assert np.array_equal(a.p2_strategy, b.p2_strategy), name
    shared_solves = len(solved)
    assert shared_solves < asked, (shared_solves, asked)

    world = world_from_toml(next(iter(sorted(FAMILY.items())))[1], "failing")
    ts = build_transition_system(world)
    dfa = translate(world.formula, ts.label_names, ts.letters)

    calls: list[int] = []

    def failing(game: TurnBasedGame):
        calls.append(game.size)
        raise SolverError("no")

    shared = perceptual_games.SharedParts()
    with monkeypatch.context() as patch:
        patch.setattr(perceptual_games, "_solve_whole", failing)
        with pytest.raises(SolverError, match="no"):
            perceptual_games.solve_game(ts, dfa, shared)
        # the same game again, from another thread: the part's failure is shared, not retried
        # (and not waited for forever)
        with ThreadPoolExecutor(max_workers=1) as pool:
            again = pool.submit(perceptual_games.solve_game, ts, dfa, shared)
            with pytest.raises(SolverError, match="no"):
                again.result(timeout=60)
    assert len(calls) == 1


def test_look_ahead_keeps_the_values(monkeypatch: pytest.MonkeyPatch) -> None:
    """Both strategy iterations with and without their look-ahead (LOOKAHEAD, P1_LOOKAHEAD: 0
    is the plain Hoffman-Karp iteration) end at the same values within 1e-10, with a single
    polishing round so that strategy iteration runs on most games."""
    from hg2prism.opponent import perceptual_games

    for name, formula, game in delay_games():
        with monkeypatch.context() as patch:
            patch.setattr(perceptual_games, "POLISH_ROUNDS", 1)
            ahead = perceptual_games.solve_game(game.ts, game.dfa).values
            patch.setattr(perceptual_games, "LOOKAHEAD", 0)
            patch.setattr(perceptual_games, "P1_LOOKAHEAD", 0)
            plain = perceptual_games.solve_game(game.ts, game.dfa).values
        assert np.abs(ahead - plain).max() <= 1e-10, (name, formula)


def test_leader_value_of_world2_with_delay_3_to_the_reference_digits(world_dir: Path) -> None:
    """V_lead of world2 with delay 3 (a long wait: P1 holds back while the traps move) equals the
    independent reference's within 1e-12; the solver before the parts and the look-ahead ended
    1.5e-10 above it, at a pair certified only to its 1e-11 residual."""
    import reference
    from hg2prism.pipeline import analyse

    text = (MODELS / "world2.toml").read_text().replace("\ndelay = 0\n", "\ndelay = 3\n", 1)
    assert "\ndelay = 3\n" in text
    path = world_dir / "world2_d3.toml"
    path.write_text(text)
    assert analyse(load_world(path)).v_lead == pytest.approx(reference.solve(path).v_lead, abs=1e-12)
