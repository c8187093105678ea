"""Figures a researcher opens: the world with one episode, P2's belief along it, completion
against time, the sweep, the detector, scaling.

Every figure is written twice, as PNG (FIGURE_DPI dots per inch) and as SVG (text kept as text),
at a fixed size in inches: no tight bounding box, so that a figure's pixel size is known in
advance (docs/cli.md "Figures")."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import matplotlib
# pyplot for its names only (Axes, Line2D, Rectangle): no backend is chosen here, and no figure
# of this module is made through pyplot, so importing hg2prism keeps a notebook's backend
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from hg2prism.model.dynamics import TransitionSystem
from hg2prism.model.world import World
from hg2prism.outputs import write_bytes
from hg2prism.report.style import HYPOTHESIS_COLOURS, hypothesis_colour

__all__ = ["FIGURE_DPI", "FIGURE_FORMATS", "figure_paths", "new_figure", "world_drawer",
           "world_figure_inches", "world_picture", "world_figure", "belief_picture",
           "belief_figure", "completion_picture", "completion_figure", "sweep_figure",
           "detection_figure", "scaling_picture", "scaling_figure", "robust_figure",
           "SWEEP_INCHES", "DETECTION_INCHES", "COMPLETION_INCHES", "BELIEF_INCHES",
           "SCALING_INCHES", "HYPOTHESIS_COLOURS", "LOG_PARAMETERS"]

FIGURE_DPI = 150
FIGURE_FORMATS = ("png", "svg")
SWEEP_INCHES = (6.4, 4.4)
DETECTION_INCHES = (10.0, 4.2)
DETECTION_REPLANNING_INCHES = (14.0, 4.2)
ROBUST_INCHES = (6.4, 4.8)
COMPLETION_INCHES = (6.4, 4.4)
BELIEF_INCHES = (8.0, 3.8)

# Deterministic SVG output (no random ids, no date) with searchable text: set while a figure is
# written, not globally (the caller's rcParams stay theirs).
SAVE_RC = {"svg.hashsalt": "hg2prism", "svg.fonttype": "none"}


def figure_paths(path: Path) -> list[Path]:
    """The files a figure named `path` (any suffix) is written to: one per FIGURE_FORMATS."""
    return [Path(path).with_suffix(f".{fmt}") for fmt in FIGURE_FORMATS]


def new_figure(inches: tuple[float, float], dpi: float | None = None,
               layout: str | None = "constrained") -> Figure:
    """A figure of `inches` on matplotlib's Agg canvas, made without pyplot: it is written to
    files headless, whatever backend is in use, and never shown nor kept by pyplot."""
    fig = Figure(figsize=inches, dpi=dpi, layout=layout)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: Path) -> list[Path]:
    written = []
    with matplotlib.rc_context(SAVE_RC):
        for target in figure_paths(path):
            buffer = io.BytesIO()
            fmt = target.suffix[1:]
            metadata = {"Date": None} if fmt == "svg" else None
            fig.savefig(buffer, format=fmt, dpi=FIGURE_DPI, metadata=metadata)
            fig.set_layout_engine("none")     # laid out once: the other formats reuse it
            write_bytes(target, buffer.getvalue())
            written.append(target)
    return written


def figure_axes(ax: plt.Axes | None, inches: tuple[float, float], dpi: float | None = None
                ) -> tuple[Figure, plt.Axes]:
    """The caller's axes (a figure function then draws into them and saves nothing), or a new
    figure of `inches` with constrained layout and its axes."""
    if ax is not None:
        return ax.figure, ax
    fig = new_figure(inches, dpi)
    return fig, fig.add_subplot()


def figure_done(fig: Figure, path: Path | None, given: object) -> list[Path]:
    """Save a figure function's own figure to `path`; nothing when it drew into given axes."""
    return [] if given is not None or path is None else _save(fig, path)


def _legend(fig: Figure, ax: plt.Axes, given: object, **style) -> None:
    """The legend below the axes on a figure function's own figure; in given axes, the
    axes' own legend in one column, inside them (the caller's figure is not ours to lay out:
    the own figure's row of columns was wider than a panel, over its neighbour and title)."""
    if given is not None:
        ax.legend(**{**style, "ncol": 1})
    else:
        fig.legend(loc="outside lower center", **style)


