"""Arena worlds (docs/semantics.md §15) in the independent reference (tests/reference.py,
tests/reference_bayes.py): the generated arenas (tests/arenagen.py) are valid and varied, the
reference solves them with values in [0, 1] and the orders §7 promises, and a grid world and its
arena form (one state per free cell, named by its coordinates, N E S W with the slip outcomes
merged) give the same values, sizes, P2 strategies and P1 strategy.

The last part compares the package with the reference on the random arenas. It needs the
package to load arena worlds and is skipped ("package does not load arena worlds yet") while
``hg2prism.worldfile`` refuses an ``[arena]`` table.
"""

from __future__ import annotations

import functools
import itertools
import math
import tomllib
from pathlib import Path

import pytest
import spot

import arenagen
import reference
import reference_bayes
import worldgen
from conftest import share

N_ARENAS = 40
SEED = 0
TOL = 1e-6
TEXTS = arenagen.arena_worlds(N_ARENAS, SEED)
NAMES = [f"arena{i:02d}" for i in range(N_ARENAS)]


@functools.cache
def arena_path(i: int, folder: str) -> Path:
    path = Path(folder) / f"{NAMES[i]}.toml"
    path.write_text(TEXTS[i])
    return path


def _kind(doc: dict) -> str:
    inf = doc["inference"]
    return inf.get("decision", "map") if inf.get("kind", "cusum") == "bayes" else "cusum"


@functools.cache
def solved(path: Path) -> reference.Reference:
    doc = tomllib.loads(path.read_text())
    return reference.solve(path) if _kind(doc) == "cusum" else reference_bayes.solve(path)


# ---------------------------------------------------------------------------------------------
# The generator
# ---------------------------------------------------------------------------------------------

def test_generated_arenas_are_valid_and_varied() -> None:
    assert arenagen.arena_worlds(N_ARENAS, SEED) == TEXTS        # deterministic
    assert arenagen.arena_worlds(3, SEED + 1) != TEXTS[:3]
    docs = [tomllib.loads(text) for text in TEXTS]
    seen = {"mode": set(), "kind": set(), "delay": set(), "window": set(), "two props": 0,
            "terminal": 0, "p2 name": 0, "p2 list": 0, "no default": 0, "traps": set(),
            "explicit AP": 0, "hypotheses": set()}
    for doc in docs:
        assert "grid" not in doc and "robot" not in doc
        arena = reference.parse_arena(doc)          # raises on anything §15 forbids
        ar, adv = doc["arena"], doc["adversary"]
        assert 4 <= len(arena["states"]) <= 12
        assert arena["actions"][arena["initial"]]
        for s, acts in arena["actions"].items():
            assert len(acts) <= 4
            for a in acts:
                for dist in arena["moves"][(s, a)].values():
                    assert 1 <= len(dist) <= 3 and all(p > 0 for p in dist.values())
                    assert math.fsum(dist.values()) == pytest.approx(1.0, abs=1e-12)
        # every (s, a1, a2) covered, exactly once
        for (s, a), row in arena["moves"].items():
            for b in (arena["a2"] if arena["p2"] == "general" else [None]):
                assert b in row or None in row
        assert 2 <= len(arena["propositions"]) <= 3
        assert not set(arena["propositions"]) & (reference.NOT_PROPOSITIONS | {"V"})
        assert frozenset() in set(arena["label"].values())       # a state without a label
        for formula in [doc["task"]["formula"], *adv["hypotheses"]]:
            f = spot.formula(formula)
            assert f.is_syntactic_guarantee(), formula
            assert {str(a) for a in spot.atomic_prop_collect(f)} <= set(arena["propositions"])
        assert 2 <= len(adv["hypotheses"]) <= 3 and len(set(adv["hypotheses"])) == len(
            adv["hypotheses"])
        seen["mode"].add(arena["p2"])
        seen["kind"].add(_kind(doc))
        seen["delay"].add(arena["delay"])
        seen["window"].add(doc["inference"]["window"])
        seen["hypotheses"].add(len(adv["hypotheses"]))
        seen["two props"] += any(len(lab) == 2 for lab in arena["label"].values())
        seen["terminal"] += any(not acts for acts in arena["actions"].values())
        seen["explicit AP"] += "propositions" in ar
        entries = ar.get("transition", [])
        seen["p2 name"] += any(isinstance(e.get("p2"), str) for e in entries)
        seen["p2 list"] += any(isinstance(e.get("p2"), list) for e in entries)
        seen["no default"] += any(None not in row for row in arena["moves"].values())
        if arena["p2"] == "traps":
            seen["traps"].add(adv["traps"])
            assert 2 <= len(arena["candidates"]) <= 4
            assert arena["initial"] not in arena["candidates"]
        if arena["delay"] > 0:
            assert arena["initial_action"] in arena["a2"]
    assert seen["mode"] == {"general", "traps"}
    assert seen["kind"] == {"cusum", "map", "sample"}
    assert seen["delay"] == {0, 1, 2} and seen["window"] == {1, 2, 3}
    assert seen["hypotheses"] == {2, 3} and seen["traps"] == {1, 2}
    for key in ("two props", "terminal", "explicit AP", "p2 name", "p2 list", "no default"):
        assert seen[key] >= 3, key


