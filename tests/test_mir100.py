"""MIR100, the attack graph of docs/results.md "MIR100": `run` on models/mir100.toml gives what
docs/results.md reports, the deceptive value is the value of the DTMC the strategy induces (induced.tra/.lab
solved here with a plain linear solve), and each simulated completion rate lies in its 95 %
Wilson interval around the exact within-horizon probability."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from conftest import MODELS
from hg2prism import pipeline
from hg2prism.worldfile import load_world

DOCS = Path(__file__).resolve().parent.parent / "docs"
RESULTS = DOCS / "results.md"     # the MIR100 section
WORLDS = DOCS / "worlds.md"       # the arena example


@pytest.fixture(scope="module")
def mir100(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("mir100")
    pipeline.run(load_world(MODELS / "mir100.toml"), out)
    return out


def induced_value(folder: Path) -> float:
    """P(F goal) from the initial state of induced.tra/.lab: x = P x on the states that can
    reach goal (goal = 1), solved directly."""
    lines = (folder / "induced.tra").read_text().split("\n")
    n = int(lines[0].split()[0])
    p = np.zeros((n, n))
    for line in lines[1:]:
        if line.strip():
            s, t, prob = line.split()
            p[int(s), int(t)] += float(prob)
    labels = (folder / "induced.lab").read_text().split("\n")
    names = dict(item.split("=") for item in labels[0].split())
    goal_id = next(k for k, v in names.items() if v == '"goal"')
    init_id = next(k for k, v in names.items() if v == '"init"')
    goal, init = np.zeros(n, dtype=bool), None
    for line in labels[1:]:
        if line.strip():
            s, ids = line.split(":")
            if goal_id in ids.split():
                goal[int(s)] = True
            if init_id in ids.split():
                init = int(s)
    reach = goal.copy()                     # states that can reach the goal
    while True:
        more = reach | (p[:, reach].sum(axis=1) > 0)
        if (more == reach).all():
            break
        reach = more
    live = reach & ~goal
    idx = np.flatnonzero(live)
    a = np.eye(len(idx)) - p[np.ix_(idx, idx)]
    b = p[np.ix_(idx, np.flatnonzero(goal))].sum(axis=1)
    x = np.zeros(n)
    x[goal] = 1.0
    x[idx] = np.linalg.solve(a, b)
    return float(x[init])


def test_the_deceptive_value_is_that_of_the_induced_dtmc(mir100: Path) -> None:
    results = json.loads((mir100 / "results.json").read_text())
    assert induced_value(mir100) == pytest.approx(results["deceptive_value"], abs=1e-9)


def wilson(rate: float, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    centre = (rate + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(rate * (1 - rate) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def test_simulated_rates_agree_with_the_exact_within_horizon_probability(mir100: Path) -> None:
    simulation = json.loads((mir100 / "results.json").read_text())["simulation"]
    for name in ("deceptive", "static", "naive", "nash", "leader"):
        row = simulation[name]
        exact, n = row["exact_within_horizon"], row["episodes"]
        low, high = wilson(exact, n)
        assert low - 1e-12 <= row["rate"] <= high + 1e-12, (name, row["rate"], exact)


def test_the_docs_report_these_numbers(mir100: Path) -> None:
    """docs/results.md "MIR100": each value in its table is the run's, at the printed precision."""
    results = json.loads((mir100 / "results.json").read_text())
    section = RESULTS.read_text().split("## MIR100", 1)[1].split("\n## ", 1)[0]
    table = {m.group(1).strip(): float(m.group(2)) for m in
             re.finditer(r"^\| ([^|]+?) \| ([0-9.]+) \|", section, re.MULTILINE)}
    expected = {"deceptive value": results["deceptive_value"], "V_lead": results["v_lead"],
                "V_NE": results["v_ne"], "V_static": results["v_static"],
                "V_naive": results["v_naive"],
                "value of deception": results["value_of_deception"],
                "simulated (deceptive)": results["simulation"]["deceptive"]["rate"],
                "simulated (naive)": results["simulation"]["naive"]["rate"]}
    assert set(expected) <= set(table), sorted(table)
    for key, value in expected.items():
        assert table[key] == pytest.approx(value, abs=5e-5), key


