"""The standard exports of `check` and `run` (docs/semantics.md §3 "Exports", §6 "Exports" and
"Objectives"): the DFAs as HOA/DOT, the induced DTMC in PRISM's explicit format and Storm's DRN,
the per-move values of strategy.json, and the timing-aware objectives. Every number is compared
with an independent computation on the exported files (tests/reference_exports.py), with Storm
on the PRISM model, or with PRISM where it is installed."""

from __future__ import annotations

import functools
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
import stormpy
import stormpy.environments as environments

import reference
import reference_exports
import worldgen
from conftest import MODELS, names_in
from hg2prism import cli, pipeline
from hg2prism.analyses import simulation
from hg2prism.worldfile import load_world

TOL = 1e-6
STUCK = """name = "stuck"
[grid]
map = \"\"\"
#######
#@..#A#
#...#t#
#######
\"\"\"
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
rationality = 1.0
"""
# world1, a delayed world and a two-trap world with several hypotheses, a world whose goal
# cannot be reached and whose episodes never end, and a Bayesian world (whose states may differ
# in P2's action in force alone: the variables o<i>_played tell them apart).
WORLDS = {
    "world1": None,
    "world3_bayes": None,
    "gen_d1": worldgen.make_world(20009, name="gen_d1", delay=1, traps=1, window=1, nhyp=2),
    "gen_d0_l2": worldgen.make_world(28000, name="gen_d0_l2", delay=0, traps=2, window=2, nhyp=3),
    "stuck": STUCK,
}


@functools.cache
def world_path(name: str, folder: str) -> Path:
    if WORLDS[name] is None:
        return MODELS / f"{name}.toml"
    path = Path(folder) / f"{name}.toml"
    path.write_text(WORLDS[name])
    return path


@functools.cache
def checked(name: str, objective: str, folder: str, bound: int | None = None
            ) -> pipeline.CheckResult:
    out = Path(folder) / f"{name}_{objective}_{bound}"
    return pipeline.check(load_world(world_path(name, folder)), out, objective=objective,
                          bound=bound)


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(tmp_path_factory.mktemp("exports"))


def sound_value(model: object, prop: str) -> float:
    env = environments.sound()
    env.solver().min_max().precision = stormpy.Rational("1e-10")
    env.solver().native().precision = stormpy.Rational("1e-10")
    formula = stormpy.parse_properties(prop)[0]
    result = stormpy.model_checking(model, formula, environment=env)
    return float(result.get_value_vector()[model.initial_states[0]])


# ---------------------------------------------------------------------------------------------
# Automata
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["world1", "gen_d0_l2"])
def test_hoa_files_read_back_to_the_dfa(name: str, folder: str) -> None:
    result = checked(name, "pmax", folder)
    analysis = result.analysis
    names = analysis.ts.label_names
    labels = [n or None for n in names]
    letters = [labels[k] for k in analysis.ts.letters]
    formulas = [("task", analysis.world.formula, analysis.task)] + [
        (f"hypothesis_{i}", h, game.dfa) for i, (h, game) in
        enumerate(zip(analysis.world.hypotheses, analysis.games))]
    for stem, formula, dfa in formulas:
        text = (result.out / f"{stem}.hoa").read_text()
        initial, table = reference_exports.hoa_table(text, labels)
        ours = {q: {lab: int(dfa.delta[q, k]) for k, lab in enumerate(labels)}
                for q in range(dfa.n_states)}
        independent = reference.DFA(formula, labels, letters)
        assert table == ours == independent.delta, stem
        assert initial == dfa.initial == independent.init, stem
        # the acceptance marks are the DFA's final states
        assert reference_exports.hoa_marked_states(text) == set(dfa.accepting) == independent.acc
        dot = (result.out / f"{stem}.dot").read_text()
        assert dot.startswith("digraph ") and dot.rstrip().endswith("}")
        for q in range(dfa.n_states):
            assert re.search(rf"^  {q} \[label=", dot, re.MULTILINE), (stem, q)
            for target in set(ours[q].values()):
                assert f"  {q} -> {target} [" in dot, (stem, q, target)
        _svg_draws_the_dfa((result.out / f"{stem}.svg").read_text(), dot, ours, dfa, stem)


