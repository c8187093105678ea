"""The Bayesian observer (docs/semantics.md §12) against the specification: Storm's transitions
against the Python observer on every state, the value against an independent explicit solver
(tests/reference_bayes.py), a prior no evidence can overturn against V_static, and the world
file's errors."""

from __future__ import annotations

import functools
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

import reference_bayes
import worldgen
from hg2prism.model import sizeguard
from hg2prism import pipeline, progress
from hg2prism.prism.decoding import DecodedStates
from hg2prism.errors import InputError
from hg2prism.worldfile import load_world, world_from_toml
from hg2prism.opponent.observer import Memory
from conftest import share

TOL = 1e-6


def bayes_text(text: str, prior: str | None, decision: str, window: int | None = None) -> str:
    """A generated CUSUM world turned Bayesian: no threshold or initial hypothesis, a prior
    ("skew": 1, 2, 3, ... normalised; "concentrated": no window overturns hypothesis 0),
    a decision, and optionally another window."""
    text = re.sub(r"^threshold = .*\n", "", text, flags=re.M)
    text = re.sub(r"^initial_hypothesis = .*\n", "", text, flags=re.M)
    if window is not None:
        text = re.sub(r"^window = .*$", f"window = {window}", text, flags=re.M)
    n = len(re.search(r"^hypotheses = \[(.*)\]$", text, flags=re.M).group(1).split('", "'))
    extra = f'kind = "bayes"\ndecision = "{decision}"\n'
    if prior == "skew":
        extra += "prior = [" + ", ".join(str(k + 1) for k in range(n)) + "]\n"
    elif prior == "concentrated":
        beta = float(re.search(r"^rationality = (.*)$", text, flags=re.M).group(1))
        w = int(re.search(r"^window = (.*)$", text, flags=re.M).group(1))
        # each other hypothesis below exp(-2 beta w - 1) relative to hypothesis 0
        other = math.exp(-2 * beta * w - 1) / 2
        extra += "prior = [1.0" + f", {other!r}" * (n - 1) + "]\n"
    return text.replace("[inference]\n", "[inference]\n" + extra)


FAMILY = dict(worldgen.world_family())
# (name, family world, prior, decision, window): windows 1-3, uniform / skewed priors, both
# decisions; the small worlds of the family keep the whole file well under a minute.
CASES = [
    (f"b{i:02d}_{base}_{prior or 'uniform'}_{decision}", base, prior, decision, window)
    for i, (base, prior, decision, window) in enumerate([
        ("fam00_d0_l1_w1_x2", None, "map", 1), ("fam00_d0_l1_w1_x2", "skew", "sample", 1),
        ("fam01_d1_l1_w1_x3", None, "sample", 1), ("fam01_d1_l1_w1_x3", "skew", "map", 1),
        ("fam02_d2_l1_w1_x4", "skew", "map", 1), ("fam02_d2_l1_w1_x4", None, "sample", 1),
        ("fam03_d0_l1_w2_x1", None, "map", 1), ("fam04_d1_l1_w2_x2", "skew", "sample", 1),
        ("fam04_d1_l1_w2_x2", None, "map", 1), ("fam06_d0_l1_w3_x2", None, "map", 1),
        ("fam11_d2_l2_w1_x1", None, "map", 3), ("fam09_d0_l2_w1_x3", None, "sample", 1),
        ("fam09_d0_l2_w1_x3", "skew", "map", 2), ("fam10_d1_l2_w1_x2", None, "map", 1),
        ("fam10_d1_l2_w1_x2", "skew", "sample", 1), ("fam11_d2_l2_w1_x1", None, "sample", 1),
        ("fam12_d0_l2_w2_x4", "skew", "map", 2), ("fam18_d0_l1_w1_x3", None, "map", 1),
        ("fam20_d2_l1_w1_x3", "skew", "sample", 1), ("fam19_d1_l1_w1_x2", None, "sample", 1),
        ("fam20_d2_l1_w1_x3", "skew", "map", 1), ("fam21_d0_l1_w2_x4", None, "sample", 2),
        ("fam24_d0_l1_w3_x3", "skew", "map", 3), ("fam27_d0_l2_w1_x2", None, "map", 1),
        ("fam28_d1_l2_w1_x4", "skew", "sample", 1), ("fam28_d1_l2_w1_x4", None, "map", 1),
        ("fam30_d0_l2_w2_x2", "skew", "sample", 2), ("fam36_eq_d0_w2", None, "sample", 2),
        ("fam37_eq_d1_w1", None, "map", 1), ("fam40_tx_d0_l1_w2", "skew", "map", 2),
        ("fam40_tx_d0_l1_w2", None, "sample", 2), ("fam43_tx_d0_l1_w3", "skew", "sample", 1),
    ])]
