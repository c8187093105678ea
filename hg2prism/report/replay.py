"""A replay of the drawn episode as an animated GIF (`replay.gif`): per frame where P1 is, the
traps P2 set, the step (P1's action and where it led), P2's hypothesis and the numbers her
observer reports (CUSUM scores, or whatever observer.ReportsBelief gives). The world is drawn by
its drawer (report.plots.world_drawer): a grid by the grid front end, any other arena as a graph.

Frames are rendered with matplotlib's Agg canvas and assembled with Pillow (which matplotlib
depends on), in memory, so that the file is written atomically like every output. An episode
of N steps has the states 0..N (0: before the first move); the replay shows them all when
there are at most REPLAY_MAX_FRAMES, else every k-th with k = ceil(N / (REPLAY_MAX_FRAMES - 1)),
and always the last (`replay_frames`).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from hg2prism.model.dynamics import TransitionSystem
from hg2prism.model.world import World
from hg2prism.outputs import write_bytes
from hg2prism.report import plots
from hg2prism.report.style import hypothesis_colour

__all__ = ["REPLAY_MAX_FRAMES", "REPLAY_FRAME_MS", "REPLAY_DPI", "REPLAY_FONT", "REPLAY_MIN_FONT",
           "FrameNote", "frame_notes", "replay_frames", "replay_inches", "replay_figure",
           "replay_gif"]

REPLAY_MAX_FRAMES = 100
REPLAY_FRAME_MS = 600        # each frame shows for this long
REPLAY_DPI = 72


def replay_frames(n_steps: int) -> list[int]:
    """The episode states (0 = the start, n = after step n) the replay shows, in order."""
    if n_steps + 1 <= REPLAY_MAX_FRAMES:
        return list(range(n_steps + 1))
    stride = math.ceil(n_steps / (REPLAY_MAX_FRAMES - 1))
    frames = list(range(0, n_steps + 1, stride))
    if frames[-1] != n_steps:
        frames.append(n_steps)
    return frames


def replay_inches(world: World, ts: TransitionSystem) -> tuple[float, float]:
    """The replay's frame size in inches: the drawer's map beside the belief panel."""
    return plots.world_drawer(world, ts).replay_inches()


def _acted_text(ts: TransitionSystem) -> str:
    """What P2 did on her hypothesis, in a caption."""
    return "set traps for" if ts.traps_mode else "acted on"


REPLAY_FONT = 10         # captions and titles, in points (= pixels at REPLAY_DPI)
REPLAY_MIN_FONT = 9      # no text of a frame is smaller (ticks, legends, map marks)


@dataclass(frozen=True)
class FrameNote:
    """What a frame says: the episode state it shows (0 = the start, n = after step n, the
    figures' step-numbering rule), its caption, P2's line, and the hypothesis she switched to
    on observing step n (None: no change of mind at this step)."""

    state: int
    caption: str
    believes: str
    changed_to: int | None


def frame_notes(world: World, ts: TransitionSystem, drawer, steps, trace) -> list[FrameNote]:
    """Every episode state's texts, in order (state 0 .. N)."""
    changes = dict(trace.changes)
    n_steps = len(steps)
    notes = [FrameNote(0, f"start (state 0 of {n_steps})", "P2 starts believing "
                       f"x{world.initial_hypothesis}", None)]
    for n, step in enumerate(steps, start=1):
        after = trace.after[n - 1]
        line = (f"P2 {_acted_text(ts)} x{trace.acted[n - 1]} at step {n};\n"
                f"after observing it: x{after}")
        if n in changes:
            line += " (changed her mind)"
        notes.append(FrameNote(n, f"step {n}/{n_steps}: {drawer.caption(step)}", line,
                               changes.get(n)))
    return notes


@dataclass
class _Replay:
    """The replay's figure, laid out once: the artists each frame changes, and the background
    they are drawn over (blitting)."""

    fig: object
    drawer: object
    map_ax: object
    trail: object
    robot: object
    traps: object
    caption: object
    believes: object
    bars: list
    threshold: object              # the threshold's line (drawn over the bars), or None
    values: np.ndarray | None      # [steps + 1, hypotheses] the observer's numbers, or None
    wrap: int = 40                 # characters of a caption line
    background: object = None

    @property
    def moving(self) -> list:
        """The artists every frame redraws."""
        return [self.trail, self.robot, self.traps, self.caption, self.believes, *self.bars,
                *([self.threshold] if self.threshold is not None else [])]


def _belief_panel(ax, world: World, trace, wrap: int) -> tuple[list, np.ndarray | None, object,
                                                                 object]:
    """The bar chart of P2's numbers (or her hypothesis), its threshold and the legend below
    it; returns the bars, the per-state values (None: bars show the hypothesis), the title and
    the threshold's line."""
    import textwrap

    n_x = len(world.hypotheses)
    if trace.values is not None:
        values = np.vstack([np.zeros(n_x), np.array(trace.values, dtype=float).reshape(-1, n_x)])
        top = max(float(values.max()), trace.threshold or 0.0, 1e-9) * 1.15
        label = trace.name
    else:
        values = None
        top, label = 1.05, "P2's hypothesis"
    bars = ax.bar(range(n_x), np.zeros(n_x),
                  color=[hypothesis_colour(x)
                         for x in range(n_x)])
    legend = [textwrap.fill(f"x{x}: {h}", wrap, subsequent_indent="    ")
              for x, h in enumerate(world.hypotheses)]
    threshold = None
    if trace.threshold is not None:
        threshold = ax.axhline(trace.threshold, color="black", ls="--", lw=1)
        legend.append(f"dashed line: threshold {trace.threshold:g}")
    ax.set_ylim(0, top)
    ax.set_xticks(range(n_x), [f"x{x}" for x in range(n_x)])
    ax.set_ylabel(label, fontsize=REPLAY_MIN_FONT)
    ax.set_xlabel("\n".join(legend), fontsize=REPLAY_MIN_FONT, loc="left")
    ax.tick_params(labelsize=REPLAY_MIN_FONT)
    believes = ax.set_title("", fontsize=REPLAY_FONT, loc="left")
    return list(bars), values, believes, threshold


def _wrapped(text: str, width: int) -> str:
    import textwrap

    return "\n".join(textwrap.fill(line, width) for line in text.split("\n"))


def replay_figure(world: World, ts: TransitionSystem, episode, trace) -> tuple[_Replay, list]:
    """The replay's figure with everything that does not move drawn, laid out once with the
    widest texts of any frame, so that nothing moves from frame to frame; and the frames'
    notes (`frame_notes`)."""
    from hg2prism.analyses.episodes import episode_steps
    from hg2prism.report.style import STEP_RULE

    drawer = plots.world_drawer(world, ts)
    steps = episode_steps(ts, episode.steps)
    notes = frame_notes(world, ts, drawer, steps, trace)
    width, _ = drawer.replay_inches()
    panel = width * 3.2 / (drawer.replay_map_width + 3.2)      # the belief panel, inches
    # characters per line: a caption spans its panel (about 0.55 em a character)
    wrap_map = max(16, int(drawer.replay_map_width * 72 / (0.58 * REPLAY_FONT)))
    wrap_panel = max(16, int(min(panel, 3.6) * 72 / (0.58 * REPLAY_MIN_FONT)))
    fig = plots.new_figure(drawer.replay_inches(), REPLAY_DPI)
    map_ax, belief_ax = fig.subplots(1, 2, width_ratios=(drawer.replay_map_width, 3.2))
    drawer.draw_map(map_ax, REPLAY_MIN_FONT)
    trail, = map_ax.plot([], [], "-", color="0.3", alpha=0.35, lw=3, zorder=2)
    robot, = map_ax.plot([], [], "o", zorder=6, **{"mec": "black", "mew": 1.2,
                                                   **drawer.robot_style})
    traps, = map_ax.plot([], [], "X", color="darkgreen", ms=14, ls="", zorder=4)
    caption = map_ax.set_title("", fontsize=REPLAY_FONT, loc="left")
    bars, values, believes, threshold = _belief_panel(belief_ax, world, trace, wrap_panel)
    fig.suptitle(_wrapped(f"{world.name}: replay of the drawn episode (seed {episode.seed}, "
                          f"{len(steps)} steps, {episode.outcome})\n{STEP_RULE}",
                          int(width * 72 / (0.58 * REPLAY_FONT))), fontsize=REPLAY_FONT)
    widest = max(notes, key=lambda note: len(_wrapped(note.caption, wrap_map)))
    caption.set_text(_wrapped(widest.caption, wrap_map))
    believes.set_text(max((note.believes for note in notes), key=len))
    fig.canvas.draw()
    fig.set_layout_engine("none")
    drawer.finish(map_ax)
    if hasattr(drawer, "trap_spot"):        # beside the state's box, off its name
        from matplotlib.transforms import offset_copy

        traps.set_transform(offset_copy(map_ax.transData, fig=fig, x=-6, y=6, units="points"))
    replay = _Replay(fig, drawer, map_ax, trail, robot, traps, caption, believes, bars,
                     threshold, values, wrap_map)
    # Blitting: the map, axes and labels are drawn once; each frame restores them and draws
    # only what moves (a full redraw per frame is about ten times slower).
    for artist in replay.moving:
        artist.set_animated(True)
    fig.canvas.draw()
    replay.background = fig.canvas.copy_from_bbox(fig.bbox)
    return replay, notes


def _frame(replay: _Replay, world: World, places: list, steps: list, trace,
           note: FrameNote) -> tuple[Image.Image, list]:
    """Draw episode state `note.state` (P1 at `places[state]`) over the background; returns
    the image and the artists added for it (removed before the next frame)."""
    map_ax, n_x, state, drawer = replay.map_ax, len(world.hypotheses), note.state, replay.drawer
    positions = [drawer.position(place) for place in places[:state + 1]]
    replay.trail.set_data(*zip(*positions))
    step = steps[state - 1] if state else None
    hypothesis_after = trace.after[state - 1] if state else world.initial_hypothesis
    replay.robot.set_data([positions[state][0]], [positions[state][1]])
    colour = ("red" if step is not None and step.trapped
              else hypothesis_colour(hypothesis_after))
    if hasattr(drawer, "ring_points"):      # a ring around the state's box: its name shows
        replay.robot.set_markersize(drawer.ring_points(places[state]))
        replay.robot.set_markeredgecolor(colour)
    else:
        replay.robot.set_markerfacecolor(colour)
    before = set(map_ax.get_children())
    if step is not None:
        trap_at = [getattr(drawer, "trap_spot", drawer.position)(p) for p in step.traps]
        replay.traps.set_data([c[0] for c in trap_at], [c[1] for c in trap_at])
        replay.drawer.draw_step(map_ax, step)
    else:
        replay.traps.set_data([], [])
    replay.caption.set_text(_wrapped(note.caption, replay.wrap))
    replay.believes.set_text(note.believes)
    added = [a for a in map_ax.get_children() if a not in before]
    for artist in added:
        artist.set_animated(True)
    heights = (replay.values[state] if replay.values is not None
               else np.eye(n_x)[hypothesis_after])
    for x, bar in enumerate(replay.bars):
        bar.set_height(heights[x])
        bar.set_edgecolor("black" if x == hypothesis_after else "none")
        bar.set_linewidth(2.0 if x == hypothesis_after else 0.0)
    canvas = replay.fig.canvas
    canvas.restore_region(replay.background)
    for artist in (*added, *replay.moving):
        replay.fig.draw_artist(artist)
    return Image.fromarray(np.array(canvas.buffer_rgba())[..., :3]), added


def _gif(images: list[Image.Image]) -> bytes:
    """The frames as one GIF with one palette for all frames, from a strip of frames spread
    over the episode (the colours of traps, steps and hypotheses need not appear in the
    first frame)."""
    sample = images[::max(1, len(images) // 8)] + [images[-1]]
    strip = Image.new("RGB", (sample[0].width * len(sample), sample[0].height))
    for i, image in enumerate(sample):
        strip.paste(image, (i * image.width, 0))
    palette = strip.quantize(colors=96, method=Image.Quantize.MEDIANCUT)
    images = [image.quantize(palette=palette, dither=Image.Dither.NONE) for image in images]
    buffer = io.BytesIO()
    images[0].save(buffer, format="GIF", save_all=True, append_images=images[1:],
                   duration=REPLAY_FRAME_MS, loop=0)
    return buffer.getvalue()


def replay_gif(world: World, ts: TransitionSystem, episode, trace, path: Path) -> int:
    """Write the replay of `episode` (episodes.ChosenEpisode) with P2's `trace`
    (episodes.BeliefTrace) to `path`; returns the number of frames."""
    from hg2prism.analyses.episodes import episode_steps

    replay, notes = replay_figure(world, ts, episode, trace)
    steps = episode_steps(ts, episode.steps)
    start = ts.decode(ts.start_state)[0]
    places = [start] + [s.landing for s in steps]
    images: list[Image.Image] = []
    added: list = []
    for state in replay_frames(len(steps)):
        for artist in added:
            artist.remove()
        image, added = _frame(replay, world, places, steps, trace, notes[state])
        images.append(image)
    write_bytes(path, _gif(images))
    return len(images)
