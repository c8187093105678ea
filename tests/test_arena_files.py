"""Arena world files (docs/semantics.md §15): loading `[arena]`, `hg2prism convert` (a grid
world's arena form reads back to the same transition system), world_from_graph (NetworkX) and
the MIR100 attack graph of models/mir100.toml."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hg2prism.frontends import transition_system
from hg2prism.frontends.arena import to_toml
from hg2prism.frontends.grid import geometry
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.worldfile import load_world, world_from_toml

REPO = Path(__file__).resolve().parent.parent
MODELS = REPO / "models"
MIR100_CSV = REPO / "data" / "mir100_edges.csv"

LATERAL = '''name = "lateral"
description = "a small attack graph"

[arena]
states = ["out", "web", "mail", "db", "hr", "burnt"]
initial = "out"
propositions = ["crown", "payroll", "noisy"]

[arena.labels]
db = ["crown"]
hr = ["payroll"]
burnt = ["noisy", "crown"]

[[arena.transition]]
state = "out"
action = "phish"
to = { mail = 0.6, out = 0.4 }

[[arena.transition]]
state = "out"
action = "exploit"
to = { web = 0.5, burnt = 0.2, out = 0.3 }

[[arena.transition]]
state = "web"
action = "scan"
to = { db = 0.3, hr = 0.3, web = 0.4, burnt = 0.0 }

[[arena.transition]]
state = "mail"
action = "pivot_db"
p2 = "watch_db"
to = { mail = 1.0 }

[[arena.transition]]
state = "mail"
action = "pivot_db"
to = { db = 0.5, mail = 0.5 }

[[arena.transition]]
state = "mail"
action = "pivot_hr"
p2 = ["watch_hr"]
to = { mail = 1 }

[[arena.transition]]
state = "mail"
action = "pivot_hr"
p2 = ["idle", "watch_db"]
to = { hr = 0.5, mail = 0.5 }

[[arena.transition]]
state = "mail"
action = "wait"
to = { mail = 1.0 }

[task]
formula = "F crown"

[adversary]
actions = ["idle", "watch_db", "watch_hr"]
delay = 1
initial_action = "watch_hr"
hypotheses = ["F crown", "F payroll"]
initial_hypothesis = 1

[inference]
window = 2
threshold = 0.6
rationality = 1.0
'''

TRAPS = '''name = "traps"

[arena]
states = ["a", "b", "c", "d", "goal"]
initial = "a"

[arena.labels]
goal = ["g"]
d = ["h", "g"]

[arena.positions]
a = [0, 0]
b = [1, 0.5]
c = [1, -0.5]
d = [2, 0]
goal = [3, 0]

[[arena.transition]]
state = "a"
action = "up"
to = { b = 0.9, a = 0.1 }

[[arena.transition]]
state = "a"
action = "down"
to = { c = 1.0 }

[[arena.transition]]
state = "b"
action = "go"
to = { d = 1.0 }

[[arena.transition]]
state = "c"
action = "go"
to = { d = 0.5, goal = 0.5 }

[[arena.transition]]
state = "d"
action = "go"
to = { goal = 1.0 }

[[arena.transition]]
state = "goal"
action = "stay"
to = { goal = 1.0 }

[task]
formula = "F g"

[adversary]
traps = 2
trap_candidates = ["d", "b", "c"]
delay = 2
initial_traps = ["c", "d"]
hypotheses = ["F g", "F h"]

[inference]
kind = "bayes"
window = 1
rationality = 2.0
prior = [1, 3]
'''


def test_general_arena_world_loads() -> None:
    w = world_from_toml(LATERAL, name="lateral.toml")
    a = w.arena
    assert (w.grid, w.traps, w.delay) == (None, 0, 1)
    assert w.initial_standing == 2 and w.initial_hypothesis == 1
    assert a.states == ("out", "web", "mail", "db", "hr", "burnt") and a.initial == 0
    assert a.propositions == ("crown", "payroll", "noisy")
    assert a.labels == (frozenset(), frozenset(), frozenset(), frozenset({"crown"}),
                        frozenset({"payroll"}), frozenset({"noisy", "crown"}))
    assert a.actions == (("phish", "exploit"), ("scan",), ("pivot_db", "pivot_hr", "wait"),
                         (), (), ())
    assert a.p2_actions == ("idle", "watch_db", "watch_hr") and a.trap_candidates == ()
    assert a.dest.shape == (6, 3, 3, 3) and a.positions is None
    # the zero-probability outcome is dropped; padding is the state itself with probability 0
    assert a.dest[1, 0, 0].tolist() == [3, 4, 1] and a.prob[1, 0, 0].tolist() == [0.3, 0.3, 0.4]
    assert a.dest[0, 0, 2].tolist() == [2, 0, 0] and a.prob[0, 0, 2].tolist() == [0.6, 0.4, 0]
    assert a.dest[1, 1].tolist() == [[1] * 3] * 3 and not a.prob[1, 1].any()
    assert [a.dest[2, 0, j, 0] for j in range(3)] == [3, 2, 3]      # watch_db blocks pivot_db
    assert [a.dest[2, 1, j, 0] for j in range(3)] == [4, 4, 2]      # watch_hr blocks pivot_hr
    assert a.terminal.tolist() == [False, False, False, True, True, True]
    ts = transition_system(w)
    assert ts.a2_names == ("idle", "watch_db", "watch_hr")
    assert ts.start_state == ts.state(0, 2, 0)


def test_trap_arena_world_loads() -> None:
    w = world_from_toml(TRAPS, name="traps.toml")
    a = w.arena
    assert a.propositions == ("g", "h")         # first occurrence in [arena.labels]
    assert a.trap_candidates == (3, 1, 2) and a.p2_actions == ()
    assert a.dest.shape == (5, 2, 1, 2)
    assert a.positions == ((0.0, 0.0), (1.0, 0.5), (1.0, -0.5), (2.0, 0.0), (3.0, 0.0))
    # the l-subsets of the candidates in combinations order: {d,b}, {d,c}, {b,c}; {c,d} is 1
    assert (w.traps, w.delay, w.initial_standing) == (2, 2, 1)
    assert w.inference == "bayes" and w.prior == (0.25, 0.75) and w.initial_hypothesis == 1
    ts = transition_system(w)
    assert ts.a2_names == ("d+b", "d+c", "b+c")
    assert ts.decode(ts.start_state) == (0, 1, 0)


# ---------------------------------------------------------------------------------------------
# convert
# ---------------------------------------------------------------------------------------------

def distributions(ts: TransitionSystem) -> dict:
    """(state, action slot, a2) -> {successor: probability}, equal successors merged in
    outcome order and zero probabilities dropped, over enabled slots."""
    out = {}
    for v in range(ts.n_states):
        for i in range(ts.n_actions):
            if not ts.enabled[v, i]:
                continue
            for j in range(ts.n_sets):
                dist: dict[int, float] = {}
                for target, p in zip(ts.succ[v, i, j].tolist(), ts.prob[v, i, j].tolist()):
                    if p > 0:
                        dist[target] = dist.get(target, 0.0) + p
                out[v, i, j] = dist
    return out


def assert_same_ts(a: TransitionSystem, b: TransitionSystem) -> None:
    assert a.n_states == b.n_states and a.start_state == b.start_state
    assert a.arena.states == b.arena.states
    assert a.arena.actions == b.arena.actions
    assert a.label_names == b.label_names
    assert np.array_equal(a.place_label, b.place_label)
    assert a.a2_names == b.a2_names and a.trap_sets == b.trap_sets
    for name in ("allowed", "enabled", "terminal"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert distributions(a) == distributions(b)


def body(text: str) -> str:
    """A world file's text without its comment lines."""
    return "\n".join(ln for ln in text.splitlines() if not ln.startswith("#"))