def _table(section: str, header: str) -> list[list[str]]:
    block = section.split(header, 1)[1].split("\n\n", 1)[0]
    return [[c.strip() for c in line.strip("|").split("|")] for line in block.splitlines()[1:]
            if line.startswith("|") and not line.startswith("|---")]


def test_the_docs_first_guess_table(tmp_path: Path) -> None:
    """docs/results.md "MIR100": deceptive value and V_naive for each first guess, delay 0 and 1."""
    import dataclasses

    world = load_world(MODELS / "mir100.toml")
    section = RESULTS.read_text().split("## MIR100", 1)[1].split("\n## ", 1)[0]
    rows = _table(section, "| P2's first guess |")
    assert len(rows) == 4
    for h, row in enumerate(rows):
        for delay, (value_col, naive_col) in ((0, (1, 2)), (1, (4, 5))):
            variant = dataclasses.replace(world, initial_hypothesis=h, delay=delay,
                                          initial_standing=0)
            checked = pipeline.check(variant, tmp_path / f"{h}_{delay}")
            worth = pipeline._deception_stage(checked)
            assert float(row[value_col]) == pytest.approx(checked.results.deceptive_value,
                                                          abs=5e-5), (h, delay)
            assert float(row[naive_col]) == pytest.approx(worth.v_naive, abs=5e-5), (h, delay)
            if delay == 0:
                assert float(row[3]) == pytest.approx(checked.results.deceptive_value
                                                      - worth.v_naive, abs=5e-5)
            # where deception is worth nothing it is exactly 0, never a rounding -1e-17
            assert worth.value_of_deception >= 0.0
            assert worth.value_of_deception == 0.0 or worth.value_of_deception > 1e-12


def test_the_docs_arena_example_loads_and_means_what_it_says(tmp_path: Path) -> None:
    """docs/worlds.md "Arena worlds": the `lateral` arena world is valid; `db` and `hr` are terminal;
    while the defender watches db the pivot to db fails, against her other actions it succeeds
    with probability 0.5; and it solves."""
    text = WORLDS.read_text()
    block = text.split('```toml\nname = "lateral"', 1)[1].split("```", 1)[0]
    path = tmp_path / "lateral.toml"
    path.write_text('name = "lateral"' + block)
    world = load_world(path)
    from hg2prism.frontends import transition_system

    ts = transition_system(world)
    arena = ts.arena
    mail, db, hr = (arena.index(n) for n in ("mail", "db", "hr"))
    assert arena.actions[db] == () and arena.actions[hr] == ()
    pivot = arena.actions[mail].index("pivot_db")
    for j, name in enumerate(ts.a2_names):
        reach = ts.prob[mail, pivot, j][ts.succ[mail, pivot, j] == db].sum()
        assert reach == pytest.approx(0.0 if name == "watch_db" else 0.5), name
    checked = pipeline.check(world, tmp_path / "out")
    assert 0.0 < checked.results.deceptive_value <= 1.0


def test_the_world_from_graph_example_of_docs_api_prints_what_it_says() -> None:
    """docs/api.md's world_from_graph example: run it, and each `print` gives its comment."""
    import contextlib
    import io

    text = (DOCS / "api.md").read_text()
    block = text.split("hg2prism.world_from_graph(G", 1)[0].rsplit("```python", 1)[1]
    block += "hg2prism.world_from_graph(G" + \
        text.split("hg2prism.world_from_graph(G", 1)[1].split("```", 1)[0]
    claims = [line.split("#", 1)[1].split(":")[0].strip() for line in block.splitlines()
              if line.startswith("print(")]
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(io.StringIO()):
        exec(compile(block, "docs/api.md", "exec"), {})
    lines = printed.getvalue().splitlines()
    assert lines == claims