CASE_NAMES = [c[0] for c in CASES]
CASE_SETTINGS = {c[0]: c[1:] for c in CASES}


@functools.cache
def world_path(name: str, folder: str) -> Path:
    base, prior, decision, window = CASE_SETTINGS[name]
    path = Path(folder) / f"{name}.toml"
    path.write_text(bayes_text(FAMILY[base], prior, decision, window))
    return path


@functools.cache
def reference_world(path: Path) -> reference_bayes.BayesWorld:
    return reference_bayes.BayesWorld(path)


@functools.cache
def run(name: str, folder: str) -> pipeline.CheckResult:
    path = world_path(name, folder)
    with progress.quiet():
        return pipeline.check(load_world(path), Path(folder) / name)


@pytest.fixture(params=share(CASE_NAMES))      # every fourth under `make test`
def case(request: pytest.FixtureRequest, world_dir: Path):
    return request.param, run(request.param, str(world_dir)), world_path(request.param,
                                                                       str(world_dir))


def test_cases_cover_windows_priors_and_decisions() -> None:
    assert len(CASES) >= 30
    assert {c[4] for c in CASES} == {1, 2, 3}
    assert {c[2] for c in CASES} == {None, "skew"}
    assert {c[3] for c in CASES} == {"map", "sample"}


def _memory(decoded: DecodedStates, s: int) -> Memory:
    return Memory(int(decoded.hypothesis[s]),
                  tuple(tuple(int(o) for o in entry) for entry in decoded.window[s] if entry[0] >= 0))


def test_storm_transitions_are_those_of_the_python_observer(case) -> None:
    """On every Storm state that is neither goal nor failure and every move: the distribution
    over (successor TS state, P2's memory) Storm built equals the one the Python observer and
    the TS tables give: sum over x of p(x | W) P(v' | v, a1, pi2_x(v)), with the memory
    W + (v, a1, pi2_x(v)), last w kept."""
    _, result, _ = case
    decoded, observer, ts = result.decoded, result.analysis.inference, result.analysis.ts
    moves = result.engine.explicit(result.checked.model).transitions
    compared = 0
    for choice in range(len(moves.source)):
        s = int(moves.source[choice])
        if decoded.goal[s] or decoded.fail[s] or moves.action[choice] < 0:
            continue
        a1 = int(moves.action[choice])
        memory = _memory(decoded, s)
        assert observer.hypothesis(memory) == observer.map_hypothesis(memory.window)
        v = ts.state(int(decoded.place[s]), int(decoded.traps[s]), int(decoded.countdown[s]))
        expected: dict[tuple, float] = {}
        for x, px in observer.hypothesis_distribution(memory):
            a2 = int(observer.trap_choice[x][v])
            after = observer.update(memory, (v, a1, a2))
            for k in range(ts.succ.shape[-1]):
                p = float(ts.prob[v, a1, a2, k])
                if p > 0:
                    key = (int(ts.succ[v, a1, a2, k]), after)
                    expected[key] = expected.get(key, 0.0) + px * p
        built: dict[tuple, float] = {}
        for e in range(moves.row_start[choice], moves.row_start[choice + 1]):
            t = int(moves.target[e])
            if moves.probability[e] <= 0:
                continue
            cell = int(decoded.place[t])
            w = ts.trapped if cell == ts.n_places else ts.state(cell, int(decoded.traps[t]),
                                                                int(decoded.countdown[t]))
            key = (w, _memory(decoded, t))
            built[key] = built.get(key, 0.0) + float(moves.probability[e])
        expected = {k: p for k, p in expected.items() if p > 1e-300}
        assert built.keys() == expected.keys()
        for key, p in expected.items():
            assert built[key] == pytest.approx(p, rel=1e-9, abs=1e-12)
        compared += 1
    assert compared > 0