def test_parse_arena_refuses_what_section_15_forbids() -> None:
    assert tomllib.loads(TEXTS[0])["adversary"].get("actions"), "arena 0: general P2 actions"
    assert tomllib.loads(TEXTS[1])["adversary"].get("traps"), "arena 1: traps"

    def refused(edit, i: int = 0) -> None:
        doc = tomllib.loads(TEXTS[i])
        reference.parse_arena(doc)
        edit(doc)
        with pytest.raises(ValueError):
            reference.parse_arena(doc)

    def entry(doc):
        return doc["arena"]["transition"][0]

    refused(lambda d: entry(d).update(to={k: 2 * p for k, p in entry(d)["to"].items()}))
    refused(lambda d: entry(d).update(to={"nowhere": 1.0}))
    refused(lambda d: entry(d).update(p2="nobody"))
    refused(lambda d: d["arena"]["transition"].append(dict(entry(d))))   # covered twice
    refused(lambda d: d["arena"].update(
        propositions=reference.parse_arena(d)["propositions"] + ["F"]))
    refused(lambda d: entry(d).update(p2="idle"), 1)      # p2 only with general actions
    refused(lambda d: d["arena"].update(states=d["arena"]["states"] + ["not an identifier"]))


# ---------------------------------------------------------------------------------------------
# The reference on random arenas
# ---------------------------------------------------------------------------------------------

def v_coop(w: reference.World) -> float:
    """Pmax of the task when P2 helps P1 (both maximise over (a1, a2)): every value is at most
    this."""
    dfa = w.task_dfa
    nodes = {}
    for v in w._ts_states:
        if not w.terminal(v):
            for q in range(dfa.n):
                if q not in dfa.acc and q not in dfa.sink:
                    nodes[(v, q)] = len(nodes)
    state_pairs, pair_rows, row_succ = [], [], []
    for i, (v, q) in enumerate(nodes):
        rows = []
        for a2, a1 in itertools.product(w.A2(v), w.actions(v)):
            succ = []
            for v2, p in w.outcomes(v, a1, a2).items():
                t = w._target(dfa, q, v2)
                succ.append((t if t in ("goal", "fail") else nodes[t], p))
            rows.append(len(row_succ))
            row_succ.append(succ)
        state_pairs.append([i])
        pair_rows.append(rows)
    x = reference.solve_reach_game(state_pairs, pair_rows, row_succ)
    s0 = w.initial()
    if s0 in ("goal", "fail"):
        return float(s0 == "goal")
    return float(x[nodes[(s0[0], s0[1])]])


@pytest.mark.parametrize("i", share(range(N_ARENAS)), ids=share(NAMES))   # every fourth under `make test`
def test_reference_solves_random_arenas(i: int, world_dir: Path) -> None:
    path = arena_path(i, str(world_dir))
    ref = solved(path)
    w = ref.world
    assert w.kind == "arena"
    assert 0.0 <= ref.value <= 1.0 and 0.0 <= ref.v_lead <= 1.0
    assert ref.states >= 1 and ref.transitions >= ref.states
    # §7: V_lead <= deceptive value (P2's inference-driven strategy is a leader-game strategy;
    # not with "sample", where P1 moves before P2's draw), and nothing beats a helping P2
    if _kind(w.doc) != "sample":
        assert ref.v_lead <= ref.value + 1e-9
    assert ref.value <= v_coop(w) + 1e-9
    # the optimal strategy, exported as records and evaluated again, keeps the value
    records = ref.optimal_records()
    if records:
        assert ref.strategy_value(records) == pytest.approx(ref.value, abs=1e-9)
    # P2's strategy is one of her available actions at every TS state the games cover
    for x in range(len(w.hyps)):
        for v in w._ts_states:
            assert w.pi2(x, v) in w.A2(v)