def _convert_cases() -> list[tuple[str, str]]:
    cases = [(name, (MODELS / f"{name}.toml").read_text())
             for name in ("world1", "world2", "world3", "world3_bayes")]
    world2 = (MODELS / "world2.toml").read_text()
    assert world2.count("delay = 0") == 1
    return cases + [("world2_delay2", world2.replace("delay = 0", "delay = 2"))]


@pytest.mark.parametrize("name,text", _convert_cases(), ids=[c[0] for c in _convert_cases()])
def test_convert_gives_the_same_transition_system(name: str, text: str) -> None:
    grid = world_from_toml(text, name=f"{name}.toml")
    converted = to_toml(grid)
    arena = world_from_toml(converted, name=f"{name}_arena.toml")
    assert arena.grid is None and arena.arena is not None
    assert_same_ts(transition_system(grid), transition_system(arena))
    for field in ("name", "description", "formula", "traps", "delay", "hypotheses",
                  "initial_hypothesis", "window", "rationality", "simulation", "detection",
                  "inference", "settings"):
        assert getattr(arena, field) == getattr(grid, field), field
    assert arena.arena.positions == tuple((float(x), float(y))
                                          for x, y in geometry(grid).cells)
    # an arena world converts to itself (but for the header naming the file it came from)
    assert body(to_toml(arena)) == body(converted)


