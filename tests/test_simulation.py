"""Online simulation (docs/semantics.md §8): Wilson intervals, reproducibility, and the statistical check that
the simulated completion rate matches P(F<=horizon goal) of the DTMC that P1's exported
strategy induces. That DTMC is built here with tests/reference.py (no hg2prism code)."""

from __future__ import annotations

import math
from collections import deque
from pathlib import Path

import sys

import numpy as np
import pytest
import scipy.sparse as sp

import reference
from conftest import MODELS
import gridview
from hg2prism import pipeline
from hg2prism.frontends.grid import ACTIONS
from hg2prism.opponent.inference import build_inference
from hg2prism.analyses.simulation import (FAIL, GOAL, TRUNCATED, SimulationSummary,
                                          deviating_policy, leader_fallback,
                                          simulate_deceptive, simulate_nash, wilson_interval)
from hg2prism.strategy.records import Strategy, StrategyError
from hg2prism.worldfile import load_world

WORLD1 = MODELS / "world1.toml"


def model_policy(rng: np.random.Generator, n: int, ts_state: int, predicted: int, memory) -> int:
    """P2 as modelled: play pi2_xh(v)."""
    return predicted
HORIZON = 200
EPISODES = 4000

TINY = '''name = "tiny"
description = "one trap between the start and A, on one of two cells"

[grid]
map = """
######
#@t.A#
#.t..#
######
"""

[robot]
slip = 0.1

[task]
formula = "F A"

[adversary]
traps = 1
hypotheses = ["F A"]

[inference]
window = 1
threshold = 1.0
rationality = 10.0
'''


# ---------------------------------------------------------------------------------------------
# fixtures
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def world1(tmp_path_factory: pytest.TempPathFactory) -> pipeline.CheckResult:
    return pipeline.check(load_world(WORLD1), tmp_path_factory.mktemp("sim_world1"))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> pipeline.CheckResult:
    folder = tmp_path_factory.mktemp("sim_tiny")
    path = folder / "tiny.toml"
    path.write_text(TINY)
    return pipeline.check(load_world(path), folder / "out")


def strategy_of(result: pipeline.CheckResult, **kwargs) -> Strategy:
    return Strategy.from_records(result.records, result.analysis.ts, **kwargs)


def run(result: pipeline.CheckResult, episodes: int = 500, seed: int = 0,
        **kwargs) -> SimulationSummary:
    strategy = kwargs.pop("strategy", None) or strategy_of(result)
    return simulate_deceptive(result.analysis, strategy, episodes, HORIZON, seed,
                              progress=False, **kwargs)


# ---------------------------------------------------------------------------------------------
# Wilson interval
# ---------------------------------------------------------------------------------------------

def closed_form(k: int, n: int, z: float) -> tuple[float, float]:
    p = k / n
    centre = (k + z * z / 2) / (n + z * z)
    half = z * math.sqrt(n) / (n + z * z) * math.sqrt(p * (1 - p) + z * z / (4 * n))
    return centre - half, centre + half


@pytest.mark.parametrize("k, n", [(0, 10), (10, 10), (50, 100), (3, 7), (244, 10000)])
def test_wilson_interval_matches_the_closed_form(k: int, n: int) -> None:
    z = 1.959963984540054          # standard normal 97.5% quantile
    low, high = wilson_interval(k, n, 0.95)
    exp_low, exp_high = closed_form(k, n, z)
    assert low == pytest.approx(max(exp_low, 0.0), abs=1e-12)
    assert high == pytest.approx(min(exp_high, 1.0), abs=1e-12)


def test_wilson_interval_hand_values() -> None:
    z = 1.959963984540054
    # 0 of 10: [0, z^2 / (10 + z^2)]; 10 of 10: [10 / (10 + z^2), 1]
    assert wilson_interval(0, 10) == pytest.approx((0.0, z * z / (10 + z * z)), abs=1e-12)
    assert wilson_interval(10, 10) == pytest.approx((10 / (10 + z * z), 1.0), abs=1e-12)
    # 50 of 100: symmetric around 1/2, half-width z sqrt(100 * 0.25 + z^2 / 4) / (100 + z^2)
    half = z * math.sqrt(25 + z * z / 4) / (100 + z * z)
    assert wilson_interval(50, 100) == pytest.approx((0.5 - half, 0.5 + half), abs=1e-12)
    assert wilson_interval(50, 100) == pytest.approx((0.4038315, 0.5961685), abs=1e-7)
    # a higher confidence gives a wider interval
    z999 = 3.2905267314918945
    assert wilson_interval(50, 100, 0.999) == pytest.approx(closed_form(50, 100, z999), abs=1e-12)