def _svg_draws_the_dfa(svg: str, dot: str, table: dict, dfa, stem: str) -> None:
    """The SVG (drawn without Graphviz) is well-formed and shows what the .dot file says: a
    circle per state (two for a final one, grey for a sink), an arrow per (state, successor)
    and the initial arrow, each edge's label, the formula."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(svg)
    ns = "{http://www.w3.org/2000/svg}"
    circles = root.findall(f"{ns}circle")
    assert len(circles) == dfa.n_states + len(dfa.accepting), stem
    assert sum(c.get("fill") == "lightgrey" for c in circles) == len(dfa.sink), stem
    arrows = [p for p in root.findall(f"{ns}path") if p.get("marker-end")]
    edges = {(q, t) for q, row in table.items() for t in row.values()}
    assert len(arrows) == len(edges) + 1, stem
    texts = [t.text for t in root.findall(f"{ns}text")]
    assert texts[0].startswith(f"DFA of {dfa.formula}")
    dot_labels = sorted(re.findall(r"^  \d+ -> \d+ \[label=\"(.*)\"\]$", dot, re.MULTILINE))
    shown = {str(q) for q in range(dfa.n_states)}
    edge_texts = sorted(t for t in texts[1:] if t not in shown | {"final", "sink"})
    assert edge_texts == dot_labels, stem


# ---------------------------------------------------------------------------------------------
# The induced DTMC
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", list(WORLDS))
def test_induced_dtmc_gives_the_deceptive_value(name: str, folder: str) -> None:
    result = checked(name, "pmax", folder)
    dtmc = reference_exports.ExplicitDTMC(result.out)
    assert dtmc.rows_sum_to_one()
    assert dtmc.labels["init"] == {0}          # PRISM's symbolic engine starts in state 0
    assert len(set(dtmc.valuations.values())) == dtmc.n     # states told apart by valuation
    value = result.results.deceptive_value
    assert dtmc.reach_goal() == pytest.approx(value, abs=TOL)
    # Storm reads the DRN and gives the same value
    model = stormpy.build_model_from_drn(str(result.out / "induced.drn"))
    assert model.nr_states == dtmc.n
    assert sound_value(model, (result.out / "goal.props").read_text()) == pytest.approx(value, abs=TOL)


def test_strategy_values_explain_the_moves(folder: str) -> None:
    """Each record's move is one of its best; the best value is the probability with which the
    induced DTMC reaches the goal from the record's state (solved on the exported files)."""
    result = checked("world1", "pmax", folder)
    dtmc = reference_exports.ExplicitDTMC(result.out)
    index, succs = dtmc.reference_succs()
    reach = reference.dtmc_reach(succs)
    by_valuation = {dtmc.valuations[s]: float(reach[i]) for s, i in index.items()}
    slots = result.analysis.world.window - 1
    records = json.loads((result.out / "strategy.json").read_text())
    assert dtmc.variables == ["s", "q", "hyp"] + [
        f"o{i}_{v}" for i in range(1, slots + 1) for v in ("s", "act")]
    moves = ["N", "E", "S", "W"]
    number = {name: i for i, name in enumerate(result.analysis.ts.arena.states)}
    assert records[0]["initial"] is True
    for record in records:
        values = record["values"]
        assert list(values) == moves
        assert values[record["action"]] >= max(values.values()) - 1e-8
        window = [(-1, -1)] * (slots - len(record["window"])) + [
            (number[o["state"]], moves.index(o["action"])) for o in record["window"]]
        key = (number[record["state"]], record["q"], record["hypothesis"], *sum(window, ()))
        assert max(values.values()) == pytest.approx(by_valuation.get(key, 0.0), abs=TOL)


def _prism() -> str | None:
    path = os.environ.get("PRISM") or shutil.which("prism")
    return path if path and os.access(path, os.X_OK) else None


PRISM = _prism()


@pytest.mark.skipif(PRISM is None, reason="PRISM is not installed (set PRISM=/path/to/prism "
                                          "or put prism on PATH)")
@pytest.mark.parametrize("name,objective,bound", [("world1", "pmax", None),
                                                  ("world3_bayes", "pmax", None),
                                                  ("gen_d1", "pmax", None),
                                                  ("gen_d1", "bounded", 7)])
