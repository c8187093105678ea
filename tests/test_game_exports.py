"""PRISM-games exports (docs/semantics.md §7 last paragraph): the symmetric game as a csg and each G(x) as an smg.

These checks need no PRISM (tests/test_prism.py runs PRISM-games itself where installed): the
files are checked with Storm (stormpy) and by independent computations, on world1 and on world2
with delay 2:
  * smg (perceptual_<i>.prism): Storm parses and builds it. Its states are those of an explicit
    search of TS x DFA(x) x turn, P2 owns exactly the turn-0 states, every choice has exactly
    the successor distribution of docs/semantics.md §2, and value iteration on Storm's matrix (P1 maximising,
    P2 minimising) gives V_x of games.py at every turn-0 state. (stormpy 2.0 returns no result
    when asked to model-check an SMG, hence our own iteration.)
  * csg (symmetric.prism): Storm has no parser for csg (test_csg_with_stormpy skips with its
    message). The file is checked against the rules PRISM-games enforces for csg models
    (simulator/Updater.java: player modules have only labelled commands whose first action is
    the player's own; the players' actions are disjoint; independent modules synchronise only on
    players' actions) and then compiled, with PRISM-games' joint-action semantics, to an mdp whose
    actions are the joint actions "a1__a2" (idle when a player has no enabled command). Storm
    builds that mdp; each state must offer exactly (P1's moves) x (P2's allowed trap sets), the
    states are those of an explicit search of TS x DFA(phi), every joint action has the
    distribution of docs/semantics.md §2, min over a2 of max over a1 gives V_lead of games.py, and the
    matrix-game value (what PRISM-games computes for <<p1>>Pmax) is V_NE of baselines.py.
"""

from __future__ import annotations

import dataclasses
import functools
import re
from collections import deque
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import stormpy
import stormpy.models
from stormpy import developer

from conftest import MODELS
from hg2prism import pipeline
from hg2prism.opponent.perceptual_games import solve_game
from hg2prism.prism.arena_tables import p2_label
from hg2prism.prism.game_models import PROPERTY, write_game_models
from hg2prism.worldfile import load_world

TOL = 1e-6


def _slots(ts, place: int) -> list[int]:
    """P1's action slots at arena state `place` (none at TRAPPED and terminal states)."""
    return [] if place == ts.n_places else list(range(len(ts.arena.actions[place])))


def _slot(label: str) -> int:
    assert re.fullmatch(r"a\d+", label), label
    return int(label[1:])


def _p2(label: str) -> int:
    assert re.fullmatch(r"p2_\d+", label), label
    return int(label.removeprefix("p2_"))


# ------------------------------------------------------------------------------------------ setup

def _world(name: str):
    if name == "world1":
        return load_world(MODELS / "world1.toml")
    world = load_world(MODELS / "world2.toml")
    # delay > 0: the traps start on the first candidate
    return dataclasses.replace(world, delay=2, initial_standing=0)


CASES = ["world1", "world2_delay2"]


@functools.cache
def _exported(name: str, folder: str) -> tuple[pipeline.Analysis, dict[str, Path]]:
    analysis = pipeline.analyse(_world(name))
    paths = write_game_models(analysis, Path(folder) / name)
    return analysis, {p.name: p for p in paths}