@pytest.mark.parametrize("n", [1, 2, 7, 100])
def test_wilson_band_is_the_interval_of_every_count(n: int) -> None:
    """The completion figure's band (one interval per step) against the closed form, count by
    count, boundaries 0 and n included."""
    from hg2prism.analyses.simulation import wilson_band

    z = 1.959963984540054
    low, high = wilson_band(np.arange(n + 1), n)
    for k in range(n + 1):
        exp_low, exp_high = closed_form(k, n, z)
        assert low[k] == pytest.approx(0.0 if k == 0 else max(exp_low, 0.0), abs=1e-12)
        assert high[k] == pytest.approx(1.0 if k == n else min(exp_high, 1.0), abs=1e-12)
        assert (low[k], high[k]) == wilson_interval(k, n)


def test_wilson_interval_rejects_bad_input() -> None:
    for args in [(1, 0), (-1, 10), (11, 10), (5, 10, 1.0), (5, 10, 0.0)]:
        with pytest.raises(ValueError):
            wilson_interval(*args)


# ---------------------------------------------------------------------------------------------
# The statistical check of docs/semantics.md §8 against an independently built DTMC
# ---------------------------------------------------------------------------------------------

def reference_chain(path: Path, records: list[dict]):
    """The DTMC induced by the records, built with tests/reference.py: (initial, states,
    index, successor lists [(target, p)] with target an index, "goal" or "fail")."""
    world = reference.World(path)
    table = {}
    for rec in map(reference.grid_record, records):
        v = world.record_ts_state(rec["cell"], rec.get("traps"), rec.get("countdown"))
        window = tuple((world.record_ts_state(o["cell"], o.get("traps"), o.get("countdown")), o["action"])
                       for o in rec["window"])
        table[(v, int(rec["q"]), (int(rec["hypothesis"]), window))] = rec["action"]
    s0 = world.initial()
    assert s0 not in ("goal", "fail")
    index, order, queue, raw = {s0: 0}, [s0], deque([s0]), []
    while queue:
        s = queue.popleft()
        succ = world.hyper_successors(s, table[s])
        raw.append(succ)
        for t in succ:
            if t not in ("goal", "fail") and t not in index:
                index[t] = len(order)
                order.append(t)
                queue.append(t)
    succs = [[(t if t in ("goal", "fail") else index[t], p) for t, p in succ.items()]
             for succ in raw]
    return world, order, index, succs


def bounded_goal_probability(succs, horizon: int) -> float:
    """P(F<=horizon goal) from state 0: x_{n} = g + P x_{n-1}, x_0 = 0."""
    n = len(succs)
    rows, cols, vals = [], [], []
    goal = np.zeros(n)
    for i, succ in enumerate(succs):
        for t, p in succ:
            if t == "goal":
                goal[i] += p
            elif t != "fail":
                rows.append(i)
                cols.append(t)
                vals.append(p)
    matrix = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    x = np.zeros(n)
    for _ in range(horizon):
        x = goal + matrix @ x
    return float(x[0])


def test_world1_rate_matches_the_bounded_probability_of_the_induced_dtmc(world1) -> None:
    world, order, index, succs = reference_chain(WORLD1, world1.records)
    # docs/semantics.md §8: P=? [F "goal"] of the induced DTMC is the deceptive value (linear solve) ...
    unbounded = float(reference.dtmc_reach(succs)[0])
    assert unbounded == pytest.approx(world1.results.deceptive_value, abs=1e-6)
    # ... and the bounded probability grows to it.
    exact = bounded_goal_probability(succs, HORIZON)
    assert 0.0 < exact <= unbounded + 1e-12
    assert bounded_goal_probability(succs, 4 * HORIZON) >= exact

    ts = gridview.view(world1.analysis)
    visited = set()

    def observe(step) -> None:
        m = step.memory
        visited.add((ts.cells[step.ts_state], step.q,
                     (m.hypothesis, tuple((ts.cells[v], ACTIONS[a]) for v, a in m.window))))

    summary = run(world1, EPISODES, seed=2024, observer=observe)
    low, high = summary.interval(0.999)
    assert low <= exact <= high, (summary, exact)
    assert summary.completed + summary.failed + summary.truncated == EPISODES
    assert summary.off_record_steps == 0
    # every augmented state P1 tracked is a state of the independently built chain
    assert visited <= set(order)


