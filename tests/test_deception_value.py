"""What the deception is worth (docs/semantics.md §11).

* V_static and V_naive equal an independent computation (tests/reference_deception.py, written
  from the semantics alone) within 1e-6, on world1, world3 and 35 generated worlds;
* invariants: V_naive <= deceptive value (the naive strategy is one of P1's strategies in the
  hypergame), V_lead <= V_static (P2's fixed policy is one of her leader-game strategies), and
  V_static = deceptive value when P2 has a single hypothesis (she can never revise it);
* the naive strategy's chain: its value is what the reference gets from the package's own moves
  (the chain is built right), and the simulated naive and static rates agree with their exact
  within-horizon probabilities (99.9 % Wilson interval);
* the simulated share of episodes in which P2 changes her hypothesis agrees with the exact
  probability of a change within the horizon, computed by the reference on the chain the
  exported strategy induces (99.9 % Wilson interval);
* world3 has the properties it was designed for (docs/results.md, "What deception is worth").
"""

from __future__ import annotations


import numpy as np
import pytest

import reference_deception
import worldgen
from conftest import MODELS
import gridview
from hg2prism import pipeline, progress
from hg2prism.analyses import deception_value, simulation
from hg2prism.worldfile import load_world
from hg2prism.strategy.records import Strategy
from conftest import share

FAMILY = dict(worldgen.world_family())
# The family less its largest worlds (kept for the core tests), and a few more small ones: 33
# worlds with delays 0-2, one and two traps, windows 1-3, one to four hypotheses, slip 0 and > 0.
SLOW = ("fam02", "fam07", "fam08", "fam14", "fam16", "fam17", "fam26", "fam32", "fam33", "fam34",
        "fam35", "fam41", "fam42", "fam44", "fam45")
FAMILY.update({f"small_{seed}": worldgen.make_world(seed, size=(3, 3), name=f"small_{seed}")
               for seed in (501, 502, 503, 504)})
NAMES = [name for name in FAMILY if not name.startswith(SLOW)]
SINGLE = {"fam03_d0_l1_w2_x1", "fam11_d2_l2_w1_x1", "fam36_eq_d0_w2", "fam37_eq_d1_w1",
          "fam38_eq_d2_w2", "fam39_eq_d0_w3"}


@pytest.fixture(scope="session")
def solved(tmp_path_factory: pytest.TempPathFactory):
    """name -> (world file, pipeline.CheckResult, DeceptionValues), solved once."""
    folder = tmp_path_factory.mktemp("deception")
    cache: dict[str, tuple] = {}

    def get(name: str):
        if name not in cache:
            if name in ("world1", "world3"):
                path = MODELS / f"{name}.toml"
            else:
                path = folder / f"{name}.toml"
                path.write_text(FAMILY[name])
            with progress.quiet():
                checked = pipeline.check(load_world(path), folder / name)
            worth = deception_value.deception_values(checked.analysis,
                                                     checked.results.deceptive_value)
            cache[name] = (path, checked, worth)
        return cache[name]

    return get


def test_family_size() -> None:
    assert len(NAMES) >= 33 and SINGLE <= set(NAMES)


@pytest.mark.parametrize("name", ["world1", "world3"] + share(NAMES))   # every fourth under `make test`
def test_values_match_reference_and_invariants(name: str, solved) -> None:
    path, checked, worth = solved(name)
    deceptive, v_lead = checked.results.deceptive_value, checked.results.v_lead
    ref = reference_deception.Deception(path)
    assert worth.v_static == pytest.approx(ref.v_static(), abs=1e-6)
    assert worth.v_naive == pytest.approx(ref.v_naive(), abs=1e-6)
    assert worth.value_of_deception == pytest.approx(deceptive - worth.v_naive, abs=1e-12)
    assert worth.v_naive <= deceptive + 1e-6
    assert v_lead <= worth.v_static + 1e-6
    if name in SINGLE:
        assert worth.v_static == pytest.approx(deceptive, abs=1e-6)


