"""Robust deception (docs/semantics.md §13) and re-planning (§14).

The robust values are compared with an independent robust value iteration on the explicit
hypergame of tests/reference.py (tests/reference_robust.py, which imports nothing from hg2prism),
on world1, world2 and generated worlds; the exported robust strategy's worst case is evaluated
by the same reference; Storm's robust mode and PRISM check the model whose deviations have a
positive lower bound; re-planning is reproducible and changes nothing when the fallback plays
as the deceptive strategy does.
"""

from __future__ import annotations

import functools
import json
import math
import os
import shutil
import subprocess
from pathlib import Path

import pytest

import worldgen
from conftest import MODELS
from reference_robust import RobustHypergame
from hg2prism import pipeline, progress
from hg2prism.analyses.simulation import (GOAL, LeaderStrategy, Replanning, deviating_policy,
                                          leader_fallback, simulate_deceptive)
from hg2prism.cli import main
from hg2prism.errors import InputError
from hg2prism.experiments import robust
from hg2prism.worldfile import load_world
from hg2prism.prism.robust_model import CHECK_CONSTANTS, EXACT_CONSTANTS
from hg2prism.strategy.records import Strategy
from conftest import share

DELTAS = (0.01, 0.1, 0.3)
TOL = 1e-6
FAMILY = dict(worldgen.world_family())
# 20 generated worlds (delay 0-2, one and two traps, windows 1-3, one to four hypotheses, slip 0
# and > 0) whose interval models solve in about a second each
GENERATED = ["fam00_d0_l1_w1_x2", "fam01_d1_l1_w1_x3", "fam02_d2_l1_w1_x4", "fam03_d0_l1_w2_x1",
             "fam05_d2_l1_w2_x3", "fam09_d0_l2_w1_x3",
             "fam10_d1_l2_w1_x2", "fam11_d2_l2_w1_x1", "fam12_d0_l2_w2_x4", "fam18_d0_l1_w1_x3",
             "fam19_d1_l1_w1_x2", "fam20_d2_l1_w1_x3", "fam21_d0_l1_w2_x4", "fam23_d2_l1_w2_x2",
             "fam24_d0_l1_w3_x3", "fam27_d0_l2_w1_x2", "fam28_d1_l2_w1_x4", "fam36_eq_d0_w2",
             "fam37_eq_d1_w1", "fam40_tx_d0_l1_w2"]
CASES = ["world1", "world2"] + share(GENERATED)      # every fourth under `make test`


@functools.cache
def world_path(name: str, folder: str) -> Path:
    if name in ("world1", "world2"):
        return MODELS / f"{name}.toml"
    path = Path(folder) / f"{name}.toml"
    path.write_text(FAMILY[name])
    return path


@functools.cache
def checked(name: str, folder: str) -> pipeline.CheckResult:
    with progress.quiet():
        return pipeline.check(load_world(world_path(name, folder)), Path(folder) / name)


@functools.cache
def solved(name: str, folder: str) -> tuple[list, RobustHypergame]:
    """Our solutions at 0 and DELTAS, and the reference's hypergame."""
    world = load_world(world_path(name, folder))
    rows = robust.solve_budgets(world, checked(name, folder), (0.0,) + DELTAS,
                                Path(folder) / f"{name}_robust", storm_check=False)
    return [row for row, _ in rows], RobustHypergame(world_path(name, folder))


@pytest.fixture(params=CASES)
def case(request: pytest.FixtureRequest, world_dir: Path):
    return request.param, str(world_dir)


def test_the_generated_worlds_vary() -> None:
    import tomllib

    worlds = [tomllib.loads(FAMILY[name]) for name in GENERATED]
    assert len(worlds) >= 20
    assert {w["adversary"].get("delay", 0) for w in worlds} == {0, 1, 2}
    assert {w["adversary"]["traps"] for w in worlds} == {1, 2}
    assert {w["inference"]["window"] for w in worlds} == {1, 2, 3}
    assert {w["robot"]["slip"] == 0 for w in worlds} == {True, False}