def test_random_arenas_are_not_all_trivial(world_dir: Path) -> None:
    refs = [solved(arena_path(i, str(world_dir))) for i in range(N_ARENAS)]
    assert sum(0 < r.value < 1 for r in refs) >= 8
    assert sum(r.value > r.v_lead + 1e-6 for r in refs) >= 4     # deception pays
    assert max(r.states for r in refs) >= 100


def test_terminal_states_end_the_episode(tmp_path: Path) -> None:
    """Reaching a terminal state is the goal when the DFA state after its label is final,
    a failure otherwise; a trap on a terminal state still traps."""
    text = """
name = "terminals"
[arena]
states = ["start", "win", "lose", "mid"]
initial = "start"
[arena.labels]
win = ["gold"]
mid = ["gold", "alarm"]
[[arena.transition]]
state = "start"
action = "bold"
to = { win = 0.5, lose = 0.5 }
[[arena.transition]]
state = "start"
action = "safe"
to = { mid = 0.3, start = 0.7 }
[[arena.transition]]
state = "mid"
action = "on"
to = { win = 1.0 }
[task]
formula = "F gold"
[adversary]
traps = 1
trap_candidates = ["win", "mid"]
hypotheses = ["F gold", "F alarm"]
initial_hypothesis = 1
[inference]
window = 1
threshold = 1.0
rationality = 2.0
"""
    path = tmp_path / "terminals.toml"
    path.write_text(text)
    ref = reference.solve(path)
    w = ref.world
    assert w.terminal("win") and w.terminal("lose") and not w.terminal("mid")
    assert w.actions("start") == ["bold", "safe"]
    dfa = w.task_dfa
    q0 = dfa.step(dfa.init, w.label("start"))
    # In G(F gold), V(start) = 1/2: trapping mid leaves "bold" (win: goal, lose: failure, each
    # 1/2); trapping win makes "bold" worthless (a trap on a terminal state traps) but "safe"
    # gets 0.3 + 0.7 V(start).
    assert w.V("F gold", "start", q0) == pytest.approx(0.5, abs=1e-12)
    assert w.Q("F gold", "start", q0, "bold", ("win",)) == pytest.approx(0.0, abs=1e-12)
    assert w.Q("F gold", "start", q0, "bold", ("mid",)) == pytest.approx(0.5, abs=1e-12)
    assert w.Q("F gold", "start", q0, "safe", ("win",)) == pytest.approx(0.65, abs=1e-12)
    assert w.Q("F gold", "start", q0, "safe", ("mid",)) == pytest.approx(0.35, abs=1e-12)
    # under either hypothesis P2 traps mid (under "F alarm" mid is the only alarm)
    assert w.pi2(0, "start") == w.pi2(1, "start") == ("mid",)
    # so P1 can only gamble: the start state, goal and fail (each with its self-loop)
    assert (ref.value, ref.v_lead) == (pytest.approx(0.5), pytest.approx(0.5))
    assert (ref.states, ref.transitions) == (3, 6)
    assert ref.strategy_value(ref.optimal_records()) == pytest.approx(0.5, abs=1e-12)


# ---------------------------------------------------------------------------------------------
# A grid world and its arena form
# ---------------------------------------------------------------------------------------------

MOVES = {"N": (0, 1), "E": (1, 0), "S": (0, -1), "W": (-1, 0)}
SIDES = {"N": "EW", "S": "EW", "E": "NS", "W": "NS"}