def world_drawer(world: World, ts: TransitionSystem):
    """What draws `world` (docs/semantics.md §15 "Figures"): its front end's drawer when it has
    one (a grid's: frontends/grid_drawing.py), else the arena as a graph (report/arena_graph.py)."""
    from hg2prism import frontends

    own = frontends.drawer(world, ts)
    if own is not None:
        return own
    from hg2prism.report.arena_graph import ArenaDrawer

    return ArenaDrawer(world, ts)


def world_figure_inches(world: World, ts: TransitionSystem) -> tuple[float, float]:
    """The world figure's size in inches: the drawer's map and the legend."""
    return world_drawer(world, ts).world_inches()


def world_picture(world: World, ts: TransitionSystem, episode, trace,
                  ax: plt.Axes | None = None):
    """The world figure, laid out and labelled (not saved; into `ax` when given), and the
    drawer that drew it (its `changes_shown`: the changes of mind (n, x) labelled)."""
    from hg2prism.analyses.episodes import episode_steps
    from hg2prism.report.style import STEP_RULE

    drawer = world_drawer(world, ts)
    given = ax
    fig, ax = figure_axes(ax, drawer.world_inches(), FIGURE_DPI)
    engine = fig.get_layout_engine()
    handles = drawer.draw_world(ax, episode_steps(ts, episode.steps), trace.changes)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1),
              fontsize=7, frameon=False, handlelength=3.2)
    ax.set_title(f"{world.name}: one deceptive episode, {episode.describe()}\n"
                 f"seed {episode.seed}, {episode.n_steps} steps, {episode.outcome}; "
                 f"task {world.formula}\n{STEP_RULE}", fontsize=8.5, loc="left")
    if given is None:
        _widen_for_the_key(fig, ax)
    drawer.finish(ax)      # measures the laid-out map, then freezes the layout
    if given is not None:
        # the caller's figure is not ours to freeze: its other panels, drawn after this one,
        # are laid out by its own engine (frozen, a belief panel beside it lost its legend)
        fig.set_layout_engine(engine)
    return fig, drawer


KEY_MARGIN_INCHES = 0.1     # between the world figure's key and the figure's right edge


def _widen_for_the_key(fig: Figure, ax: plt.Axes) -> None:
    """Widen the figure when its key (beside the map) would end beyond its right edge: a flat
    map in a figure of the drawer's least height grows with the height left to it and pushed
    the key out (a corridor of nine states: 40 pixels of the key cut)."""
    width, height = fig.get_size_inches()
    key = ax.get_legend().get_window_extent(fig.canvas.get_renderer()).width / fig.dpi
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    if height * abs(x1 - x0) / abs(y1 - y0) + key + 0.02 * width + 2 * KEY_MARGIN_INCHES <= width:
        return      # even a map as high as the figure leaves its key room: no layout needed
    engine = fig.get_layout_engine()
    for attempt in range(3):            # the wider figure is laid out anew: measured again
        if engine is not None:
            engine.execute(fig)         # laid out as it will be, nothing drawn
        ax.apply_aspect()
        key = ax.get_legend().get_window_extent(fig.canvas.get_renderer())
        beyond = (key.x1 - fig.bbox.width) / fig.dpi + KEY_MARGIN_INCHES
        if beyond <= 0 or (attempt == 0 and beyond <= KEY_MARGIN_INCHES):
            return                      # inside (a figure planned well is left as it is)
        width, height = fig.get_size_inches()
        fig.set_size_inches(width + beyond, height)


def world_figure(world: World, ts: TransitionSystem, episode, trace, path: Path | None,
                 ax: plt.Axes | None = None) -> list[Path]:
    """The world and one deceptive episode (episodes.ChosenEpisode) with P2's belief along it
    (episodes.BeliefTrace), drawn by the world's drawer (`world_drawer`): every distinct step
    drawn once, coloured by P2's hypothesis, labelled with its step numbers; the traps P2 set;
    where P2 changed her mind ("n=k: P2 now x": observing step k made her switch). Returns
    the files written (PNG and SVG); into the given `ax` it draws and writes nothing."""
    fig, _ = world_picture(world, ts, episode, trace, ax)
    return figure_done(fig, path, ax)


