"""hg2prism: deceptive strategies in dynamic hypergames, checked with Storm.

The Python API (docs/api.md):

    load_world(path), world_from_toml(text, name="world")   -> World
    world_from_graph(G, entries=..., task=..., ...)          -> World (an attack graph's arena)
    solve(world, *, out=None, storm_method="sound")          -> Solution
    baselines(world)                                         -> Baselines (V_NE, its bracket, V_lead)
    simulate(solution, *, episodes, horizon, seed)           -> Simulation (rate, 95% interval)

The pipeline, one module per stage, is listed in docs/architecture.md; the meaning of every number is in
docs/semantics.md.
"""

__version__ = "0.1.0"

from hg2prism.api import (Baselines, Simulation, Solution, Strategy,  # noqa: E402
                          baselines, load_world, simulate, solve, world_from_graph,
                          world_from_toml)

__all__ = ["__version__", "load_world", "world_from_toml", "world_from_graph", "solve", "baselines", "simulate",
           "Solution", "Strategy", "Baselines", "Simulation"]
