"""P1's one Policy protocol and the hypergame's one successor function in Python.

* every strategy of P1 the package plays (deceptive, step-bounded, leader, naive, static, robust)
  is a `strategy.policy.Policy` (runtime_checkable), and objects without `action` are not;
  the product policies (leader, static) answer the move of their product state;
* `analyses.successor.Hypergame.successors` is the hypergame of the independent reference
  (tests/reference.py, tests/reference_bayes.py for the Bayesian observer): walked together
  from the initial state under every move of P1 (so for every fixed strategy), every reachable
  state has the same successors with the same probabilities, goal and failure included, on
  generated worlds (delays 0-2, one and two traps, windows 1-3), on world3_bayes ("map") and on
  Bayesian "sample" worlds, where P2 draws her hypothesis. DFA states are matched through the
  walk (a consistent one-to-one renaming), not by number;
* the simulation's two-memory observer (`TrackedObserver`) is the model hypergame when P2
  behaves as modelled, and with another real inference keeps both memories apart: P2's records
  the set she played, P1's model the set it predicts ("map") or the set played ("sample").
"""

from __future__ import annotations

import json
from collections import deque
from pathlib import Path

import numpy as np
import pytest

import reference
import reference_bayes
import worldgen
from conftest import MODELS
from test_bayes import bayes_text
import gridview
from hg2prism import pipeline, progress
from hg2prism.analyses import deception_value
from hg2prism.analyses.simulation import LeaderStrategy, leader_fallback
from hg2prism.analyses.successor import GOAL, RUNNING, Hypergame, TrackedObserver
from hg2prism.frontends.grid import ACTIONS
from hg2prism.worldfile import load_world
from hg2prism.strategy.policy import Policy, ProductPolicy
from hg2prism.strategy.records import Strategy
from hg2prism.strategy.stepped import StepCounter, SteppedStrategy

FAMILY = dict(worldgen.world_family())
# CUSUM worlds: delays 0-2, one and two traps, windows 1-3, one to four hypotheses, slip 0 and > 0
CUSUM = ["fam00_d0_l1_w1_x2", "fam01_d1_l1_w1_x3", "fam04_d1_l1_w2_x2", "fam06_d0_l1_w3_x2",
         "fam10_d1_l2_w1_x2", "fam11_d2_l2_w1_x1", "fam13_d1_l2_w2_x2", "fam20_d2_l1_w1_x3",
         "fam21_d0_l1_w2_x4", "fam30_d0_l2_w2_x2", "fam37_eq_d1_w1"]
# Bayesian worlds: (family world, prior, decision, window)
BAYES = {"bayes_fam00_sample": ("fam00_d0_l1_w1_x2", "skew", "sample", 1),
         "bayes_fam01_sample": ("fam01_d1_l1_w1_x3", None, "sample", 1),
         "bayes_fam21_sample": ("fam21_d0_l1_w2_x4", None, "sample", 2),
         "bayes_fam10_map": ("fam10_d1_l2_w1_x2", "skew", "map", 1)}
LIMIT = 3000       # hypergame states walked per world (all of them on these worlds but a few)


def world_file(name: str, folder: Path) -> Path:
    """The world file of a test case, written into `folder` unless it is in models/."""
    if name == "world3_bayes":
        return MODELS / "world3_bayes.toml"
    path = folder / f"{name}.toml"
    if name == "world3_bayes_sample":
        text = (MODELS / "world3_bayes.toml").read_text()
        assert 'decision = "map"' in text
        path.write_text(text.replace('decision = "map"', 'decision = "sample"')
                        .replace('name = "world3_bayes"', 'name = "world3_bayes_sample"'))
    elif name in BAYES:
        base, prior, decision, window = BAYES[name]
        path.write_text(bayes_text(FAMILY[base], prior, decision, window))
    else:
        path.write_text(FAMILY[name])
    return path


# ---------------------------------------------------------------------------------------------
# The Policy protocol
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def small_world(tmp_path_factory: pytest.TempPathFactory):
    """A generated world checked twice (Pmax and the step-bounded objective)."""
    folder = tmp_path_factory.mktemp("policy")
    path = world_file("fam04_d1_l1_w2_x2", folder)
    world = load_world(path)
    with progress.quiet():
        checked = pipeline.check(world, folder / "pmax")
        bounded = pipeline.check(world, folder / "bounded", objective="bounded", bound=6)
    return world, checked, bounded, folder


