"""Figures a reader can read (issue 26), measured on the rendered figures, not by eye:

- no text of a world picture (labels, the key, the legend, titles, ticks, the map's letters)
  overlaps another or a mark (start, traps, trapped), and none leaves the figure: the showcase
  worlds' drawn episodes and 20 episodes on generated worlds;
- one step-numbering rule: world3's change of mind is at the same step in the world picture's
  label, the belief plot's marker and the replay's frame, the step whose observation made P2
  switch (read from the simulation's records, not from BeliefTrace);
- the replay's texts are at least 9 px high at the GIF's 72 dpi, inside the frame and apart
  in every frame; the belief plot's lines stay visible where they coincide; scaling.png has a
  series per delay.
"""

from __future__ import annotations

import functools
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from matplotlib.text import Text

import worldgen
from conftest import MODELS, share
from hg2prism import pipeline
from hg2prism.analyses import episodes, simulation
from hg2prism.frontends import transition_system
from hg2prism.opponent.observer import Memory
from hg2prism.report import plots, replay
from hg2prism.strategy.records import Strategy
from hg2prism.worldfile import load_world

SHOWCASE = ("world1", "world2", "world3", "world3_bayes", "mir100")
GENERATED = range(20)
TOLERANCE = 0.5        # pixels two boxes may share (anti-aliasing), each side


@functools.lru_cache(maxsize=None)
def showcase(name: str):
    """A showcase world's drawn episode as `run` draws it: (world, ts, episode, trace, steps)."""
    world = load_world(MODELS / f"{name}.toml")
    checked = pipeline.check(world, Path(tempfile.mkdtemp()))
    assert checked.bounded is None
    strategy = Strategy.from_records(checked.records, checked.analysis.ts)
    episode = episodes.choose_episode(checked.analysis, strategy, world.simulation.horizon,
                                      world.simulation.seed)
    trace = episodes.belief_trace(checked.analysis.inference, episode.steps)
    return world, checked.analysis.ts, episode, trace


def random_episode(seed: int, length: int = 60):
    """A generated world (tests/worldgen.py) and a random walk on it: P1's actions, P2's trap
    sets and her hypothesis (switching now and then) drawn at random, mostly avoiding steps
    into a trap (one ends the walk); the longest of a few walks. No model checking: only the
    drawing is under test."""
    folder = Path(tempfile.mkdtemp())
    (folder / "w.toml").write_text(worldgen.random_world(seed))
    world = load_world(folder / "w.toml")
    ts = transition_system(world)
    rng = np.random.default_rng(seed)
    n_x = len(world.hypotheses)

    def walk():
        state, hypothesis, records = ts.start_state, world.initial_hypothesis, []
        for n in range(1, length + 1):
            if ts.terminal[state]:
                break
            for _ in range(10):         # mostly steps that do not end in a trap
                a1 = int(rng.choice(np.flatnonzero(ts.enabled[state])))
                a2 = int(rng.choice(np.flatnonzero(ts.allowed[state])))
                p = ts.prob[state, a1, a2]
                nxt = int(ts.succ[state, a1, a2, rng.choice(len(p), p=p / p.sum())])
                if nxt != ts.trapped:
                    break
            memory = Memory(hypothesis)
            records.append(simulation.StepRecord(0, n, state, 0, memory, a1, a2, a2, ts.n_sets,
                                                 memory, nxt, 0))
            if nxt == ts.trapped:
                break
            state = nxt
            if n_x > 1 and rng.random() < 0.15:
                hypothesis = int(rng.choice([x for x in range(n_x) if x != hypothesis]))
        return records

    steps = max((walk() for _ in range(4)), key=len)
    acted = tuple(s.p2_memory.hypothesis for s in steps)
    trace = episodes.BeliefTrace(acted, acted[1:] + acted[-1:], None, None, None)
    episode = episodes.ChosenEpisode(steps, seed, "cut by the horizon",
                                     episodes.EpisodeRule("seed", seed), None, ())
    return world, ts, episode, trace