def test_robust_values_match_the_reference_and_are_ordered(case) -> None:
    name, folder = case
    rows, reference = solved(name, folder)
    deceptive = checked(name, folder).results.deceptive_value
    assert rows[0].robust_value == pytest.approx(deceptive, abs=TOL)
    for row in rows:
        assert row.nominal_worst_case <= row.robust_value + 1e-9
        assert row.robust_strategy_nominal_value <= deceptive + 1e-9
        assert row.residual <= 1e-10
    for earlier, later in zip(rows, rows[1:]):
        assert later.robust_value <= earlier.robust_value + 1e-9
    expected = reference.robust_values([row.delta for row in rows[1:]])
    for row, value in zip(rows[1:], expected):
        assert row.robust_value == pytest.approx(value, abs=TOL)
    # the size guard's estimate of the interval model is near it (model/sizeguard.py: 0.22 to
    # 1.05 times its Storm states on these worlds, which keep each goal and failure state apart)
    from hg2prism.model import sizeguard
    bound = sizeguard.check_robust_size(load_world(world_path(name, folder)))
    assert max(row.storm_states for row in rows) <= 1.1 * bound


BAYES_DELAY = """
name = "bayes_delay"
[grid]
map = \"\"\"
########
#BB.t..#
##.....#
#.....@#
#..t..t#
#DtA...#
########
\"\"\"
[robot]
slip = 0.1
[task]
formula = "(!obs U D) & F B"
[adversary]
traps = 1
delay = 1
initial_traps = [[2, 1]]
hypotheses = ["F (B & F D)", "!A U D", "F (A & F D)"]
[inference]
kind = "bayes"
window = 2
rationality = 3.0
decision = "map"
prior = [2, 1, 1]
"""


def test_a_bayesian_world_with_delay_is_bounded_given_p2s_games(tmp_path: Path) -> None:
    """A stress test's Bayesian world with delay (23k canonical states; its interval model,
    forced, had 4.46e6 Storm states and took 6 GB). Its hypergame: an observation records P2's
    choice at its state or the standing set, one of the hypotheses' sets there, so the bound
    from the world alone and, tighter, the one given P2's games hold (within 6x). Its interval
    model: there P2 also plays sets no hypothesis chooses and the window records them, so the
    estimate counts every set per observation step (above the nominal bound) and `robust`
    refuses it by default, naming the size."""
    from hg2prism.errors import InputError
    from hg2prism.model import sizeguard

    path = tmp_path / "bayes_delay.toml"
    path.write_text(BAYES_DELAY)
    world = load_world(path)
    games = sizeguard.solved_games(world)
    with progress.quiet():
        states = pipeline.check(world, tmp_path / "out").results.states
    assert states <= sizeguard.estimate_states(world, games) <= 6 * states
    assert sizeguard.estimate_states(world, games) <= sizeguard.estimate_states(world)
    deviating = sizeguard.estimate_states(world, deviations=True)
    assert deviating > sizeguard.estimate_states(world)
    with pytest.raises(InputError) as refused:
        sizeguard.check_robust_size(world)
    assert refused.value.key == "size" and f"{deviating * 17 + 2:,}" in str(refused.value)


def test_the_size_guard_bounds_the_interval_model(tmp_path: Path, capsys) -> None:
    """`robust` refuses a world whose interval model (the hypergame's estimate times 1 + P1's
    actions x P2's actions played) exceeds --max-states, though its hypergame does not, in
    one line and writing nothing; at exactly that estimate it is accepted."""
    from hg2prism.model import sizeguard

    world = load_world(MODELS / "world1.toml")
    hypergame = sizeguard.estimate_states(world)
    interval = sizeguard.check_robust_size(world)
    assert interval > hypergame
    assert sizeguard.check_robust_size(world, interval) == interval
    out = tmp_path / "out"
    status = main(["robust", str(MODELS / "world1.toml"), "--out", str(out),
                   "--max-states", str(interval - 1)])
    lines = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(lines) == 1
    assert ": size: the interval model of robust deception" in lines[0]
    assert f"--max-states {interval}" in lines[0]
    assert not out.exists()


def test_without_the_cross_check(world_dir: Path, tmp_path: Path, capsys) -> None:
    """`robust --no-cross-check`: the same values and strategy as the solve (world1, delta
    0.1), robust.json's storm_check null in every row, and no cross-check line printed."""
    out = tmp_path / "out"
    assert main(["robust", str(MODELS / "world1.toml"), "--deltas", "0.1", "--no-cross-check",
                 "--out", str(out)]) == 0
    assert "cross-checking" not in capsys.readouterr().err
    result = json.loads((out / "robust.json").read_text())
    rows, _ = solved("world1", str(world_dir))
    (row,) = [r for r in rows if r.delta == 0.1]
    assert result["storm_check_eps"] is None
    assert [r["storm_check"] for r in result["rows"]] == [None]
    assert result["rows"][0]["robust_value"] == row.robust_value
    assert (out / "robust_0.1" / "strategy.json").read_bytes() == row.records_json