@pytest.fixture(params=CASES)
def exported(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.getbasetemp() / "game_exports"
    return _exported(request.param, str(folder))


def _build(path: Path) -> object:
    program = stormpy.parse_prism_program(str(path))
    options = developer.BuilderOptions([])
    options.set_build_state_valuations(True)
    options.set_build_choice_labels(True)
    options.set_build_all_labels(True)
    return stormpy.build_model(program, options=options)


@dataclasses.dataclass
class Explicit:
    """A Storm model as arrays: variables per state, choices with labels, sparse transitions."""

    var: dict[str, np.ndarray]
    choice_state: np.ndarray
    choice_label: list[str]
    matrix: sp.csr_matrix           # [choices, states]
    labels: dict[str, np.ndarray]   # state labels as masks
    players: np.ndarray | None      # SMG: owner of each state
    initial: int


def _explicit(model: object) -> Explicit:
    n = model.nr_states
    valuations = model.state_valuations
    var = {v.name: np.asarray(valuations.get_int64_values(v), dtype=np.int64)
           for v in valuations.get_all_variables()}
    matrix = model.transition_matrix
    rows, cols, vals, choice_state, choice_label = [], [], [], [], []
    for s in range(n):
        for r in range(matrix.get_row_group_start(s), matrix.get_row_group_end(s)):
            choice_state.append(s)
            labels = model.choice_labeling.get_labels_of_choice(r)
            assert len(labels) == 1, f"choice {r} of state {s} has labels {labels}"
            choice_label.append(next(iter(labels)))
            for entry in matrix.get_row(r):
                rows.append(r)
                cols.append(entry.column)
                vals.append(entry.value)
    labels = {}
    for name in model.labeling.get_labels():
        mask = np.zeros(n, dtype=bool)
        mask[list(model.labeling.get_states(name))] = True
        labels[name] = mask
    players = (np.array([model.get_player_of_state(s) for s in range(n)])
               if model.model_type == stormpy.models.ModelType.SMG else None)
    return Explicit(var=var, choice_state=np.array(choice_state), choice_label=choice_label,
                    matrix=sp.csr_matrix((vals, (rows, cols)), shape=(len(choice_state), n)),
                    labels=labels, players=players, initial=model.initial_states[0])


# ------------------------------------------------------------------ expected state spaces

def _stop(ts, dfa, cell: int, q_prev: int) -> bool:
    """Goal or failure of the DFA one step behind: docs/semantics.md §§6, 15's absorbing states
    (trapped, q final or a sink, a terminal arena state)."""
    if cell == ts.n_places:
        return True
    q = dfa.delta[q_prev, ts.place_label[cell]]
    return q in dfa.accepting or q in dfa.sink or not ts.arena.actions[cell]


def _landing(ts, cell: int, slot: int, a2: int) -> dict[int, float]:
    """Where P1 lands (n_places = TRAPPED) with what probability (docs/semantics.md §§2, 15,
    read off the arena's tables); outcomes of probability 0 are dropped, outcomes landing in the
    same state merged."""
    arena = ts.arena
    j = a2 if arena.dest.shape[2] > 1 else 0
    out: dict[int, float] = {}
    for target, p in zip(arena.dest[cell, slot, j].tolist(), arena.prob[cell, slot, j].tolist()):
        if p > 0:
            if ts.traps_mode and ts.set_places[a2, target]:
                target = ts.n_places
            out[target] = out.get(target, 0.0) + p
    return out


def _allowed(ts, traps: int, countdown: int) -> list[int]:
    if ts.delay and countdown > 0:
        return [traps]
    return list(range(ts.n_sets))


def _after(ts, traps: int, countdown: int, new: int) -> tuple[int, int]:
    if not ts.delay:
        return 0, 0
    return new, (ts.delay if new != traps else max(countdown - 1, 0))


def _start(ts, dfa) -> tuple[int, int, int, int]:
    cell, traps, countdown = ts.decode(ts.start_state)
    return cell, traps, countdown, dfa.initial


def expected_csg_states(ts, dfa) -> set[tuple]:
    """(cell, traps, countdown, q_prev) reachable when both players move at once."""
    seen = {_start(ts, dfa)}
    todo = deque(seen)
    while todo:
        cell, traps, countdown, q = todo.popleft()
        if _stop(ts, dfa, cell, q):
            continue
        q_next = int(dfa.delta[q, ts.place_label[cell]])
        for t in _allowed(ts, traps, countdown):
            traps2, countdown2 = _after(ts, traps, countdown, t)
            for a in _slots(ts, cell):
                for cell2 in _landing(ts, cell, a, t):
                    state = (cell2, traps2, countdown2, q_next)
                    if state not in seen:
                        seen.add(state)
                        todo.append(state)
    return seen


def expected_smg_states(ts, dfa) -> set[tuple]:
    """(turn, cell, traps, countdown, q_prev): P2 places the traps at turn 0, P1 moves at turn 1.
    With delay 0 the trap choice is kept only during P1's turn (traps = 0 at turn 0)."""
    cell, traps, countdown, q = _start(ts, dfa)
    seen = {(0, cell, traps, countdown, q)}
    todo = deque(seen)
    while todo:
        turn, cell, traps, countdown, q = todo.popleft()
        successors = []
        if turn == 0 and not _stop(ts, dfa, cell, q):
            for t in _allowed(ts, traps, countdown):
                traps2, countdown2 = _after(ts, traps, countdown, t)
                successors.append((1, cell, t if not ts.delay else traps2, countdown2, q))
        elif turn == 1:
            q_next = int(dfa.delta[q, ts.place_label[cell]])
            for a in _slots(ts, cell):
                for cell2 in _landing(ts, cell, a, traps):
                    successors.append((0, cell2, traps if ts.delay else 0, countdown, q_next))
        for state in successors:
            if state not in seen:
                seen.add(state)
                todo.append(state)
    return seen


def _state_tuples(explicit: Explicit, names: list[str]) -> list[tuple]:
    n = explicit.matrix.shape[1]
    columns = [explicit.var.get(name, np.zeros(n, dtype=np.int64)) for name in names]
    return list(zip(*(c.tolist() for c in columns)))


def _csg_row(ts, dfa, state: tuple, label: str) -> dict[tuple, float]:
    cell, traps, countdown, q = state
    if label == "halt__idle":
        return {state: 1.0}
    move, place = label.split("__")
    a, t = _slot(move), _p2(place)
    traps2, countdown2 = _after(ts, traps, countdown, t)
    q2 = int(dfa.delta[q, ts.place_label[cell]])
    return {(cell2, traps2, countdown2, q2): p for cell2, p in _landing(ts, cell, a, t).items()}


def _smg_row(ts, dfa, state: tuple, label: str) -> dict[tuple, float]:
    turn, cell, traps, countdown, q = state
    if label == "done":
        return {state: 1.0}
    if label.startswith("p2_"):
        t = _p2(label)
        traps2, countdown2 = _after(ts, traps, countdown, t)
        return {(1, cell, t, countdown2, q): 1.0}
    a = _slot(label)
    q2 = int(dfa.delta[q, ts.place_label[cell]])
    return {(0, cell2, traps if ts.delay else 0, countdown, q2): p
            for cell2, p in _landing(ts, cell, a, traps).items()}


def _states_of(explicit: Explicit, names: list[str]) -> set[tuple]:
    return set(_state_tuples(explicit, names))


def _check_rows(explicit: Explicit, names: list[str], expected_row) -> None:
    """Every choice's successor distribution, over the variables `names`, is expected_row(state
    tuple, choice label) (a dict state tuple -> probability)."""
    states = _state_tuples(explicit, names)
    matrix = explicit.matrix
    for c, s in enumerate(explicit.choice_state):
        row = matrix.getrow(c)
        got: dict[tuple, float] = {}
        for column, p in zip(row.indices, row.data):
            got[states[column]] = got.get(states[column], 0.0) + p
        want = expected_row(states[s], explicit.choice_label[c])
        assert got.keys() == want.keys(), (states[s], explicit.choice_label[c], got, want)
        for key, p in want.items():
            assert abs(got[key] - p) <= 1e-12, (states[s], explicit.choice_label[c], key, got[key], p)


def _ts_index(ts, cell: np.ndarray, traps: np.ndarray, countdown: np.ndarray) -> np.ndarray:
    """TS state numbers (docs/semantics.md §2 numbering of dynamics.py); `trapped` for cell = TRAPPED."""
    if ts.delay:
        index = (cell * ts.n_sets + traps) * ts.phases + countdown
    else:
        index = cell.copy()
    return np.where(cell == ts.n_places, ts.trapped, index)


def _value_iteration(explicit: Explicit, combine, tolerance: float = 1e-13,
                     max_sweeps: int = 1_000_000) -> np.ndarray:
    """Least fixed point from below: goal states 1, failure states 0, `combine` folds the
    choice values of each other state."""
    goal, fail = explicit.labels["goal"], explicit.labels["fail"]
    v = goal.astype(float)
    for _ in range(max_sweeps):
        new = combine(explicit.matrix @ v)
        new[goal], new[fail] = 1.0, 0.0
        if np.abs(new - v).max() < tolerance:
            return new
        v = new
    raise AssertionError("value iteration did not converge")


# ------------------------------------------------------------------------------ all files

def test_writes_every_game_and_property(exported) -> None:
    analysis, paths = exported
    names = ["symmetric.prism", "symmetric.props"]
    for i in range(len(analysis.games)):
        names += [f"perceptual_{i}.prism", f"perceptual_{i}.props"]
    assert sorted(paths) == sorted(names)
    for name, path in paths.items():
        text = path.read_text()
        if name.endswith(".props"):
            assert text.splitlines()[-1] == PROPERTY
        else:
            assert text.startswith("// ")
            assert analysis.world.name in text.split("\n\n")[0]
            # the world it is of, as hypergame.prism says it (a reader can cite it)
            assert f"\n// digest       {analysis.world.digest()}\n" in text
            # PRISM keywords that Storm would accept but PRISM-games would not
            assert not re.search(r"\[(A|C|E|F|G|I|P|R|S|U|W|X)\]", text)
            assert not re.search(r"\bformula label\b", text)
    prop = stormpy.parse_properties(PROPERTY)[0]
    assert str(prop.get_raw_formula()) == PROPERTY


# ------------------------------------------------------------------------------ smg: G(x)

def test_perceptual_smg_builds_with_expected_states(exported) -> None:
    analysis, paths = exported
    ts = analysis.ts
    for i, game in enumerate(analysis.games):
        model = _build(paths[f"perceptual_{i}.prism"])
        assert model.model_type == stormpy.models.ModelType.SMG
        explicit = _explicit(model)
        expected = expected_smg_states(ts, game.dfa)
        assert model.nr_states == len(expected), (i, model.nr_states, len(expected))
        assert _states_of(explicit, ["turn", "place", "traps", "countdown", "q"]) == expected
        # P2 (player index 1) owns the turn-0 states, P1 the turn-1 states
        turn = explicit.var["turn"]
        assert ((explicit.players == 1) == (turn == 0)).all()
        # P1's choices are its action slots; P2's the actions she may play, or done when absorbing
        for s in range(model.nr_states):
            labels = sorted(explicit.choice_label[c] for c in np.flatnonzero(explicit.choice_state == s))
            if turn[s] == 1:
                place = explicit.var["place"][s]
                assert labels == sorted(f"a{i}" for i in _slots(ts, place))
            elif explicit.labels["goal"][s] or explicit.labels["fail"][s]:
                assert labels == ["done"]
            else:
                allowed = _allowed(ts, explicit.var["traps"][s] if ts.delay else 0,
                                   explicit.var["countdown"][s] if ts.delay else 0)
                assert labels == sorted(p2_label(t) for t in allowed)
        _check_rows(explicit, ["turn", "place", "traps", "countdown", "q"],
                    functools.partial(_smg_row, ts, game.dfa))


def test_perceptual_smg_values_are_the_games_values(exported) -> None:
    analysis, paths = exported
    ts = analysis.ts
    for i, game in enumerate(analysis.games):
        explicit = _explicit(_build(paths[f"perceptual_{i}.prism"]))
        n = explicit.matrix.shape[1]
        p1 = explicit.players == 0

        def combine(choice_values: np.ndarray) -> np.ndarray:
            best = np.full(n, -np.inf)
            worst = np.full(n, np.inf)
            np.maximum.at(best, explicit.choice_state, choice_values)
            np.minimum.at(worst, explicit.choice_state, choice_values)
            return np.where(p1, best, worst)

        values = _value_iteration(explicit, combine)
        turn0 = explicit.var["turn"] == 0
        cell, q_prev = explicit.var["place"], explicit.var["q"]
        ts_state = _ts_index(ts, cell, explicit.var.get("traps", 0 * cell),
                             explicit.var.get("countdown", 0 * cell))
        label = np.append(ts.place_label, 0)[cell]
        expected = game.values[ts_state, game.dfa.delta[q_prev, label]]
        np.testing.assert_allclose(values[turn0], expected[turn0], atol=TOL)
        v0 = game.values[ts.start_state, game.dfa.delta[game.dfa.initial, label[explicit.initial]]]
        assert abs(values[explicit.initial] - v0) <= TOL


# ------------------------------------------------------------------------ csg: symmetric game

def test_csg_with_stormpy(exported) -> None:
    """Storm has no csg front end; if a future stormpy parses csg, the model must build."""
    _, paths = exported
    try:
        program = stormpy.parse_prism_program(str(paths["symmetric.prism"]))
    except RuntimeError as error:
        message = " ".join(str(error).split())
        assert "csg" in message
        pytest.skip(f"stormpy {stormpy.__version__} cannot parse PRISM-games csg models: {message}")
    model = stormpy.build_model(program)
    assert model.nr_states > 0


_COMMAND = re.compile(r"^\s*\[([^\]]*)\]\s*(.*?)\s*->\s*(.*?);\s*$")


@dataclasses.dataclass
class Csg:
    text: str                                   # without comments
    players: dict[str, list[str]]               # player -> modules
    modules: dict[str, tuple[str, list[tuple[list[str], str, str]]]]  # name -> (body, commands)
    actions: dict[str, list[str]]               # player -> actions (in order of appearance)


def parse_csg(text: str) -> Csg:
    """The csg structure, checked against PRISM-games' rules for csg models."""
    text = re.sub(r"//[^\n]*", "", text)
    assert re.match(r"\s*csg\s", text), "the model type must be csg"
    players = {}
    for name, items in re.findall(r"\bplayer\s+(\w+)\s+(.*?)\s*\bendplayer\b", text, re.S):
        entries = [e.strip() for e in items.split(",")]
        assert all(re.fullmatch(r"\w+", e) for e in entries), "csg players are lists of modules"
        players[name] = entries
    assert list(players) == ["p1", "p2"]
    modules = {}
    for name, body in re.findall(r"\bmodule\s+(\w+)\b(.*?)\bendmodule\b", text, re.S):
        commands = []
        # statements end with ';' (a long one is wrapped over several lines)
        for line in (" ".join(part.split()) + ";" for part in body.split(";")[:-1]):
            if "->" in line:
                match = _COMMAND.match(line)
                assert match, f"unreadable command in module {name}: {line!r}"
                labels = [a.strip() for a in match.group(1).split(",") if a.strip()]
                commands.append((labels, match.group(2), match.group(3)))
        modules[name] = (body, commands)
    owner = {m: p for p, ms in players.items() for m in ms}
    assert set(owner) <= set(modules), "a player owns a module that does not exist"
    actions: dict[str, list[str]] = {p: [] for p in players}
    for name, (_, commands) in modules.items():
        if name in owner:
            for labels, _, _ in commands:
                assert labels, f"unlabelled command in player module {name}"
                if labels[0] not in actions[owner[name]]:
                    actions[owner[name]].append(labels[0])
    assert not set(actions["p1"]) & set(actions["p2"]), "the players' actions must be disjoint"
    player_of = {a: p for p, acts in actions.items() for a in acts}
    for name, (_, commands) in modules.items():
        for labels, _, _ in commands:
            assert labels, f"unlabelled command in module {name}"
            assert all(a in player_of for a in labels), f"{labels} in {name}: not players' actions"
            of = [player_of[a] for a in labels]
            assert len(set(of)) == len(of), f"{labels} in {name}: two actions of one player"
            if name in owner:
                assert player_of[labels[0]] == owner[name]
    return Csg(text=text, players=players, modules=modules, actions=actions)


def csg_to_mdp(csg: Csg) -> str:
    """The same game with PRISM-games' csg semantics, as an mdp over joint actions.

    Joint action (a1, a2) becomes the label a1__a2 (a player with no enabled command idles:
    "idle"). A command labelled with a set L of actions fires in every joint action containing
    L; a module that has no enabled command for a joint action does not move. Storm then makes
    one choice per joint action available in a state."""
    owner = {m: p for p, ms in csg.players.items() for m in ms}
    # a player's action is available where one of her commands starting with it is enabled;
    # she idles where none of her commands is
    available = {a: " | ".join(f"({g})" for m in ms for labels, g, _ in csg.modules[m][1]
                               if labels[0] == a)
                 for p, ms in csg.players.items() for a in csg.actions[p]}
    playing = {p: " | ".join(f"({available[a]})" for a in csg.actions[p]) or "false"
               for p in csg.players}
    joint = [(a1, a2) for a1 in csg.actions["p1"] + ["idle"] for a2 in csg.actions["p2"] + ["idle"]
             if (a1, a2) != ("idle", "idle")]
    chosen = {(a1, a2): [f"!({playing[p]})" if a == "idle" else f"({available[a]})"
                         for p, a in (("p1", a1), ("p2", a2))] for a1, a2 in joint}
    out = re.sub(r"\bplayer\s+\w+\s+.*?\bendplayer\b", "", csg.text, flags=re.S)
    out = re.sub(r"^\s*csg\b", "mdp", out, count=1)
    for name, (body, commands) in csg.modules.items():
        lines = ["  " + " ".join(part.split()) + ";" for part in body.split(";")[:-1]
                 if "->" not in part]           # statements: a long one is wrapped
        by_label: dict[str, list[str]] = {}
        for labels, guard, update in commands:
            for a1, a2 in joint:
                if set(labels) <= {a1, a2}:
                    by_label.setdefault((a1, a2), []).append(f"({guard})")
                    conditions = [f"({guard})"] + chosen[a1, a2]
                    lines.append(f"  [{a1}__{a2}] {' & '.join(conditions)} -> {update};")
        if name not in owner:
            # an independent module stays put in joint actions none of its commands match
            for (a1, a2), guards in by_label.items():
                conditions = [f"!({' | '.join(guards)})"] + chosen[a1, a2]
                lines.append(f"  [{a1}__{a2}] {' & '.join(conditions)} -> true;")
        out = out.replace(body, "\n".join(lines) + "\n", 1)
    return out


def test_symmetric_csg_is_the_concurrent_game(exported, tmp_path: Path) -> None:
    analysis, paths = exported
    ts, task = analysis.ts, analysis.task
    csg = parse_csg(paths["symmetric.prism"].read_text())
    assert csg.players == {"p1": ["robot"], "p2": ["adversary"]}
    slots = sorted({i for place in range(ts.n_places) for i in _slots(ts, place)})
    assert csg.actions["p1"] == [f"a{i}" for i in slots] + ["halt"]
    assert csg.actions["p2"] == [p2_label(t) for t in range(ts.n_sets)]
    mdp = tmp_path / "symmetric_joint.prism"
    mdp.write_text(csg_to_mdp(csg))
    model = _build(mdp)
    explicit = _explicit(model)

    # States: TS x DFA(phi) with the DFA one step behind.
    expected = expected_csg_states(ts, task)
    assert model.nr_states == len(expected)
    assert _states_of(explicit, ["place", "traps", "countdown", "q"]) == expected

    # Each state offers exactly P1's moves x P2's allowed sets, one choice each (PRISM-games
    # rejects a missing joint action or two active commands for one), and halt when absorbing.
    absorbing = explicit.labels["goal"] | explicit.labels["fail"]
    for s in range(model.nr_states):
        labels = [explicit.choice_label[c] for c in np.flatnonzero(explicit.choice_state == s)]
        assert len(labels) == len(set(labels))
        if absorbing[s]:
            assert labels == ["halt__idle"]
            continue
        allowed = _allowed(ts, explicit.var["traps"][s] if ts.delay else 0,
                           explicit.var["countdown"][s] if ts.delay else 0)
        place = explicit.var["place"][s]
        assert sorted(labels) == sorted(f"a{a}__{p2_label(t)}" for a in _slots(ts, place)
                                        for t in allowed)

    # Every joint action moves as docs/semantics.md §2 says.
    _check_rows(explicit, ["place", "traps", "countdown", "q"], functools.partial(_csg_row, ts, task))

    # Leader values on Storm's matrix (P2 commits to a2, P1 answers) are V_lead of games.py.
    n = model.nr_states
    a1 = np.array([label.split("__")[0] for label in explicit.choice_label])
    a2 = np.array([label.split("__")[1] for label in explicit.choice_label])
    a1_index = np.unique(a1, return_inverse=True)[1].reshape(-1)
    a2_names, a2_index = np.unique(a2, return_inverse=True)
    a2_index = a2_index.reshape(-1)

    def min_max(choice_values: np.ndarray) -> np.ndarray:
        table = np.full((n, a1_index.max() + 1, len(a2_names)), -np.inf)
        table[explicit.choice_state, a1_index, a2_index] = choice_values
        best = table.max(axis=1)                         # [n, a2]; -inf where a2 is not allowed
        return np.where(np.isfinite(best), best, np.inf).min(axis=1)

    values = _value_iteration(explicit, min_max)
    leader = solve_game(ts, task)
    cell, q_prev = explicit.var["place"], explicit.var["q"]
    ts_state = _ts_index(ts, cell, explicit.var.get("traps", 0 * cell), explicit.var.get("countdown", 0 * cell))
    label = np.append(ts.place_label, 0)[cell]
    np.testing.assert_allclose(values, leader.values[ts_state, task.delta[q_prev, label]], atol=TOL)
    assert abs(values[explicit.initial] - analysis.v_lead) <= TOL


def test_symmetric_csg_value_is_v_ne(exported, tmp_path: Path) -> None:
    """The matrix games Storm builds from the csg (through the joint-action mdp) have the value
    V_NE of hg2prism.analyses.baselines: what PRISM-games' <<p1>>Pmax=? [F "goal"] computes."""
    baselines = pytest.importorskip("hg2prism.analyses.baselines")
    if not all(hasattr(baselines, f) for f in ("ConcurrentGame", "solve_nash", "nash_baseline")):
        pytest.skip("hg2prism.analyses.baselines has no Nash solver")
    analysis, paths = exported
    ts, task = analysis.ts, analysis.task
    mdp = tmp_path / "symmetric_joint.prism"
    mdp.write_text(csg_to_mdp(parse_csg(paths["symmetric.prism"].read_text())))
    explicit = _explicit(_build(mdp))
    n = explicit.matrix.shape[1]
    n_a = ts.n_actions
    width = max(np.diff(explicit.matrix.indptr).max(), 1)
    nxt = np.repeat(np.arange(n), n_a * ts.n_sets * width).reshape(n, n_a, ts.n_sets, width)
    prob = np.zeros((n, n_a, ts.n_sets, width))
    prob[..., 0] = 1.0
    allowed = np.zeros((n, ts.n_sets), dtype=bool)
    goal, fail = explicit.labels["goal"], explicit.labels["fail"]
    allowed[goal | fail] = True
    for c, s in enumerate(explicit.choice_state):
        label = explicit.choice_label[c]
        if label == "halt__idle":
            continue
        move, place = label.split("__")
        i, t = _slot(move), _p2(place)
        row = explicit.matrix.getrow(c)
        k = len(row.indices)
        nxt[s, i, t, :k], prob[s, i, t, :] = row.indices, 0.0
        prob[s, i, t, :k] = row.data
        nxt[s, i, t, k:] = s
        allowed[s, t] = True
    game = baselines.ConcurrentGame(next=nxt, prob=prob, allowed=allowed, goal=goal, zero=fail)
    value = baselines.solve_nash(game).values[explicit.initial]
    assert abs(value - baselines.nash_baseline(ts, task).v_ne) <= TOL