def test_rate_interval_and_lengths_are_consistent(world1) -> None:
    summary = run(world1, 300, seed=5)
    assert summary.rate == summary.completed / summary.episodes
    assert summary.ci95 == wilson_interval(summary.completed, summary.episodes, 0.95)
    assert summary.ci95[0] <= summary.rate <= summary.ci95[1]
    assert len(summary.lengths) == len(summary.outcomes) == 300
    assert set(np.unique(summary.outcomes)) <= {FAIL, GOAL, TRUNCATED}
    assert (summary.lengths[summary.outcomes == TRUNCATED] == HORIZON).all()
    assert (summary.lengths[summary.outcomes != TRUNCATED] <= HORIZON).all()
    assert (summary.lengths >= 1).all()
    assert summary.episodes == 300


# ---------------------------------------------------------------------------------------------
# reproducibility, observer, progress
# ---------------------------------------------------------------------------------------------

def test_same_seed_same_numbers_different_seed_different_numbers(world1) -> None:
    a, b = run(world1, 400, seed=7), run(world1, 400, seed=7)
    assert (a.completed, a.failed, a.truncated) == (b.completed, b.failed, b.truncated)
    assert np.array_equal(a.lengths, b.lengths) and np.array_equal(a.outcomes, b.outcomes)
    c = run(world1, 400, seed=8)
    assert not np.array_equal(a.lengths, c.lengths)
    # P2 given her model policy explicitly plays exactly as by default
    d = run(world1, 400, seed=7, p2_policy=model_policy)
    assert np.array_equal(a.lengths, d.lengths) and np.array_equal(a.outcomes, d.outcomes)


def test_observer_sees_every_transition(world1) -> None:
    steps = []
    summary = run(world1, 50, seed=3, observer=steps.append)
    assert len(steps) == int(summary.lengths.sum())
    games = world1.analysis.games
    ts = world1.analysis.ts
    by_episode: dict[int, list] = {}
    for step in steps:
        by_episode.setdefault(step.episode, []).append(step)
        assert step.a2 == step.predicted_a2 == games[step.memory.hypothesis].trap_choice[step.ts_state]
        assert step.p2_memory == step.memory
        assert step.n_a2 == int(ts.allowed[step.ts_state].sum())
        assert step.augmented_state == (step.ts_state, step.q, step.memory)
    for episode, episode_steps in by_episode.items():
        assert [s.n for s in episode_steps] == list(range(1, summary.lengths[episode] + 1))
        for before, after in zip(episode_steps, episode_steps[1:]):
            assert (after.ts_state, after.q) == (before.next_state, before.next_q)
        if summary.outcomes[episode] == GOAL:
            assert episode_steps[-1].next_q in world1.analysis.task.accepting


def test_progress_bar_goes_to_stderr_and_can_be_disabled(world1, capsys) -> None:
    strategy = strategy_of(world1)
    simulate_deceptive(world1.analysis, strategy, 1000, 50, 0, progress=False)
    assert capsys.readouterr().err == ""
    # Not a terminal (pytest captures stderr): one final line, no redrawing.
    simulate_deceptive(world1.analysis, strategy, 1000, 50, 0, progress=True)
    err = capsys.readouterr().err
    assert "1000 episodes" in err and err.count("\r") == 0 and err.count("\n") == 1


def test_progress_bar_redraws_on_a_terminal(world1, capsys, monkeypatch) -> None:
    strategy = strategy_of(world1)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    simulate_deceptive(world1.analysis, strategy, 1000, 50, 0, progress=True)
    err = capsys.readouterr().err
    assert "1000/1000" in err and 2 <= err.count("\r") <= 25


# ---------------------------------------------------------------------------------------------
# strategy records
# ---------------------------------------------------------------------------------------------

def test_missing_record_is_a_clear_error(world1) -> None:
    records = [r for r in world1.records if r["window"]]      # drop the initial state's record
    with pytest.raises(StrategyError, match="no record.*x2_y4"):
        run(world1, 5, strategy=strategy_of_records(world1, records))


def strategy_of_records(result, records) -> Strategy:
    return Strategy.from_records(records, result.analysis.ts)