def test_robust_strategy_guarantees_the_robust_value(case) -> None:
    """The exported records' worst case, with P1's moves fixed and the reference's adversary
    minimising, is R_delta."""
    name, folder = case
    rows, reference = solved(name, folder)
    for row in rows:
        records = json.loads(row.records_json)
        assert reference.worst_case(records, row.delta) == pytest.approx(row.robust_value, abs=TOL)


def test_robust_records_give_each_moves_worst_case(case) -> None:
    """`values` of a robust record: each move's worst case under the budget; the move played is
    a best one, and at the initial state its worst case is R_delta."""
    name, folder = case
    rows, _ = solved(name, folder)
    analysis = checked(name, folder).analysis
    ts, task = analysis.ts, analysis.task
    start = ts.describe_state(ts.start_state)
    start.update(q=int(task.delta[task.initial, ts.state_label()[ts.start_state]]),
                 hypothesis=analysis.inference.initial_hypothesis, window=[])
    for row in rows:
        records = json.loads(row.records_json)
        for record in records:
            values = [v for v in record["values"].values() if v is not None]
            assert record["values"][record["action"]] >= max(values) - 1e-8
        initial = [r for r in records if {k: r[k] for k in start} == start]
        assert len(initial) == 1 and initial[0] is records[0] and records[0]["initial"] is True
        assert initial[0]["values"][initial[0]["action"]] == pytest.approx(row.robust_value,
                                                                            abs=1e-9)


def test_at_delta_zero_the_robust_strategy_is_the_deceptive_one(world_dir: Path) -> None:
    rows, _ = solved("world2", str(world_dir))
    result = checked("world2", str(world_dir))
    robust_records = json.loads(rows[0].records_json)
    assert [{k: v for k, v in r.items() if k != "values"} for r in robust_records] == \
        [{k: v for k, v in r.items() if k != "values"} for r in result.records]
    # each move's worst case at delta = 0 (numpy, on the interval model) is its value in
    # strategy.json (Storm's values on the hypergame)
    for ours, theirs in zip(robust_records, result.records):
        for move, value in theirs["values"].items():
            assert (ours["values"][move] is None) == (value is None)
            if value is not None:
                assert ours["values"][move] == pytest.approx(value, abs=1e-9)
    assert rows[0].states == result.results.states
    assert rows[0].nominal_worst_case == pytest.approx(result.results.deceptive_value, abs=1e-9)