def texts_of(fig) -> list[tuple[str, object]]:
    """Every visible non-empty text of a drawn figure with its window box (its bbox patch
    when it has one: the white box that would hide what lies under it)."""
    renderer = fig.canvas.get_renderer()
    boxes = []
    hidden = {id(label) for ax in fig.axes if not ax.axison      # an axes drawn without axes
              for label in ax.get_xticklabels() + ax.get_yticklabels()}  # shows no tick text
    for text in fig.findobj(Text):
        if not text.get_visible() or not text.get_text().strip() or id(text) in hidden:
            continue
        patch = text.get_bbox_patch()
        boxes.append((text.get_text(), (patch or text).get_window_extent(renderer)))
    return boxes


def marks_of(ax) -> list[tuple[str, object]]:
    """The marks of a map (start, traps set, trapped): its lines drawn as markers (not the
    replay's moving robot and traps, which pass over the map)."""
    renderer = ax.figure.canvas.get_renderer()
    return [(f"mark {line.get_marker()}", line.get_window_extent(renderer)) for line in ax.lines
            if line.get_visible() and not line.get_animated()
            and line.get_marker() not in (None, "", "None") and len(line.get_xdata())]


def _apart(a, b) -> bool:
    return (a.x1 - TOLERANCE <= b.x0 or b.x1 - TOLERANCE <= a.x0
            or a.y1 - TOLERANCE <= b.y0 or b.y1 - TOLERANCE <= a.y0)


def problems(fig, ax) -> list[str]:
    """Overlapping texts, texts over marks, texts outside the figure."""
    fig.canvas.draw()
    texts, marks = texts_of(fig), marks_of(ax)
    frame = fig.bbox
    found = []
    for i, (a, box_a) in enumerate(texts):
        if (box_a.x0 < frame.x0 - TOLERANCE or box_a.y0 < frame.y0 - TOLERANCE
                or box_a.x1 > frame.x1 + TOLERANCE or box_a.y1 > frame.y1 + TOLERANCE):
            found.append(f"{a!r} leaves the figure")
        for b, box_b in texts[i + 1:] + marks:
            if not _apart(box_a, box_b):
                found.append(f"{a!r} overlaps {b!r}")
    return found


def world_problems(world, ts, episode, trace) -> tuple[list[str], list[str]]:
    """What `problems` finds in the world picture, and its texts."""
    fig, _ = plots.world_picture(world, ts, episode, trace)
    try:
        return problems(fig, fig.axes[0]), [t for t, _ in texts_of(fig)]
    finally:
        plots.plt.close(fig)


@pytest.mark.parametrize("name", SHOWCASE)
def test_showcase_world_pictures_hide_nothing(name: str) -> None:
    found, texts = world_problems(*showcase(name))
    assert not found, found
    # every step of the episode is labelled on the map or in the key (first and last of a
    # long list)
    _, _, episode, _ = showcase(name)
    labelled = {n for t in texts for n in _step_numbers(t)}
    assert {1, episode.n_steps} <= labelled


@pytest.mark.parametrize("seed", share(GENERATED))     # every fourth under `make test`
def test_generated_world_pictures_hide_nothing(seed: int) -> None:
    world, ts, episode, trace = random_episode(seed)
    assert episode.n_steps >= 5
    found, _ = world_problems(world, ts, episode, trace)
    assert not found, found


@pytest.mark.parametrize("seed", (3, 4))
def test_crowded_pictures_list_labels_in_the_key(seed: int) -> None:
    """200 random steps on a small map: labels that find no free spot become tags (a, b, ...)
    beside their arrow, listed in the key; still nothing overlaps, and every step is named."""
    world, ts, episode, trace = random_episode(seed, length=200)
    fig, drawer = plots.world_picture(world, ts, episode, trace)
    try:
        found = problems(fig, fig.axes[0])
        texts = [t for t, _ in texts_of(fig)]
    finally:
        plots.plt.close(fig)
    assert not found, found
    assert len(drawer.key) >= 10
    for tag, label in drawer.key:
        assert f"{tag}: {label.text}" in texts
        assert tag in texts or tag.endswith(" (not on the map)")
    assert sum(tag in texts for tag, _ in drawer.key) >= 0.9 * len(drawer.key)
    named = {n for t in texts for n in _step_numbers(t)}
    assert {1, episode.n_steps} <= named


