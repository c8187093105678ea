"""Figures into a caller's matplotlib Axes, and hg2prism leaving matplotlib's backend alone
(docs/api.md "Figures"):

* every figure function (report/plots.py: world, belief, completion, sweep and sweep grid,
  detection, scaling, robust; report/adaptive_plot.py: P1's belief over the types, the prior
  sweep) draws into the Axes a caller gives, on the caller's Figure: the artists land
  there, no figure is made (neither through pyplot nor otherwise) and no file is written;
* importing hg2prism and drawing keeps the backend a notebook set (matplotlib_inline's, or any
  other), and figures are still written headless: MPLBACKEND unset and no display.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import matplotlib
import matplotlib.figure
import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

import hg2prism
from conftest import MODELS, ROOT, window_sweep_table
from hg2prism.analyses.simulation import FAIL, GOAL
from hg2prism.report import adaptive_plot, plots


class Made:
    """Counts the matplotlib Figures made while it is active."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.count = 0
        original = matplotlib.figure.Figure.__init__

        def counting(figure, *args, **kwargs):
            self.count += 1
            original(figure, *args, **kwargs)
        monkeypatch.setattr(matplotlib.figure.Figure, "__init__", counting)


def _callers_axes(panels: int = 1):
    """A caller's Figure (made without pyplot) and its Axes: one, or a row of `panels`."""
    fig = matplotlib.figure.Figure(figsize=(8, 4))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, panels) if panels > 1 else fig.add_subplot()
    return fig, axes


def _drawn(ax) -> int:
    """The artists drawn into `ax` (lines, patches, collections, texts, images)."""
    return (len(ax.lines) + len(ax.patches) + len(ax.collections) + len(ax.texts)
            + len(ax.images))


def _summary(lengths: list[int], done: list[bool], horizon: int = 20) -> SimpleNamespace:
    """What completion_picture reads of a simulation.SimulationSummary."""
    return SimpleNamespace(episodes=len(lengths), horizon=horizon,
                           lengths=np.array(lengths), outcomes=np.array(
                               [GOAL if d else FAIL for d in done]))


ROBUST = {"world": "worldR", "deceptive_value": 0.9, "v_lead": 0.7,
          "rows": [{"delta": d, "robust_value": 0.9 - d, "nominal_worst_case": 0.9 - 2 * d,
                    "robust_strategy_nominal_value": 0.9 - d / 2} for d in (0.0, 0.1, 0.2)]}
REPLANNING = {"delta": 0.1, "fallback": "robust",
              **{batch: {key: {"rate": 0.6, "ci95": [0.55, 0.65]} for key in ("with", "without")}
                 for batch in ("deviation", "compliant")}}
STATISTICS = [0.0] * 4 + [3.0, 12.0] + [12.0 + i for i in range(20)]
THRESHOLDS = [None] + [3.84 + 0.5 * i for i in range(len(STATISTICS) - 1)]


