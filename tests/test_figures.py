"""Figures and the replay (README "Figures"): every figure as PNG and SVG at its stated size, the
world picture drawing the episode its rule names, the replay's frames, P2's belief trace, and
`--episode` errors."""

from __future__ import annotations

import json
import math
import re
import statistics
import struct
from pathlib import Path

import pytest
from PIL import Image

from conftest import MODELS
from hg2prism import cli
from hg2prism.analyses import episodes, simulation
from hg2prism.frontends.grid import ACTIONS
from hg2prism.worldfile import load_world
from hg2prism.report import plots, replay
from hg2prism.strategy.records import Strategy

# The sizes README "Figures" states: inches at 150 dpi.
DPI = 150
EPISODE_SEEDS = 50
SIZES = {"belief": (8.0, 3.8), "completion": (6.4, 4.4), "sweep": (6.4, 4.4),
         "detection": (10.0, 4.2), "scaling": (8.5, 4.8)}


def world_inches(width: int, height: int) -> tuple[float, float]:
    return (0.85 * width + 4.2, max(0.85 * height + 1.0, 5.0))


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def svg_text(path: Path) -> str:
    text = path.read_text()
    assert text.lstrip().startswith("<?xml") and "<svg" in text
    return text


def svg_inches(text: str) -> tuple[float, float]:
    width = re.search(r'<svg[^>]* width="([\d.]+)pt"', text).group(1)
    height = re.search(r'<svg[^>]* height="([\d.]+)pt"', text).group(1)
    return float(width) / 72, float(height) / 72


def assert_figure(folder: Path, name: str, inches: tuple[float, float]) -> str:
    """Both files exist at the stated size; returns the SVG's text."""
    width, height = inches
    assert png_size(folder / f"{name}.png") == (round(width * DPI), round(height * DPI))
    text = svg_text(folder / f"{name}.svg")
    assert svg_inches(text) == pytest.approx(inches, abs=0.01)
    return text


@pytest.fixture(scope="module")
def world1_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("figures") / "world1"
    assert cli.main(["run", str(MODELS / "world1.toml"), "--out", str(out),
                     "--episodes", "300"]) == 0
    return out


@pytest.fixture(scope="module")
def seed_set(world1_run: Path):
    """The documented seed set (seeds 0..49, the world's seed 0 onwards), each simulated as one
    episode of the exported strategy: (seed, length, outcome, steps) per seed."""
    from hg2prism import pipeline

    world = load_world(MODELS / "world1.toml")
    analysis = pipeline.analyse(world)
    strategy = Strategy.load(world1_run / "strategy.json", analysis.ts)
    rows = []
    for seed in range(EPISODE_SEEDS):
        steps: list = []
        summary = simulation.simulate_deceptive(analysis, strategy, 1, world.simulation.horizon,
                                                seed, observer=steps.append, progress=False)
        rows.append((seed, len(steps), int(summary.outcomes[0]), steps))
    return world, analysis, strategy, rows


def test_every_figure_is_written_as_png_and_svg_at_its_size(world1_run: Path) -> None:
    world = load_world(MODELS / "world1.toml")
    text = assert_figure(world1_run, "world", world_inches(world.grid.width, world.grid.height))
    assert "world1" in text
    for name in ("belief", "completion"):
        assert "world1" in assert_figure(world1_run, name, SIZES[name])


def test_world_picture_draws_the_median_completed_episode(world1_run: Path, seed_set) -> None:
    _, _, _, rows = seed_set
    completed = sorted((length, seed) for seed, length, outcome, _ in rows
                       if outcome == simulation.GOAL)
    lengths = [length for length, _ in completed]
    drawn = json.loads((world1_run / "results.json").read_text())["episode"]
    assert drawn["rule"] == "median" and drawn["seed_set"] == [0, EPISODE_SEEDS - 1]
    assert drawn["completed_in_seed_set"] == len(completed)
    assert drawn["steps"] == statistics.median_low(lengths)
    # the drawn seed is the first (by seed) of that length, and the picture says so
    assert drawn["seed"] == min(seed for length, seed in completed if length == drawn["steps"])
    title = svg_text(world1_run / "world.svg")
    assert f"seed {drawn['seed']}, {drawn['steps']} steps" in title
    assert "median-length" in title
    # the replay has one frame per episode state: the start and after each step
    with Image.open(world1_run / "replay.gif") as gif:
        assert gif.n_frames == drawn["steps"] + 1 == drawn["replay_frames"]