@pytest.mark.parametrize("name", ["world1", "fam00_d0_l1_w1_x2", "fam13_d1_l2_w2_x2",
                                  "fam21_d0_l1_w2_x4"])
def test_naive_chain_is_the_naive_strategy(name: str, solved) -> None:
    """The package's chain is the reference's naive chain: walked together from the initial
    state, every state has the same TS state, DFA state (both number it as docs/semantics.md §3
    says), P2 memory and move, and the same successors with the same probabilities."""
    path, checked, worth = solved(name)
    ref = reference_deception.Deception(path)
    w = ref.w
    grid = gridview.view(checked.analysis)
    chain = worth.naive_chain
    s0, table = ref.naive_table()

    def ref_state(v: int):
        described = grid.describe_state(v)
        if described["cell"] is None:
            return "trapped"
        return w.record_ts_state(described["cell"], described["traps"], described["countdown"])

    def key(i: int):
        if i in (deception_value.GOAL, deception_value.FAIL):
            return ("goal", "fail")[i]
        v, q, memory = chain.states[i]
        return (ref_state(v), int(q), (memory.hypothesis,
                               tuple((ref_state(o), "NESW"[a]) for o, a in memory.window)))

    def ref_key(s):
        return s if s in ("goal", "fail") else (s[0], s[1], s[2])

    pairs = {chain.start: s0}
    queue = [chain.start]
    while queue:
        i = queue.pop()
        s = pairs[i]
        assert key(i) == ref_key(s)
        if s in ("goal", "fail"):
            continue
        assert "NESW"[chain.action[i]] == table[s]
        row = chain.matrix.getrow(i)
        ours = {key(j): (j, p) for j, p in zip(row.indices.tolist(), row.data.tolist())}
        theirs = {ref_key(t): (t, p) for t, p in w.hyper_successors(s, table[s]).items()}
        assert set(ours) == set(theirs)
        for k, (j, p) in ours.items():
            t, p_ref = theirs[k]
            assert p == pytest.approx(p_ref, abs=1e-12)
            if j not in pairs:
                pairs[j] = t
                queue.append(j)
            assert pairs[j] == t
    assert len(pairs) == chain.size - (deception_value.GOAL not in pairs) \
        - (deception_value.FAIL not in pairs)
    assert len(table) == sum(1 for s in pairs.values() if s not in ("goal", "fail"))


@pytest.mark.parametrize("name", ["world1", "fam04_d1_l1_w2_x2", "fam30_d0_l2_w2_x2"])
def test_static_and_naive_simulations(name: str, solved) -> None:
    _, checked, worth = solved(name)
    analysis = checked.analysis
    horizon, episodes = 40, 3000
    p1 = np.eye(4)[worth.static.p1]
    p2 = np.eye(analysis.ts.n_sets)[worth.static.p2]
    static_sim = simulation.simulate_nash(analysis.ts, analysis.task, p1, p2, episodes, horizon,
                                          seed=5, progress=False)
    static_exact = simulation.exact_completion(analysis.ts, analysis.task, p1, p2, horizon)
    naive_sim = simulation.simulate_deceptive(analysis, worth.naive, episodes, horizon, seed=5,
                                              progress=False)
    naive_exact = worth.naive_chain.within(horizon)
    for sim, exact, value in ((static_sim, static_exact, worth.v_static),
                              (naive_sim, naive_exact, worth.v_naive)):
        low, high = sim.interval(0.999)
        assert low <= exact <= high
        assert exact <= value + 1e-9
    # P1's static strategy is optimal: its chain reaches the goal with probability V_static.
    assert simulation.exact_completion(analysis.ts, analysis.task, p1, p2, 10**6) == \
        pytest.approx(worth.v_static, abs=1e-6)
    assert worth.naive_chain.within(10**6) == pytest.approx(worth.v_naive, abs=1e-6)