def _figures(ax, path: Path) -> dict[str, object]:
    """Each figure function of report/plots.py that needs no solved world, drawing into `ax`."""
    rows = [{"rationality": v, "deceptive_value": 0.9, "v_lead": 0.7, "v_ne": 0.3}
            for v in (0.1, 1.0, 10.0)]
    completion = [("deceptive", _summary([3, 5, 8, 2], [True, True, False, True]), 0.7),
                  ("naive", _summary([4, 6, 9, 1], [True, False, False, True]), None)]
    scaling = [{"states": n, "time_games": 0.01 * n ** 0.5, "time_total": 1e-4 * n}
               for n in (1000, 10000, 100000)]
    grid = [{"delay": d, "window": w, "deceptive_value": 0.9, "v_lead": 0.7}
            for d in (0, 1) for w in (1, 2)]
    weights = [{"weight": w, "v_adapt": 0.8, "v_oracle": 0.9, "v_commit": {"a": w, "b": 0.7}}
               for w in (0.0, 0.5, 1.0)]
    return {
        "sweep grid": lambda: plots.sweep_grid_figure(["delay", "window"], grid, path, "worldG",
                                                      ax=ax),
        "adaptive belief": lambda: adaptive_plot.adaptive_belief_figure(
            "worldA", ["a", "b"], [[0.5, 0.5], [0.5, 0.5], [0.0, 1.0]], 1, 0, "goal", path,
            ax=ax),
        "prior weight": lambda: adaptive_plot.weight_sweep_figure("worldA", ["a", "b"], weights,
                                                                  path, ax=ax),
        "completion": lambda: plots.completion_figure("worldC", completion, path, ax=ax),
        "sweep": lambda: plots.sweep_figure("rationality", rows, path, "worldS", ax=ax),
        "scaling": lambda: plots.scaling_figure(scaling, ("games",), path, "bench", ax=ax),
        "robust": lambda: plots.robust_figure(ROBUST, path, ax=ax),
        "detection": lambda: plots.detection_figure(STATISTICS, THRESHOLDS, 4, 6, path,
                                                    world_name="worldD", seed=3, ax=ax),
    }


@pytest.mark.parametrize("name", ["completion", "sweep", "sweep grid", "scaling", "robust",
                                  "detection", "adaptive belief", "prior weight"])