@pytest.mark.parametrize("text", [LATERAL, TRAPS], ids=["general", "traps"])
def test_arena_world_converts_to_itself(text: str) -> None:
    world = world_from_toml(text, name="w.toml")
    converted = to_toml(world)
    again = world_from_toml(converted, name="w.toml")
    assert_same_ts(transition_system(world), transition_system(again))
    assert (again.initial_standing, again.settings, again.arena.positions) == (
        world.initial_standing, world.settings, world.arena.positions)
    assert to_toml(again) == converted


def run_cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "hg2prism", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


def test_convert_command(tmp_path: Path) -> None:
    proc = run_cli(["convert", str(MODELS / "world3.toml")], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == to_toml(load_world(MODELS / "world3.toml"))
    out = tmp_path / "sub" / "w3.toml"
    proc = run_cli(["convert", str(MODELS / "world3.toml"), "--out", str(out)], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert out.read_text() == to_toml(load_world(MODELS / "world3.toml"))
    assert sorted(p.name for p in out.parent.iterdir()) == ["w3.toml"]     # no temporary left
    proc = run_cli(["validate", str(out)], tmp_path)
    assert proc.returncode == 0 and "arena of 14 states, 3 trap candidates" in proc.stdout
    proc = run_cli(["convert", str(MODELS / "world3.toml"), "--out", str(tmp_path)], tmp_path)
    assert proc.returncode == 2 and "--out" in proc.stderr


# ---------------------------------------------------------------------------------------------
# MIR100 and NetworkX
# ---------------------------------------------------------------------------------------------

def mir100_edges() -> list[tuple[int, int, float]]:
    lines = [ln for ln in MIR100_CSV.read_text().splitlines() if not ln.startswith("#")]
    return [(int(r["source"]), int(r["target"]), float(r["success_probability"]))
            for r in csv.DictReader(lines)]


def test_mir100_world_has_every_edge_exactly() -> None:
    world = load_world(MODELS / "mir100.toml")
    a = world.arena
    edges = mir100_edges()
    assert len(edges) == 24 and len({(u, v) for u, v, _ in edges}) == 24
    found = {}
    for s, actions in enumerate(a.actions):
        for i, action in enumerate(actions):
            dist = {a.states[int(t)]: p for t, p in zip(a.dest[s, i, 0], a.prob[s, i, 0])
                    if p > 0}
            assert action.startswith("to_n")
            target = action[3:]
            if a.states[s] == "outside":
                assert dist == {target: 1.0}
                continue
            u, v = int(a.states[s][1:]), int(target[1:])
            assert dist[target] + dist.get(a.states[s], 0.0) == pytest.approx(1.0, abs=1e-15)
            found[u, v] = dist[target]
    assert found == {(u, v): p for u, v, p in edges}       # exactly, as floats
    assert a.actions[a.initial] == ("to_n1", "to_n2", "to_n3", "to_n4")
    assert [a.states[s] for s in np.flatnonzero(a.terminal)] == ["n12", "n13", "n14", "n16"]
    assert a.propositions == ("asset12", "asset13", "asset14", "asset16")
    assert [a.states[c] for c in a.trap_candidates] == [f"n{v}" for v in (*range(1, 12), 15)]
    assert world.traps == 1 and world.formula == "F asset16"
    assert world.hypotheses == ("F asset12", "F asset13", "F asset14", "F asset16")
    assert (world.window, world.rationality, world.threshold) == (2, 1.0, 0.6)


def test_world_from_graph_builds_the_mir100_arena() -> None:
    nx = pytest.importorskip("networkx")
    import hg2prism

    graph = nx.DiGraph()
    for u, v, p in mir100_edges():
        graph.add_edge(u, v, p=p)
    file = load_world(MODELS / "mir100.toml")
    built = hg2prism.world_from_graph(
        graph, entries=[1, 2, 3, 4], task="F asset16",
        hypotheses=["F asset12", "F asset13", "F asset14", "F asset16"], initial_hypothesis=1,
        traps=1, trap_candidates=[*range(1, 12), 15],
        inference={"kind": "cusum", "window": 2, "rationality": 1.0, "threshold": 0.6},
        name="mir100")
    a, b = built.arena, file.arena
    assert (a.states, a.initial, a.propositions, a.labels, a.actions) == (
        b.states, b.initial, b.propositions, b.labels, b.actions)
    assert (a.p2_actions, a.trap_candidates) == (b.p2_actions, b.trap_candidates)
    assert np.array_equal(a.dest, b.dest) and np.array_equal(a.prob, b.prob)
    for field in ("formula", "traps", "delay", "initial_standing", "hypotheses",
                  "initial_hypothesis", "window", "rationality", "inference", "settings"):
        assert getattr(built, field) == getattr(file, field), field


def _small_graph():
    nx = pytest.importorskip("networkx")
    graph = nx.DiGraph()
    graph.add_edge(1, 2, p=0.5)
    graph.add_edge(2, 3, p=1)
    graph.add_edge(1, 3, p=0.0)
    graph.add_edge(2, 4, p=0.25)
    return graph


def test_world_from_graph_small() -> None:
    import hg2prism

    world = hg2prism.world_from_graph(_small_graph(), entries=[2, 1], task="F asset3",
                                      trap_candidates=[2], name="small")
    a = world.arena
    assert a.states == ("outside", "n1", "n2", "n3", "n4") and a.initial == 0
    assert a.actions == (("to_n1", "to_n2"), ("to_n2", "to_n3"), ("to_n3", "to_n4"), (), ())
    assert a.propositions == ("asset3", "asset4")
    assert a.labels == (frozenset(),) * 3 + (frozenset({"asset3"}), frozenset({"asset4"}))
    assert world.hypotheses == ("F asset3", "F asset4")
    assert a.trap_candidates == (2,) and world.traps == 1
    assert a.dest[1, 0, 0].tolist() == [2, 1] and a.prob[1, 0, 0].tolist() == [0.5, 0.5]
    assert a.dest[1, 1, 0, 0] == 1 and a.prob[1, 1, 0].tolist() == [1.0, 0.0]   # p = 0: stays
    assert a.dest[2, 0, 0, 0] == 3 and a.prob[2, 0, 0].tolist() == [1.0, 0.0]   # p = 1
    assert a.prob[2, 1, 0].tolist() == [0.25, 0.75]
    # written and read back: the same arena
    again = world_from_toml(to_toml(world), name="small.toml")
    assert_same_ts(transition_system(world), transition_system(again))
    # node arguments given as generators are read once (trap_candidates was 'is empty')
    lazy = hg2prism.world_from_graph(_small_graph(), entries=(v for v in [2, 1]),
                                     task="F asset3", trap_candidates=(v for v in [2]),
                                     name="small")
    assert lazy.arena.trap_candidates == (2,) and lazy.arena.actions == a.actions


def _graph_warnings(caplog, **arguments) -> list[str]:
    """The warnings world_from_graph gives (the world is built all the same)."""
    import logging

    import hg2prism

    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="hg2prism"):
        world = hg2prism.world_from_graph(**{"task": "F asset3", "name": "g", **arguments})
    assert world.arena.states[0] == "outside"
    return [record.getMessage() for record in caplog.records]


def test_world_from_graph_warns_of_likely_mistakes(caplog) -> None:
    """Inputs that have a meaning (semantics §15) but are likely mistakes are built with one
    warning line each, saying what they mean and how to avoid them (they passed silently): an
    edge with probability 0, a target (no outgoing edge) among the trap candidates or the
    entries, and with `labels` a target without a label. A graph without them: no warning."""
    graph = _small_graph()
    targets = sorted(v for v in graph if graph.out_degree(v) == 0)
    assert targets == [3, 4]
    graph.remove_edge(1, 3)
    assert _graph_warnings(caplog, graph=graph, entries=[1], trap_candidates=[2],
                           labels={3: "asset3", 4: ["asset4"]}) == []
    zero = _graph_warnings(caplog, graph=_small_graph(), entries=[1], trap_candidates=[2])
    assert zero == ["warning: g: edge (1, 3): probability 0, so the attacker's action along it "
                    "never succeeds (he stays where he is); remove the edge if the step is "
                    "impossible"]
    guarded = _graph_warnings(caplog, graph=graph, entries=[1], trap_candidates=[2, 3, 4])
    assert len(guarded) == 1 and guarded[0].startswith(
        "warning: g: trap_candidates: n3, n4 have no outgoing edge (a target): a honeypot there "
        "catches the attacker on reaching the target itself")
    exposed = _graph_warnings(caplog, graph=graph, entries=[1, 4], trap_candidates=[2])
    assert len(exposed) == 1 and exposed[0].startswith(
        "warning: g: entries: n4 has no outgoing edge (a target): the attacker reaches that "
        "target from outside in one step with probability 1")
    bare = _graph_warnings(caplog, graph=graph, entries=[1], trap_candidates=[2],
                           labels={3: "asset3"})
    assert len(bare) == 1 and bare[0].startswith(
        "warning: g: labels: n4 has no outgoing edge and no label: reaching one ends the "
        "episode with nothing gained")
    assert "label it in labels=" in bare[0] and "labels={node: []} leaves one" in bare[0]
    # an empty label given on purpose is no mistake (a review: a caught node could not be
    # modelled without the warning)
    assert _graph_warnings(caplog, graph=graph, entries=[1], trap_candidates=[2],
                           labels={3: "asset3", 4: []}) == []


def test_a_script_sees_the_warnings_without_configuring_logging(tmp_path) -> None:
    """A plain script (logging not configured) gets world_from_graph's warnings on stderr, one
    line each (they showed only after logging.basicConfig), and no progress report."""
    import subprocess
    import sys

    script = tmp_path / "script.py"
    script.write_text("import networkx as nx, hg2prism\n"
                      "g = nx.DiGraph()\n"
                      "g.add_edge(1, 2, p=0.5); g.add_edge(2, 3, p=1); g.add_edge(1, 3, p=0.0)\n"
                      "g.add_edge(1, 5, p=0.5); g.add_edge(5, 3, p=1)\n"
                      "w = hg2prism.world_from_graph(g, entries=[1], task='F asset3', "
                      "trap_candidates=[2, 5], name='g')\n"
                      "print(round(hg2prism.solve(w).deceptive_value, 6))\n")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines() == [
        "warning: g: edge (1, 3): probability 0, so the attacker's action along it never "
        "succeeds (he stays where he is); remove the edge if the step is impossible"]
    assert float(done.stdout) > 0


@pytest.mark.parametrize("change,key,word", [
    (lambda g: g.add_edge(3, 5, p=1.5), "edge (3, 5)", "outside [0, 1]"),
    (lambda g: g.add_edge(3, 5, p=-0.1), "edge (3, 5)", "outside [0, 1]"),
    (lambda g: g.add_edge(3, 5, p="high"), "edge (3, 5)", "not a probability"),
    # what a CSV reader gives: the message says so
    (lambda g: g.add_edge(3, 5, p="0.6"), "edge (3, 5)", "convert them with float"),
    (lambda g: g.add_edge(3, 5), "edge (3, 5)",
     "has no 'p' attribute (its success probability) and no 'outcomes'"),
    (lambda g: g.add_edge(3, 3, p=0.5), "edge (3, 3)", "self-loop"),
    (lambda g: g.add_edge(3, "a b", p=0.5), "node 'a b'", "no state name"),
    (lambda g: g.add_edge(3, "outside", p=0.5), "node 'outside'", "initial state"),
    # the clash names both nodes (it named neither)
    (lambda g: g.add_edge(3, "n4", p=0.5), "nodes 4 and 'n4'", "would both be the state 'n4'"),
    # a negative node was reported as a state name "n-1" it never had
    (lambda g: g.add_edge(3, -1, p=0.5), "node -1", "has no state name"),
    # Python calls it an identifier: the message says which (it said "identifiers")
    (lambda g: g.add_edge(3, "сервер", p=0.5), "node 'сервер'", "ASCII identifiers"),
    # an edge's outcomes (a third outcome, world_from_graph's `outcomes`)
    (lambda g: g.add_edge(3, 5, outcomes={5: 0.5, 3: 0.4}), "edge (3, 5)",
     "add up to 0.9, not 1"),
    (lambda g: g.add_edge(3, 5, outcomes={5: 0.5, 9: 0.5}), "edge (3, 5)",
     "9 is not a node of the graph (add it: graph.add_node(9))"),
    (lambda g: g.add_edge(3, 5, outcomes={5: 1.5, 3: -0.5}), "edge (3, 5)",
     "5: 1.5 is not a probability"),
    (lambda g: g.add_edge(3, 5, outcomes={5: "1"}), "edge (3, 5)", "'1' is not a probability"),
    (lambda g: g.add_edge(3, 5, outcomes=[5]), "edge (3, 5)", "expected a dict node -> "),
    (lambda g: g.add_edge(3, 5, outcomes={}), "edge (3, 5)", "expected a dict node -> "),
    (lambda g: g.add_edge(3, 5, p=0.5, outcomes={5: 1.0}), "edge (3, 5)",
     "has both 'p' and 'outcomes'"),
], ids=["above-1", "negative", "not-a-number", "text", "missing", "self-loop", "bad-name",
        "named-outside", "name-clash", "negative-node", "unicode-name", "outcomes-sum",
        "outcomes-node", "outcomes-probability", "outcomes-text", "outcomes-list",
        "outcomes-empty", "outcomes-and-p"])
def test_world_from_graph_errors(change, key: str, word: str) -> None:
    import hg2prism
    from hg2prism.errors import InputError

    graph = _small_graph()
    change(graph)
    with pytest.raises(InputError) as err:
        hg2prism.world_from_graph(graph, entries=[1], task="F asset4", name="g")
    assert (err.value.file, err.value.key) == ("g", key) and word in err.value.reason


def test_world_from_graph_edge_outcomes_give_a_third_outcome(caplog) -> None:
    """An edge whose `outcomes` attribute (node -> probability) gives where the attack step
    leads: here an exploit that succeeds, fails in place or gets the attacker caught (world_from_graph
    could only say success or staying). The arena is the one its world file, written by hand,
    gives; the names of the attribute are world_from_graph's arguments; an edge whose outcomes
    never reach its node warns as probability 0 does."""
    import hg2prism
    from hg2prism.errors import InputError

    nx = pytest.importorskip("networkx")
    graph = nx.DiGraph()
    graph.add_edge(1, 2, p=0.5)
    graph.add_edge(2, 3, outcomes={3: 0.625, 2: 0.25, "caught": 0.125})
    graph.add_node("caught")
    arguments = dict(entries=[1], task="F asset3", hypotheses=["F asset3"], name="g",
                     labels={3: "asset3", "caught": "caught"}, trap_candidates=[1, 2])
    world = hg2prism.world_from_graph(graph, **arguments)
    by_hand = world_from_toml("""
name = "g"
[arena]
states = ["outside", "n1", "n2", "n3", "caught"]
initial = "outside"
propositions = ["asset3", "caught"]
[arena.labels]
n3 = ["asset3"]
caught = ["caught"]
[[arena.transition]]
state = "outside"
action = "to_n1"
to = { n1 = 1.0 }
[[arena.transition]]
state = "n1"
action = "to_n2"
to = { n2 = 0.5, n1 = 0.5 }
[[arena.transition]]
state = "n2"
action = "to_n3"
to = { n2 = 0.25, n3 = 0.625, caught = 0.125 }
[task]
formula = "F asset3"
[adversary]
traps = 1
trap_candidates = ["n1", "n2"]
hypotheses = ["F asset3"]
[inference]
kind = "cusum"
window = 2
rationality = 1.0
threshold = 0.6
""", name="g.toml")
    assert world.arena.states == by_hand.arena.states
    assert_same_ts(transition_system(world), transition_system(by_hand))
    # the attribute names are arguments, like `probability`
    renamed = nx.relabel_nodes(graph, {})
    for _, _, data in renamed.edges(data=True):
        if "outcomes" in data:
            data["dist"] = data.pop("outcomes")
        else:
            data["chance"] = data.pop("p")
    again = hg2prism.world_from_graph(renamed, probability="chance", outcomes="dist",
                                      **arguments)
    assert_same_ts(transition_system(again), transition_system(world))
    with pytest.raises(InputError) as refused:
        hg2prism.world_from_graph(graph, outcomes=3, **arguments)
    assert (refused.value.key, refused.value.reason) == (
        "outcomes", "expected an edge attribute's name (a str), got 3")
    # outcomes that never reach the edge's node: the warning of probability 0
    graph.add_edge(1, 3, outcomes={1: 0.5, "caught": 0.5})
    warned = _graph_warnings(caplog, graph=graph, **{k: v for k, v in arguments.items()
                                                     if k not in ("task", "name")})
    assert warned == ["warning: g: edge (1, 3): probability 0, so the attacker's action along "
                      "it never succeeds (he stays where he is, or goes where its outcomes "
                      "say); remove the edge if the step is impossible"]
    # a node only outcomes reach is no target: no asset label, no hypothesis by default; an
    # entry without edges still is one (a code review: it had lost its label)
    default = hg2prism.world_from_graph(graph, entries=[1], task="F asset3", name="g")
    assert default.hypotheses == ("F asset3",) and default.arena.propositions == ("asset3",)
    graph.add_node(7)
    exposed = hg2prism.world_from_graph(graph, entries=[1, 7], task="F asset3", name="g")
    assert exposed.arena.propositions == ("asset3", "asset7")
    for key, value, reason in (("outcomes", "p", "names the same edge attribute as "
                                "probability ('p'); expected another"),):
        with pytest.raises(InputError) as refused:
            hg2prism.world_from_graph(graph, **{**arguments, key: value})
        assert (refused.value.key, refused.value.reason) == (key, reason)


def test_world_from_graph_inference_keys_default_one_by_one() -> None:
    """`inference` keys not given take the documented defaults (window 2, rationality 1, CUSUM's
    threshold 0.6): {"kind": "bayes"} was "inference.window: missing required key", and so was
    a misspelt kind, whose own error now comes first."""
    import hg2prism

    graph = _small_graph()
    bayes = hg2prism.world_from_graph(graph, entries=[1], task="F asset4", name="g",
                                      inference={"kind": "bayes"})
    assert (bayes.inference, bayes.window, bayes.rationality) == ("bayes", 2, 1.0)
    assert bayes.threshold is None
    cusum = hg2prism.world_from_graph(graph, entries=[1], task="F asset4", name="g",
                                      inference={"window": 3})
    assert (cusum.inference, cusum.window, cusum.threshold) == ("cusum", 3, 0.6)
    with pytest.raises(hg2prism.InputError) as err:        # the top level names it too
        hg2prism.world_from_graph(graph, entries=[1], task="F asset4", name="g",
                                  inference={"kind": "bayesian"})
    assert err.value.key == "inference.kind" and "bayesian" in err.value.reason


def test_world_from_graph_argument_errors() -> None:
    import hg2prism
    from hg2prism.errors import InputError

    nx = pytest.importorskip("networkx")
    graph = _small_graph()
    for kwargs, key in (({"entries": [9]}, "entries"), ({"entries": []}, "entries"),
                        ({"entries": [1], "trap_candidates": [7]}, "trap_candidates"),
                        ({"entries": [1], "labels": {8: "x"}}, "labels"),
                        ({"entries": [1], "traps": 5}, "adversary.traps"),
                        ({"entries": [1], "task": "F nothing"}, "task.formula")):
        with pytest.raises(InputError) as err:
            hg2prism.world_from_graph(graph, **{"task": "F asset4", "name": "g", **kwargs})
        assert err.value.key == key, err.value
    with pytest.raises(InputError) as err:
        hg2prism.world_from_graph(nx.Graph(graph), entries=[1], task="F asset4")
    assert "directed" in err.value.reason


def test_convert_random_mazes() -> None:
    """Random mazes (slip 0 or not, delay 0-2, either observer): the arena form reads back to
    the grid's transition system and settings (all 200 seeds pass; a sample runs here)."""
    from mazegen import maze_world

    for seed in range(0, 200, 10):
        grid = world_from_toml(maze_world(seed), name="maze.toml")
        arena = world_from_toml(to_toml(grid), name="maze_arena.toml")
        assert_same_ts(transition_system(grid), transition_system(arena))
        for field in ("settings", "initial_hypothesis", "hypotheses", "formula", "delay"):
            assert getattr(arena, field) == getattr(grid, field), (seed, field)


def test_world_from_graph_places_the_nodes_where_told(tmp_path: Path) -> None:
    """positions= (node -> [x, y]) reaches the arena's positions, `outside` one unit left of
    the entries at their mean height, and survives the world file; a missing node or a bad
    point is one InputError naming `positions` (there was no way to place the nodes but
    editing the world file)."""
    import networkx as nx

    import hg2prism
    from hg2prism.errors import InputError
    from hg2prism.frontends.arena import to_toml

    graph = nx.DiGraph()
    for u, v, p in ((1, 3, 0.9), (2, 4, 0.7), (3, 5, 0.6), (4, 5, 0.5)):
        graph.add_edge(u, v, p=p)
    where = {1: (0, 2), 2: (0, -1), 3: (1, 1), 4: (1, -1), 5: (2.5, 0)}
    world = hg2prism.world_from_graph(graph, entries=[1, 2], task="F asset5",
                                      trap_candidates=[3, 4], name="placed", positions=where)
    placed = dict(zip(world.arena.states, world.arena.positions))
    assert placed["outside"] == (-1.0, 0.5)
    assert all(placed[f"n{v}"] == (float(x), float(y)) for v, (x, y) in where.items())
    path = tmp_path / "placed.toml"
    path.write_text(to_toml(world))
    assert hg2prism.load_world(path).arena.positions == world.arena.positions
    for bad, word in (({1: (0, 0)}, "no position for 4 node(s)"),
                      ({**where, 3: (0, "y")}, "node 3: expected [x, y]"),
                      ({**where, 9: (0, 0)}, "9 is not a node")):
        with pytest.raises(InputError) as caught:
            hg2prism.world_from_graph(graph, entries=[1, 2], task="F asset5",
                                      trap_candidates=[3, 4], name="placed", positions=bad)
        assert caught.value.key == "positions" and word in caught.value.reason
