"""hg2prism: deceptive strategies in dynamic hypergames, checked with Storm.

The Python API (docs/api.md):

    load_world(path), world_from_toml(text, name="world")   -> World
    world_from_graph(G, entries=..., task=..., ...)          -> World (an attack graph's arena)
    solve(world, *, out=None, storm_method="sound",          -> Solution (AdaptiveSolution
          objective="pmax", bound=None)                         with P2's types, [[type]])
    run(world, out, *, episodes, horizon, seed, episode,     -> Run (what `hg2prism run` writes
        storm_method="sound", objective="pmax")                 into out: table, figures, ...)
    baselines(world)                                         -> Baselines (V_NE, its bracket, V_lead)
    simulate(solution, *, episodes, horizon, seed)           -> Simulation (rate, 95% interval)
    deception_values(solution)                               -> V_static, V_naive, value of deception
    robust(solution, deltas)                                 -> [RobustValue] (robust deception)
    sweep(world, parameter, values) or sweep(world, grid=),  -> SweepTable (rows, to_csv)
          storm_method, workers, deception
    detection(solution, *, episodes, seed, horizon,          -> detection.json's content
              fallback, fallback_delta)
    episode(solution, seed)                                  -> Episode (steps, P2's belief)
    draw_world / draw_belief(solution, episode, ax=)         -> the figures, in a matplotlib Axes
    draw_sweep(table, ax=)
    load_strategy(folder, world=None)                        -> Strategy (strategy.json read back)

The pipeline, one module per stage, is listed in docs/architecture.md; the meaning of every number is in
docs/semantics.md.
"""

from typing import TYPE_CHECKING, Any

from hg2prism.reproducible import pin_kernels

pin_kernels()      # before anything imports numpy: the same last bits on every x86-64 machine

__version__ = "0.1.0"

__all__ = ["__version__", "InputError", "load_world", "world_from_toml", "world_from_graph", "solve", "run",
           "baselines", "simulate", "deception_values", "robust", "sweep", "detection", "episode",
           "draw_world", "draw_belief", "draw_sweep", "Solution", "AdaptiveSolution", "Run", "Strategy", "Baselines", "Simulation",
           "DeceptionValues", "RobustValue", "SweepRow", "SweepTable", "Episode", "EpisodeStep",
           "PlayerType", "load_strategy"]


if TYPE_CHECKING:      # what editors and type checkers read; at run time, __getattr__ below
    from hg2prism.api import (AdaptiveSolution, Baselines, DeceptionValues, Episode,
                              EpisodeStep, PlayerType, RobustValue, Run, Simulation, Solution,
                              Strategy, SweepRow, SweepTable, baselines, deception_values,
                              detection, draw_belief, draw_sweep, draw_world, episode,
                              load_strategy, load_world, robust, run, simulate, solve, sweep,
                              world_from_graph, world_from_toml)
    from hg2prism.errors import InputError


def __getattr__(name: str) -> Any:
    """The API's names, imported when first asked for (`hg2prism.solve`, `from hg2prism
    import solve`), and the package's modules (`hg2prism.errors` after `import hg2prism`):
    importing the package itself, or one of its modules such as the program's
    `hg2prism.program`, takes no time."""
    import importlib
    import importlib.util

    if name.startswith("__"):        # copy, pickle and help ask for such names: not here
        raise AttributeError(f"module 'hg2prism' has no attribute {name!r}")
    # the package as importing it gave it before: its API and what the API imports
    # (hg2prism.errors, hg2prism.opponent.registry, ...)
    api = importlib.import_module("hg2prism.api")
    if name == "InputError":
        from hg2prism.errors import InputError as value
    elif name in __all__:
        value = getattr(api, name)
    elif name in globals():         # a module the API imported
        return globals()[name]
    elif importlib.util.find_spec(f"hg2prism.{name}") is not None:
        value = importlib.import_module(f"hg2prism.{name}")
    else:
        raise AttributeError(f"module 'hg2prism' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
