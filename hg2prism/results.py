"""What `check` and `run` compute for one world, as typed values (docs/semantics.md §§6–8).

:func:`hg2prism.pipeline.check` returns a :class:`CheckResults`, :func:`hg2prism.pipeline.run`
a :class:`RunResults` (the check's fields, the symmetric baselines of §7 and the simulations of
§8). Each ``to_json()`` returns the content of ``results.json``: the keys in the order the file
lists them, the numbers unchanged except the timings, rounded to 0.1 ms. The report
(:mod:`hg2prism.report.tables`), the experiments and the Python API read the attributes.

Probabilities are in [0, 1] (docs/semantics.md §10), sizes are counts, times are seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hg2prism.analyses.simulation import SimulationSummary
    from hg2prism.model.world import World

__all__ = ["Parameters", "CheckResults", "SimulatedRow", "Simulations", "RunResults"]

TIMING_DIGITS = 4
"""Timings are written to results.json rounded to this many decimals (0.1 ms)."""


@dataclass(frozen=True)
class Parameters:
    """The world's parameters that shape the hypergame (docs/semantics.md §1), as echoed in
    results.json under ``parameters`` and, less the swept one, in sweep.json under
    ``fixed_parameters``."""

    formula: str                    # P1's task, co-safe LTL in Spot syntax (§3)
    slip: float                     # probability of slipping to each side of a move (§2)
    traps: int                      # traps P2 places at once (§2)
    delay: int                      # steps P2 waits after moving traps (§2)
    hypotheses: tuple[str, ...]     # P2's candidate tasks (§4)
    initial_hypothesis: int         # index into `hypotheses` of P2's first guess (§5)
    window: int                     # w: transitions in P2's sliding window (§5)
    threshold: float | None         # c: P2's CUSUM change threshold (§5); None for "bayes"
    rationality: float              # β: P2's softmax model of P1 (§4)
    inference: str = "cusum"        # P2's observer: "cusum" (§5) or "bayes" (§12)
    prior: tuple[float, ...] = ()   # bayes: the normalised prior
    decision: str = "map"           # bayes: "map" or "sample"

    @classmethod
    def of(cls, world: World) -> Parameters:
        return cls(formula=world.formula, slip=world.slip, traps=world.traps, delay=world.delay,
                   hypotheses=tuple(world.hypotheses),
                   initial_hypothesis=world.initial_hypothesis, window=world.window,
                   threshold=world.threshold, rationality=world.rationality,
                   inference=world.inference, prior=tuple(world.prior), decision=world.decision)

    def to_json(self) -> dict:
        return {
            "formula": self.formula, "slip": self.slip, "traps": self.traps, "delay": self.delay,
            "hypotheses": list(self.hypotheses), "initial_hypothesis": self.initial_hypothesis,
            "window": self.window, "threshold": self.threshold, "rationality": self.rationality,
        } if self.inference == "cusum" else {   # CUSUM's results.json stays as it was
            "formula": self.formula, "slip": self.slip, "traps": self.traps, "delay": self.delay,
            "hypotheses": list(self.hypotheses), "initial_hypothesis": self.initial_hypothesis,
            "inference": self.inference, "window": self.window, "prior": list(self.prior),
            "decision": self.decision, "rationality": self.rationality,
        }


def _timings_json(timings: dict[str, float]) -> dict[str, float]:
    return {stage: round(seconds, TIMING_DIGITS) for stage, seconds in timings.items()}


@dataclass(frozen=True)
class CheckResults:
    """What `hg2prism check` computes: the deceptive value and the hypergame's size
    (results.json, docs/semantics.md §6 "results.json (from check)")."""

    world: str                      # the world's name
    world_file: str                 # the world file as given (may be relative)
    hg2prism_version: str
    deceptive_value: float          # Pmax=? [F "goal"] at the hypergame's initial state (§6), by Storm
    storm_method: str               # "sound", "sound-ovi" or "fast" (§10)
    sound: bool                     # False only for "fast": deceptive_value is then not certified (§10)
    v_lead: float                   # V_lead at the initial state: P2 knows the task, commits first (§7)
    states: int                     # canonical hypergame states, goal and fail merged (§6 "Canonical size")
    transitions: int                # canonical (state, action, successor) triples (§6 "Canonical size")
    storm_states: int               # Storm's own counts, which depend on the encoding (§6)
    storm_transitions: int
    storm_choices: int
    model_commands: dict[str, int]  # hypergame.prism: module name -> number of commands
    parameters: Parameters
    # Seconds per stage, in the order the stages ran: games, generate, parse, build, check,
    # export (and with `run`: exports, nash, simulation, plots). Unrounded here, rounded in
    # to_json(); a copy, not the pipeline's live dict.
    timings: dict[str, float]

    def to_json(self) -> dict:
        """The content of results.json written by `check`."""
        return {
            "world": self.world,
            "world_file": self.world_file,
            "hg2prism_version": self.hg2prism_version,
            "deceptive_value": self.deceptive_value,
            "storm_method": self.storm_method,
            "sound": self.sound,
            "v_lead": self.v_lead,
            "states": self.states,
            "transitions": self.transitions,
            "storm_states": self.storm_states,
            "storm_transitions": self.storm_transitions,
            "storm_choices": self.storm_choices,
            "model_commands": dict(self.model_commands),
            "parameters": self.parameters.to_json(),
            "timings": _timings_json(self.timings),
        }


@dataclass(frozen=True)
class SimulatedRow:
    """One strategy pair played online (docs/semantics.md §8): a row of the completion table."""

    rate: float                     # completed / episodes: completion within the horizon
    ci95: tuple[float, float]       # Wilson score interval of `rate` at 95 % (§8)
    episodes: int
    truncated: int                  # episodes cut by the horizon (not completed)
    exact_within_horizon: float     # P(goal within `horizon` steps) for the pair simulated (§8)

    @classmethod
    def of(cls, summary: SimulationSummary, exact_within_horizon: float) -> SimulatedRow:
        return cls(rate=summary.rate, ci95=tuple(summary.ci95), episodes=summary.episodes,
                   truncated=summary.truncated, exact_within_horizon=exact_within_horizon)

    def to_json(self) -> dict:
        return {"rate": self.rate, "ci95": list(self.ci95), "episodes": self.episodes,
                "truncated": self.truncated, "exact_within_horizon": self.exact_within_horizon}


@dataclass(frozen=True)
class Simulations:
    """The online simulations of `run` (docs/semantics.md §8), all with the same horizon and
    seed: results.json's ``simulation``."""

    horizon: int                    # transitions after which an episode is cut
    seed: int                       # numpy.random.default_rng seed of every row
    deceptive: SimulatedRow         # P1's deceptive strategy against P2's inference (§6, §8)
    nash: SimulatedRow              # both players' extracted Nash strategies (§7)
    leader: SimulatedRow            # P2's leader strategy and P1's answer to it (§7)

    def to_json(self) -> dict:
        return {"horizon": self.horizon, "seed": self.seed,
                "deceptive": self.deceptive.to_json(), "nash": self.nash.to_json(),
                "leader": self.leader.to_json()}