def grid_as_arena(text: str) -> str:
    """The arena form of a grid world file (§15, last items), written from the SPEC here
    (independently of reference.grid_arena): one state per free cell named x<x>_y<y>, in map
    reading order; the actions N, E, S, W with the intended move (1 - 2 slip) and the two
    perpendicular ones (slip each), merged when they land on the same cell; labels obs / the
    region letter; P2's trap candidates the `t` cells in reading order."""
    doc = tomllib.loads(text)
    rows = [r for r in doc["grid"]["map"].split("\n") if r.strip()]
    height = len(rows)
    cells = {}
    for i, row in enumerate(rows):
        for x, ch in enumerate(row):
            if ch != "#":
                cells[(x, height - 1 - i)] = ch

    def name(c):
        return f"x{c[0]}_y{c[1]}"

    slip = doc["robot"]["slip"]
    letters = sorted({ch for ch in cells.values() if ch.isupper()})
    lines = [f'name = "{doc["name"]}_arena"', "[arena]",
             "states = [" + ", ".join(f'"{name(c)}"' for c in cells) + "]",
             f'initial = "{name(next(c for c, ch in cells.items() if ch == "@"))}"',
             "propositions = [" + ", ".join(f'"{p}"' for p in ["obs", *letters]) + "]",
             "[arena.labels]"]
    for c, ch in cells.items():
        if ch == "o" or ch.isupper():
            lines.append(f'{name(c)} = ["{"obs" if ch == "o" else ch}"]')
    for c in cells:
        for a in "NESW":
            to: dict[str, float] = {}
            for d, p in [(a, 1 - 2 * slip), (SIDES[a][0], slip), (SIDES[a][1], slip)]:
                if p == 0:
                    continue
                target = (c[0] + MOVES[d][0], c[1] + MOVES[d][1])
                target = target if target in cells else c
                to[name(target)] = to.get(name(target), 0.0) + p
            lines += ["[[arena.transition]]", f'state = "{name(c)}"', f'action = "{a}"',
                      "to = { " + ", ".join(f"{k} = {p!r}" for k, p in to.items()) + " }"]
    adv = dict(doc["adversary"])
    adv["trap_candidates"] = [name(c) for c, ch in cells.items() if ch == "t"]
    adv["initial_traps"] = [name(tuple(c)) for c in adv.get("initial_traps", [])]
    lines.append("[adversary]")
    lines += [f"{k} = {_toml(v)}" for k, v in adv.items()]
    for table in ("task", "inference"):
        lines.append(f"[{table}]")
        lines += [f"{k} = {_toml(v)}" for k, v in doc[table].items()]
    return "\n".join(lines) + "\n"


def _toml(value) -> str:
    if isinstance(value, str):
        return '"' + value.replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(value)


SMALL_GRID = '''name = "small"
[grid]
map = """
#####
#@.A#
#t#t#
#.oB#
#####
"""
[robot]
slip = 0.1
[task]
formula = "!obs U B"
[adversary]
traps = 1
delay = 0
hypotheses = ["!obs U B", "F A"]
initial_hypothesis = 1
[inference]
window = 2
threshold = 1.0
rationality = 5.0
'''

# The corridor "#@tA#" by hand: slip 0.1, so N and S from a cell move east or west with 0.1
# each, and a wall keeps the robot in place.
CORRIDOR_GRID = '''name = "corridor"
[grid]
map = """
#####
#@tA#
#####
"""
[robot]
slip = 0.1
[task]
formula = "F A"
[adversary]
traps = 1
delay = 1
initial_traps = [[2, 1]]
hypotheses = ["F A"]
[inference]
window = 1
threshold = 1.0
rationality = 3.0
'''
CORRIDOR_ARENA = '''name = "corridor_arena"
[arena]
states = ["x1_y1", "x2_y1", "x3_y1"]
initial = "x1_y1"
propositions = ["obs", "A"]
[arena.labels]
x3_y1 = ["A"]
''' + "".join(
    f'[[arena.transition]]\nstate = "{s}"\naction = "{a}"\nto = {{ {to} }}\n'
    for s, a, to in [
        ("x1_y1", "N", "x1_y1 = 0.9, x2_y1 = 0.1"), ("x1_y1", "E", "x2_y1 = 0.8, x1_y1 = 0.2"),
        ("x1_y1", "S", "x1_y1 = 0.9, x2_y1 = 0.1"), ("x1_y1", "W", "x1_y1 = 1.0"),
        ("x2_y1", "N", "x2_y1 = 0.8, x3_y1 = 0.1, x1_y1 = 0.1"),
        ("x2_y1", "E", "x3_y1 = 0.8, x2_y1 = 0.2"),
        ("x2_y1", "S", "x2_y1 = 0.8, x3_y1 = 0.1, x1_y1 = 0.1"),
        ("x2_y1", "W", "x1_y1 = 0.8, x2_y1 = 0.2"),
        ("x3_y1", "N", "x3_y1 = 0.9, x2_y1 = 0.1"), ("x3_y1", "E", "x3_y1 = 1.0"),
        ("x3_y1", "S", "x3_y1 = 0.9, x2_y1 = 0.1"), ("x3_y1", "W", "x2_y1 = 0.8, x3_y1 = 0.2"),
    ]) + '''[task]
formula = "F A"
[adversary]
traps = 1
delay = 1
trap_candidates = ["x2_y1"]
initial_traps = ["x2_y1"]
hypotheses = ["F A"]
[inference]
window = 1
threshold = 1.0
rationality = 3.0
'''


