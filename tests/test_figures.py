"""Figures and the replay (docs/cli.md "Figures"): every figure as PNG and SVG at its stated size, the
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
from hg2prism.frontends import transition_system
from hg2prism.frontends.grid import ACTIONS, geometry
from hg2prism.frontends.grid_drawing import grid_moves
from hg2prism.worldfile import load_world
from hg2prism.report import plots, replay
from hg2prism.strategy.records import Strategy

# The sizes docs/cli.md "Figures" states: inches at 150 dpi.
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


def test_completion_figure_plots_every_row_of_the_table(world1_run: Path) -> None:
    """table.md's rows (its first column) are the completion figure's curves, in order."""
    rows = [line.split("|")[1].strip() for line in
            (world1_run / "table.md").read_text().splitlines()
            if line.startswith("| ") and not line.startswith("| information")]
    assert len(rows) == 5
    texts = re.findall(r">([^<>]*)</text>", svg_text(world1_run / "completion.svg"))
    legend = [t for t in texts if t in rows]
    assert legend == rows


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
        drawn = episodes.episode_steps(analysis.ts, steps)
        moves = grid_moves(geometry(world), analysis.ts.arena.states, drawn)
        for record, move in zip(steps, moves):
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
    assert "V_static" not in text
    # a sweep with --deception's values draws V_static and V_naive too, and their legend
    import matplotlib.pyplot as plt

    worth = [{**row, "v_static": 0.8, "v_naive": 0.8} for row in rows]
    lines = plots.sweep_figure("rationality", worth, None, "worldX",
                               ax=plt.figure().add_subplot())
    assert lines == []
    ax = plt.gcf().axes[0]
    assert [line.get_label() for line in ax.get_lines()][-2:] == [
        "P2 never revises (V_static)", "P1 ignores her inference (V_naive)"]
    assert list(ax.get_lines()[-1].get_ydata()) == [0.8] * 4
    plt.close("all")
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


# ---- arena worlds (docs/semantics.md §15 "Figures"): the arena drawn as a graph ----

def hand_episode(ts, script, seeds=range(40), pick=len):
    """The longest episode over `seeds` of P1 and P2 playing `script` (a list of (P1's action
    slot, P2's action, P2's hypothesis)), outcomes drawn from the TS; simulation.StepRecords
    built by hand, so that the figures are tested whatever the simulation does."""
    import numpy as np

    from hg2prism.opponent.observer import Memory

    def walk(seed):
        rng = np.random.default_rng(seed)
        state, records = ts.start_state, []
        for n, (a1, a2, hypothesis) in enumerate(script, start=1):
            if ts.terminal[state]:
                break
            p = ts.prob[state, a1, a2]
            nxt = int(ts.succ[state, a1, a2, rng.choice(len(p), p=p / p.sum())])
            memory = Memory(hypothesis)
            records.append(simulation.StepRecord(0, n, state, 0, memory, a1, a2, a2, ts.n_sets,
                                                 memory, nxt, 0))
            state = nxt
        return records

    steps = max((walk(seed) for seed in seeds), key=pick)
    episode = episodes.ChosenEpisode(steps, 0, "cut by the horizon", episodes.EpisodeRule("seed", 0),
                                     None, ())
    acted = tuple(s.p2_memory.hypothesis for s in steps)
    trace = episodes.BeliefTrace(acted, acted[1:] + acted[-1:], None, None, None)
    return episode, trace


# lateral: out 0, web 1, mail 2, db 3, hr 4, burnt 5; P1 at out: phish, exploit; at mail:
# pivot_db, pivot_hr, wait. General P2: idle, watch_db, watch_hr; traps: web, mail.
LATERAL_SCRIPTS = {
    False: [(0, 2, 1), (0, 2, 1), (0, 1, 1), (2, 0, 1), (1, 2, 0), (1, 2, 0), (1, 0, 0)],
    True: [(0, 0, 1), (0, 0, 1), (2, 0, 1), (2, 0, 0), (0, 0, 0), (0, 0, 0)],
}


@pytest.fixture(scope="module", params=[(False, 0), (True, 0), (False, 1)],
                ids=["general", "traps", "general-delay1"])
def lateral_drawn(request, tmp_path_factory: pytest.TempPathFactory):
    """A lateral world (general P2 actions or traps; a delay), a hand-built episode, and its
    world picture and replay."""
    from arenas import lateral

    traps_mode, delay = request.param
    world = lateral(delay=delay, traps_mode=traps_mode)
    ts = transition_system(world)
    episode, trace = hand_episode(ts, LATERAL_SCRIPTS[traps_mode])
    out = tmp_path_factory.mktemp("arena")
    plots.world_figure(world, ts, episode, trace, out / "world.png")
    frames = replay.replay_gif(world, ts, episode, trace, out / "replay.gif")
    return world, ts, episode, out, frames


def test_arena_steps_are_the_arena_s(lateral_drawn) -> None:
    """Each drawn step: the action is one of the state's, the outcome taken has positive
    probability and leads to the landing state (or into P2's trap)."""
    world, ts, episode, _, _ = lateral_drawn
    arena = world.arena
    drawn = episodes.episode_steps(ts, episode.steps)
    assert len(drawn) == len(episode.steps) >= 4
    for record, step in zip(episode.steps, drawn):
        assert step.action_name == arena.actions[step.start][step.action]
        j = step.p2_action if arena.p2_dependent else 0
        assert arena.prob[step.start, step.action, j, step.outcome] > 0
        assert arena.dest[step.start, step.action, j, step.outcome] == step.landing
        assert step.p2_action_name == ts.a2_names[record.a2]
        assert step.trapped == (record.next_state == ts.trapped)
        assert step.traps == (tuple(arena.trap_candidates[c] for c in ts.trap_sets[record.a2])
                              if ts.traps_mode else ())
    assert any(step.stays for step in drawn) and any(not step.stays for step in drawn)


def _numbers(label: str) -> list[int]:
    """The step numbers of an "n=..." label (steps_text's forms)."""
    text = label[2:].split(":")[0]
    if "…" in text:
        first, rest = text.split("…")
        return [int(first), int(rest.split(" ")[0])]
    return [int(n) for n in text.split(",")]


def test_arena_world_picture_draws_states_and_episode(lateral_drawn) -> None:
    world, ts, episode, out, _ = lateral_drawn
    text = assert_figure(out, "world", plots.world_figure_inches(world, ts))
    texts = re.findall(r">([^<>]*)</text>", text)
    arena = world.arena
    for name in arena.states:
        assert name in texts
    for props in ("{crown}", "{payroll}"):
        assert props in texts
    for names in arena.actions:
        for name in names:
            assert any(name in t for t in texts), name
    # every step of the episode is labelled with its number and P1's action
    labels = [t for t in texts if re.match(r"n=\d", t) and "P2 now" not in t]
    drawn = episodes.episode_steps(ts, episode.steps)
    numbered = {n for label in labels for n in _numbers(label)}
    assert numbered == {step.n for step in drawn}
    for step in drawn:
        assert any(step.n in _numbers(label) and step.action_name in label for label in labels)
        if not ts.traps_mode:
            assert any(step.n in _numbers(label) and step.p2_action_name in label
                       for label in labels)
    if ts.traps_mode:
        assert any(t.startswith("trap ") and t.endswith("×") for t in texts)
        assert "trap candidate (honeypot)" in texts
    assert f"start state ({arena.states[arena.initial]})" in texts


def test_arena_replay_has_a_frame_per_state(lateral_drawn) -> None:
    _, _, episode, out, frames = lateral_drawn
    with Image.open(out / "replay.gif") as gif:
        assert gif.n_frames == frames == episode.n_steps + 1


def test_arena_labels_do_not_overlap(lateral_drawn) -> None:
    """No two texts of the map (states, actions, steps, traps, changes of mind) overlap."""
    from hg2prism.report.plots import plt

    world, ts, episode, _, _ = lateral_drawn
    drawer = plots.world_drawer(world, ts)
    fig = plt.figure(figsize=drawer.world_inches(), layout="constrained")
    ax = fig.add_subplot()
    drawer.draw_world(ax, episodes.episode_steps(ts, episode.steps), ())
    drawer.finish(ax)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = [(t.get_text(), t.get_bbox_patch().get_window_extent(renderer)) for t in ax.texts]
    plt.close(fig)
    assert len(boxes) > world.arena.n_states
    for i, (a, box_a) in enumerate(boxes):
        for b, box_b in boxes[i + 1:]:
            assert not box_a.overlaps(box_b), (a, b)


def test_arena_trapped_step_and_given_positions(tmp_path: Path) -> None:
    """A step into P2's trap is drawn (red, "P1 trapped"); positions the arena gives are used
    (two states at the same place do not break the drawing)."""
    import dataclasses

    from arenas import lateral

    world = lateral(traps_mode=True)
    positions = ((0.0, 0.0), (1.0, 1.0), (1.0, 0.0), (2.0, 1.0), (2.0, 0.0), (1.0, 0.0))
    world = dataclasses.replace(world, front=dataclasses.replace(world.arena, positions=positions))
    ts = transition_system(world)
    # phish while P2 traps mail: trapped with probability 0.6
    episode, trace = hand_episode(ts, [(0, 1, 0)], pick=lambda s: s[-1].next_state == ts.trapped)
    assert episode.steps[-1].next_state == ts.trapped
    plots.world_figure(world, ts, episode, trace, tmp_path / "world.png")
    texts = re.findall(r">([^<>]*)</text>", svg_text(tmp_path / "world.svg"))
    assert "P1 trapped" in texts and "n=1: phish" in texts
    drawer = plots.world_drawer(world, ts)
    assert drawer.position(3)[0] > drawer.position(2)[0] > drawer.position(0)[0]
    assert replay.replay_gif(world, ts, episode, trace, tmp_path / "replay.gif") == 2


def test_report_layer_holds_no_grid_concept() -> None:
    """Below the front end the figures know arenas only (issue 23)."""
    root = Path(__file__).resolve().parent.parent / "hg2prism"
    files = [*(root / "report").glob("*.py"), root / "analyses" / "episodes.py"]
    for path in files:
        source = path.read_text()
        for word in ("ACTIONS", "outcome_directions", "geometry", ".cells", "cell_index",
                     "trap_cells", "set_cells", "PERPENDICULAR", "slip"):
            assert word not in source, (path.name, word)


def test_twelve_hypotheses_are_told_apart_in_the_belief_figure() -> None:
    """The belief figure's lines: the first twelve hypotheses each have their own colour (with
    six colours x5 and x11 shared one, and their marker, told apart only by "--" against "-."
    in a small legend: a stress test with 12 targets could not), read off the lines the figure
    draws; no hypothesis takes the traps' or the trapped state's colour."""
    from types import SimpleNamespace

    import matplotlib.colors as mcolors

    from hg2prism.report import plots, style

    k = 12
    world = SimpleNamespace(name="twelve", hypotheses=tuple(f"F asset{x}" for x in range(k)))
    trace = SimpleNamespace(after=[0, 1, 2], values=[[float(x) for x in range(k)]] * 3,
                            threshold=None, name="CUSUM score", changes=())
    fig, _ = plots.belief_picture(world, trace, SimpleNamespace(n_steps=3, seed=0))
    lines = [line for line in fig.axes[0].get_lines() if line.get_label().startswith("x")]
    looks = {(mcolors.to_hex(line.get_color()), line.get_linestyle(), line.get_marker())
             for line in lines}
    assert len(lines) == k and len(looks) == k
    assert len({mcolors.to_hex(line.get_color()) for line in lines}) == k
    reserved = {mcolors.to_hex(style.TRAP_COLOUR), mcolors.to_hex(style.TRAPPED_COLOUR)}
    assert not {mcolors.to_hex(c) for c in style.HYPOTHESIS_COLOURS} & reserved
