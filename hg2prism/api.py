"""The Python API: a few verbs over the pipeline, for notebooks and scripts.

    world = hg2prism.load_world("models/world1.toml")        # or world_from_toml(text)
    solution = hg2prism.solve(world)                          # Storm, sound; writes nothing
    solution.deceptive_value, solution.strategy.move(...)     # numbers and P1's moves
    hg2prism.baselines(world).v_ne_bounds                     # the symmetric baselines
    hg2prism.simulate(solution, episodes=2000).rate           # online play against P2

Nothing is printed unless the application configures logging (the `hg2prism` logger reports
each stage at INFO), and nothing is written unless `out` is given. docs/api.md has the details
and docs/semantics.md the meaning of every number.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from hg2prism.model.world import World

from hg2prism.worldfile import load_world, world_from_toml
from hg2prism.results import CheckResult, CheckResults
from hg2prism.strategy.records import Strategy

__all__ = ["load_world", "world_from_toml", "solve", "baselines", "simulate", "Solution",
           "Strategy", "Baselines", "Simulation"]

_MOVES = ("N", "E", "S", "W")


def _reported(name: str, doc: str) -> property:
    """A Solution attribute read from its CheckResults (not a copy)."""
    return property(lambda self: getattr(self.results, name), doc=doc)


@dataclass(frozen=True, eq=False)
class Solution:
    """The deceptive value and strategy of a world (what `hg2prism check` computes): a view of
    the pipeline's CheckResult (hg2prism.results), with P1's strategy read from its records."""

    world: World
    strategy: Strategy              # P1's move in every reachable hypergame state
    check: CheckResult = field(repr=False)   # everything `check` computed (hg2prism.results)

    deceptive_value = _reported("deceptive_value", "Pmax of reaching the goal in the hypergame MDP")
    v_lead = _reported("v_lead", "the leader baseline (docs/semantics.md §7)")
    states = _reported("states", "canonical hypergame states")
    transitions = _reported("transitions", "canonical hypergame transitions")
    storm_method = _reported("storm_method", "how Pmax was solved")
    sound = _reported("sound", 'False for the "fast" method: the value is not certified')
    objective = _reported("objective", "what the strategy optimises: name, bound, value, steps")

    @property
    def results(self) -> CheckResults:
        """Everything `check` reports: results.json's fields as typed attributes."""
        return self.check.results

    def to_json(self) -> dict:
        """The content of results.json."""
        return self.results.to_json()

    def __repr__(self) -> str:
        shown = ("world", "deceptive_value", "v_lead", "states", "transitions", "storm_method",
                 "sound", "strategy", "objective")
        return "Solution(" + ", ".join(f"{name}={getattr(self, name)!r}" for name in shown) + ")"


def solve(world: World | str | Path, *, out: str | Path | None = None,
          storm_method: str = "sound", objective: str = "pmax",
          bound: int | None = None) -> Solution:
    """Build the hypergame of `world` (a World or the path of a world file), check it with
    Storm and extract P1's deceptive strategy. With `out`, what `hg2prism check` writes (the
    model, strategy.json, results.json, the automata and the induced DTMC) goes there
    (atomically); without, nothing is written (the model passes through a temporary folder
    Storm reads, removed before returning). `objective` is what the strategy optimises among
    the moves that keep Pmax (docs/semantics.md §6): "pmax" (the default), "lexicographic"
    (then the fewest expected steps) or "bounded" (the probability of the goal within `bound`
    steps, by default the world's simulation horizon; the moves then depend on the step)."""
    from hg2prism import pipeline
    from hg2prism.model import sizeguard
    from hg2prism.outputs import staged

    from hg2prism.strategy.objectives import OBJECTIVES

    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    if bound is not None and (objective != "bounded" or bound < 1):
        raise ValueError(f"bound (got {bound}) is a number of steps >= 1, for objective='bounded'")
    if not isinstance(world, World):
        world = load_world(world)
    sizeguard.check_size(world)
    if out is not None:
        with staged(Path(out)) as stage:
            checked = pipeline.check(world, stage, storm_method, objective, bound)
            records = tuple(checked.records)
    else:
        with tempfile.TemporaryDirectory(prefix="hg2prism-") as scratch:
            checked = pipeline.check(world, Path(scratch), storm_method, objective, bound)
            records = tuple(checked.records)
    return Solution(world=world, strategy=Strategy.from_records(records, checked.analysis.ts),
                    check=checked)


@dataclass(frozen=True)
class Baselines:
    """The symmetric-information baselines at the initial state (docs/semantics.md §7)."""

    v_ne: float
    v_ne_bounds: tuple[float, float]    # sound bracket around V_NE
    v_ne_p1_guaranteed: float           # what P1's extracted Nash strategy guarantees
    v_lead: float


def baselines(world: World | str | Path) -> Baselines:
    """V_NE (with its sound bracket) and V_lead of `world`."""
    from hg2prism.analyses import baselines as nash
    from hg2prism import pipeline

    if not isinstance(world, World):
        world = load_world(world)
    analysis = pipeline.analyse(world)
    solved = nash.nash_baseline(analysis.ts, analysis.task)
    return Baselines(v_ne=solved.v_ne, v_ne_bounds=solved.v_ne_bounds,
                     v_ne_p1_guaranteed=solved.v_ne_p1_guaranteed, v_lead=analysis.v_lead)


@dataclass(frozen=True)
class Simulation:
    """Episodes of P1's deceptive strategy against P2's inference (docs/semantics.md §8)."""

    episodes: int
    horizon: int
    seed: int
    completed: int
    failed: int
    truncated: int
    rate: float                     # completed / episodes
    ci95: tuple[float, float]       # Wilson score interval of the rate


def simulate(solution: Solution, *, episodes: int = 10_000, horizon: int | None = None,
             seed: int = 0) -> Simulation:
    """Play `episodes` episodes of the solution's strategy, each cut after `horizon` steps
    (by default 200, or the bound of a step-bounded solution, whose rate then estimates its
    bounded value)."""
    import dataclasses

    from hg2prism.analyses.simulation import simulate_deceptive
    from hg2prism.strategy.stepped import StepCounter, SteppedStrategy

    checked = solution.check
    analysis, strategy = checked.analysis, solution.strategy
    bounded = checked.bounded
    if horizon is None:
        horizon = bounded.bound if bounded is not None else 200
    if bounded is not None:
        # the move depends on the steps taken: P1 counts them beside P2's memory
        strategy = SteppedStrategy(strategy.records, analysis.ts, bounded.bound)
        analysis = dataclasses.replace(analysis, inference=StepCounter(analysis.inference,
                                                                       bounded.bound - 1))
    summary = simulate_deceptive(analysis, strategy, episodes, horizon, seed, progress=False)
    return Simulation(episodes=summary.episodes, horizon=horizon, seed=seed,
                      completed=summary.completed, failed=summary.failed,
                      truncated=summary.truncated, rate=summary.rate, ci95=tuple(summary.ci95))