def test_the_converter_writes_the_hand_written_arena() -> None:
    ours = reference.parse_arena(tomllib.loads(grid_as_arena(CORRIDOR_GRID)))
    hand = reference.parse_arena(tomllib.loads(CORRIDOR_ARENA))
    assert ours["states"] == hand["states"] and ours["label"] == hand["label"]
    assert ours["actions"] == hand["actions"] and ours["a2"] == hand["a2"]
    assert ours["initial_action"] == hand["initial_action"]
    assert ours["moves"].keys() == hand["moves"].keys()
    for key, row in ours["moves"].items():
        assert row[None].keys() == hand["moves"][key][None].keys(), key
        for t, p in row[None].items():
            assert p == pytest.approx(hand["moves"][key][None][t], abs=1e-15)


def _rename(v, names):
    """A grid TS state in the arena's naming."""
    if v == reference.TRAPPED:
        return v
    if len(v) == 2:
        return names[v]
    return (names[v[:2]], tuple(names[c] for c in v[2]), v[3])


def _variants():
    small = tomllib.loads(SMALL_GRID)
    yield "small", SMALL_GRID
    yield "small_d1", SMALL_GRID.replace("delay = 0", "delay = 1\ninitial_traps = [[1, 2]]")
    yield "small_l2_d2", SMALL_GRID.replace("traps = 1\ndelay = 0",
                                            "traps = 2\ndelay = 2\ninitial_traps = [[1, 2], [3, 2]]")
    yield "small_slip0_w3", SMALL_GRID.replace("slip = 0.1", "slip = 0.0").replace(
        "window = 2", "window = 3")
    bayes = SMALL_GRID.replace("initial_hypothesis = 1\n", "").replace("threshold = 1.0\n", "")
    yield "small_map", bayes.replace("[inference]", '[inference]\nkind = "bayes"\nprior = [1, 3]')
    yield "small_sample", bayes.replace("[inference]", '[inference]\nkind = "bayes"\n'
                                        'decision = "sample"')
    yield "corridor", CORRIDOR_GRID
    assert small["adversary"]["delay"] == 0
    family = dict(worldgen.world_family())
    for name in ("fam00_d0_l1_w1_x2", "fam01_d1_l1_w1_x3", "fam11_d2_l2_w1_x1",
                 "fam40_tx_d0_l1_w2"):
        yield name, family[name]


VARIANTS = dict(_variants())


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_grid_and_its_arena_form_agree(name: str, tmp_path: Path) -> None:
    grid_text = VARIANTS[name]
    arena_text = grid_as_arena(grid_text)
    (tmp_path / "grid.toml").write_text(grid_text)
    (tmp_path / "arena.toml").write_text(arena_text)
    bayes = 'kind = "bayes"' in grid_text
    module = reference_bayes.BayesWorld if bayes else reference.World
    g, a = module(tmp_path / "grid.toml"), module(tmp_path / "arena.toml")
    assert (g.kind, a.kind) == ("grid", "arena")
    rg, ra = g.solve(), a.solve()
    assert (ra.states, ra.transitions) == (rg.states, rg.transitions)
    assert ra.value == pytest.approx(rg.value, abs=1e-12)
    assert ra.v_lead == pytest.approx(rg.v_lead, abs=1e-12)
    names = {c: f"x{c[0]}_y{c[1]}" for c in g.arena["states"]}
    # the same TS, the same DFA numbering, the same P2 strategies
    assert [_rename(v, names) for v in g._ts_states] == a._ts_states
    assert g.task_dfa.delta.keys() == a.task_dfa.delta.keys()
    for x in range(len(g.hyps)):
        for v in g._ts_states:
            assert tuple(names[c] for c in g.pi2(x, v)) == a.pi2(x, _rename(v, names))
    # P1's grid strategy, renamed, is optimal in the arena form
    records = rg.optimal_records()
    for rec in records:
        _rename_record(rec, names)
        for o in rec["window"]:
            _rename_record(o, names)
    assert ra.strategy_value(records) == pytest.approx(ra.value, abs=1e-9)