# Worlds whose deceptive strategy makes P2 change her mind with probability 0.06 to 0.83 within
# 30 steps, once or (fam20) up to twice.
@pytest.mark.parametrize("name", ["fam09_d0_l2_w1_x3", "fam19_d1_l1_w1_x2", "fam20_d2_l1_w1_x3",
                                  "fam27_d0_l2_w1_x2", "fam30_d0_l2_w2_x2"])
def test_simulated_switches_agree_with_exact(name: str, solved) -> None:
    path, checked, _ = solved(name)
    analysis = checked.analysis
    horizon, episodes = 30, 4000
    strategy = Strategy.from_records(checked.records, analysis.ts)
    sim = simulation.simulate_deceptive(analysis, strategy, episodes, horizon, seed=11,
                                        progress=False)
    ref = reference_deception.Deception(path)
    exact = reference_deception.switch_probability(ref.w, checked.records, horizon)
    low, high = simulation.wilson_interval(sim.p2_switched, episodes, 0.999)
    assert low <= exact <= high, (sim.p2_switched, exact)
    assert sim.p2_switches >= sim.p2_switched >= sim.p2_switched_in_play
    assert 0.01 < exact < 0.99
    # the changes P2 can act on: after them the episode goes on
    in_play = reference_deception.switch_probability(ref.w, checked.records, horizon,
                                                     in_play=True)
    low, high = simulation.wilson_interval(sim.p2_switched_in_play, episodes, 0.999)
    assert low <= in_play <= high, (sim.p2_switched_in_play, in_play)
    assert in_play <= exact


def test_world3_deception_steers_belief(solved) -> None:
    """world3 is what docs/results.md says: the deceptive value exceeds V_static and V_naive by at
    least 0.1, and P2 changes her mind in at least half of the deceptive episodes (simulated,
    and exactly within the horizon by the reference)."""
    path, checked, worth = solved("world3")
    deceptive = checked.results.deceptive_value
    assert deceptive - max(worth.v_static, worth.v_naive) >= 0.1
    analysis = checked.analysis
    horizon, episodes = 50, 2000
    strategy = Strategy.from_records(checked.records, analysis.ts)
    sim = simulation.simulate_deceptive(analysis, strategy, episodes, horizon, seed=3,
                                        progress=False)
    ref = reference_deception.Deception(path)
    exact = reference_deception.switch_probability(ref.w, checked.records, horizon)
    low, high = simulation.wilson_interval(sim.p2_switched, episodes, 0.999)
    assert low <= exact <= high
    assert sim.p2_switched >= episodes / 2 and exact >= 0.5


def test_a_difference_of_equal_values_computed_two_ways_is_zero() -> None:
    """value_difference: what one value is worth over another (the value of deception, of
    adaptivity, the cost of not knowing P2's type). The adaptive results wrote V_adapt -
    max V_commit as -1.39e-17 where the two values were equal (an API review, a two-type
    attack graph; the value of deception had been cleaned, mir100's -1.4e-17, but not these):
    below WORTH_TOLERANCE the difference is 0, at it and above it is kept, sign and all."""
    from hg2prism.analyses.deception_value import WORTH_TOLERANCE, value_difference

    assert value_difference(0.07499999999999997, 0.07499999999999998) == 0.0
    assert str(value_difference(0.07499999999999997, 0.07499999999999998)) == "0.0"
    assert value_difference(0.5, 0.5 - WORTH_TOLERANCE / 2) == 0.0
    assert value_difference(0.5 + 2 * WORTH_TOLERANCE, 0.5) == (0.5 + 2 * WORTH_TOLERANCE) - 0.5
    assert value_difference(0.5, 0.5 + 2 * WORTH_TOLERANCE) < 0
    assert value_difference(1.0, 0.0) == 1.0 and value_difference(0.0, 1.0) == -1.0