BELIEF_MARKERS = ("o", "s", "^", "D", "v", "P")


def belief_picture(world: World, trace, episode, ax: plt.Axes | None = None):
    """The belief figure (not saved; into `ax` when given) and the steps it marks as changes
    of mind (BeliefTrace.changes: the step whose observation made P2 switch)."""
    from hg2prism.report.style import STEP_RULE

    fig, ax = figure_axes(ax, BELIEF_INCHES, FIGURE_DPI)
    n = len(trace.after)
    steps = np.arange(1, n + 1)
    for i, x in enumerate(trace.after):
        ax.axvspan(i + 0.5, i + 1.5, color=hypothesis_colour(x), alpha=0.10, lw=0)
    if trace.values is not None and n:
        values = np.array(trace.values)
        k = values.shape[1]
        for x in range(k):
            # lines that coincide stay visible: each hypothesis its marker, size and dash,
            # and a small sideways shift (the larger markers drawn first, under the smaller)
            shift = (x - (k - 1) / 2) * min(0.12, 0.5 / k)
            ax.plot(steps + shift, values[:, x], BELIEF_MARKERS[x % len(BELIEF_MARKERS)],
                    ls=("-", "--", ":", "-.")[x % 4], ms=5.5 - 1.2 * min(x, 3), lw=1.1,
                    color=hypothesis_colour(x), mfc="white" if x == 0 else hypothesis_colour(x),
                    zorder=2 + x, label=f"x{x}: {world.hypotheses[x]}")
        if trace.threshold is not None:
            ax.axhline(trace.threshold, color="black", ls="--", lw=1,
                       label=f"threshold {trace.threshold:g}")
        ax.set_ylabel(trace.name, fontsize=8)
    else:
        ax.step(steps, trace.after, "o-", where="mid", ms=3, color="black",
                label="P2's hypothesis")
        ax.set_ylabel("P2's hypothesis", fontsize=8)
    changes = tuple(n for n, _ in trace.changes)
    for s in changes:
        ax.axvline(s, color="red", lw=0.8, alpha=0.6)
    if changes:
        ax.plot([], [], color="red", lw=0.8, alpha=0.6, label="change of mind")
    shading = ", ".join(f"x{x}" for x in sorted(set(trace.after)))
    ax.set_xlabel(f"{STEP_RULE}\n(shaded: her hypothesis at step n: {shading}; "
                  f"{len(changes)} change(s) of mind)", fontsize=8)
    ax.set_xlim(0.5, max(n, 1) + 0.5)
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1), frameon=False)
    ax.set_title(f"{world.name}: P2's belief along the drawn episode (seed {episode.seed}, "
                 f"{episode.n_steps} steps)", fontsize=9)
    return fig, changes


def belief_figure(world: World, trace, episode, path: Path | None,
                  ax: plt.Axes | None = None) -> list[Path]:
    """P2's belief along the drawn episode (episodes.BeliefTrace): the numbers her observer
    reports per hypothesis after observing each step, her threshold, and, shaded, the
    hypothesis she holds after each step; red lines where she changed her mind (into `ax`
    when given, then writing nothing)."""
    fig, _ = belief_picture(world, trace, episode, ax)
    return figure_done(fig, path, ax)


COMPLETION_STYLES = (("-", "o"), ("--", "s"), (":", "^"), ("-.", "P"), ((0, (6, 2, 1, 2)), "v"))