def _rename_record(rec: dict, names: dict) -> None:
    rec["cell"] = names[tuple(rec["cell"])]
    if rec.get("traps") is not None:
        rec["traps"] = [names[tuple(c)] for c in rec["traps"]]
    if rec.get("played") is not None:
        rec["played"] = [names[tuple(c)] for c in rec["played"]]


# ---------------------------------------------------------------------------------------------
# The package against the reference (once the package loads arena worlds)
# ---------------------------------------------------------------------------------------------

@functools.cache
def _package_refusal() -> str | None:
    """None when hg2prism.worldfile loads an arena world; the reason to skip otherwise."""
    try:
        from hg2prism.errors import InputError
        from hg2prism.worldfile import world_from_toml
    except ImportError as error:           # pragma: no cover - the package is installed
        return f"hg2prism not importable: {error}"
    try:
        world_from_toml(CORRIDOR_ARENA, name="corridor_arena")
    except InputError as error:
        if "arena" in str(error) or "grid" in str(error):
            return "package does not load arena worlds yet"
        raise
    return None


def _needs_package() -> None:
    reason = _package_refusal()
    if reason is not None:
        pytest.skip(reason)


@functools.cache
def package_check(i: int, folder: str):
    from hg2prism import pipeline, progress
    from hg2prism.worldfile import load_world
    path = arena_path(i, folder)
    with progress.quiet():
        return pipeline.check(load_world(path), Path(folder) / f"{NAMES[i]}_out")


@pytest.mark.parametrize("i", share(range(N_ARENAS)), ids=share(NAMES))   # every fourth under `make test`
def test_package_matches_the_reference_on_random_arenas(i: int, world_dir: Path) -> None:
    """Mirrors tests/test_core.py and tests/test_bayes.py on grid worlds: the deceptive value,
    V_lead and the canonical size equal the reference's, and the strategy Storm's scheduler
    gives induces the deceptive value."""
    _needs_package()
    result = package_check(i, str(world_dir))
    ref = solved(arena_path(i, str(world_dir)))
    assert result.results.deceptive_value == pytest.approx(ref.value, abs=TOL)
    assert result.results.v_lead == pytest.approx(ref.v_lead, abs=TOL)
    assert (result.results.states, result.results.transitions) == (ref.states, ref.transitions)
    assert result.engine.induced_probability(result.checked, result.strategy.choice) == \
        pytest.approx(result.results.deceptive_value, abs=TOL)


@pytest.mark.parametrize("name", ["small", "small_l2_d2", "small_sample", "corridor",
                                  "fam01_d1_l1_w1_x3"])
def test_package_gives_a_grid_and_its_arena_form_the_same_numbers(name: str,
                                                                  tmp_path: Path) -> None:
    """§15: every value and canonical size of a grid world equals that of its arena form (a
    few of the variants above, to keep the file's runtime down)."""
    _needs_package()
    import hg2prism
    grid = hg2prism.solve(hg2prism.world_from_toml(VARIANTS[name], name=name))
    arena = hg2prism.solve(hg2prism.world_from_toml(grid_as_arena(VARIANTS[name]),
                                                    name=f"{name}_arena"))
    assert arena.deceptive_value == pytest.approx(grid.deceptive_value, abs=TOL)
    assert arena.v_lead == pytest.approx(grid.v_lead, abs=TOL)
    assert (arena.states, arena.transitions) == (grid.states, grid.transitions)