def _step_numbers(text: str) -> list[int]:
    """The step numbers a label names: "n=3", "n=3,5", "n=2…40 (20×)" (first and last), "a: n=…"
    in the key."""
    match = re.search(r"n=([\d,…]+)", text)
    if not match:
        return []
    return [int(n) for n in re.split(r"[,…]", match.group(1)) if n]


def test_overlap_check_can_fail() -> None:
    """The measurement finds an overlap when there is one: two labels at the same place."""
    world, ts, episode, trace = showcase("world3")
    fig, _ = plots.world_picture(world, ts, episode, trace)
    ax = fig.axes[0]
    ax.text(3, 2, "n=99", fontsize=6.5)
    ax.text(3, 2, "n=98", fontsize=6.5)
    try:
        assert any("'n=99' overlaps 'n=98'" in p for p in problems(fig, ax))
    finally:
        plots.plt.close(fig)


# ---- one step-numbering rule ----

def test_world3_change_of_mind_is_at_the_same_step_everywhere() -> None:
    """docs/semantics.md §15 "Figures": step n is P1's n-th move, P2's hypothesis at step n
    the one she holds after observing it. The change of mind caused by step n's observation:
    step n+1's records show P2 acting on another hypothesis than at step n."""
    world, ts, episode, trace = showcase("world3")
    steps = episode.steps
    expected = [(n, steps[n].p2_memory.hypothesis) for n in range(1, len(steps))
                if steps[n].p2_memory.hypothesis != steps[n - 1].p2_memory.hypothesis]
    assert expected, "world3's drawn episode has a change of mind (its feint)"
    # the world picture: its "n=k: P2 now xi" labels (on the map or in the key)
    fig, drawer = plots.world_picture(world, ts, episode, trace)
    fig.canvas.draw()
    labels = sorted((int(m.group(1)), int(m.group(2))) for t, _ in texts_of(fig)
                    for m in [re.search(r"n=(\d+): P2 now x(\d+)", t)] if m)
    plots.plt.close(fig)
    # the belief plot: its red lines
    fig, marked = plots.belief_picture(world, trace, episode)
    lines = sorted(int(round(line.get_xdata()[0])) for line in fig.axes[0].lines
                   if line.get_color() == "red" and len(line.get_xdata()))
    plots.plt.close(fig)
    # the replay: the frames that say she changed her mind
    shown, notes = replay.replay_figure(world, ts, episode, trace)
    plots.plt.close(shown.fig)
    frames = [(note.state, note.changed_to) for note in notes if note.changed_to is not None]
    assert all("changed her mind" in note.believes for note in notes if note.changed_to is not None)
    assert labels == expected == frames
    assert lines == list(marked) == [n for n, _ in expected]
    assert expected[0][0] == 2      # the feint: observing step 2 ((4,2) -> (5,2)) convinces her


def test_step_rule_is_stated_in_each_figure() -> None:
    from hg2prism.report.style import STEP_RULE

    world, ts, episode, trace = showcase("world3")
    fig, _ = plots.world_picture(world, ts, episode, trace)
    assert STEP_RULE in fig.axes[0].get_title(loc="left")
    plots.plt.close(fig)
    fig, _ = plots.belief_picture(world, trace, episode)
    assert fig.axes[0].get_xlabel().startswith(STEP_RULE)
    plots.plt.close(fig)
    shown, _ = replay.replay_figure(world, ts, episode, trace)
    assert STEP_RULE.split(";")[0] in shown.fig.get_suptitle()
    plots.plt.close(shown.fig)


# ---- the replay ----

def _legible(fig, text) -> bool:
    """At least 9 px a line at the figure's resolution (its font size and its drawn box)."""
    lines = text.get_text().count("\n") + 1
    height = text.get_window_extent(fig.canvas.get_renderer()).height / lines
    return text.get_fontsize() * fig.dpi / 72 >= 9 and height >= 9