def test_bad_records_are_rejected(world1) -> None:
    good = world1.records[0]
    with pytest.raises(StrategyError, match="not a state of the world"):
        strategy_of_records(world1, [dict(good, state="x0_y0")])
    with pytest.raises(StrategyError, match="action"):
        strategy_of_records(world1, [dict(good, action="up")])
    other = next(a for a in ACTIONS if a != good["action"])
    with pytest.raises(StrategyError, match="conflicting"):
        strategy_of_records(world1, [good, dict(good, action=other)])
    assert len(strategy_of(world1)) == len(world1.records)


# ---------------------------------------------------------------------------------------------
# experiments where P2 deviates
# ---------------------------------------------------------------------------------------------

def test_p2_deviation_changes_the_completion_rate(tiny) -> None:
    assert tiny.results.deceptive_value == pytest.approx(0.0, abs=1e-9)
    modelled = run(tiny, 1000, seed=1)
    assert modelled.completed == 0
    ts = gridview.view(tiny.analysis)
    # P2 always puts the trap on the lower candidate: P1 walks past on the upper row.
    lower = next(k for k in range(ts.n_sets) if ts.trap_cells(k) == ((2, 1),))
    # Under the model a robot on a trap candidate is trapped, so the records never cover those
    # cells: P1 needs a fallback once P2 deviates.
    strategy = strategy_of(tiny, fallback=leader_fallback(tiny.analysis))
    fixed = run(tiny, 1000, seed=1, strategy=strategy,
                p2_policy=lambda rng, n, v, predicted, memory: lower)
    assert fixed.off_record_steps > 0
    assert fixed.interval(0.999)[0] > modelled.interval(0.999)[1]
    uniform = run(tiny, 1000, seed=1, strategy=strategy,
                  p2_policy=deviating_policy(ts, deviate_after=2))
    assert uniform.interval(0.999)[0] > modelled.interval(0.999)[1]
    with pytest.raises(ValueError, match="p2_policy"):
        run(tiny, 5, p2_policy=lambda rng, n, v, predicted, memory: ts.n_sets)


def test_deviating_policy_follows_the_model_first(world1) -> None:
    steps = []
    strategy = strategy_of(world1, fallback=leader_fallback(world1.analysis))
    run(world1, 200, seed=4, strategy=strategy, observer=steps.append,
        p2_policy=deviating_policy(world1.analysis.ts, deviate_after=3))
    assert all(s.a2 == s.predicted_a2 for s in steps if s.n <= 3)
    assert any(s.a2 != s.predicted_a2 for s in steps if s.n > 3)


def _same_episodes(a: SimulationSummary, b: SimulationSummary) -> None:
    assert np.array_equal(a.lengths, b.lengths) and np.array_equal(a.outcomes, b.outcomes)
    assert (a.off_record_steps, a.p2_switched, a.p2_switches, a.p2_switched_in_play) == (
        b.off_record_steps, b.p2_switched, b.p2_switches, b.p2_switched_in_play)


def test_a_plain_run_plays_the_episodes_of_a_run_with_an_observer(world1, tmp_path) -> None:
    """Without an observer, a detector or a deviating P2 (what `run` plays) the simulation
    looks each node's step up once; with an observer it takes every step in full. Both draw
    the same random numbers in the same order: the same episodes, switches and off-record
    steps, where P2 runs another inference than P1's model and where she draws her hypothesis
    (Bayesian "sample")."""
    analysis = world1.analysis
    hasty = build_inference(analysis.games, analysis.world.window, 0.01,
                            analysis.world.initial_hypothesis)
    strategy = strategy_of(world1, fallback=leader_fallback(analysis))
    plain = run(world1, 300, seed=6, strategy=strategy, p2_inference=hasty)
    _same_episodes(plain, run(world1, 300, seed=6, strategy=strategy, p2_inference=hasty,
                              observer=lambda step: None))
    assert plain.p2_switched > 0
    text = (MODELS / "world3_bayes.toml").read_text()
    assert 'decision = "map"' in text
    path = tmp_path / "sample.toml"
    path.write_text(text.replace('decision = "map"', 'decision = "sample"'))
    sample = pipeline.check(load_world(path), tmp_path / "out")
    steps = []
    plain = run(sample, 300, seed=2)
    _same_episodes(plain, run(sample, 300, seed=2, observer=steps.append))
    # she drew, and not always her memory's most likely hypothesis
    assert any(step.p2_drawn != step.p2_memory.hypothesis for step in steps)