def test_value_and_size_match_the_reference(case) -> None:
    _, result, path = case
    ref = reference_world(path).solve()
    assert result.results.deceptive_value == pytest.approx(ref.value, abs=TOL)
    assert (result.results.states, result.results.transitions) == (ref.states, ref.transitions)
    # the size guard's estimates bound the Bayesian hypergame (model/sizeguard.py), the one
    # given P2's games no more loosely than the one from the world alone
    world = result.analysis.world
    solved = sizeguard.estimate_states(world, result.analysis.games)
    assert ref.states <= solved <= sizeguard.estimate_states(world)
    if result.analysis.world.decision == "map":
        # P1 moves knowing a2 only when P2 is deterministic; a drawn trap set can beat V_lead
        assert result.results.v_lead <= result.results.deceptive_value + TOL


def test_exported_strategy_is_optimal(case) -> None:
    _, result, path = case
    value = result.results.deceptive_value
    written = json.loads((result.out / "strategy.json").read_text())
    assert written == list(result.records)
    assert reference_world(path).strategy_value(written) == pytest.approx(value, abs=TOL)


@pytest.mark.parametrize("base, window", [("fam00_d0_l1_w1_x2", 2), ("fam04_d1_l1_w2_x2", 2),
                                          ("fam09_d0_l2_w1_x3", 1), ("fam40_tx_d0_l1_w2", 3)])
def test_a_prior_no_evidence_overturns_gives_v_static(base: str, window: int,
                                                      world_dir: Path) -> None:
    """Each other hypothesis below exp(-2 beta w - 1) relative to hypothesis 0: every
    log-likelihood ratio lies within [-beta, beta] (Q values lie in [0, 1]), so no window of w
    observations overturns it, and the MAP observer is P2 playing pi2_x0 forever."""
    path = world_dir / f"static_{base}_{window}.toml"
    path.write_text(bayes_text(FAMILY[base], "concentrated", "map", window))
    with progress.quiet():
        result = pipeline.check(load_world(path), world_dir / path.stem)
    v_static = reference_bayes.solve(path, static=True).value
    assert result.results.deceptive_value == pytest.approx(v_static, abs=TOL)
    assert set(result.decoded.hypothesis.tolist()) == {0}


WORLD = """
[grid]
map = \"\"\"
#######
#A.t.B#
#.t@..#
#######
\"\"\"
[robot]
slip = 0.1
[task]
formula = "F A"
[adversary]
traps = 1
hypotheses = ["F A", "F B"]
[inference]
kind = "bayes"
window = 2
rationality = 5.0
"""


@pytest.mark.parametrize("edit, key, reason", [
    (("window = 2", "window = 2\nprior = [1.0]"), "inference.prior", "one per hypothesis"),
    (("window = 2", "window = 2\nprior = [1.0, 0.0]"), "inference.prior[1]", "must be > 0"),
    (("window = 2", "window = 2\nprior = [1.0, -2]"), "inference.prior[1]", "must be > 0"),
    (("window = 2", 'window = 2\nprior = [1.0, "a"]'), "inference.prior[1]", "must be a number"),
    (("window = 2", 'window = 2\nprior = "uniform"'), "inference.prior", "array"),
    # finite numbers whose sum overflows (a traceback: fsum's OverflowError)
    (("window = 2", "window = 2\nprior = [1e308, 1e308]"), "inference.prior", "too large"),
    (("window = 2", "window = 2\nthreshold = 1.5"), "inference.threshold", "no threshold"),
    (("traps = 1", "traps = 1\ninitial_hypothesis = 0"), "adversary.initial_hypothesis",
     "not allowed"),
    (("window = 2", 'window = 2\ndecision = "mode"'), "inference.decision", "unknown decision"),
    (('kind = "bayes"', 'kind = "kalman"'), "inference.kind", "unknown inference kind"),
    (('kind = "bayes"', 'kind = "cusum"\nthreshold = 1.0\nprior = [1, 1]'), "inference.prior",
     "Bayesian"),
])
def test_world_errors_are_one_clear_line(edit, key, reason) -> None:
    with pytest.raises(InputError) as err:
        world_from_toml(WORLD.replace(*edit), "w.toml")
    message = str(err.value)
    assert "\n" not in message and key in message and reason in message, message