@pytest.mark.parametrize("name", ("world1", "world3", "world3_bayes", "mir100"))
def test_replay_texts_are_legible_and_apart_in_every_frame(name: str) -> None:
    """The frame laid out (with the widest caption) hides nothing and loses nothing; in every
    frame the caption and P2's line are legible, inside the frame and apart from the rest."""
    world, ts, episode, trace = showcase(name)
    shown, notes = replay.replay_figure(world, ts, episode, trace)
    fig = shown.fig
    drawn = episodes.episode_steps(ts, episode.steps)
    start = ts.decode(ts.start_state)[0]
    places = [start] + [s.landing for s in drawn]
    try:
        assert fig.dpi == replay.REPLAY_DPI == 72
        found = problems(fig, shown.map_ax)
        assert not found, found
        hidden = {id(label) for ax in fig.axes if not ax.axison
                  for label in ax.get_xticklabels() + ax.get_yticklabels()}
        texts = [t for t in fig.findobj(Text)
                 if t.get_visible() and t.get_text().strip() and id(t) not in hidden]
        assert all(_legible(fig, t) for t in texts), [t.get_text() for t in texts
                                                      if not _legible(fig, t)]
        renderer = fig.canvas.get_renderer()
        fixed = [t.get_window_extent(renderer) for t in texts
                 if t not in (shown.caption, shown.believes)]
        added: list = []
        for state in replay.replay_frames(len(drawn)):
            for artist in added:
                artist.remove()
            _, added = replay._frame(shown, world, places, drawn, trace, notes[state])
            for text in (shown.caption, shown.believes):
                box = text.get_window_extent(renderer)
                assert _legible(fig, text)
                assert fig.bbox.x0 <= box.x0 and box.x1 <= fig.bbox.x1 and box.y1 <= fig.bbox.y1
                assert all(_apart(box, other) for other in fixed), (state, text.get_text())
    finally:
        plots.plt.close(fig)


def test_replay_marks_leave_the_state_names_readable() -> None:
    """On an arena world's replay, P1 is a ring around the box of the state he is at, and the
    traps are crosses beside their states' boxes: no mark covers a state's name (a dot and
    crosses at the states' centres hid them: attack-graph stress test). mir100's drawn
    episode, every frame."""
    world, ts, episode, trace = showcase("mir100")
    shown, notes = replay.replay_figure(world, ts, episode, trace)
    fig, drawer = shown.fig, shown.drawer
    drawn = episodes.episode_steps(ts, episode.steps)
    places = [ts.decode(ts.start_state)[0]] + [s.landing for s in drawn]
    renderer = fig.canvas.get_renderer()
    names = {s: node.get_window_extent(renderer) for s, node in enumerate(drawer.nodes)}
    pixels = fig.dpi / 72
    added: list = []
    crosses = 0
    try:
        for state in replay.replay_frames(len(drawn)):
            for artist in added:
                artist.remove()
            _, added = replay._frame(shown, world, places, drawn, trace, notes[state])
            robot = shown.robot
            centre = robot.get_transform().transform((robot.get_xdata()[0],
                                                      robot.get_ydata()[0]))
            inner = (robot.get_markersize() - robot.get_markeredgewidth()) / 2 * pixels
            name = names[places[state]]
            corners = [(x, y) for x in (name.x0, name.x1) for y in (name.y0, name.y1)]
            assert all(np.hypot(x - centre[0], y - centre[1]) < inner for x, y in corners)
            # ... and crosses no other state's name: the ring's outer circle misses their boxes
            outer = (robot.get_markersize() + robot.get_markeredgewidth()) / 2 * pixels
            for s, box in names.items():
                if s != places[state]:
                    nearest = (np.clip(centre[0], box.x0, box.x1), np.clip(centre[1], box.y0,
                                                                            box.y1))
                    far = max(np.hypot(x - centre[0], y - centre[1])
                              for x in (box.x0, box.x1) for y in (box.y0, box.y1))
                    assert not (np.hypot(nearest[0] - centre[0], nearest[1] - centre[1])
                                <= outer and far >= inner - 1), (state, s)
            half = shown.traps.get_markersize() / 2 * pixels
            for point in zip(shown.traps.get_xdata(), shown.traps.get_ydata()):
                x, y = shown.traps.get_transform().transform(point)
                crosses += 1
                for box in names.values():
                    assert (x + half <= box.x0 or x - half >= box.x1 or y + half <= box.y0
                            or y - half >= box.y1), (state, point)
    finally:
        plots.plt.close(fig)
    assert crosses > 0