def completion_picture(world_name: str, rows: Sequence[tuple[str, object, float | None]],
                       ax: plt.Axes | None = None) -> Figure:
    """The completion figure (not saved; into `ax` when given): a curve per row
    (tables.COMPLETION_ROWS's order), each its colour, dash and marker (markers staggered, so
    that curves that coincide stay visible)."""
    from hg2prism.analyses.simulation import GOAL, wilson_band

    given = ax
    fig, ax = figure_axes(ax, COMPLETION_INCHES, FIGURE_DPI)
    horizon = max([1] + [summary.horizon for _, summary, _ in rows])
    episodes = sorted({summary.episodes for _, summary, _ in rows})
    # the last step at which some curve still rises; when every curve is flat over the last
    # three quarters of the horizon (mir100's episodes end within 10 of 200 steps), the axis is
    # logarithmic beyond step 1, so that the rise is not squeezed against the left edge
    last = max([0] + [int(summary.lengths[summary.outcomes == GOAL].max(initial=0))
                      for _, summary, _ in rows])
    stretched = 0 < 4 * last <= horizon and horizon >= 20
    for i, (label, summary, exact) in enumerate(rows):
        done = np.sort(summary.lengths[summary.outcomes == GOAL])
        steps = np.arange(0, summary.horizon + 1)
        counts = np.searchsorted(done, steps, side="right")
        rate = counts / summary.episodes
        low, high = wilson_band(counts, summary.episodes)
        colour = f"C{i}"
        dash, marker = COMPLETION_STYLES[i % len(COMPLETION_STYLES)]
        every = max(1, summary.horizon // 8)
        # markers evenly spaced along the drawn axis (by distance on the figure when stretched)
        markevery = ((i / len(rows) / 8, 1 / 8) if stretched
                     else (i * every // len(rows), every))
        ax.fill_between(steps, low, high, color=colour, alpha=0.18, lw=0)
        ax.plot(steps, rate, ls=dash, marker=marker, ms=4, markevery=markevery,
                color=colour, lw=1.4, label=label if len(episodes) == 1
                else f"{label} ({summary.episodes} episodes)")
        if exact is not None:
            # on the axis's right edge: drawn whole, not cut in half by it (a review)
            ax.plot([summary.horizon], [exact], marker="D", color=colour, ms=5, ls="",
                    mec="black", mew=0.5, clip_on=False, zorder=3)
    ax.plot([], [], marker="D", color="0.3", ls="", label="exact at the horizon")
    ax.fill_between([], [], [], color="0.3", alpha=0.25, label="95 % Wilson band")
    ax.set_xlim(0, horizon)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("step n")
    if stretched:
        ax.set_xscale("symlog", linthresh=1, linscale=0.5)
        ticks = [t for t in (0, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000)
                 if t < horizon * 0.8] + [horizon]
        ax.set_xticks(ticks, [str(t) for t in ticks])
        ax.minorticks_off()
        ax.set_xlabel(f"step n (logarithmic beyond 1: every completion came within {last} "
                      "steps)")
    ax.set_ylabel("share completed within n steps")
    ax.grid(alpha=0.3)
    _legend(fig, ax, given, ncol=2, fontsize=7, frameon=False)
    each = f", {episodes[0]} episodes each" if len(episodes) == 1 else ""
    ax.set_title(f"{world_name}: completion against time, simulated{each}", fontsize=9)
    return fig


def completion_figure(world_name: str, rows: Sequence[tuple[str, object, float | None]],
                      path: Path | None, ax: plt.Axes | None = None) -> list[Path]:
    """Completion by step n of each simulated strategy pair: `rows` holds (label,
    simulation.SimulationSummary, exact within-horizon probability or None), one per row of
    the completion table (tables.COMPLETION_ROWS). Each curve is the share of episodes
    completed within n steps with its 95 % Wilson band; the exact value at the horizon is
    marked (into `ax` when given, then writing nothing)."""
    return figure_done(completion_picture(world_name, rows, ax), path, ax)


def _value_text(value: object) -> str:
    if isinstance(value, (list, tuple)):            # a prior
        return ",".join(_value_text(v) for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


LOG_PARAMETERS = ("rationality", "threshold")


def _parameter_axis(ax: plt.Axes, parameter: str, values: Sequence[object]):
    """The x axis of a swept parameter: its values as ticks (a logarithmic axis for
    LOG_PARAMETERS); an observer kind or a prior is a category, evenly spaced in the order
    swept. Returns the x position of a value."""
    categorical = not all(isinstance(v, (int, float)) for v in values)
    labels = list(dict.fromkeys(_value_text(v) for v in values))
    if categorical:
        def x_of(value: object) -> float:
            return float(labels.index(_value_text(value)))
        ticks = [float(i) for i in range(len(labels))]
    else:
        def x_of(value: object) -> float:
            return value                    # type: ignore[return-value]
        ticks = sorted(set(values))         # type: ignore[type-var]
        labels = [_value_text(v) for v in ticks]
    if parameter in LOG_PARAMETERS and not categorical:
        ax.set_xscale("log")
        ax.minorticks_off()
        ax.set_xlabel(f"{parameter} (log scale)")
    else:
        ax.set_xlabel(parameter)
    ax.set_xticks(ticks, labels)
    if len(ticks) > 8:
        ax.tick_params(axis="x", labelrotation=45)
    return x_of


def sweep_figure(parameter: str, rows: Sequence[dict], path: Path | None,
                 world_name: str | None = None, ax: plt.Axes | None = None) -> list[Path]:
    """Completion probability against a swept parameter, one line per value (with a sweep's
    --deception values, V_static and V_naive too); a logarithmic axis for rationality and
    threshold (LOG_PARAMETERS), the legend below the axes (into `ax` when given, then writing
    nothing)."""
    given = ax
    fig, ax = figure_axes(ax, SWEEP_INCHES)
    x_of = _parameter_axis(ax, parameter, [row[parameter] for row in rows])
    # along the axis, whatever order the values were given in (--values 2 0 1 drew 2 -> 0 -> 1)
    rows = sorted(rows, key=lambda row: x_of(row[parameter]))
    xs = [x_of(row[parameter]) for row in rows]
    # each series' markers smaller than the one's before: values that coincide (V_lead,
    # V_static and V_naive often do) show as rings around dots rather than one hiding another
    for n, (key, label, style) in enumerate((
            ("deceptive_value", "deceptive (asymmetric)", "o-"),
            ("v_lead", "symmetric, leader", "s--"),
            ("v_ne", "symmetric, Nash", "^:"),
            ("v_static", "P2 never revises (V_static)", "d-."),
            ("v_naive", "P1 ignores her inference (V_naive)", "v-."))):
        if all(key in row for row in rows):
            ax.plot(xs, [row[key] for row in rows], style, label=label, ms=10.0 - 1.5 * n)
    return _finish_sweep(fig, ax, path, parameter, world_name, ncol=3, fontsize=8, given=given)


DETECTION_ZOOM = 6      # steps shown either side of the detection in the zoomed panel


def sweep_grid_figure(parameters: Sequence[str], rows: Sequence[dict], path: Path | None,
                      world_name: str | None = None, ax: plt.Axes | None = None) -> list[Path]:
    """A sweep over several parameters: the deceptive value (solid) and V_lead (dashed) against
    the first parameter, one colour per combination of the others' values; the same axis and
    legend rules as :func:`sweep_figure`. Each series' markers are smaller than the one's
    before, so that series that coincide (traps 1 and 2 on mir100) show as rings around dots
    rather than one hiding the other; V_lead's markers are hollow squares and its lines' dashes
    take turns between the series."""
    given = ax
    fig, ax = figure_axes(ax, SWEEP_INCHES)
    first, others = parameters[0], list(parameters[1:])
    series: dict[tuple, list[dict]] = {}
    for row in rows:     # a prior is a list: keyed by its text
        series.setdefault(tuple(_value_text(row[p]) for p in others), []).append(row)
    colours = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    x_of = _parameter_axis(ax, first, [row[first] for row in rows])
    # V_lead's dashes take turns: series n draws the n-th of every len(series) dashes, so that
    # lines that coincide (V_lead does not depend on the observer's window) alternate their
    # colours along the line; they were translucent and blended into a colour no legend has
    dash, turns = (4.0 if len(series) <= 3 else 2.5), len(series)
    for n, (key, members) in enumerate(series.items()):
        members = sorted(members, key=lambda r: x_of(r[first]))
        xs = [x_of(r[first]) for r in members]
        label = ", ".join(f"{p}={_value_text(v)}" for p, v in zip(others, key))
        colour = colours[n % len(colours)]
        size = max(3.0, 9.0 - 2.0 * n)
        ax.plot(xs, [r["deceptive_value"] for r in members], "o-", color=colour, ms=size,
                lw=max(0.8, 2.4 - 0.5 * n), label=f"deceptive, {label}")
        ax.plot(xs, [r["v_lead"] for r in members], marker="s", mfc="none", color=colour,
                ms=size, ls=(n * dash, (dash, dash * max(1, turns - 1))), lw=1.4,
                label=f"V_lead, {label}")
    return _finish_sweep(fig, ax, path, " x ".join(parameters), world_name, ncol=2, fontsize=7,
                         given=given)


def _finish_sweep(fig, ax, path: Path | None, against: str, world_name: str | None, ncol: int,
                  fontsize: int, given: plt.Axes | None = None) -> list[Path]:
    """The axis, legend and title every sweep figure shares; saves the figure (not the
    caller's: in given axes the legend is the axes')."""
    ax.set_ylabel("P1's completion probability")
    ax.set_ylim(-0.02, 1.02)        # a value of 0 drawn whole, not cut in half by the axis
    ax.grid(alpha=0.3)
    _legend(fig, ax, given, ncol=ncol, fontsize=fontsize, frameon=False)
    title = f"completion probability at the initial state against {against}"
    ax.set_title(f"{world_name}: {title}" if world_name else title, fontsize=9)
    return figure_done(fig, path, given)


def _detection_panels(ax, replanning: dict | None) -> tuple[Figure, list]:
    """The detection figure's panels (the whole episode, the zoom, re-planning): a new
    figure's, or the caller's, one Axes (the whole episode only) or a sequence of them (the
    panels in that order, as many as given)."""
    if ax is None:
        fig = new_figure(DETECTION_INCHES if replanning is None else DETECTION_REPLANNING_INCHES)
        if replanning is None:
            return fig, list(fig.subplots(1, 2, width_ratios=(1.5, 1)))
        return fig, list(fig.subplots(1, 3, width_ratios=(1.5, 1, 1.2)))
    panels = [ax] if isinstance(ax, plt.Axes) else list(ax)
    if not 1 <= len(panels) <= (2 if replanning is None else 3):
        raise ValueError(f"the detection figure draws 1 to {2 if replanning is None else 3} "
                         f"panels; {len(panels)} axes given")
    return panels[0].figure, panels


def detection_figure(statistics: Sequence[float], thresholds: Sequence[float | None],
                     deviate_after: int, detected_at: int | None, path: Path | None,
                     world_name: str | None = None, seed: int | None = None,
                     replanning: dict | None = None, ax=None) -> list[Path]:
    """The likelihood-ratio statistic G per step against the chi-square threshold: the whole
    episode on the left, and on the right the steps around the detection (DETECTION_ZOOM either
    side; around the deviation when nothing was detected). With `replanning` (detection.json's
    section, docs/semantics.md §14) a third panel: completion with and without re-planning in
    the deviation and compliant batches, with their 95% Wilson intervals. `ax`: the caller's
    Axes (the whole episode's panel) or a sequence of Axes (the panels in that order); then
    nothing is written."""
    fig, panels = _detection_panels(ax, replanning)
    full, zoom = panels[0], (panels[1] if len(panels) > 1 else None)
    if len(panels) > 2:
        _replanning_panel(panels[2], replanning)
    steps = np.arange(1, len(statistics) + 1)
    limits = np.array([t if t is not None else np.nan for t in thresholds], dtype=float)
    centre = detected_at if detected_at is not None else deviate_after
    low, high = max(1, centre - DETECTION_ZOOM), min(len(statistics), centre + DETECTION_ZOOM)
    for axes, zoomed in ((full, False), (zoom, True)):
        if axes is None:
            continue
        _statistic_panel(axes, steps, statistics, limits, deviate_after, detected_at, zoomed,
                         (low, high))
    if len(statistics) and zoom is not None:
        full.axvspan(low - 0.5, high + 0.5, color="0.85", alpha=0.5, lw=0, zorder=0)
    full.set_ylabel("statistic")
    where = f"{world_name}: " if world_name else ""
    which = f" (seed {seed})" if seed is not None else ""
    title = f"{where}P1's test of its model of P2 along one episode{which}"
    if zoom is not None:
        full.set_title("the whole episode (grey: the steps shown on the right)", fontsize=8)
        zoom.legend(fontsize=7, loc="upper left")
    else:
        full.legend(fontsize=7, loc="upper left")
    if ax is None:
        fig.suptitle(title, fontsize=9)
    else:
        full.set_title(title if zoom is None else f"{title}\n(grey: the steps shown beside)",
                       fontsize=8)
    return figure_done(fig, path, ax)


def _statistic_panel(ax: plt.Axes, steps, statistics, limits, deviate_after: int,
                     detected_at: int | None, zoomed: bool, shown: tuple[int, int]) -> None:
    """One panel of the statistic against the threshold (zoomed: the steps `shown`)."""
    low, high = shown
    ax.plot(steps, statistics, "o-", ms=3 if not zoomed else 5, label="G = 2 (ln L1 − ln L0)")
    ax.plot(steps, limits, "s--", ms=3 if not zoomed else 5, label="χ² threshold (1 − α, df)")
    ax.axvline(deviate_after + 0.5, color="grey", ls=":",
               label=f"P2 deviates after step {deviate_after}")
    if detected_at is not None:
        ax.axvline(detected_at, color="red", alpha=0.5,
                   label=f"mismatch detected at step {detected_at}")
    ax.set_xlabel("step n")
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=7)
    if zoomed and len(statistics):
        ax.set_xlim(low - 0.5, high + 0.5)
        inside = slice(low - 1, high)
        top = np.nanmax(np.r_[np.asarray(statistics, dtype=float)[inside], limits[inside], 1.0])
        ax.set_ylim(0, top * 1.1)
        ax.set_xticks(range(low, high + 1))
        ax.set_title(f"steps {low}–{high}", fontsize=8)


def _replanning_panel(bars: plt.Axes, replanning: dict) -> None:
    shown = (f"robust, δ = {replanning['delta']:g}" if replanning["fallback"] == "robust"
             else "leader-game strategy")
    batches = (("deviation", "P2 deviates"), ("compliant", "P2 follows the model"))
    for offset, (key, label, colour) in enumerate((("without", "without re-planning", "tab:blue"),
                                                   ("with", f"re-planning ({shown})", "tab:green"))):
        xs = [i + (offset - 0.5) * 0.36 for i in range(len(batches))]
        rates = [replanning[b][key]["rate"] for b, _ in batches]
        low = [r - replanning[b][key]["ci95"][0] for r, (b, _) in zip(rates, batches)]
        high = [replanning[b][key]["ci95"][1] - r for r, (b, _) in zip(rates, batches)]
        bars.bar(xs, rates, width=0.34, color=colour, label=label, yerr=[low, high], capsize=4)
        for x, r in zip(xs, rates):
            bars.text(x, r / 2, f"{r:.3f}", ha="center", va="center", fontsize=7, color="white")
    bars.set_xticks(range(len(batches)), [name for _, name in batches], fontsize=7)
    bars.set_ylabel("completion rate (95% Wilson interval)", fontsize=8)
    bars.set_ylim(0, 1.15)
    bars.grid(alpha=0.3, axis="y")
    bars.tick_params(labelsize=7)
    bars.legend(fontsize=7, loc="upper center")
    bars.set_title("re-planning after the first rejection", fontsize=8)


SCALING_INCHES = (8.5, 4.8)


DELAY_MARKERS = ("s", "D", "v", "P", "*", "X")


def scaling_picture(rows: Sequence[dict], stages: Sequence[str], title: str | None = None,
                    ax: plt.Axes | None = None) -> Figure:
    """The scaling figure (not saved; into `ax` when given): time per stage against canonical
    states, log-log, of the worlds without delay (a line each, ordered by states) with a
    slope-1 guide through the largest one's total; each delay's worlds as a separate series of
    their total time (its own marker, "delay d" in the legend)."""
    fig, ax = figure_axes(ax, SCALING_INCHES, FIGURE_DPI)
    by_delay: dict[int, list[dict]] = {}
    for row in rows:
        by_delay.setdefault(int(row.get("delay") or 0), []).append(row)
    plain = sorted(by_delay.pop(0, []), key=lambda r: r["states"])
    xs = [r["states"] for r in plain]
    for stage in stages:
        ax.loglog(xs, [max(r[f"time_{stage}"], 1e-3) for r in plain], "o-", ms=4, lw=0.8,
                  alpha=0.85, label=stage)
    totals = [r["time_total"] for r in plain]
    if plain:
        ax.loglog(xs, totals, "k^-", lw=2, label="total (no delay)")
    if len(xs) >= 2 and xs[0] < xs[-1]:
        ax.loglog([xs[0], xs[-1]], [totals[-1] * xs[0] / xs[-1], totals[-1]], "k:", lw=1,
                  label="slope 1")
    for i, delay in enumerate(sorted(by_delay)):
        delayed = sorted(by_delay[delay], key=lambda r: r["states"])
        ax.loglog([r["states"] for r in delayed], [r["time_total"] for r in delayed],
                  DELAY_MARKERS[i % len(DELAY_MARKERS)], ls="none", ms=8, mfc="none", mew=1.6,
                  color=("crimson", "darkorange", "teal", "olive", "navy", "grey")[i % 6],
                  label=f"total, delay {delay} ({len(delayed)} world{'s' * (len(delayed) > 1)})")
    ax.set_xlabel("hypergame states (canonical)")
    ax.set_ylabel("seconds (floor 1 ms)")
    ax.set_title(title or "hg2prism: time per stage against hypergame size", fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))
    return fig


def scaling_figure(rows: Sequence[dict], stages: Sequence[str], path: Path | None,
                   title: str | None = None, ax: plt.Axes | None = None) -> list[Path]:
    """`scaling_picture` written as PNG and SVG (into `ax` when given, then writing
    nothing)."""
    return figure_done(scaling_picture(rows, stages, title, ax), path, ax)


def robust_figure(result: dict, path: Path | None, ax: plt.Axes | None = None) -> list[Path]:
    """Robust deception (docs/semantics.md §13) against the deviation budget: R_delta, what the
    deceptive strategy guarantees under the same budget, and the nominal references (into
    `ax` when given, then writing nothing)."""
    rows = sorted(result["rows"], key=lambda row: row["delta"])
    deltas = [row["delta"] for row in rows]
    given = ax
    fig, ax = figure_axes(ax, ROBUST_INCHES)
    ax.plot(deltas, [row["robust_value"] for row in rows], "o-",
            label="robust value $R_\\delta$ (robust strategy, worst case)")
    ax.plot(deltas, [row["nominal_worst_case"] for row in rows], "s--",
            label="deceptive strategy, worst case")
    ax.plot(deltas, [row["robust_strategy_nominal_value"] for row in rows], "^:", alpha=0.8,
            label="robust strategy when P2 does not deviate")
    ax.axhline(result["deceptive_value"], color="grey", lw=0.8, ls="-.",
               label=f"deceptive value {result['deceptive_value']:.4f}")
    ax.axhline(result["v_lead"], color="grey", lw=0.8, ls=":",
               label=f"V_lead (P2 knows the task) {result['v_lead']:.4f}")
    ax.set_xlabel("deviation budget $\\delta$ (P2 leaves her predicted action with probability ≤ δ)")
    ax.set_ylabel("P1's completion probability")
    ax.set_xticks(deltas)
    # a budget within 4 % of the axis from the last labelled one keeps its tick, not its label
    # (0 and 1e-6 printed on top of each other)
    span, last, labels = (deltas[-1] - deltas[0]) or 1.0, None, []
    for delta in deltas:
        near = last is not None and delta - last < 0.04 * span
        labels.append("" if near else f"{delta:g}")
        last = last if near else delta
    if "" in labels:
        ax.set_xticks(deltas, labels)
    ax.set_title(f"{result['world']}: robust deception", fontsize=9)
    ax.grid(alpha=0.3)
    _legend(fig, ax, given, ncol=2, fontsize=7, frameon=False)
    return figure_done(fig, path, given)