def test_prior_is_normalised_and_sets_the_first_guess() -> None:
    world = world_from_toml(WORLD.replace("window = 2", "window = 2\nprior = [1, 3]"))
    assert world.prior == (0.25, 0.75) and world.initial_hypothesis == 1
    assert world.threshold is None and world.decision == "map"
    tied = world_from_toml(WORLD.replace("window = 2", "window = 2\nprior = [2, 2]"))
    assert tied.initial_hypothesis == 0 and tied.prior == (0.5, 0.5)
    assert world_from_toml(WORLD).prior == (0.5, 0.5)


def test_commands_do_not_grow_with_the_window(world_dir: Path) -> None:
    counts = []
    for window in (1, 3):
        path = world_dir / f"commands_{window}.toml"
        path.write_text(bayes_text(FAMILY["fam09_d0_l2_w1_x3"], None, "sample", window))
        with progress.quiet():
            model = pipeline.emit(load_world(path), world_dir / path.stem)
        counts.append(model.commands)
    # "sample": per action slot one command where the hypotheses' actions agree and one that
    # draws where they differ, and the absorbing one
    assert counts[0] == counts[1] == {"robot": 9, "task": 4, "p2_inference": 4}


@pytest.mark.parametrize("name", ["b11_fam09_d0_l2_w1_x3_uniform_sample",
                                  "b02_fam01_d1_l1_w1_x3_uniform_sample",
                                  "b05_fam02_d2_l1_w1_x4_uniform_sample",
                                  "b30_fam40_tx_d0_l1_w2_uniform_sample"])
def test_where_the_hypotheses_agree_the_draw_is_not_modelled(name: str, world_dir: Path) -> None:
    """"sample": where every hypothesis plays the same action the draw changes nothing, and
    Storm's distribution is the move's alone, P(v' | v, a1, a2) as Storm reads the arena's
    numbers: the same bits at every window (sum_x p(x | W) P(v' | v, a1, a2), computed,
    would vary with W in its last digits). Where the actions differ, P2 draws."""
    result = run(name, str(world_dir))
    decoded, observer, ts = result.decoded, result.analysis.inference, result.analysis.ts
    moves = result.engine.explicit(result.checked.model).transitions
    rows: dict[tuple[int, int], set] = {}
    met: dict[tuple[int, int], int] = {}
    drawn = 0
    for choice in range(len(moves.source)):
        s = int(moves.source[choice])
        if decoded.goal[s] or decoded.fail[s] or moves.action[choice] < 0:
            continue
        a1 = int(moves.action[choice])
        v = ts.state(int(decoded.place[s]), int(decoded.traps[s]), int(decoded.countdown[s]))
        sets = {int(observer.trap_choice[x][v]) for x in range(observer.n_hypotheses)}
        if len(sets) > 1:
            drawn += 1
            continue
        a2 = sets.pop()
        expected: dict[int, float] = {}
        for k in range(ts.succ.shape[-1]):
            if ts.prob[v, a1, a2, k] > 0:
                w = int(ts.succ[v, a1, a2, k])
                expected[w] = expected.get(w, 0.0) + float(ts.prob[v, a1, a2, k])
        built = {}
        for e in range(moves.row_start[choice], moves.row_start[choice + 1]):
            t = int(moves.target[e])
            cell = int(decoded.place[t])
            w = ts.trapped if cell == ts.n_places else ts.state(cell, int(decoded.traps[t]),
                                                                int(decoded.countdown[t]))
            built[w] = float(moves.probability[e])
        assert built.keys() == expected.keys()
        assert all(built[w] == pytest.approx(p, rel=1e-15) for w, p in expected.items())
        rows.setdefault((v, a1), set()).add(tuple(sorted(built.items())))
        met[v, a1] = met.get((v, a1), 0) + 1
    assert drawn > 0 and max(met.values()) > 1           # a move met at several windows
    assert all(len(found) == 1 for found in rows.values())