# ---- the belief plot and scaling ----

def test_belief_lines_that_coincide_stay_visible() -> None:
    """world1's scores: x0's (the hypothesis she holds) is 0 at every step, like most of the
    others'; each line has its own marker and dash and sits apart sideways."""
    world, ts, episode, trace = showcase("world1")
    fig, _ = plots.belief_picture(world, trace, episode)
    lines = [line for line in fig.axes[0].lines if line.get_label().startswith("x")]
    plots.plt.close(fig)
    assert len(lines) == len(world.hypotheses) == 3
    assert len({(line.get_marker(), line.get_linestyle()) for line in lines}) == 3
    xs = [np.asarray(line.get_xdata(), dtype=float) for line in lines]
    for i in range(len(xs)):
        for j in range(i + 1, len(xs)):
            assert np.all(np.abs(xs[i] - xs[j]) >= 0.05)
            assert np.all(np.abs(xs[i] - xs[j]) < 0.5)       # still at their step


def _corridor(states: int) -> str:
    """An arena world file: a corridor of `states` states in a row (given positions), A at
    the west end, B at the east, P1 starting in the middle."""
    names = [f"c{i}" for i in range(states)]
    lines = ['name = "corridor"', "", "[arena]", f"states = {names}".replace("'", '"'),
             f'initial = "c{states // 2}"', 'propositions = ["A", "B"]', "",
             "[arena.labels]", 'c0 = ["A"]', f'{names[-1]} = ["B"]', "", "[arena.positions]"]
    lines += [f"{name} = [{i}.0, 0.0]" for i, name in enumerate(names)]
    for i, name in enumerate(names):
        for action, j in (("L", max(i - 1, 0)), ("R", min(i + 1, states - 1))):
            to = (f"{{ {names[j]} = 1.0 }}" if j == i
                  else f"{{ {names[j]} = 0.9, {name} = 0.1 }}")
            lines += ["", "[[arena.transition]]", f'state = "{name}"', f'action = "{action}"',
                      f"to = {to}"]
    lines += ["", "[task]", 'formula = "F A"', "", "[adversary]", "traps = 1",
              'trap_candidates = ["c2", "c6"]', 'hypotheses = ["F A", "F B"]',
              "initial_hypothesis = 1", "", "[inference]", "window = 2", "threshold = 0.5",
              "rationality = 10.0"]
    return "\n".join(lines) + "\n"


def test_the_key_of_a_flat_map_stays_in_the_figure(tmp_path) -> None:
    """A corridor of nine states (a flat map in a figure of the drawer's least height): the
    map grew with the height left to it and pushed the key 40 pixels out of the figure; the
    figure is now widened, the map as before."""
    for states in (9, 20):
        path = tmp_path / f"corridor{states}.toml"
        path.write_text(_corridor(states))
        world = load_world(path)
        checked = pipeline.check(world, tmp_path / f"out{states}")
        strategy = Strategy.from_records(checked.records, checked.analysis.ts)
        episode = episodes.choose_episode(checked.analysis, strategy, 50, 0)
        trace = episodes.belief_trace(checked.analysis.inference, episode.steps)
        planned = plots.world_figure_inches(world, checked.analysis.ts)
        fig, _ = plots.world_picture(world, checked.analysis.ts, episode, trace)
        try:
            key = fig.axes[0].get_legend().get_window_extent(fig.canvas.get_renderer())
            # inside, with the margin it was widened for (one widening left 2 pixels)
            assert key.x0 >= 0 and key.x1 <= fig.bbox.width - 0.09 * fig.dpi, states
            assert fig.get_size_inches()[0] > planned[0]     # widened for its key
        finally:
            plots.plt.close(fig)
    # a map that leaves its key room keeps the planned size
    world, ts, episode, trace = showcase("mir100")
    fig, _ = plots.world_picture(world, ts, episode, trace)
    try:
        assert tuple(fig.get_size_inches()) == pytest.approx(plots.world_figure_inches(world, ts))
    finally:
        plots.plt.close(fig)