def test_a_figure_draws_into_the_callers_axes(name: str, tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    fig, ax = _callers_axes()
    before = plt.get_fignums()
    made = Made(monkeypatch)
    written = _figures(ax, tmp_path / "figure.png")[name]()
    assert written == [] and list(tmp_path.iterdir()) == []
    assert made.count == 0 and plt.get_fignums() == before
    assert fig.axes == [ax] and _drawn(ax) > 0
    assert ax.get_title() or ax.get_xlabel()


@pytest.mark.parametrize("last, horizon, scale", [(10, 40, "symlog"), (11, 40, "linear"),
                                                  (4, 16, "linear"), (0, 200, "linear")])
def test_the_completion_axis_is_logarithmic_when_every_completion_is_early(
        last: int, horizon: int, scale: str) -> None:
    """mir100's episodes complete within 10 of 200 steps: the rise was squeezed against the
    left edge. When every completion comes within the first quarter of the horizon (exactly a
    quarter included; not on horizons under 20, nor without any completion) the axis is logarithmic beyond step 1, runs to
    the horizon, and its label says so."""
    fig, ax = _callers_axes()
    lengths = [max(last, 1), 2, 3, horizon]
    rows = [("deceptive", _summary(lengths, [last > 0, last > 0, last > 0, False], horizon),
             0.7), ("naive", _summary([1, 2, 3, horizon], [False] * 4, horizon), None)]
    plots.completion_picture("worldC", rows, ax=ax)
    assert ax.get_xscale() == scale
    assert ax.get_xlim() == (0, horizon)
    assert ("logarithmic" in ax.get_xlabel()) == (scale == "symlog")
    if scale == "symlog":
        assert f"within {last} steps" in ax.get_xlabel()
        assert ax.get_xticks()[-1] == horizon


def test_without_axes_a_figure_is_its_own_and_written(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """The check above can fail: without `ax` each function makes one figure (not through
    pyplot) and writes PNG and SVG."""
    before = plt.get_fignums()
    for name in _figures(None, tmp_path):
        made = Made(monkeypatch)
        written = _figures(None, tmp_path / name.replace(" ", "_") / "figure.png")[name]()
        assert made.count == 1, name
        assert sorted(p.suffix for p in written) == [".png", ".svg"], name
        assert all(p.is_file() for p in written)
    assert plt.get_fignums() == before


def test_the_detection_figure_fills_the_panels_given(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    fig, axes = _callers_axes(3)
    made = Made(monkeypatch)
    assert plots.detection_figure(STATISTICS, THRESHOLDS, 4, 6, tmp_path / "d.png",
                                  replanning=REPLANNING, ax=axes) == []
    assert made.count == 0 and list(tmp_path.iterdir()) == []
    assert all(_drawn(ax) > 0 for ax in axes)
    assert axes[1].get_title() == "steps 1–12"
    assert axes[2].get_title() == "re-planning after the first rejection"
    with pytest.raises(ValueError, match="1 to 2 panels; 3 axes given"):
        plots.detection_figure(STATISTICS, THRESHOLDS, 4, 6, None, ax=axes)


@pytest.fixture(scope="module")
def world3():
    solution = hg2prism.solve(hg2prism.load_world(MODELS / "world3.toml"))
    return solution, hg2prism.episode(solution)


@pytest.mark.parametrize("verb", ["draw_world", "draw_belief"])
def test_the_apis_world_and_belief_draw_into_the_callers_axes(
        verb: str, world3, monkeypatch: pytest.MonkeyPatch) -> None:
    solution, played = world3
    fig, ax = _callers_axes()
    before = plt.get_fignums()
    made = Made(monkeypatch)
    assert getattr(hg2prism, verb)(solution, played, ax=ax) is ax
    assert made.count == 0 and plt.get_fignums() == before
    assert fig.axes == [ax] and _drawn(ax) > 0


def test_the_world_leaves_the_callers_layout_to_the_callers_figure(world3) -> None:
    """docs/api.md's two panels: the world drawn on the left must not freeze the figure's
    constrained layout, or the belief drawn on the right after it is laid out by no one and
    its legend and axis label fall outside the figure (they did)."""
    solution, played = world3
    fig = matplotlib.figure.Figure(figsize=(12, 4), layout="constrained")
    FigureCanvasAgg(fig)
    left, right = fig.subplots(1, 2)
    engine = fig.get_layout_engine()
    hg2prism.draw_world(solution, played, ax=left)
    assert fig.get_layout_engine() is engine
    hg2prism.draw_belief(solution, played, ax=right)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    frame = fig.bbox
    for artist in (right.get_legend(), right.xaxis.label, left.title):
        box = artist.get_window_extent(renderer)
        assert (box.x0 >= frame.x0 - 1 and box.x1 <= frame.x1 + 1
                and box.y0 >= frame.y0 - 1 and box.y1 <= frame.y1 + 1), (artist, box, frame)


def test_a_legend_in_the_callers_axes_stays_within_them() -> None:
    """In a caller's panel the legend is the axes' own, in one column inside them: the own
    figure's row of three columns spilled over the neighbouring panel and the title."""
    table = window_sweep_table()
    fig = matplotlib.figure.Figure(figsize=(12, 4), layout="constrained")
    FigureCanvasAgg(fig)
    third = fig.subplots(1, 3)[2]
    hg2prism.draw_sweep(table, ax=third)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legend, frame = third.get_legend().get_window_extent(renderer), third.get_window_extent(renderer)
    assert frame.x0 <= legend.x0 and legend.x1 <= frame.x1 and legend.y1 <= frame.y1


# ---- the backend ----

def _python(code: str, env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess:
    """`DRAW` (which writes robust.png and .svg into `cwd`), then `code`, in a new Python."""
    program = textwrap.dedent(DRAW) + textwrap.dedent(code)
    return subprocess.run([sys.executable, "-c", program], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=120)


def _env(**changes: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("MPLBACKEND", "DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONPATH"] = str(ROOT)
    return {**env, **changes}


DRAW = """
    import matplotlib
    backend = matplotlib.get_backend()
    from pathlib import Path
    import hg2prism
    from hg2prism import pipeline
    from hg2prism.report import plots, replay, adaptive_plot
    rows = [{"delta": d, "robust_value": 0.9, "nominal_worst_case": 0.8,
             "robust_strategy_nominal_value": 0.85} for d in (0.0, 0.1)]
    written = plots.robust_figure({"world": "w", "deceptive_value": 0.9, "v_lead": 0.7,
                                   "rows": rows}, Path("robust.png"))
    assert [p.is_file() for p in written] == [True, True], written
"""


@pytest.mark.parametrize("backend", ["module://matplotlib_inline.backend_inline", "svg"])
def test_importing_hg2prism_keeps_the_backend_set(backend: str, tmp_path: Path) -> None:
    """A notebook's backend (ipykernel sets MPLBACKEND to matplotlib_inline's) stays after
    importing hg2prism and writing a figure; an API figure is made on it."""
    if backend.startswith("module://"):
        pytest.importorskip("matplotlib_inline")
    done = _python("""
        solution = hg2prism.solve(hg2prism.load_world("models/world3.toml"))
        ax = hg2prism.draw_belief(solution)
        assert matplotlib.get_backend() == backend, (matplotlib.get_backend(), backend)
        print(backend)
    """.replace("models/", str(MODELS) + "/"), _env(MPLBACKEND=backend), tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().lower() == backend.lower()


def test_figures_are_written_headless(tmp_path: Path) -> None:
    """No MPLBACKEND, no display: run's figures are written (report/plots.py never asks pyplot
    for a figure), and pyplot itself falls back to Agg for the API's own Axes."""
    done = _python("""
        import matplotlib.pyplot as plt
        ax = plt.figure().add_subplot()
        print(plt.get_backend())
    """, _env(), tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().lower() == "agg"
    assert (tmp_path / "robust.svg").is_file()


def test_robust_budgets_close_together_keep_their_ticks_not_their_labels() -> None:
    """`robust --deltas 0 1e-6 0.5 0.99` printed "0" and "1e-06" on top of each other: a budget
    within 4 % of the axis from the last labelled one keeps its tick without a label; budgets
    apart keep matplotlib's own labels."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hg2prism.report import plots

    def labels(deltas: tuple[float, ...]) -> list[str]:
        rows = [{"delta": d, "robust_value": 0.9, "nominal_worst_case": 0.8,
                 "robust_strategy_nominal_value": 0.85} for d in deltas]
        fig, ax = plt.subplots()
        plots.robust_figure({"world": "w", "deceptive_value": 0.9, "v_lead": 0.7,
                             "rows": rows}, None, ax=ax)
        fig.canvas.draw()
        shown = [t.get_text() for t in ax.get_xticklabels()]
        plt.close(fig)
        return shown

    assert labels((0.0, 1e-6, 0.5, 0.99)) == ["0", "", "0.5", "0.99"]
    assert labels((0.0, 0.01, 0.02, 0.5)) == ["0", "", "0.02", "0.5"]
    assert "" not in labels((0.0, 0.05, 0.1, 0.2))


def test_a_sweep_figure_draws_its_values_in_axis_order() -> None:
    """sweep.png of `--values 2 0 1` drew its curves 2 -> 0 -> 1 (a line from 2 to 0, none from
    1 to 2; reproducibility check): the rows are drawn along the axis whatever their order, the
    same picture as for `--values 0 1 2`; the adaptive weight sweep too."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hg2prism.report import adaptive_plot, plots

    def row(d: int) -> dict:
        return {"delay": d, "deceptive_value": [0.9, 0.5, 0.7][d], "v_lead": 0.3, "v_ne": 0.2,
                "weight": d / 2, "v_adapt": [0.9, 0.5, 0.7][d], "v_oracle": 1.0,
                "v_commit": {"a": 0.4}}

    def lines(draw, order) -> list:
        fig, ax = plt.subplots()
        draw([row(d) for d in order], ax)
        drawn = [line.get_xydata().tolist() for line in ax.get_lines()]
        plt.close(fig)
        return drawn

    for draw in (lambda rows, ax: plots.sweep_figure("delay", rows, None, ax=ax),
                 lambda rows, ax: adaptive_plot.weight_sweep_figure("w", ["a"], rows, None,
                                                                    ax=ax)):
        assert lines(draw, (2, 0, 1)) == lines(draw, (0, 1, 2))