def test_p2_can_run_another_inference_model(world1) -> None:
    analysis = world1.analysis
    # P2 really switches on the slightest evidence; P1 still models the world's threshold
    hasty = build_inference(analysis.games, analysis.world.window, 0.01,
                            analysis.world.initial_hypothesis)
    steps = []
    strategy = strategy_of(world1, fallback=leader_fallback(analysis))
    run(world1, 200, seed=6, strategy=strategy, observer=steps.append, p2_inference=hasty)
    games = analysis.games
    p1_model, p2_model = analysis.inference, hasty
    by_episode: dict[int, list] = {}
    for s in steps:
        by_episode.setdefault(s.episode, []).append(s)
        assert s.a2 == games[s.p2_memory.hypothesis].trap_choice[s.ts_state]
        assert s.predicted_a2 == games[s.memory.hypothesis].trap_choice[s.ts_state]
    for episode_steps in by_episode.values():
        assert episode_steps[0].memory == p1_model.initial_memory()
        assert episode_steps[0].p2_memory == p2_model.initial_memory()
        for before, after in zip(episode_steps, episode_steps[1:]):
            observation = (before.ts_state, before.a1)
            assert after.memory == p1_model.update(before.memory, observation)
            assert after.p2_memory == p2_model.update(before.p2_memory, observation)
    assert any(s.memory.hypothesis != s.p2_memory.hypothesis for s in steps)
    assert any(s.a2 != s.predicted_a2 for s in steps)


# ---------------------------------------------------------------------------------------------
# Nash baseline runs
# ---------------------------------------------------------------------------------------------

def exact_stationary(ts, dfa, p1: np.ndarray, p2: np.ndarray, horizon: int) -> float:
    """P(F<=horizon goal) when both play the stationary mixed strategies, by explicit loops."""
    n_q = dfa.n_states
    label = {s: int(ts.place_label[ts.decode(s)[0]]) for s in range(ts.n_states - 1)}

    def outcome(s: int, q: int) -> str | None:
        if s == ts.trapped:
            return "fail"
        if q in dfa.accepting:
            return "goal"
        if q in dfa.sink:
            return "fail"
        return None

    start = (ts.start_state, int(dfa.delta[dfa.initial, label[ts.start_state]]))
    dist, reached = {start: 1.0}, 0.0
    for _ in range(horizon):
        new: dict[tuple[int, int], float] = {}
        for (s, q), mass in dist.items():
            g = s * n_q + q
            for a1 in range(4):
                for a2 in range(ts.n_sets):
                    w = mass * p1[g, a1] * p2[g, a2]
                    if w == 0:
                        continue
                    for k in range(3):
                        p = ts.prob[s, a1, a2, k]
                        if p == 0:
                            continue
                        t = int(ts.succ[s, a1, a2, k])
                        qt = q if t == ts.trapped else int(dfa.delta[q, label[t]])
                        end = outcome(t, qt)
                        if end == "goal":
                            reached += w * p
                        elif end is None:
                            new[(t, qt)] = new.get((t, qt), 0.0) + w * p
        dist = new
    return reached


def test_nash_simulation_matches_the_exact_bounded_probability(world1) -> None:
    ts, dfa = world1.analysis.ts, world1.analysis.task
    size = ts.n_states * dfa.n_states
    rng = np.random.default_rng(11)
    # some mixed strategies: P1 favours one random action, P2 uniform over the allowed sets
    p1 = np.full((size, 4), 0.1)
    p1[np.arange(size), rng.integers(0, 4, size)] = 0.7
    p2 = np.repeat(ts.allowed, dfa.n_states, axis=0).astype(float)
    p2 /= p2.sum(axis=1, keepdims=True)
    horizon = 60
    exact = exact_stationary(ts, dfa, p1, p2, horizon)
    summary = simulate_nash(ts, dfa, p1, p2, EPISODES, horizon, seed=3, progress=False)
    low, high = summary.interval(0.999)
    assert low <= exact <= high, (summary, exact)
    again = simulate_nash(ts, dfa, p1, p2, EPISODES, horizon, seed=3, progress=False)
    assert np.array_equal(summary.lengths, again.lengths)
    assert np.array_equal(summary.outcomes, again.outcomes)
    other = simulate_nash(ts, dfa, p1, p2, EPISODES, horizon, seed=4, progress=False)
    assert not np.array_equal(summary.lengths, other.lengths)
    bad = p2.copy()
    bad[:, :] = 0.0
    bad[:, 0] = 1.0
    bad[:, 1] = 0.5
    with pytest.raises(ValueError):
        simulate_nash(ts, dfa, p1, bad, 10, horizon, seed=0, progress=False)