def test_coinciding_v_lead_lines_of_a_sweep_grid_take_turns() -> None:
    """V_lead does not depend on the window: on a delay x window sweep its lines coincide.
    They were translucent and blended into a colour no legend entry has; now each series
    draws every other dash (its own offset), opaque, with its legend's colour."""
    from matplotlib.colors import to_rgba

    grid = [{"delay": d, "window": w, "deceptive_value": 0.9 - 0.1 * d - 0.01 * w,
             "v_lead": 0.7 - 0.1 * d} for d in (0, 1) for w in (1, 2)]
    fig = plots.new_figure((6.4, 4.4))
    ax = fig.add_subplot()
    plots.sweep_grid_figure(["delay", "window"], grid, None, "worldG", ax=ax)
    lines = [line for line in ax.lines if line.get_label().startswith("V_lead")]
    assert len(lines) == 2
    offsets, patterns = set(), set()
    for line in lines:
        assert line.get_alpha() in (None, 1.0)
        assert to_rgba(line.get_color())[3] == 1.0
        offset, pattern = line._unscaled_dash_pattern
        offsets.add(offset)
        patterns.add(tuple(pattern))
        on, off = pattern
        assert off == on                   # one dash in two: the other series' turn
    assert len(offsets) == 2 and len(patterns) == 1
    assert abs(offsets.pop() - offsets.pop()) == next(iter(patterns))[0]


def test_scaling_has_a_series_per_delay() -> None:
    rows = [{"states": n, "delay": 0, "time_games": 0.01, "time_total": 1e-4 * n}
            for n in (1000, 10000, 100000)]
    rows += [{"states": n, "delay": d, "time_games": 2.0 * d, "time_total": 3.0 * d}
             for n, d in ((2500, 1), (2600, 2), (45000, 1))]
    fig = plots.scaling_picture(rows, ("games",))
    ax = fig.axes[0]
    by_label = {line.get_label(): list(line.get_xdata()) for line in ax.lines}
    plots.plt.close(fig)
    assert by_label["total (no delay)"] == [1000, 10000, 100000]
    assert by_label["games"] == [1000, 10000, 100000]
    assert by_label["total, delay 1 (2 worlds)"] == [2500, 45000]
    assert by_label["total, delay 2 (1 world)"] == [2600]


def test_the_trapped_cross_leaves_the_state_name_readable() -> None:
    """On an arena world the red cross where P1 was trapped sits beside the state's box, not on
    its name (it was drawn on the box's corner, over the name: attack-graph stress test)."""
    import matplotlib.colors as mcolors
    import networkx as nx

    import hg2prism
    from hg2prism.report.style import TRAPPED_COLOUR

    graph = nx.DiGraph()
    for u, v, p in ((1, 3, 0.9), (1, 4, 0.7), (3, 5, 0.6), (3, 6, 0.6), (4, 6, 0.5), (4, 1, 0.5)):
        graph.add_edge(u, v, p=p)
    graph.add_node(9)
    world = hg2prism.world_from_graph(graph, entries=[1, 9], task="F asset6",
                                      trap_candidates=[3, 4, 6], initial_hypothesis=2,
                                      hypotheses=["F asset6", "F asset5", "F asset9"], name="e")
    solution = hg2prism.solve(world)
    played = hg2prism.episode(solution, seed=4)
    assert played.outcome == "failed" and played.steps[-1].landing == "trapped"
    ax = hg2prism.draw_world(solution, played)
    ax.figure.canvas.draw()
    renderer = ax.figure.canvas.get_renderer()
    crosses = [line for line in ax.get_lines() if line.get_marker() == "X" and
               mcolors.to_hex(line.get_color()) == mcolors.to_hex(TRAPPED_COLOUR) and
               len(line.get_xdata()) == 1]
    name = next(text for text in ax.texts if text.get_text() == "n3")
    box = name.get_window_extent(renderer)
    assert crosses
    for cross in crosses:
        x, y = cross.get_transform().transform((cross.get_xdata()[0], cross.get_ydata()[0]))
        half = cross.get_markersize() / 2 * ax.figure.dpi / 72
        assert x - half > box.x1 or y - half > box.y1 or x + half < box.x0 or y + half < box.y0