@pytest.mark.parametrize("name", ["b02_fam01_d1_l1_w1_x3_uniform_sample",
                                  "b07_fam04_d1_l1_w2_x2_skew_sample",
                                  "b08_fam04_d1_l1_w2_x2_uniform_map"])
def test_prism_accepts_the_model_and_gives_storms_value(name: str, world_dir: Path) -> None:
    """PRISM (default engine, -epsilon 1e-12) reads the Bayesian models, pow() included, and
    finds Storm's value; skipped without PRISM."""
    import test_prism

    if test_prism.PRISM is None:
        pytest.skip("PRISM is not installed (set PRISM=/path/to/prism or put prism on PATH)")
    result = run(name, str(world_dir))
    value = test_prism.prism_value(result.out / "hypergame.prism")
    assert value == pytest.approx(result.results.deceptive_value, abs=TOL)


@pytest.mark.parametrize("name", ["b01_fam00_d0_l1_w1_x2_skew_sample",
                                  "b08_fam04_d1_l1_w2_x2_uniform_map"])
def test_simulation_agrees_with_the_exact_value_within_the_horizon(name: str,
                                                                  world_dir: Path) -> None:
    """P2 draws her hypothesis in the simulation as the model mixes: the simulated rate's 99.9 %
    Wilson interval holds Storm's P(F<=horizon goal) of the induced DTMC; the mismatch detector
    runs on the posterior mixture."""
    from hg2prism.analyses.simulation import simulate_deceptive
    from hg2prism.experiments.detect import detection_batch
    from hg2prism.strategy.records import Strategy

    result = run(name, str(world_dir))
    strategy = Strategy.from_records(result.records, result.analysis.ts)
    horizon, episodes = 30, 3000
    summary = simulate_deceptive(result.analysis, strategy, episodes, horizon, 7, progress=False)
    exact = result.engine.induced_within(result.checked, result.strategy.choice, horizon)
    low, high = summary.interval(0.999)
    assert low <= exact <= high
    assert result.engine.induced_probability(result.checked, result.strategy.choice) == pytest.approx(
        result.results.deceptive_value, abs=TOL)
    _, batch = detection_batch(result.analysis, strategy, 200, horizon, 7, 0.05, 0.01)
    # P2 behaves as modelled: the test may raise a rare false alarm, never in most episodes
    assert len(batch.first_rejection) < 20


def test_sweeps_over_prior_and_observer(world_dir: Path) -> None:
    from hg2prism.experiments import sweep

    path = world_dir / "sweep_bayes.toml"
    path.write_text(WORLD)
    world = load_world(path)
    with progress.quiet():
        rows = sweep.sweep(world, "prior", ["1,3", "3,1"], world_dir / "sweep_prior",
                           show_progress=False)
    assert [r["prior"] for r in rows] == [[0.25, 0.75], [0.75, 0.25]]
    assert (world_dir / "sweep_prior" / "prior_0.25,0.75" / "strategy.json").exists()
    for row, prior in zip(rows, ([1, 3], [3, 1])):
        single = world_dir / f"sweep_single_{prior[0]}.toml"
        single.write_text(WORLD.replace("window = 2", f"window = 2\nprior = {prior}"))
        assert row["deceptive_value"] == pytest.approx(reference_bayes.solve(single).value, abs=TOL)
    cusum = world_dir / "sweep_cusum.toml"
    cusum.write_text(WORLD.replace('kind = "bayes"', "threshold = 1.0"))
    switched = sweep.sweep_world(load_world(cusum), "inference", "bayes")
    assert (switched.inference, switched.prior, switched.decision, switched.threshold) == (
        "bayes", (0.5, 0.5), "map", None)
    for parameter, values, reason in [("prior", ["1,x"], "comma-separated"),
                                      ("prior", ["1,0"], "comma-separated"),
                                      ("inference", ["kalman"], "cusum")]:
        with pytest.raises(InputError, match=reason):
            sweep.parse_sweep_values(parameter, values)
    with pytest.raises(InputError, match="kind"):
        sweep.sweep_world(load_world(cusum), "prior", "1,1")
    with pytest.raises(InputError, match="one per hypothesis"):
        sweep.sweep_world(world, "prior", "1,1,1")


