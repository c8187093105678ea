"""Experiments (hg2prism.experiments.sweep and .detect): the delay semantics the sweep relies on (docs/semantics.md §2), the
parameter sweep (paper Fig. 4) and the detection of a wrong opponent model (docs/semantics.md §9, paper
Fig. 5). The LRT statistic itself is tested in test_detection.py."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from conftest import MODELS, QUICK
from gridview import GridView, initial_trap_cells
from hg2prism import pipeline
from hg2prism.experiments import detect, sweep
from hg2prism.frontends import transition_system as build_transition_system
from hg2prism.frontends.grid import ACTIONS
from hg2prism.errors import InputError
from hg2prism.analyses.simulation import deviating_policy, leader_fallback
from hg2prism.strategy.records import Strategy
from hg2prism.worldfile import load_world

WORLD2 = MODELS / "world2.toml"

# Two trap candidates: c0 = (2, 2) on the top row, c1 = (3, 1) on the bottom row.
DELAYED = '''name = "delayed"
description = "tiny world with a 2-step delay on moving the single trap"

[grid]
map = """
######
#@t.A#
#..t.#
######
"""

[robot]
slip = 0.1

[task]
formula = "F A"

[adversary]
traps = 1
delay = 2
initial_traps = [[3, 1]]
hypotheses = ["F A"]

[inference]
window = 1
threshold = 1.0
rationality = 10.0
'''

# Two hypotheses so that window and threshold matter; no initial_traps in the file.
SMALL = '''name = "small"

[grid]
map = """
#######
#@.t.A#
#..t..#
#.B...#
#######
"""

[robot]
slip = 0.1

[task]
formula = "F A"

[adversary]
traps = 1
hypotheses = ["F A", "F B"]

[inference]
window = 2
threshold = 1.0
rationality = 5.0
'''

STEP = {"N": (0, 1), "E": (1, 0), "S": (0, -1), "W": (-1, 0)}
SIDES = {"N": "EW", "E": "NS", "S": "EW", "W": "NS"}


def write_world(folder: Path, name: str, text: str) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def delayed(tmp_path_factory: pytest.TempPathFactory):
    world = load_world(write_world(tmp_path_factory.mktemp("delayed"), "delayed", DELAYED))
    return world, build_transition_system(world)


@pytest.fixture(scope="module")
def world2(tmp_path_factory: pytest.TempPathFactory) -> pipeline.CheckResult:
    return pipeline.check(load_world(WORLD2), tmp_path_factory.mktemp("exp_world2"))


# ---------------------------------------------------------------------------------------------
# delay semantics on the TS tables (docs/semantics.md §2)
# ---------------------------------------------------------------------------------------------

def outcomes(ts, state: int, a1: int, a2: int) -> dict[int, float]:
    """The successor distribution the tables give, merged."""
    dist: dict[int, float] = {}
    for k in range(ts.succ.shape[-1]):
        p = float(ts.prob[state, a1, a2, k])
        if p > 0:
            s = int(ts.succ[state, a1, a2, k])
            dist[s] = dist.get(s, 0.0) + p
    return dist


def expected(world, ts, cell, traps: int, countdown: int, a1: str, a2: int) -> dict[int, float]:
    """docs/semantics.md §2 written out directly on cells, for one state (cell, T, c) and joint action."""
    view = GridView(world, ts)
    free = set(view.cells)
    trap_cells = set(view.trap_cells(a2))
    dist: dict[int, float] = {}
    slip = world.grid.slip
    for direction, p in ((a1, 1 - 2 * slip), (SIDES[a1][0], slip), (SIDES[a1][1], slip)):
        if p == 0:
            continue
        x, y = cell[0] + STEP[direction][0], cell[1] + STEP[direction][1]
        target = (x, y) if (x, y) in free else cell
        if target in trap_cells:
            succ = ts.trapped
        else:
            c = world.delay if a2 != traps else max(countdown - 1, 0)
            succ = ts.state(view.cell_index[target], a2, c)
        dist[succ] = dist.get(succ, 0.0) + p
    return dist


def test_delay_tables_follow_spec_section_2_everywhere(delayed) -> None:
    world, ts = delayed
    view = GridView(world, ts)
    assert ts.delay == 2 and view.trap_cells(0) == ((2, 2),) and view.trap_cells(1) == ((3, 1),)
    assert ts.decode(ts.start_state) == (view.cell_index[(1, 2)], 1, 0)   # initial traps, c = 0
    for state in range(ts.n_states - 1):
        cell, traps, countdown = ts.decode(state)
        for a1, name in enumerate(ACTIONS):
            for a2 in range(ts.n_sets):
                got = outcomes(ts, state, a1, a2)
                want = expected(world, ts, view.cells[cell], traps, countdown, name, a2)
                assert got.keys() == want.keys(), (state, name, a2)
                for s, p in want.items():
                    assert got[s] == pytest.approx(p, abs=1e-12)
    for a1 in range(4):
        for a2 in range(ts.n_sets):
            assert outcomes(ts, ts.trapped, a1, a2) == {ts.trapped: 1.0}


def test_p2_cannot_move_traps_while_the_countdown_is_positive(delayed) -> None:
    _, ts = delayed
    for state in range(ts.n_states - 1):
        _, traps, countdown = ts.decode(state)
        allowed = set(map(int, ts.allowed[state].nonzero()[0]))
        assert allowed == ({traps} if countdown > 0 else set(range(ts.n_sets))), state


def test_moving_traps_starts_the_countdown_and_keeping_them_does_not_restart_it(delayed) -> None:
    world, ts = delayed
    cell = GridView(world, ts).cell_index[(1, 1)]           # bottom-left corner, no trap candidate around
    east = ACTIONS.index("E")

    def countdowns(traps: int, countdown: int, a2: int) -> set[tuple[int, int]]:
        return {ts.decode(s)[1:] for s in outcomes(ts, ts.state(cell, traps, countdown), east, a2)
                if s != ts.trapped}

    assert countdowns(1, 0, 0) == {(0, 2)}     # moved: wait k = 2
    assert countdowns(0, 2, 0) == {(0, 1)}     # kept: count down
    assert countdowns(0, 1, 0) == {(0, 0)}
    assert countdowns(0, 0, 0) == {(0, 0)}     # kept at 0: stays 0, not restarted
    assert countdowns(0, 0, 1) == {(1, 2)}     # moved again


def test_a_robot_on_a_cell_where_a_trap_stays_is_trapped(delayed) -> None:
    world, ts = delayed
    view = GridView(world, ts)
    on_c0 = view.cell_index[(2, 2)]
    north = ACTIONS.index("N")                 # into the wall: the robot stays unless it slips
    # The trap stands on the robot's cell and must stay (countdown 1): trapped unless it leaves.
    dist = outcomes(ts, ts.state(on_c0, 0, 1), north, 0)
    assert dist[ts.trapped] == pytest.approx(0.8)
    assert {view.cells[ts.decode(s)[0]] for s in dist if s != ts.trapped} == {(1, 2), (3, 2)}
    # A trap P2 now sets on the robot's cell traps it the same way.
    dist = outcomes(ts, ts.state(on_c0, 1, 0), north, 0)
    assert dist[ts.trapped] == pytest.approx(0.8)
    # Moving the trap away from under the robot frees it.
    dist = outcomes(ts, ts.state(on_c0, 0, 0), north, 1)
    assert ts.trapped not in dist
    # Walking onto the standing trap: the intended move (0.8) is trapped.
    dist = outcomes(ts, ts.state(view.cell_index[(1, 2)], 0, 1), ACTIONS.index("E"), 0)
    assert dist[ts.trapped] == pytest.approx(0.8)


# ---------------------------------------------------------------------------------------------
# sweep
# ---------------------------------------------------------------------------------------------

def test_delay_sweep_equals_single_runs_on_world2(tmp_path: Path) -> None:
    world = load_world(WORLD2)
    rows = sweep.sweep(world, "delay", [0, 1, 2, 3], tmp_path / "sweep", show_progress=False)
    assert [r["delay"] for r in rows] == [0, 1, 2, 3]
    text = WORLD2.read_text()
    assert "delay = 0\n" in text and "initial_traps = [[2, 5]]" in text
    for row in rows:
        k = row["delay"]
        assert row["standing"] == ("x2_y5" if k else None)
        # docs/semantics.md §7: V_NE <= V_lead <= deceptive value at the initial state
        assert row["v_ne"] <= row["v_lead"] + 1e-6 <= row["deceptive_value"] + 2e-6
        if QUICK and k in (1, 2):       # make test: the first and last points re-solved alone
            continue
        single_path = write_world(tmp_path, f"world2_k{k}", text.replace("delay = 0\n", f"delay = {k}\n"))
        single = pipeline.check(load_world(single_path), tmp_path / f"single_{k}")
        assert row["deceptive_value"] == pytest.approx(single.results.deceptive_value, abs=1e-9)
        assert row["v_lead"] == pytest.approx(single.results.v_lead, abs=1e-9)
        assert row["states"] == single.results.states
        assert row["transitions"] == single.results.transitions
    values = [r["deceptive_value"] for r in rows]
    assert all(a < b for a, b in zip(values, values[1:]))          # the paper's Fig. 4
    assert values[0] == pytest.approx(0.709, abs=1e-3)
    assert values[3] == pytest.approx(0.8592, abs=1e-3)

    out = tmp_path / "sweep"
    saved = json.loads((out / "sweep.json").read_text())
    assert saved["parameter"] == "delay" and saved["values"] == [0, 1, 2, 3]
    assert saved["rows"] == json.loads(json.dumps(rows))
    with open(out / "sweep.csv", newline="") as handle:
        table = list(csv.DictReader(handle))
    assert [int(r["delay"]) for r in table] == [0, 1, 2, 3]
    assert [float(r["deceptive_value"]) for r in table] == values
    # the trap standing at the start of a delayed point (the values depend on it): sweep.csv
    # and the printed table give it, as sweep.json's rows do
    assert [r["standing"] for r in table] == ["", "x2_y5", "x2_y5", "x2_y5"]
    assert [r["standing"] for r in rows] == [None, "x2_y5", "x2_y5", "x2_y5"]
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "delay_2" / "results.json").exists()
    assert not list(out.glob(".*.tmp"))
    lines = sweep.sweep_summary_lines("delay", rows, "world2")
    assert lines[2].startswith("| delay | standing at the start | deceptive value |")
    assert any(line.startswith("| 0 | - | 0.7090 |") for line in lines)
    assert any(line.startswith("| 3 | x2_y5 | 0.8592 |") for line in lines)
    assert "V_static" not in lines[2]
    # with --deception's values, the printed table shows them as sweep.csv does
    worth = [{**row, "v_static": 0.5 + i / 10, "v_naive": 0.25, "value_of_deception": 0.125}
             for i, row in enumerate(rows)]
    lines = sweep.sweep_summary_lines("delay", worth, "world2")
    assert lines[2].split(" | ")[5:8] == ["V_static", "V_naive", "value of deception"]
    assert lines[3].count("---|") == len(lines[2].split(" | "))
    assert any(line.startswith("| 3 | x2_y5 | 0.8592 |")
               and " | 0.8000 | 0.2500 | 0.1250 | " in line for line in lines)


def test_sweep_other_parameters_and_the_initial_traps_rule(tmp_path: Path, capsys) -> None:
    world = load_world(write_world(tmp_path, "small", SMALL))
    assert initial_trap_cells(world) == ()
    # no initial_traps anywhere: the first candidate, (3, 3)
    point = sweep.sweep_world(world, "delay", 1)
    assert initial_trap_cells(point) == (world.grid.trap_candidates[0],) == ((3, 3),)
    rows = sweep.sweep(world, "window", ["1", "3"], tmp_path / "w", show_progress=True)
    assert [r["window"] for r in rows] == [1, 3]
    err = capsys.readouterr().err
    assert "sweep window=1 (1/2)" in err and "sweep window=3 (2/2)" in err
    assert "games:" not in err                      # the stages' own messages are not shown
    for row in rows:
        single = pipeline.check(sweep.sweep_world(world, "window", row["window"]),
                                tmp_path / f"single_w{row['window']}")
        assert row["deceptive_value"] == pytest.approx(single.results.deceptive_value, abs=1e-9)
    capsys.readouterr()
    rows = sweep.sweep(world, "threshold", [0.5, 2], tmp_path / "t", show_progress=False)
    assert [r["threshold"] for r in rows] == [0.5, 2.0]
    rows = sweep.sweep(world, "rationality", [1, 20.0], tmp_path / "r", show_progress=False)
    assert [r["rationality"] for r in rows] == [1.0, 20.0]
    assert capsys.readouterr().err == ""


def test_sweep_progress_is_the_package_bar(tmp_path: Path, capsys, monkeypatch) -> None:
    """The sweep draws its progress with progress.Bar, the package's one bar: on a terminal
    each point is shown under way ("sweep window=1 ...", then a carriage return) and replaced
    by its line with the count of points and the bar."""
    import sys

    from hg2prism import progress

    made = []

    class Recorded(progress.Bar):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(progress, "Bar", Recorded)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    world = load_world(write_world(tmp_path, "small", SMALL))
    sweep.sweep(world, "window", ["1", "3"], tmp_path / "w", show_progress=True)
    err = capsys.readouterr().err
    assert [(bar.unit, bar.total, bar.live) for bar in made] == [("points", 2, True)]
    assert err.startswith("sweep window=1 ...\rsweep window=1 (1/2) [##########..........]: "
                          "deceptive "), err
    assert "\nsweep window=3 ...\rsweep window=3 (2/2) [####################]: " in err
    assert progress.bar_text(1, 2, 20) == "#" * 10 + "." * 10
    assert progress.bar_text(7, 3, 4) == "####"             # never past the end


@pytest.mark.parametrize("parameter, values, key, fragment", [
    ("colour", [0.1], "--param", "unknown parameter 'colour'"),
    ("slip", [0.5], "--values", "slip value 0.5 must be a number in [0, 0.5)"),
    ("traps", [0], "--values", "traps value 0 must be an integer >= 1"),
    ("window", [0], "--values", "window value 0 must be an integer >= 1"),
    ("window", ["two"], "--values", "is not an integer >= 1"),
    ("delay", [-1], "--values", "delay value -1 must be an integer >= 0"),
    ("delay", [1.5], "--values", "must be an integer"),
    ("delay", [True], "--values", "must be an integer"),
    ("threshold", [0], "--values", "must be a number > 0"),
    ("threshold", ["nan"], "--values", "threshold value nan is not a finite number; expected "
                                       "a number > 0"),
    ("threshold", ["1e309"], "--values", "threshold value 1e309 is not a finite number"),
    ("rationality", [-2.0], "--values", "must be a number > 0"),
    # the world's own limit: the value's fault, said under --values (it named the world file)
    ("rationality", ["1e200"], "--values", "rationality must be at most 1e+100, got 1e+200"),
    ("delay", [], "--values", "at least one value"),
    ("delay", [1, "1"], "--values", "repeated"),
])
def test_sweep_rejects_bad_parameters(tmp_path: Path, parameter, values, key, fragment) -> None:
    world = load_world(WORLD2)
    with pytest.raises(InputError) as caught:
        sweep.sweep(world, parameter, values, tmp_path / "out", show_progress=False)
    assert caught.value.key == key and caught.value.file == "command line"
    assert fragment in caught.value.reason
    assert not (tmp_path / "out").exists()


def test_a_sweep_refused_whole_names_its_largest_point(tmp_path: Path) -> None:
    """When the size guard refuses every point, the refusal is the largest point's, so that
    the --max-states it gives lets every point through (it was the first point's: following
    it, delay 2 still failed); one point alone is refused in its own words."""
    from hg2prism.model import sizeguard

    world = load_world(WORLD2)
    sizes = [sizeguard.check_size(sweep.sweep_point(world, {"delay": d}), 10**9) for d in (1, 2)]
    assert sizes[0] < sizes[1]
    with pytest.raises(InputError) as caught:
        sweep.guard_points(world, [{"delay": 1}, {"delay": 2}], 10)      # the first smaller
    assert caught.value.key == "size" and caught.value.reason.startswith(
        "every point is refused; the largest, delay=2: the hypergame may have up to "
        f"{sizes[1]:,} states")
    assert caught.value.reason.endswith(f"pass --max-states {sizes[1]}")
    sweep.guard_points(world, [{"delay": 1}, {"delay": 2}], sizes[0])     # one fits: no refusal
    with pytest.raises(InputError) as caught:
        sweep.guard_points(world, [{"delay": 1}], 10)
    assert caught.value.reason.startswith("the hypergame may have up to ")


def test_bad_initial_traps_in_the_file_are_refused_with_delay_0(tmp_path: Path) -> None:
    """With delay 0 initial_traps are what a sweep over delay starts from: checked when the
    world is loaded (they were checked only when a sweep over delay needed them), an empty
    list naming none."""
    text = SMALL.replace("hypotheses = [", "initial_traps = [[1, 1]]\nhypotheses = [")
    with pytest.raises(InputError) as caught:
        load_world(write_world(tmp_path, "bad", text))
    assert caught.value.key == "adversary.initial_traps[0]"
    assert "not a trap candidate" in caught.value.reason
    world = load_world(write_world(tmp_path, "none", text.replace("[[1, 1]]", "[]")))
    assert world.initial_standing == 0


# ---------------------------------------------------------------------------------------------
# detection (docs/semantics.md §9)
# ---------------------------------------------------------------------------------------------

def strategy(result: pipeline.CheckResult) -> Strategy:
    return Strategy.from_records(result.records, result.analysis.ts,
                                 fallback=leader_fallback(result.analysis))


def test_no_false_alarm_when_p2_follows_the_model(world2) -> None:
    summary, batch = detect.detection_batch(world2.analysis, strategy(world2), 300, 200, 0,
                                                 alpha=0.05, epsilon=0.01, keep_steps=True)
    assert batch.rejections(300) == [None] * 300
    assert summary.off_record_steps == 0 and not batch.unpredicted and not batch.diverged
    steps = [s for episode in batch.steps.values() for s in episode]
    assert len(steps) == int(summary.lengths.sum())          # every transition was observed
    assert all(s.statistic < s.threshold for s in steps if s.threshold is not None)


def test_detection_when_p2_plays_at_random_from_step_1(world2) -> None:
    ts = world2.analysis.ts
    summary, batch = detect.detection_batch(
        world2.analysis, strategy(world2), 300, 200, 0, alpha=0.05, epsilon=0.01,
        p2_policy=deviating_policy(ts, 0), keep_steps=True)
    rejections = batch.rejections(300)
    detected = [e for e in range(300) if rejections[e] is not None]
    assert len(detected) >= 0.9 * 300
    assert len([e for e in batch.unpredicted if e in batch.first_rejection]) >= 0.95 * len(batch.unpredicted)
    for episode, records in batch.records.items():
        first = records[0]
        if first.n_a2 > 1 and first.a2 != first.predicted_a2:
            # one unpredicted action: G = 2 ln(2 / epsilon) = 10.6 > chi2(0.95, 1) = 3.84
            assert rejections[episode] == 1
        if episode not in batch.unpredicted:
            assert rejections[episode] is None     # P2 happened to play the prediction
    again = detect.detection_batch(world2.analysis, strategy(world2), 300, 200, 0, alpha=0.05,
                                        epsilon=0.01, p2_policy=deviating_policy(ts, 0))
    assert again[1].rejections(300) == rejections and (again[0].outcomes == summary.outcomes).all()


def test_detection_experiment_writes_a_consistent_report(world2, tmp_path: Path) -> None:
    world = world2.analysis.world
    k = world.detection.deviate_after
    result = detect.detection_experiment(world, world2, tmp_path, episodes=200,
                                              show_progress=False)
    assert json.loads((tmp_path / "detection.json").read_text()) == json.loads(json.dumps(result))
    assert (tmp_path / "detection.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    seeded = result["seeded_episode"]
    assert seeded["seed"] >= world.simulation.seed
    assert seeded["steps"] == len(seeded["per_step"]) > k + detect.STEPS_AFTER_DEVIATION
    assert all(s["predicted"] == s["played"] for s in seeded["per_step"][:k])
    first = next((s["n"] for s in seeded["per_step"] if s["rejected"]), None)
    assert seeded["detected_at"] == first
    assert first is None or first > k

    dev = result["deviation"]
    assert dev["episodes"] == 200 == dev["detected"] + dev["not_detected"]
    assert sum(dev["histogram"].values()) == dev["detected"]
    assert dev["detected_before_deviation"] == 0
    assert all(int(n) > k for n in dev["histogram"])
    assert dev["share_not_detected"] == pytest.approx(dev["not_detected"] / 200)

    comp = result["compliant"]
    assert comp["false_alarms"] == 0 and comp["false_alarm_rate"] == 0.0
    assert comp["completion"]["off_record_steps"] == 0
    assert 0 < comp["max_cusum_score"] < world.threshold

    reference = result["model_mismatch"]["reference"]["completion"]
    variants = result["model_mismatch"]["variants"]
    assert [v["p2_inference"] for v in variants[:4]] == [
        f"window {world.window + 1}", f"window {world.window - 1}",
        f"threshold {world.threshold / 2:.4g}", f"threshold {world.threshold * 2:.4g}"]
    for v in variants:
        c = v["completion"]
        assert c["ci95"][0] <= c["rate"] <= c["ci95"][1]
        assert 0.0 <= v["detection_rate"] <= 1.0
        if v["episodes_with_unpredicted_traps"] == 0:
            # P2 never played differently: the very same episodes (same seed), never detected
            assert v["detection_rate"] == 0.0 and c == reference
    # the threshold below every score P1 lets P2 reach makes P2 change her mind
    hasty = variants[-1]
    assert hasty["p2_threshold"] == pytest.approx(comp["max_cusum_score"] / 2)
    assert hasty["episodes_with_hypothesis_divergence"] > 0

    text = "\n".join(detect.detection_summary_lines(result))
    assert "seeded episode (seed" in text and "false alarms when P2 follows the model: 0/200" in text


def test_detection_experiment_rejects_bad_options(world2, tmp_path: Path) -> None:
    world = world2.analysis.world
    for options, key in (({"episodes": 0}, "--episodes"), ({"seed": -1}, "--seed"),
                         ({"horizon": 0}, "--horizon")):
        with pytest.raises(InputError) as caught:
            detect.detection_experiment(world, world2, tmp_path / "out", show_progress=False,
                                             **options)
        assert caught.value.key == key
    assert not (tmp_path / "out").exists()
    with pytest.raises(InputError):
        detect.detect(world, tmp_path / "out", episodes=0, show_progress=False)
    assert not (tmp_path / "out").exists()
    # a horizon of at most deviate_after (4): P2 never deviates, every batch the compliant one
    # (analysis stress test: all-zero bars, no word); deviate_after + 1 is accepted
    after = world.detection.deviate_after
    for run in (detect.detect, lambda *a, **k: detect.detection_experiment(a[0], world2, *a[1:],
                                                                          **k)):
        with pytest.raises(InputError, match=f"expected a horizon above {after}") as caught:
            run(world, tmp_path / "out", horizon=after, show_progress=False)
        assert caught.value.key == "--horizon"
    short = world.replace(simulation=dataclasses.replace(world.simulation, horizon=after))
    with pytest.raises(InputError, match=r"the world's \[simulation\] horizon"):
        detect.detect(short, tmp_path / "out", show_progress=False)
    assert not (tmp_path / "out").exists()
    detect.detection_experiment(world, world2, tmp_path / "out", episodes=5, horizon=after + 1,
                                show_progress=False)


def test_detect_checks_elsewhere_and_writes_only_the_detection_files(tmp_path: Path) -> None:
    world = load_world(write_world(tmp_path, "small", SMALL))
    result = detect.detect(world, tmp_path / "out", episodes=50, show_progress=False)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["detection.json",
                                                                     "detection.png",
                                                                     "detection.svg"]
    assert result["compliant"]["false_alarms"] == 0


def test_the_off_record_fallback_is_the_fastest_leader_answer_and_does_not_stall(
        tmp_path: Path) -> None:
    """Where P2's deviation takes P1 off its records, P1 falls back on its naive answer
    (docs/semantics.md §11): among the moves optimal in the leader game against the set its
    model predicts, the fastest. The first optimal move in slot order (the fallback before)
    stalls: on world2 with delay 2, P2 deviating from step 3, 233 of 1000 episodes ran to the
    horizon against 56 now."""
    from hg2prism.analyses.successor import Hypergame
    from hg2prism.model.product import product_state
    from hg2prism.opponent.perceptual_games import TurnBasedGame

    result = pipeline.check(load_world(WORLD2).replace(delay=2), tmp_path)
    analysis = result.analysis
    model = Hypergame(analysis.ts, analysis.task, analysis.games, analysis.inference)
    q_lead = TurnBasedGame(analysis.ts, analysis.task).q_values(
        analysis.leader.values.reshape(-1))                              # [G, A1, A2]
    n_q = analysis.task.n_states

    def slot_order(ts_state: int, q: int, memory) -> int:
        g = product_state(ts_state, q, n_q)
        return int(np.argmax(q_lead[g, :, model.predicted(ts_state, memory)]))

    fallback = leader_fallback(analysis)

    def naive(ts_state: int, q: int, memory) -> int:
        move = fallback(ts_state, q, memory)
        g = product_state(ts_state, q, n_q)
        best = q_lead[g, :, model.predicted(ts_state, memory)]
        assert best[move] >= best.max() - 1e-9           # optimal in the leader game
        return move

    truncated = {}
    for name, rule in (("naive", naive), ("slot order", slot_order)):
        summary, _ = detect.detection_batch(
            analysis, Strategy.from_records(result.records, analysis.ts, fallback=rule),
            400, 200, 0, alpha=0.05, epsilon=0.01, p2_policy=deviating_policy(analysis.ts, 2))
        assert summary.off_record_steps > 1000
        truncated[name] = summary.truncated
    assert truncated["naive"] < 0.1 * 400 and truncated["slot order"] > 0.15 * 400, truncated


def test_sweeping_the_observer_says_when_p2s_first_guess_changes(tmp_path: Path,
                                                                  caplog) -> None:
    """mir100's P2 first guesses x1; a Bayesian P2 with the uniform prior first guesses x0, so
    `--param inference` compared first guesses as well as observers without a word (analysis
    stress test): it now warns, once, and not for the world's own observer."""
    import logging

    with caplog.at_level(logging.WARNING, logger="hg2prism"):
        rows = sweep.sweep(load_world(MODELS / "mir100.toml"), "inference", ["cusum", "bayes"],
                           tmp_path / "out", show_progress=False)
    said = [r.getMessage() for r in caplog.records if "first guess" in r.getMessage()]
    assert said == ["warning: sweep inference=bayes: P2's first guess is x0 (the prior's most "
                    "probable hypothesis), not the world's x1: the point compares first "
                    "guesses as well as observers"]
    first = {row["inference"]: json.loads((tmp_path / "out" / f"inference_{row['inference']}" /
                                           "results.json").read_text())["parameters"]
             for row in rows}
    assert {k: v["initial_hypothesis"] for k, v in first.items()} == {"cusum": 1, "bayes": 0}


def test_a_sweeps_points_warnings_are_shown_with_the_point(tmp_path: Path, capsys) -> None:
    """A point's warning, collected while it is solved, is shown with the point's name, each
    point's (the command line shows a warning repeated word for word once: the points' were
    dropped as seen when replayed, on one process, the review found)."""
    from hg2prism import cli

    assert cli.main(["sweep", str(MODELS / "world3.toml"), "--param", "rationality", "--values",
                     "5", "10", "--storm-method", "fast", "--workers", "1",
                     "--out", str(tmp_path / "out")]) == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert [line.split(":")[0] for line in lines] == ["sweep rationality=5",
                                                      "sweep rationality=10"], lines
    assert all("Storm method 'fast' is not sound" in line for line in lines)