def test_prism_reads_the_induced_dtmc(name: str, objective: str, bound: int | None,
                                      folder: str) -> None:
    """The command of docs/cli.md (plus -epsilon: PRISM's default stopping rule is relative), with
    the goal.props that check writes beside the induced DTMC."""
    result = checked(name, objective, folder, bound)
    out = result.out
    props = out / "goal.props"
    assert props.read_text().splitlines()[-1] == 'P=? [F "goal"]'
    command = [PRISM, "-importtrans", str(out / "induced.tra"), "-importstates",
               str(out / "induced.sta"), "-importlabels", str(out / "induced.lab"), "-dtmc",
               str(props), "-epsilon", "1e-12", "-maxiters", "10000000"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=600)
    output = done.stdout + done.stderr
    assert done.returncode == 0 and "Error" not in output, output[-3000:]
    found = re.findall(r"^Result: ([0-9.eE+-]+)", output, re.MULTILINE)
    assert len(found) == 1, output[-3000:]
    assert float(found[0]) == pytest.approx(result.results.objective.value, abs=TOL)


# ---------------------------------------------------------------------------------------------
# Objectives
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", list(WORLDS))
def test_lexicographic_keeps_the_value_and_is_not_slower(name: str, folder: str) -> None:
    default = checked(name, "pmax", folder)
    fast = checked(name, "lexicographic", folder)
    value = default.results.deceptive_value
    assert fast.results.deceptive_value == value
    fast_dtmc = reference_exports.ExplicitDTMC(fast.out)
    default_dtmc = reference_exports.ExplicitDTMC(default.out)
    assert fast_dtmc.reach_goal() == pytest.approx(value, abs=TOL)
    steps, default_steps = (fast_dtmc.expected_steps_to_absorption(),
                            default_dtmc.expected_steps_to_absorption())
    assert steps <= default_steps * (1 + 1e-9)
    # results.json reports the expected steps of the exported strategy (None: infinite)
    for result, expected in ((fast, steps), (default, default_steps)):
        reported = result.results.objective.expected_steps
        if expected == float("inf"):
            assert reported is None
        else:
            assert reported == pytest.approx(expected, rel=1e-9)
    if name == "stuck":
        assert steps == float("inf") and value == 0.0
    else:
        assert steps < float("inf")


@pytest.mark.parametrize("name,bound", [("world1", None), ("gen_d1", 7), ("gen_d0_l2", 12)])
def test_bounded_value_is_exact_within_horizon_of_its_dtmc(name: str, bound: int | None,
                                                           folder: str) -> None:
    result = checked(name, "bounded", folder, bound)
    objective = result.results.objective
    horizon = objective.bound
    assert horizon == (bound or result.analysis.world.simulation.horizon)
    dtmc = reference_exports.ExplicitDTMC(result.out)
    # exact within horizon of the exported (step-unfolded) DTMC, computed on its files
    assert dtmc.bounded_goal(horizon) == pytest.approx(objective.value, abs=TOL)
    assert dtmc.reach_goal() == pytest.approx(objective.value, abs=TOL)
    # the bounded value is Storm's Pmax=? [F<=H "goal"] on the hypergame model ...
    program = stormpy.parse_prism_program(str(result.out / "hypergame.prism"))
    model = stormpy.build_model(program)
    assert sound_value(model, f'Pmax=? [F<={horizon} "goal"]') == pytest.approx(objective.value,
                                                                               abs=TOL)
    # ... at least what the default strategy completes within the horizon
    default = checked(name, "pmax", folder)
    assert objective.value >= default.engine.induced_within(
        default.checked, default.strategy.choice, horizon) - TOL
    # every record's schedule covers the steps 0..H-1 and starts with the record's move
    for record in json.loads((result.out / "strategy.json").read_text()):
        runs = record["schedule"]
        assert runs[0][0] == 0 and runs[-1][1] == horizon - 1
        assert all(a[1] + 1 == b[0] for a, b in zip(runs, runs[1:]))
        assert runs[0][2] == record["action"]


# ---------------------------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------------------------