@dataclass(frozen=True)
class RunResults(CheckResults):
    """What `hg2prism run` computes: the check's results (with the timings of every stage of
    the run), the Nash baseline with its sound bracket (docs/semantics.md §7) and the online
    simulations (§8)."""

    v_ne: float                     # V_NE at the initial state, inside v_ne_bounds (§7)
    v_ne_p1_guaranteed: float       # what P1's extracted Nash strategy guarantees: the lower end (§7)
    v_ne_bounds: tuple[float, float]  # sound bracket (lower, upper) around V_NE (§7)
    simulation: Simulations

    @classmethod
    def extending(cls, check: CheckResults, *, timings: dict[str, float], v_ne: float,
                  v_ne_p1_guaranteed: float, v_ne_bounds: tuple[float, float],
                  simulation: Simulations) -> RunResults:
        """The check's results, with the run's timings and the run's additions."""
        inherited = {f.name: getattr(check, f.name) for f in fields(CheckResults)}
        inherited["timings"] = timings
        return cls(**inherited, v_ne=v_ne, v_ne_p1_guaranteed=v_ne_p1_guaranteed,
                   v_ne_bounds=tuple(v_ne_bounds), simulation=simulation)

    def to_json(self) -> dict:
        """The content of results.json written by `run`: the check's keys (``timings`` keeps
        its place), then the baselines and the simulations."""
        return {
            **super().to_json(),
            "v_ne": self.v_ne,
            "v_ne_p1_guaranteed": self.v_ne_p1_guaranteed,
            "v_ne_bounds": list(self.v_ne_bounds),
            "simulation": self.simulation.to_json(),
        }