def test_v_naive_is_the_naive_strategy_on_storms_model_and_at_most_the_deceptive_value(case) -> None:
    """docs/semantics.md §11 with the Bayesian observer: V_naive, computed in Python on the chain
    the naive strategy induces (P2 drawing her hypothesis under "sample"), equals the value Storm
    gives the same strategy fixed on the PRISM model's states, and is at most the deceptive
    value (V_static is not bounded by it: a P2 who never revises can be weaker or stronger)."""
    from hg2prism.analyses.deception_value import deception_values
    from hg2prism.strategy.deceptive import storm_choices

    _, result, _ = case
    analysis, decoded = result.analysis, result.decoded
    ts, deceptive = analysis.ts, result.results.deceptive_value
    worth = deception_values(analysis, deceptive)
    assert worth.v_naive <= deceptive + 1e-9
    moves = result.engine.explicit(result.checked.model).transitions
    representative = result.strategy.representative
    action = np.zeros(len(representative), dtype=np.int64)
    for c, s in enumerate(representative.tolist()):
        if decoded.goal[s] or decoded.fail[s] or decoded.place[s] >= ts.n_places:
            continue
        v = ts.state(int(decoded.place[s]), int(decoded.traps[s]), int(decoded.countdown[s]))
        action[c] = worth.naive.action(v, int(decoded.q[s]), _memory(decoded, s))
    fixed = storm_choices(decoded, moves, representative, action)
    assert result.engine.induced_probability(result.checked, fixed.choice) == pytest.approx(worth.v_naive,
                                                                              abs=TOL)


def _first_within_reference(scores: list[float], tolerance: float) -> int:
    """The first score within `tolerance` of the largest of all (the rule the "map" model had
    written out before, lpn_x >= lpnmax - tolerance)."""
    top = max(scores)
    return next(k for k, score in enumerate(scores) if score >= top - tolerance)


def test_first_within_is_the_first_score_near_the_maximum() -> None:
    """observers.first_within compares each score with the largest of the later ones only: the
    same index as against the largest of all, in floating point, on scores with exact ties,
    ties within the tolerance and values at its edge (evaluated as PRISM reads the text)."""
    from hg2prism.prism.observers import first_within

    tolerance = 1e-9
    rng = np.random.default_rng(27)
    base = [-4.802618865011778, -1.3862943611198906, -2.4948141022067594]
    for n in range(1, 6):
        names = [f"lpn_x{x}_a0" for x in range(n)]
        text = first_within(names, "0.000000001")
        assert text.count("lpn_x") == (n + 2) * (n - 1) // 2
        for _ in range(400):
            pick = rng.choice(len(base), size=n)
            scores = [base[p] + rng.choice([0.0, 1e-15, 5e-10, 1e-9, 2e-9, -1e-9, 3e-16, 1.0])
                      for p in pick]
            values = dict(zip(names, map(repr, scores)))
            branches = re.sub(r"lpn_x\d+_a0", lambda m: values[m.group(0)], text).split(" : ")
            got = next((int(b.split(" ? ")[1]) for b in branches[:-1]
                        if eval(b.split(" ? ")[0])), int(branches[-1]))  # noqa: S307
            assert got == _first_within_reference(scores, tolerance), (scores, text)