def test_bound_options_are_checked(folder: str, tmp_path: Path, capsys) -> None:
    world = str(world_path("stuck", folder))
    for args in (["check", world, "--bound", "5"],
                 ["check", world, "--objective", "bounded", "--bound", "0"],
                 ["run", world, "--objective", "bounded", "--bound", "5", "--horizon", "6"]):
        out = tmp_path / "out"
        assert cli.main(args + ["--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--bound" in err[0]
        assert not out.exists()


def test_exports_are_owned_by_check(folder: str, tmp_path: Path, capsys) -> None:
    """emit after check removes the exports, which would describe a model no longer checked."""
    world, out = str(world_path("stuck", folder)), tmp_path / "out"
    assert cli.main(["check", world, "--out", str(out), "--objective", "lexicographic"]) == 0
    summary = capsys.readouterr().out
    # its goal is walled off: never reached (it printed "none to the goal when reached")
    assert "expected steps infinite to the end, the goal is never reached" in summary
    written = set(names_in(out))
    assert {"task.hoa", "task.dot", "task.svg", "hypothesis_0.hoa", "hypothesis_0.dot",
            "hypothesis_0.svg", "induced.tra",
            "induced.sta", "induced.lab", "induced.drn"} <= written
    assert json.loads((out / "results.json").read_text())["objective"]["name"] == "lexicographic"
    assert cli.main(["emit", world, "--out", str(out)]) == 0
    assert set(names_in(out)) == {"hypergame.prism", "hypergame.props"}


def test_run_simulates_the_bounded_strategy(folder: str, tmp_path: Path) -> None:
    """`run --objective bounded` plays the step-dependent schedule (P1 counts the steps): the
    simulated completion within the horizon is consistent with the bounded value."""
    world = load_world(world_path("gen_d1", folder))
    result = pipeline.run(world, tmp_path / "out", episodes=4000, horizon=7, seed=11,
                          show_progress=False, objective="bounded")
    row = result.results.simulation.deceptive
    objective = result.results.objective
    assert objective.bound == 7
    assert row.exact_within_horizon == pytest.approx(objective.value, abs=TOL)
    completed = round(row.rate * row.episodes)
    low, high = simulation.wilson_interval(completed, row.episodes, 0.999)
    assert low <= objective.value <= high
    # the same world under the default strategy completes less within 7 steps, or as much
    default = checked("gen_d1", "pmax", folder)
    assert default.engine.induced_within(default.checked, default.strategy.choice, 7) <= objective.value + TOL


# ---------------------------------------------------------------------------------------------
# Probabilities as the world gives them (issue 25 item 4)
# ---------------------------------------------------------------------------------------------

def _significant_digits(text: str) -> int:
    mantissa = text.lower().split("e")[0].lstrip("-").replace(".", "")
    return len(mantissa.lstrip("0").rstrip("0") or "0")


def _written_probabilities(out: Path) -> dict[str, list[str]]:
    """Every probability of the induced DTMC (.tra, .drn) and of the hypergame's commands."""
    tra = [line.split()[2] for line in (out / "induced.tra").read_text().splitlines()[1:]]
    drn = re.findall(r"^\t\t\d+ : (\S+)$", (out / "induced.drn").read_text(), re.MULTILINE)
    prism = re.findall(r"([0-9][0-9.eE-]*)\s*:\s*\(", "\n".join(
        line for line in (out / "hypergame.prism").read_text().splitlines()
        if line.lstrip().startswith("[")))
    return {"induced.tra": tra, "induced.drn": drn, "hypergame.prism": prism}


@pytest.mark.parametrize("name", ["world1", "world2"])
def test_probabilities_are_written_as_the_world_gives_them(name: str, folder: str) -> None:
    """slip 0.1 gives 0.8 and 0.1 (and their sums 0.9, 0.2), never 0.7999999999999999."""
    out = (checked(name, "pmax", folder).out if name in WORLDS else
           pipeline.check(load_world(MODELS / f"{name}.toml"), Path(folder) / name).out)
    written = _written_probabilities(out)
    assert written["induced.tra"] and written["hypergame.prism"]
    assert sorted(written["induced.tra"]) == sorted(written["induced.drn"])
    for file, numbers in written.items():
        long = sorted({p for p in numbers if _significant_digits(p) >= 15})
        assert not long, (file, long[:5])
        assert set(numbers) <= {"0.8", "0.1", "0.9", "0.2", "1.0", "1"}, (file, set(numbers))


def test_a_short_decimal_moves_a_value_by_at_most_two_units_in_the_last_place() -> None:
    import math

    from hg2prism.prism.rendering import prism_number, probability_text, short_decimal

    assert (probability_text(1 - 2 * 0.1), probability_text(0.7999999999999999)) == ("0.8", "0.8")
    assert probability_text(0.7999999999999999 + 0.1) == "0.9"
    assert probability_text(0.1 + 0.05) == "0.15" and prism_number(0.1 + 0.05) == "0.15"
    rng = __import__("numpy").random.default_rng(7)
    for value in [*rng.random(2000), *(rng.random(200) * 1e-6), 1 / 3, 2 / 3, 0.0, 1.0]:
        snapped = short_decimal(value)
        assert abs(snapped - value) <= 2 * math.ulp(value), value
        assert float(probability_text(value)) == snapped