def test_every_p1_strategy_is_a_policy(small_world) -> None:
    from hg2prism.experiments.robust import robust_strategy_for

    world, checked, bounded, folder = small_world
    analysis = checked.analysis
    worth = deception_value.deception_values(analysis, checked.results.deceptive_value)
    robust_records = json.loads(robust_strategy_for(world, checked, 0.1, folder / "robust"))
    policies = {
        "deceptive": Strategy.from_records(checked.records, analysis.ts),
        "stepped": SteppedStrategy(bounded.records, analysis.ts, bounded.bounded.bound),
        "leader": LeaderStrategy(analysis),
        "naive": worth.naive,
        "static": worth.static.policy,
        "robust": Strategy.from_records(robust_records, analysis.ts,
                                        fallback=leader_fallback(analysis)),
    }
    for name, policy in policies.items():
        assert isinstance(policy, Policy), name
    # each answers a move at the initial hypergame state
    v, q, memory = Hypergame(analysis.ts, analysis.task, analysis.games,
                             analysis.inference).initial()
    timed = StepCounter(analysis.inference, 5).initial_memory()
    for name, policy in policies.items():
        move = policy.action(v, q, timed if name == "stepped" else memory)
        assert move in range(len(ACTIONS)), name


def test_what_is_not_a_policy() -> None:
    class Named:
        def act(self, ts_state: int, q: int, memory: object) -> int:
            return 0

    assert not isinstance(object(), Policy)
    assert not isinstance(Named(), Policy)
    assert not isinstance(np.zeros(3), Policy)


def test_product_policies_answer_their_product_state(small_world) -> None:
    _, checked, _, _ = small_world
    analysis = checked.analysis
    n_q = analysis.task.n_states
    static = deception_value.deception_values(analysis, checked.results.deceptive_value).static
    leader = LeaderStrategy(analysis)
    memory = analysis.inference.initial_memory()
    for policy, moves in ((static.policy, static.p1), (leader, leader.answers)):
        mixed = policy.mixed()
        assert mixed.shape == (analysis.ts.n_states * n_q, len(ACTIONS))
        assert (mixed.sum(axis=1) == 1.0).all()
        for v in range(analysis.ts.n_states):
            for q in range(n_q):
                assert policy.action(v, q, memory) == int(moves[v * n_q + q])
                assert mixed[v * n_q + q, policy.action(v, q, memory)] == 1.0
    assert ProductPolicy([3, 1, 0, 2], 2).action(1, 1, None) == 2


# ---------------------------------------------------------------------------------------------
# The successor function against the reference
# ---------------------------------------------------------------------------------------------

class _Walk:
    """The package's hypergame and the reference's, walked together: states are translated
    into the reference's terms, DFA states matched one to one as they are met."""

    def __init__(self, game: Hypergame, ref: reference.World, bayes: bool, world) -> None:
        self.game, self.ref, self.bayes = game, ref, bayes
        self.grid = gridview.GridView(world, game.ts)
        self.q_ours: dict[int, int] = {}
        self.q_theirs: dict[int, int] = {}

    def ts_state(self, v: int):
        described = self.grid.describe_state(v)
        if described["cell"] is None:
            return reference.TRAPPED
        return self.ref.record_ts_state(described["cell"], described["traps"],
                                        described["countdown"])

    def memory(self, memory):
        ts = self.grid
        if self.bayes:
            return tuple((self.ts_state(o[0]), ACTIONS[o[1]],
                          self.ref.norm_traps(ts.trap_cells(o[2]))) for o in memory.window)
        return (memory.hypothesis,
                tuple((self.ts_state(o[0]), ACTIONS[o[1]]) for o in memory.window))

    def key(self, state) -> object:
        """"goal", "fail", or (TS state, memory) in the reference's terms."""
        v, q, memory = state
        status = self.game.status(v, q)
        if status != RUNNING:
            return "goal" if status == GOAL else "fail"
        return self.ts_state(v), self.memory(memory)

    def match_q(self, ours: int, theirs: int) -> None:
        assert self.q_ours.setdefault(ours, theirs) == theirs, "DFA states do not match"
        assert self.q_theirs.setdefault(theirs, ours) == ours, "DFA states do not match"

    def successors(self, state, a1: int) -> dict:
        """key -> (successor, probability) of the package's successors; goal and failure
        merged (their successor is the first met)."""
        merged: dict = {}
        for nxt, p in self.game.successors(state, a1):
            k = self.key(nxt)
            first, total = merged.get(k, (nxt, 0.0))
            assert k in ("goal", "fail") or first == nxt
            merged[k] = (first, total + p)
        return merged

    def run(self, limit: int) -> int:
        """Walk from the initial states; returns the number of states compared."""
        start, s0 = self.game.initial(), self.ref.initial()
        if self.key(start) in ("goal", "fail"):
            assert s0 == self.key(start)
            return 0
        assert self.key(start) == (s0[0], s0[2])
        self.match_q(start[1], s0[1])
        pairs = {start: s0}
        queue = deque([start])
        walked = 0
        while queue and walked < limit:
            state = queue.popleft()
            walked += 1
            for a1, move in enumerate(ACTIONS):
                ours = self.successors(state, a1)
                theirs = {(t if t in ("goal", "fail") else (t[0], t[2])): (t, p)
                          for t, p in self.ref.hyper_successors(pairs[state], move).items()}
                assert set(ours) == set(theirs), (state, move)
                assert sum(p for _, p in ours.values()) == pytest.approx(1.0, abs=1e-12)
                for k, (nxt, p) in ours.items():
                    t, p_ref = theirs[k]
                    assert p == pytest.approx(p_ref, abs=1e-12), (state, move, k)
                    if t in ("goal", "fail"):
                        continue
                    self.match_q(nxt[1], t[1])
                    if nxt not in pairs:
                        pairs[nxt] = t
                        queue.append(nxt)
        return walked