def test_the_layered_layout_of_an_attack_graph_with_unreachable_nodes() -> None:
    """Reachable states by their distance from the start; the states no entry leads to by
    their distance from the unreachable states nothing unreachable leads to, from column 1,
    below the reachable states of their column (they all went to one last column, their edges
    crossing the whole figure); a cycle no root reaches starts at column 1 too."""
    import networkx as nx

    import hg2prism
    from hg2prism.report.arena_graph import _layers, graph_edges

    graph = nx.DiGraph()
    for u, v in ((1, 2), (2, 9), (5, 6), (6, 7), (7, 9), (3, 4), (4, 3), (4, 9)):
        graph.add_edge(u, v, p=0.5)
    world = hg2prism.world_from_graph(graph, entries=[1], task="F asset9", name="g")
    arena = world.arena
    layers = _layers(arena, graph_edges(arena))
    column = {arena.states[s]: x for x, layer in enumerate(layers) for s in layer}
    assert column == {"outside": 0, "n1": 1, "n2": 2, "n9": 3,      # from the start
                      "n5": 1, "n6": 2, "n7": 3,                     # from the root n5
                      "n3": 1, "n4": 2}                              # the cycle, from n3
    for layer in layers:                    # the unreachable ones below the reachable ones
        reachable = [arena.states[s] in ("outside", "n1", "n2", "n9") for s in layer]
        assert reachable == sorted(reachable, reverse=True), layer


def _layered_attack_graph(layers: int, width: int, seed: int = 3):
    """An attack graph of `layers` layers of `width` nodes (each node attacks two of the next
    layer at random), the last layer going to two targets 9000 and 9001: some nodes no entry
    leads to, as in published graphs."""
    import random

    import networkx as nx

    rng = random.Random(seed)
    graph = nx.DiGraph()
    rows = [list(range(i * width, (i + 1) * width)) for i in range(layers)]
    for here, there in zip(rows, rows[1:]):
        for u in here:
            for v in rng.sample(there, 2):
                graph.add_edge(u, v, p=round(rng.uniform(0.5, 0.95), 2))
    for u in rows[-1]:
        graph.add_edge(u, 9000 + u % 2, p=0.9)
    return graph, rows


def test_a_large_attack_graph_is_drawn_apart() -> None:
    """162 states, 320 arrows (the world picture shrank a layered layout to 12 x 9 inches, so
    its boxes covered one another and the arrows' names covered everything): the map grows
    instead (rows at least 0.5 in apart), the arrows of P1's actions go unnamed above
    MAX_NAMED_ARROWS (the legend says so), and no text overlaps another: every state's name
    and the episode's labels are readable."""
    import hg2prism
    from hg2prism.report.arena_graph import MAX_NAMED_ARROWS

    graph, rows = _layered_attack_graph(8, 20)
    world = hg2prism.world_from_graph(graph, entries=rows[0], task="F asset9000",
                                      trap_candidates=rows[4][:6], name="big")
    solution = hg2prism.solve(world)
    ts = solution.check.analysis.ts
    episode = episodes.choose_episode(solution.check.analysis, solution.strategy,
                                      world.simulation.horizon, world.simulation.seed)
    trace = episodes.belief_trace(solution.check.analysis.inference, episode.steps)
    fig, drawer = plots.world_picture(world, ts, episode, trace)
    try:
        found = problems(fig, fig.axes[0])
        texts = [t for t, _ in texts_of(fig)]
        # the last step's arrowhead, into the target, is under no label
        last = drawer.steps[-1]
        assert not last.stays
        heads = drawer._head_boxes(last, 0)
        inverse = fig.axes[0].transData.inverted()
        for text, box in texts_of(fig):
            if text.startswith("n="):
                (x0, y0), (x1, y1) = inverse.transform([[box.x0, box.y0], [box.x1, box.y1]])
                assert all(x1 <= h[0] or x0 >= h[2] or y1 <= h[1] or y0 >= h[3]
                           for h in heads), text
    finally:
        plots.plt.close(fig)
    assert len(drawer.edges) > MAX_NAMED_ARROWS and not drawer.names_arrows
    assert not found, found[:5]
    assert all(name in texts for name in world.arena.states if not name.startswith("n90"))
    assert any("arrows, unnamed" in t for t in texts)
    assert not any(t.startswith("to_") for t in texts)          # no arrow carries a name
    labelled = {n for t in texts for n in _step_numbers(t)}
    assert {1, episode.n_steps} <= labelled