def test_a_bayesian_observer_records_the_set_played(world_dir: Path, capsys) -> None:
    """With the Bayesian observer ("map") P2's window records the trap set she played
    (docs/semantics.md §13): R_delta against the reference's robust value iteration on
    world3_bayes, whose states keep that set; "sample" is refused in one line."""
    import reference_bayes

    path = MODELS / "world3_bayes.toml"
    world = load_world(path)
    with progress.quiet():
        result = pipeline.check(world, world_dir / "bayes_check")
    # one positive budget (each costs both solvers about 2.5 s here; the others' tests sweep)
    rows = [row for row, _ in robust.solve_budgets(world, result, (0.0, 0.3),
                                                   world_dir / "bayes_robust", storm_check=False)]
    reference = RobustHypergame(path, reference_bayes.BayesWorld(path))
    assert rows[0].robust_value == pytest.approx(result.results.deceptive_value, abs=TOL)
    expected = reference.robust_values([0.3])
    assert expected[0] < rows[0].robust_value - 0.05      # deviations cost P1 something here
    for row, value in zip(rows[1:], expected):
        assert row.robust_value == pytest.approx(value, abs=TOL)
        assert row.residual <= 1e-10
    sample = world_dir / "bayes_sample.toml"
    sample.write_text(path.read_text().replace('decision = "map"', 'decision = "sample"'))
    assert main(["robust", str(sample), "--out", str(world_dir / "bayes_sample")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "inference.decision" in err[0]
    assert not (world_dir / "bayes_sample").exists()


def _exported_model(name: str, folder: Path, delta: float) -> Path:
    """robust_<delta>/robust.prism as `robust` wrote it (its constant eps undefined)."""
    return folder / f"{name}_robust" / f"robust_{delta}" / "robust.prism"


@pytest.mark.parametrize("name", ["world2", "fam01_d1_l1_w1_x3", "fam09_d0_l2_w1_x3"])
def test_storm_robust_mode_agrees_on_the_eps_model(name: str, world_dir: Path) -> None:
    """Storm's robust mode and our solver on the same model (every deviation at least eps), and
    that model's value is R_delta up to what eps changes (measured here, at most 1e-6)."""
    from hg2prism.engines import storm
    from hg2prism.strategy.robust import IntervalGame, solve_robust

    rows, _ = solved(name, str(world_dir))
    path = _exported_model(name, world_dir, 0.1)
    model, _ = storm.build_interval_model(path, CHECK_CONSTANTS)
    moves = storm.read_structure(model)
    game = IntervalGame.of(moves, moves.labels["goal"], moves.labels["fail"], model.initial_states[0])
    ours = solve_robust(game).value(game.initial)
    assert storm.check_robust(path, 'Pmax=? [F "goal"]', CHECK_CONSTANTS) == \
        pytest.approx(ours, abs=TOL)
    exact = next(row.robust_value for row in rows if row.delta == 0.1)
    assert exact - 1e-9 <= ours <= exact + TOL


def _prism() -> str | None:
    return os.environ.get("PRISM") or shutil.which("prism") or (
        "/opt/prism-games/bin/prism" if Path("/opt/prism-games/bin/prism").exists() else None)


@pytest.mark.skipif(_prism() is None, reason="PRISM not installed (set PRISM or PATH)")
def test_prism_reads_the_interval_model_and_gives_the_value(world_dir: Path) -> None:
    """The command robust.prism's header gives checks it with PRISM (it did not: eps was
    defined as 0 in the file, which PRISM cannot check nor redefine); with eps=0 PRISM builds
    the model but refuses to check it."""
    name = "fam09_d0_l2_w1_x3"
    rows, _ = solved(name, str(world_dir))
    model = _exported_model(name, world_dir, 0.1)
    header = next(line for line in model.read_text().splitlines() if "-const" in line)
    constants = header.split("-const", 1)[1].split()[0]
    assert constants == CHECK_CONSTANTS
    for given, expect_value in ((EXACT_CONSTANTS, False), (constants, True)):
        run = subprocess.run([_prism(), str(model), str(model.with_suffix(".props")), "-const",
                              given, "-epsilon", "1e-12"], capture_output=True, text=True,
                             timeout=300)
        output = run.stdout + run.stderr
        assert "Type:        IMDP" in output, output[-2000:]
        if not expect_value:
            # PRISM builds the exact model but checks interval models only with positive
            # lower bounds (docs/semantics.md §13)
            assert "lower bound of 0" in output, output[-2000:]
            continue
        line = next(line for line in output.splitlines() if line.startswith("Result:"))
        value = float(line.split()[1])
        exact = next(row.robust_value for row in rows if row.delta == 0.1)
        assert value == pytest.approx(exact, abs=TOL)


# -- re-planning (docs/semantics.md §14) ------------------------------------------------------

def _replanning_runs(world_dir: Path, fallback, episodes: int = 300, seed: int = 3):
    result = checked("world2", str(world_dir))
    a = result.analysis
    deceptive = Strategy.from_records(result.records, a.ts, fallback=leader_fallback(a))
    policy = deviating_policy(a.ts, a.world.detection.deviate_after)
    settings = a.world.detection

    def play(plan_fallback):
        plan = Replanning(plan_fallback, settings.alpha, settings.epsilon)
        return simulate_deceptive(a, deceptive, episodes, 100, seed, p2_policy=policy,
                                  progress=False, replanning=plan, episode_streams=True)

    return play(deceptive), play(fallback(a, result))


def test_replanning_to_an_identical_strategy_changes_nothing(world_dir: Path) -> None:
    """The robust strategy at delta 0 is the deceptive strategy: switching to it after a
    detection plays every episode exactly as without re-planning."""
    def robust_zero(a, result):
        records = json.loads(robust.robust_strategy_for(a.world, result, 0.0,
                                                        world_dir / "fallback_zero"))
        return Strategy.from_records(records, a.ts, fallback=leader_fallback(a))

    without, with_ = _replanning_runs(world_dir, robust_zero)
    assert without.replanned > 0
    assert with_.replanned == without.replanned
    assert (with_.outcomes == without.outcomes).all() and (with_.lengths == without.lengths).all()
    assert with_.rate == without.rate


def test_replanning_is_seeded_and_paired(world_dir: Path) -> None:
    """Same seed, same numbers; episodes in which the detector never fires are played
    identically with and without re-planning, and the detector fires in the same episodes."""
    without, with_ = _replanning_runs(world_dir, lambda a, result: LeaderStrategy(a))
    again_without, again_with = _replanning_runs(world_dir, lambda a, result: LeaderStrategy(a))
    assert (again_with.outcomes == with_.outcomes).all() and again_with.rate == with_.rate
    assert (again_without.outcomes == without.outcomes).all()
    assert with_.replanned == without.replanned > 0
    # an episode can only differ where P1 switched (each episode has its own random numbers)
    differs = (with_.outcomes != without.outcomes) | (with_.lengths != without.lengths)
    assert 0 < differs.sum() <= without.replanned
    # detection.json's paired comparison, by counting episode by episode and the binomial
    # distribution summed by hand (the exact McNemar test: a statistics review found the two
    # runs reported as two overlapping intervals only)
    from math import comb

    from hg2prism.experiments.detect import paired_change

    paired = paired_change(without, with_)
    pairs = list(zip(without.outcomes.tolist(), with_.outcomes.tolist()))
    b = sum(1 for w, x in pairs if x == GOAL != w)
    c = sum(1 for w, x in pairs if w == GOAL != x)
    assert (paired["only_with"], paired["only_without"]) == (b, c) and b + c > 0
    assert paired["change"] == pytest.approx(with_.rate - without.rate, abs=1e-15)
    tail = sum(comb(b + c, i) for i in range(min(b, c) + 1)) / 2 ** (b + c)
    assert paired["mcnemar_p"] == pytest.approx(min(1.0, 2 * tail), rel=1e-9)
    assert paired_change(without, without) == {"only_with": 0, "only_without": 0,
                                               "change": 0.0, "mcnemar_p": 1.0}


def test_robust_command_writes_its_outputs(world_dir: Path, tmp_path: Path) -> None:
    name = "fam00_d0_l1_w1_x2"
    world = load_world(world_path(name, str(world_dir)))
    result = robust.robust(world, ["0", "0.1"], tmp_path, show_progress=False,
                           check_result=checked(name, str(world_dir)))
    assert [row["delta"] for row in result["rows"]] == [0.0, 0.1]
    assert set(result["rows"][0]) >= {"delta", "robust_value", "nominal_worst_case", "states",
                                      "seconds"}
    written = json.loads((tmp_path / "robust.json").read_text())
    assert written["rows"][1]["robust_value"] == result["rows"][1]["robust_value"]
    check = written["rows"][1]["storm_check"]
    assert abs(check["storm_minus_numpy"]) <= TOL
    for item in ("robust.csv", "robust.png", "robust.svg", "robust_0/strategy.json",
                 "robust_0.1/strategy.json", "robust_0.1/robust.prism", "robust_0.1/robust.props"):
        assert (tmp_path / item).is_file(), item
    assert f"\n// digest       {world.digest()}\n" in (
        tmp_path / "robust_0.1" / "robust.prism").read_text()         # the world it is of
    lines = (tmp_path / "robust.csv").read_text().splitlines()
    assert lines[0].startswith("delta,robust_value,nominal_worst_case") and len(lines) == 3


@pytest.mark.parametrize("argv, key", [
    (["robust", "WORLD", "--deltas", "1"], "--deltas"),
    (["robust", "WORLD", "--deltas", "0.1", "0.1"], "--deltas"),
    (["robust", "WORLD", "--deltas", "x"], "--deltas"),
    # below what the cross-check's model can give P2's other sets (1e-9 each): was a ValueError
    (["robust", "WORLD", "--deltas", "0", "1e-30"], "--deltas"),
    (["detect", "WORLD", "--fallback-delta", "0.1"], "--fallback-delta"),
    (["detect", "WORLD", "--fallback", "robust", "--fallback-delta", "-0.5"], "--fallback-delta"),
    (["detect", "WORLD", "--fallback", "leader", "--fallback-delta", "0.1"], "--fallback-delta"),
])
def test_bad_options_are_one_line_and_write_nothing(argv, key, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    argv = [str(MODELS / "world2.toml") if a == "WORLD" else a for a in argv] + ["--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0] and "Traceback" not in err[0]
    assert not out.exists()


def test_the_adversary_places_exactly_the_mass_left_on_a_large_model() -> None:
    """worst_case on 200,000 choices shaped like the robust model's (a [0.9, 1] branch and seven
    [0, 0.1] ones): every branch gets the room left by the cheaper branches of its own choice,
    computed here choice by choice, and every choice's probabilities sum to 1. (A running sum
    of the room over all choices, which worst_case once used, is 1e-11 off after 1e5 choices:
    rows summed to more than 1 and a bench world's robust values exceeded 1.)"""
    import numpy as np
    from hg2prism.strategy.robust import IntervalGame, worst_case

    rng = np.random.default_rng(7)
    n, width = 200_000, 8
    goal = np.zeros(n + 1, dtype=bool)
    goal[n] = True
    target = rng.integers(0, n + 1, size=(n, width))
    lower = np.zeros((n, width))
    lower[:, 0] = 0.9
    upper = np.full((n, width), 0.1)
    upper[:, 0] = 1.0
    game = IntervalGame.build(choice_start=np.r_[np.arange(n + 1), n],
                              row_start=np.arange(0, n * width + 1, width),
                              target=target.reshape(-1), lower=lower.reshape(-1),
                              upper=upper.reshape(-1), goal=goal, stop=goal, initial=0)
    values = np.where(goal, 1.0, rng.random(n + 1).round(2))     # rounded: ties in branch order
    _, probability = worst_case(game, values)
    probability = probability.reshape(n, width)
    assert np.abs(probability.sum(axis=1) - 1.0).max() <= 4 * np.finfo(float).eps
    for i in rng.choice(n, size=300, replace=False).tolist() + [n - 1]:
        expected, left = lower[i].copy(), 1.0 - lower[i].sum()
        for b in sorted(range(width), key=lambda b: (values[target[i, b]], b)):
            expected[b] += min(max(left, 0.0), upper[i, b] - lower[i, b])
            left -= upper[i, b] - lower[i, b]
        assert np.abs(probability[i] - expected).max() <= 2 * np.finfo(float).eps, i


def _positive_by_levels(game, fixed=None):
    """positive_states by its definition, every choice tested every round (the least fixed
    point, the first progress choice of each state at the round it joins)."""
    import numpy as np

    positive = game.goal.copy()
    progress = np.full(game.n_states, -1)
    for _ in range(game.n_states + 1):
        joining = {}
        for s in range(game.n_states):
            if positive[s] or game.stop[s]:
                continue
            choices = range(game.choice_start[s], game.choice_start[s + 1])
            for c in choices if fixed is None else [fixed[s]]:
                branches = range(game.row_start[c], game.row_start[c + 1])
                forced = any(positive[game.target[b]] and game.lower[b] > 0 for b in branches)
                outside = sum(game.upper[b] for b in branches if not positive[game.target[b]])
                if forced or outside < 1.0 - 1e-12:
                    joining[s] = c
                    break
        if not joining:
            break
        for s, c in joining.items():
            positive[s], progress[s] = True, c
    return positive, progress


@pytest.mark.parametrize("seed", range(6))
def test_positive_states_is_the_least_fixed_point(seed: int) -> None:
    """positive_states (breadth-first over the choices the last round could change) against
    its definition on random interval games, with P1's choices free and fixed."""
    import numpy as np
    from hg2prism.strategy.robust import IntervalGame, positive_states

    rng = np.random.default_rng(seed)
    n = 60
    counts = rng.integers(1, 4, size=n)
    counts[:3] = 0                                   # absorbing: the goal and two failures
    widths = rng.integers(1, 4, size=counts.sum())
    target = rng.integers(0, n, size=widths.sum())
    lower = np.where(rng.random(widths.sum()) < 0.5, 0.0, rng.random(widths.sum()) / 4)
    upper = np.minimum(lower + np.where(rng.random(widths.sum()) < 0.3, 0.0, 0.6), 1.0)
    goal = np.zeros(n, dtype=bool)
    goal[0] = True
    stop = goal.copy()
    stop[1:3] = True
    game = IntervalGame.build(choice_start=np.r_[0, np.cumsum(counts)],
                              row_start=np.r_[0, np.cumsum(widths)], target=target,
                              lower=lower, upper=upper, goal=goal, stop=stop, initial=5)
    fixed = game.choice_start[:-1] + rng.integers(0, 3, size=n) % np.maximum(counts, 1)
    for choice in (None, fixed):
        positive, progress = positive_states(game, choice)
        expected, first = _positive_by_levels(game, choice)
        assert (positive == expected).all() and (progress == first).all()
        assert 0 < positive.sum() < n


DRAWING = '''name = "drawing"
[grid]
map = """
#######
#..##t#
#o.@..#
#B.ttA#
#BtoCE#
#######
"""
[robot]
slip = 0.2
[task]
formula = "!obs U C"
[adversary]
traps = 1
delay = 1
initial_traps = [[4, 2]]
hypotheses = ["F A", "!obs U E", "!E U C", "F E"]
[inference]
kind = "bayes"
window = 2
rationality = 2.0
decision = "sample"
prior = [1, 2, 3, 4]
'''


def test_replanning_predicts_a_drawing_p2_by_her_mixture(tmp_path: Path) -> None:
    """P2 draws her hypothesis (Bayesian "sample") and follows the model: re-planning's
    detector sees what the detection experiment's sees until it fires, so it fires in exactly
    the episodes of the experiment's false alarms (both predict her by the posterior mixture;
    re-planning once compared her draws with the most likely set alone and fired in 1,667 of
    2,000 episodes of this world, against 11 false alarms)."""
    from hg2prism.experiments.detect import detection_batch

    path = tmp_path / "drawing.toml"
    path.write_text(DRAWING)
    with progress.quiet():
        result = pipeline.check(load_world(path), tmp_path / "out")
    a = result.analysis
    assert a.inference.draws
    deceptive = Strategy.from_records(result.records, a.ts, fallback=leader_fallback(a))
    settings = a.world.detection
    plan = Replanning(LeaderStrategy(a), settings.alpha, settings.epsilon)
    summary, batch = detection_batch(a, deceptive, 400, 100, 0, settings.alpha,
                                     settings.epsilon, replanning=plan)
    assert summary.replanned == len(batch.first_rejection) <= 0.05 * 400


def test_budget_names_stay_short() -> None:
    """A budget's folder is robust_<its shortest decimal>, or its scientific form where that
    decimal would be long (1e-300 wrote a 300-digit folder name: "File name too long")."""
    from hg2prism.prism.robust_model import delta_text

    assert [delta_text(d) for d in (0, 0.0, 0.02, 0.1, 0.05, 1e-4)] == \
        ["0", "0", "0.02", "0.1", "0.05", "0.0001"]
    assert delta_text(1e-300) == "1e-300" and delta_text(1.5e-12) == "1.5e-12"


def test_the_constants_a_checker_is_told_leave_the_budget_its_mass() -> None:
    """robust.prism's header gives eps = 1e-9 unless the budget is below 1e-9 for each of P2's
    other actions, where 1e-9 would make a step's lower bounds sum above 1 (PRISM refused the
    header's own command on such a model): then eps = delta / |A2|."""
    from types import SimpleNamespace

    from hg2prism.prism.robust_model import CHECK_EPS, checkable_constants

    ts = SimpleNamespace(n_sets=4)
    assert checkable_constants(0.0, ts) == CHECK_CONSTANTS == f"eps={CHECK_EPS!r}"
    assert checkable_constants(3 * CHECK_EPS, ts) == CHECK_CONSTANTS      # exactly enough
    for delta in (1e-10, math.nextafter(3 * CHECK_EPS, 0.0)):
        eps = float(checkable_constants(delta, ts).split("=")[1])
        assert eps == delta / 4 and 3 * eps < delta


def test_solving_with_the_cross_check_refuses_a_budget_it_cannot_check(world_dir: Path) -> None:
    """solve_budgets with the cross-check refuses a budget below eps * (|A2| - 1) before any
    work (it built an interval model whose lower bounds sum above 1 and failed in the solver)."""
    result = checked("world2", str(world_dir))
    out = world_dir / "tiny_budget"
    with pytest.raises(InputError) as caught:
        robust.solve_budgets(result.analysis.world, result, [1e-10], out)
    assert caught.value.key == "--deltas" and "least budget" in caught.value.reason
    assert not out.exists()