def test_shortest_and_seed_rules(seed_set) -> None:
    world, analysis, strategy, rows = seed_set
    horizon = world.simulation.horizon
    shortest = episodes.choose_episode(analysis, strategy, horizon, 0, "shortest")
    completed = [(length, seed) for seed, length, outcome, _ in rows if outcome == simulation.GOAL]
    assert (shortest.n_steps, shortest.seed) == min(completed)
    chosen = episodes.choose_episode(analysis, strategy, horizon, 0, "seed=7")
    assert chosen.seed == 7 and chosen.n_steps == rows[7][1] and chosen.seeds is None


def test_moves_follow_the_grid(seed_set) -> None:
    """Each drawn step: the realised direction is the chosen one or perpendicular to it, the
    landing cell is one step that way or, into a wall, the start (independent of dynamics)."""
    world, analysis, _, rows = seed_set
    step = {"N": (0, 1), "E": (1, 0), "S": (0, -1), "W": (-1, 0)}
    slips = 0
    for _, _, _, steps in rows[:10]:
        for record, move in zip(steps, episodes.episode_moves(analysis.ts, steps)):
            assert move.chosen == ACTIONS[record.a1]
            dx, dy = step[move.chosen]
            rx, ry = step[move.realised]
            assert dx * rx + dy * ry >= 0 and (rx, ry) != (-dx, -dy)
            ahead = (move.start[0] + rx, move.start[1] + ry)
            expected = move.start if ahead in world.grid.walls else ahead
            assert move.landing == expected
            assert move.bump == (ahead in world.grid.walls)
            slips += move.slip
    assert slips > 0        # world1 slips with probability 0.2 per step


def test_belief_trace_explains_every_change_of_mind(seed_set) -> None:
    """CUSUM: P2 changes her mind at a step exactly when the largest score reaches the
    threshold; the score of the hypothesis she holds is 0 (docs/semantics.md §5)."""
    world, analysis, _, rows = seed_set
    for _, _, _, steps in rows:
        trace = episodes.belief_trace(analysis.inference, steps)
        assert trace.threshold == world.threshold and trace.name
        for acted, after, values in zip(trace.acted, trace.after, trace.values):
            assert values[acted] == 0.0
            assert (after != acted) == (max(values) >= world.threshold - 1e-9)


def test_replay_frames_rule() -> None:
    assert replay.replay_frames(0) == [0]
    assert replay.replay_frames(99) == list(range(100))
    for n in (100, 150, 200, 1000):
        frames = replay.replay_frames(n)
        stride = math.ceil(n / 99)
        assert frames == sorted(set(range(0, n + 1, stride)) | {n})
        assert len(frames) <= 100 and frames[0] == 0 and frames[-1] == n


def test_sweep_and_detection_figures(tmp_path: Path) -> None:
    rows = [{"rationality": v, "deceptive_value": 0.9 + 0.01 * i, "v_lead": 0.7, "v_ne": 0.3}
            for i, v in enumerate((0.1, 1.0, 10.0, 100.0))]
    plots.sweep_figure("rationality", rows, tmp_path / "sweep.png", "worldX")
    text = assert_figure(tmp_path, "sweep", SIZES["sweep"])
    assert "worldX" in text and "log scale" in text
    # every swept value is a tick label, once
    for label in ("0.1", "1", "10", "100"):
        assert text.count(f">{label}<") == 1
    statistics_ = [0.0] * 4 + [3.0, 12.0] + [12.0 + i for i in range(150)]
    thresholds = [None] + [3.84 + 0.5 * i for i in range(len(statistics_) - 1)]
    plots.detection_figure(statistics_, thresholds, 4, 6, tmp_path / "detection.png",
                           world_name="worldY", seed=3)
    text = assert_figure(tmp_path, "detection", SIZES["detection"])
    assert "worldY" in text and "steps 1–12" in text
    rows = [{"states": n, "time_games": 0.01 * n ** 0.5, "time_total": 1e-4 * n}
            for n in (1000, 10000, 100000)]
    plots.scaling_figure(rows, ("games",), tmp_path / "scaling.png", "bench title")
    assert "bench title" in assert_figure(tmp_path, "scaling", SIZES["scaling"])


@pytest.mark.parametrize("value", ["longest", "seed=", "seed=-1", "seed=x", "median,shortest"])
def test_bad_episode_rule_is_one_line(value: str, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    assert cli.main(["run", str(MODELS / "world1.toml"), "--out", str(out),
                     "--episode", value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hg2prism: error: command line: --episode:")
    assert "Traceback" not in err[0] and not out.exists()