@pytest.mark.parametrize("extra, named", [(0, True), (1, False)])
def test_arrows_are_named_up_to_the_limit(extra: int, named: bool) -> None:
    """A star: `outside` to n0, n0 to n1 ... n(k): exactly MAX_NAMED_ARROWS arrows are named,
    one more are not."""
    import networkx as nx

    import hg2prism
    from hg2prism.report.arena_graph import MAX_NAMED_ARROWS, ArenaDrawer

    graph = nx.DiGraph()
    for v in range(1, MAX_NAMED_ARROWS + extra):
        graph.add_edge(0, v, p=0.5)
    world = hg2prism.world_from_graph(graph, entries=[0], task="F goal", labels={1: "goal"},
                                      name="star")
    drawer = ArenaDrawer(world, transition_system(world))
    assert len(drawer.edges) == MAX_NAMED_ARROWS + extra
    assert drawer.names_arrows is named
    fig = plots.plt.figure()
    try:
        legend = [h.get_label() for h in drawer.draw_map(fig.add_subplot())]
    finally:
        plots.plt.close(fig)
    assert any(("unnamed" in text) is not named and "u → v" in text for text in legend)


def test_a_huge_layer_is_capped() -> None:
    """A star of 900 leaves, one column: the map grows with the graph (rows 0.5 in apart) but
    not beyond MAP_CAP_INCHES (it was 447 in tall, a PNG past 2^16 pixels near 900 states)."""
    import networkx as nx

    import hg2prism
    from hg2prism.report.arena_graph import MAP_CAP_INCHES, MIN_SHRINK, ROW_INCHES, layout

    for leaves, capped in ((100, False), (900, True)):
        graph = nx.DiGraph()
        for v in range(1, leaves + 1):
            graph.add_edge(0, v, p=0.5)
        world = hg2prism.world_from_graph(graph, entries=[0], task="F goal", labels={1: "goal"},
                                          name="star")
        span = layout(world.arena).max(axis=0)
        assert span[1] == pytest.approx(MAP_CAP_INCHES if capped
                                        else (leaves - 1) * ROW_INCHES * MIN_SHRINK)


@pytest.mark.parametrize("name", ("mir100",))
def test_a_trap_label_sits_beside_its_mark(name: str) -> None:
    """Each "trap k×" of an arena world's picture is placed beside a trap mark (left of it or
    above), not below or right of the state's box, where it read as a neighbour's (a stress
    test's "trap 14×" sat between two states)."""
    world, ts, episode, trace = showcase(name)
    fig, _ = plots.world_picture(world, ts, episode, trace)
    try:
        ax = fig.axes[0]
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        marks = [line.get_window_extent(renderer) for line in ax.lines
                 if line.get_marker() == "X" and len(line.get_xdata()) == 1]
        labels = [(text, box) for text, box in texts_of(fig)
                  if re.fullmatch(r"trap \d+×", text)]
    finally:
        plots.plt.close(fig)
    assert labels and marks
    near = 0.12 * fig.dpi            # pixels: 0.12 in
    for text, box in labels:
        gaps = [max(box.x0 - m.x1, m.x0 - box.x1, 0) + max(box.y0 - m.y1, m.y0 - box.y1, 0)
                for m in marks]
        assert min(gaps) <= near, (text, min(gaps) / fig.dpi)