def _walk(name: str, folder: Path) -> tuple[int, int]:
    path = world_file(name, folder)
    analysis = pipeline.analyse(load_world(path))
    bayes = analysis.inference.kind == "bayes"
    ref = reference_bayes.BayesWorld(path) if bayes else reference.World(path)
    game = Hypergame(analysis.ts, analysis.task, analysis.games, analysis.inference)
    walk = _Walk(game, ref, bayes, analysis.world)
    return walk.run(LIMIT), len(walk.q_ours)


@pytest.mark.parametrize("name", CUSUM)
def test_successors_match_the_reference(name: str, tmp_path: Path) -> None:
    walked, _ = _walk(name, tmp_path)
    assert walked > 1


@pytest.mark.parametrize("name", ["world3_bayes", "world3_bayes_sample", *BAYES])
def test_bayesian_successors_match_the_reference(name: str, tmp_path: Path) -> None:
    walked, _ = _walk(name, tmp_path)
    assert walked > 1


def test_sample_world_draws_hypotheses(tmp_path: Path) -> None:
    """The "sample" variant of world3_bayes is one where P2's draw matters: some state has
    successors from two hypotheses' trap sets."""
    analysis = pipeline.analyse(load_world(world_file("world3_bayes_sample", tmp_path)))
    game = Hypergame(analysis.ts, analysis.task, analysis.games, analysis.inference)
    start = game.initial()
    sets = {a2 for a2, _ in game.trap_sets(start[0], start[2])}
    assert len(game.trap_sets(start[0], start[2])) == 2
    assert len(sets) == 2


def test_tracked_observer_is_the_model_when_p2_follows_it(tmp_path: Path) -> None:
    """With P2 playing the predicted set, the simulation's pair of memories moves as the model
    hypergame: same successors, both memories equal to the model's."""
    analysis = pipeline.analyse(load_world(world_file("fam13_d1_l2_w2_x2", tmp_path)))
    model = Hypergame(analysis.ts, analysis.task, analysis.games, analysis.inference)
    tracked = Hypergame(analysis.ts, analysis.task, analysis.games, TrackedObserver(model))
    v, q, m = model.initial()
    queue, seen = deque([(v, q, m)]), {(v, q, m)}
    while queue and len(seen) < 500:
        state = queue.popleft()
        v, q, m = state
        for a1 in range(len(ACTIONS)):
            a2 = model.predicted(v, m)
            ours = list(model.after(state, a1, a2))
            pair = list(tracked.after((v, q, (m, m)), a1, a2))
            assert [(w, q2, (n, n)) for (w, q2, n), _ in ours] == [s for s, _ in pair]
            assert [p for _, p in ours] == [p for _, p in pair]
            for nxt, _ in ours:
                if model.status(nxt[0], nxt[1]) == RUNNING and nxt not in seen:
                    seen.add(nxt)
                    queue.append(nxt)
    assert len(seen) > 10


@pytest.mark.parametrize("name, decision", [("world3_bayes", "map"),
                                            ("world3_bayes_sample", "sample")])
def test_tracked_observer_keeps_both_memories(name: str, decision: str, tmp_path: Path) -> None:
    """With P2's real inference another than P1's model (here the other window), P2's memory
    records the set she played and P1's model the set it predicts when it says she is
    deterministic ("map"), the set played when it says she draws ("sample"); P2 plays from
    her real memory."""
    from hg2prism.opponent.bayes import build_bayes

    analysis = pipeline.analyse(load_world(world_file(name, tmp_path)))
    world, games = analysis.world, analysis.games
    model = Hypergame(analysis.ts, analysis.task, games, analysis.inference)
    real = Hypergame(analysis.ts, analysis.task, games,
                     build_bayes(games, world.window + 1, world.prior, decision))
    tracked = TrackedObserver(model, real)
    v, q, m1 = model.initial()
    m2 = real.observer.initial_memory()
    assert tracked.initial_memory() == (m1, m2)
    played = np.flatnonzero(analysis.ts.allowed[v]).tolist()
    assert len(played) > 1
    for a1 in range(len(ACTIONS)):
        for a2 in played:
            n1, n2 = tracked.update((m1, m2), (v, a1, a2))
            modelled = a2 if decision == "sample" else model.predicted(v, m1)
            assert n1 == analysis.inference.update(m1, (v, a1, modelled))
            assert n2 == real.observer.update(m2, (v, a1, a2))
            assert tracked.hypothesis((n1, n2)) == real.observer.hypothesis(n2)
            assert tracked.hypothesis_distribution((n1, n2)) == \
                real.observer.hypothesis_distribution(n2)
