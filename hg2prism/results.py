"""What the pipeline computes for one world, in one place (docs/semantics.md §§6–8).

Two layers. What the stages hand on: :class:`Analysis` (the games and the opponent model, before
any model checking), :class:`CheckResult` (what :func:`hg2prism.pipeline.check` computes: the
model, the engine's answer, the strategy) and :class:`RunResult` (:func:`hg2prism.pipeline.run`).
And the numbers they report: a CheckResult's :class:`CheckResults`, a RunResult's
:class:`RunResults` (the check's fields, the symmetric baselines of §7, V_static and V_naive of
§11 and the simulations of §8). Each ``to_json()`` returns the content of ``results.json``: the
keys in the order the file lists them, the numbers unchanged except the timings, rounded to
0.1 ms. The report (:mod:`hg2prism.report.tables`), the experiments and the Python API
(:class:`hg2prism.api.Solution` wraps a CheckResult) read the attributes.

Probabilities are in [0, 1] (docs/semantics.md §10), sizes are counts, times are seconds.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from hg2prism.engines.engine import CheckedModel, ModelChecker
    from hg2prism.model.automata import DFA
    from hg2prism.model.dynamics import TransitionSystem
    from hg2prism.model.world import World
    from hg2prism.opponent.observer import Observer
    from hg2prism.opponent.perceptual_games import GameSolution, PerceptualGame
    from hg2prism.prism.decoding import DecodedStates
    from hg2prism.prism.hypergame import PrismModel
    from hg2prism.strategy.deceptive import StormChoices
    from hg2prism.strategy.exports import InducedDTMC
    from hg2prism.strategy.objectives import Bounded
    from hg2prism.strategy.policy import Policy
    from hg2prism.strategy.records import RecordExtras, Strategy

__all__ = ["Timings", "Analysis", "CheckResult", "RunResult", "Parameters", "StrategyObjective", "CheckResults",
           "SimulatedRow", "Simulations", "DrawnEpisode", "RunResults", "provenance"]

TIMING_DIGITS = 4
"""Timings are written to results.json rounded to this many decimals (0.1 ms)."""


def provenance(world: World, engine: ModelChecker | None = None) -> dict[str, object]:
    """The keys every record (results.json, robust.json, detection.json, sweep.json, the
    adaptive results) starts with: the world (its name, file and `World.digest`, by which
    hg2prism.outputs tells whose outputs a folder holds), the hg2prism that wrote it and the
    software it ran on (`software`; `engine`: the model checker, default Storm); for the world
    of one of P2's types (`--type`, an adaptive run's type<k>/), `p2_type`: that type's name."""
    from hg2prism import __version__

    typed = {"p2_type": world.of_type} if world.of_type and not world.types else {}
    return {"world": world.name, **typed, "world_file": str(world.path),
            "world_digest": world.digest(), "hg2prism_version": __version__,
            "software": software(engine)}


def software(engine: ModelChecker | None = None) -> dict[str, str]:
    """What a record was computed with: hg2prism (and, run from a git checkout, its commit,
    "+edits" when the tracked files differ from it), Python, numpy, scipy, Spot and the model
    checker (its `version`, when it says)."""
    from hg2prism.engines import default

    engine = engine or default()
    return {**_libraries(), "model_checker": str(getattr(engine, "version", type(engine).__name__))}


@functools.lru_cache(maxsize=1)
def _libraries() -> dict[str, str]:
    import importlib.metadata
    import platform
    import subprocess

    from hg2prism import __version__
    from hg2prism.reproducible import kernels

    found = {"hg2prism": __version__}
    root = Path(__file__).resolve().parent.parent
    if (root / ".git").exists():
        try:
            def git(*args: str) -> str:
                return subprocess.run(["git", "-C", str(root), *args], capture_output=True,
                                      text=True, timeout=10, check=True).stdout.strip()
            found["hg2prism_commit"] = git("rev-parse", "HEAD") + (
                "+edits" if git("status", "--porcelain", "--untracked-files=no") else "")
        except (OSError, subprocess.SubprocessError):
            pass
    found["python"] = platform.python_version()
    for package in ("numpy", "scipy"):
        found[package] = importlib.metadata.version(package)
    found.update(kernels())        # the code the last bits depend on (reproducible.py)
    try:
        import spot

        found["spot"] = spot.version()
    except ImportError:
        pass
    return found


@dataclass(frozen=True)
class Parameters:
    """The world's parameters that shape the hypergame (docs/semantics.md §1), as echoed in
    results.json under ``parameters`` and, less the swept one, in sweep.json under
    ``fixed_parameters``."""

    formula: str                    # P1's task, co-safe LTL in Spot syntax (§3)
    # the front end's own parameters (frontends.parameters: a grid world's robot, §2; none for
    # an arena world, whose arena gives the outcomes, §15), echoed after the formula
    front_end: tuple[tuple[str, object], ...]
    traps: int                      # traps P2 places at once (§2)
    delay: int                      # steps P2 waits after moving traps (§2)
    hypotheses: tuple[str, ...]     # P2's candidate tasks (§4)
    initial_hypothesis: int         # index into `hypotheses` of P2's first guess (§5)
    window: int                     # w: transitions in P2's sliding window (§5)
    rationality: float              # β: P2's softmax model of P1 (§4)
    # P2's observer: its kind (opponent/registry.py) and its own settings in its kind's order
    # (CUSUM's threshold, §5; the Bayesian prior and decision, §12)
    inference: str = "cusum"
    settings: tuple[tuple[str, object], ...] = ()
    tie_break: str = "first"        # which of P2's tied actions she takes (§4)

    @classmethod
    def of(cls, world: World) -> Parameters:
        from hg2prism.frontends import parameters

        return cls(formula=world.formula, front_end=tuple(parameters(world).items()),
                   traps=world.traps, delay=world.delay, hypotheses=tuple(world.hypotheses),
                   initial_hypothesis=world.initial_hypothesis, window=world.window,
                   rationality=world.rationality, inference=world.inference,
                   settings=world.settings, tie_break=world.tie_break)

    def to_json(self) -> dict:
        """The parameters in file order: the observer's kind is named unless it is the default
        one (CUSUM's results.json has always omitted it), then the window, the kind's own
        settings and P2's rationality; P2's tie break when it is not the rule's ("first")."""
        from hg2prism.model.world import World

        default = next(f.default for f in fields(World) if f.name == "inference")
        kind = {} if self.inference == default else {"inference": self.inference}
        ties = {} if self.tie_break == "first" else {"tie_break": self.tie_break}
        return {"formula": self.formula, **dict(self.front_end), "traps": self.traps,
                "delay": self.delay, **ties, "hypotheses": list(self.hypotheses),
                "initial_hypothesis": self.initial_hypothesis, **kind, "window": self.window,
                **{key: list(value) if isinstance(value, tuple) else value
                   for key, value in self.settings},
                "rationality": self.rationality}


@dataclass(frozen=True)
class StrategyObjective:
    """The objective P1's exported strategy optimises and its timing (docs/semantics.md §6
    "Objectives"), read off the DTMC the strategy induces (induced.tra/.drn): results.json's
    ``objective``."""

    name: str                       # "pmax" (the default), "bounded" or "lexicographic"
    bound: int | None               # H of the bounded objective, else None
    value: float                    # the objective's value: Pmax, or Pmax=? [F<=H "goal"] when bounded
    goal_probability: float         # P(F "goal") in the strategy's induced DTMC
    expected_steps: float | None    # E[steps until goal or failure (or the bound)]; None: infinite
    expected_steps_to_goal: float | None   # E[steps | goal reached]; None: the goal is never reached

    def to_json(self) -> dict:
        return {"name": self.name, "bound": self.bound, "value": self.value,
                "goal_probability": self.goal_probability,
                "expected_steps": self.expected_steps,
                "expected_steps_to_goal": self.expected_steps_to_goal}


@dataclass(frozen=True)
class Timings(Mapping):
    """Seconds per stage, in the order the stages ran: a read-only mapping (stage -> seconds).
    A stage adds its time by making new Timings (`then`), so that a value handed on never
    changes after it is built."""

    stages: tuple[tuple[str, float], ...] = ()

    def __getitem__(self, stage: str) -> float:
        for name, seconds in self.stages:
            if name == stage:
                return seconds
        raise KeyError(stage)

    def __iter__(self) -> Iterator[str]:
        return (name for name, _ in self.stages)

    def __len__(self) -> int:
        return len(self.stages)

    def then(self, more: Mapping[str, float] | None = None, /, **seconds: float) -> Timings:
        """These timings followed by `more`'s and `seconds`' stages (a stage timed again keeps
        its place and takes the new time, as a dict's key does)."""
        merged = dict(self.stages)
        merged.update(more or {})
        merged.update(seconds)
        return Timings(tuple(merged.items()))


def _timings_json(timings: Mapping[str, float]) -> dict[str, float]:
    return {stage: round(seconds, TIMING_DIGITS) for stage, seconds in timings.items()}


@dataclass(frozen=True)
class CheckResults:
    """What `hg2prism check` computes: the deceptive value and the hypergame's size
    (results.json, docs/semantics.md §6 "results.json (from check)")."""

    world: str                      # the world's name
    world_file: str                 # the world file as given (may be relative)
    world_digest: str               # World.digest(): which world exactly (not where its file is)
    hg2prism_version: str
    software: dict[str, str]        # the versions it ran on (results.software)
    deceptive_value: float          # Pmax=? [F "goal"] at the hypergame's initial state (§6), by Storm
    storm_method: str               # "sound", "storm-sound", "sound-ovi" or "fast" (§10)
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
    # export (and with `run`: exports, nash, deception, simulation, plots, replay). Unrounded
    # here, rounded in to_json(); read-only.
    timings: Timings
    objective: StrategyObjective    # what the exported strategy optimises, and its timing
    # the name of P2's type the world is of (`--type`, an adaptive run's type<k>/); "" for a
    # world as its file gives it, and then not in results.json
    p2_type: str = field(default="", kw_only=True)

    def to_json(self) -> dict:
        """The content of results.json written by `check`."""
        return {
            "world": self.world,
            **({"p2_type": self.p2_type} if self.p2_type else {}),
            "world_file": self.world_file,
            "world_digest": self.world_digest,
            "hg2prism_version": self.hg2prism_version,
            "software": self.software,
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
            "objective": self.objective.to_json(),
        }


class Summary(Protocol):
    """What a row reads of a simulation (analyses/simulation.py SimulationSummary)."""

    rate: float
    ci95: tuple[float, float]
    episodes: int
    truncated: int
    p2_switched: int
    p2_switches: int
    p2_switched_in_play: int


@dataclass(frozen=True)
class SimulatedRow:
    """One strategy pair played online (docs/semantics.md §8): a row of the completion table."""

    rate: float                     # completed / episodes: completion within the horizon
    ci95: tuple[float, float]       # Wilson score interval of `rate` at 95 % (§8)
    episodes: int
    truncated: int                  # episodes cut by the horizon (not completed)
    exact_within_horizon: float     # P(goal within `horizon` steps) for the pair simulated (§8)
    # Rows played against P2's inference (§11): the share of episodes in which her hypothesis
    # changed at least once, and the mean number of changes per episode; None for the others.
    # `p2_switched_in_play`: the share with a change after which the episode went on (neither
    # the goal nor a failure reached; cut by the horizon counts): a change P2 could act on.
    p2_switched: float | None = None
    p2_switches_mean: float | None = None
    p2_switched_in_play: float | None = None

    @classmethod
    def of(cls, summary: Summary, exact_within_horizon: float,
           switches: bool = False) -> SimulatedRow:
        """The row of a simulation; with `switches`, P2's changes of hypothesis too."""
        return cls(rate=summary.rate, ci95=tuple(summary.ci95), episodes=summary.episodes,
                   truncated=summary.truncated, exact_within_horizon=exact_within_horizon,
                   p2_switched=summary.p2_switched / summary.episodes if switches else None,
                   p2_switches_mean=summary.p2_switches / summary.episodes if switches else None,
                   p2_switched_in_play=(summary.p2_switched_in_play / summary.episodes
                                        if switches else None))

    def to_json(self) -> dict:
        row = {"rate": self.rate, "ci95": list(self.ci95), "episodes": self.episodes,
               "truncated": self.truncated, "exact_within_horizon": self.exact_within_horizon}
        if self.p2_switched is not None:
            row["p2_switched"] = self.p2_switched
            row["p2_switches_mean"] = self.p2_switches_mean
            row["p2_switched_in_play"] = self.p2_switched_in_play
        return row


@dataclass(frozen=True)
class Simulations:
    """The online simulations of `run` (docs/semantics.md §8), all with the same horizon and
    seed: results.json's ``simulation``."""

    horizon: int                    # transitions after which an episode is cut
    seed: int                       # numpy.random.default_rng seed of every row
    deceptive: SimulatedRow         # P1's deceptive strategy against P2's inference (§6, §8)
    nash: SimulatedRow              # both players' extracted Nash strategies (§7)
    leader: SimulatedRow            # P2's leader strategy and P1's answer to it (§7)
    static: SimulatedRow            # P2 keeps her first guess, P1's best response to it (§11)
    naive: SimulatedRow             # P1's leader-game answers against P2's inference (§11)

    def to_json(self) -> dict:
        return {"horizon": self.horizon, "seed": self.seed,
                "deceptive": self.deceptive.to_json(), "nash": self.nash.to_json(),
                "leader": self.leader.to_json(), "static": self.static.to_json(),
                "naive": self.naive.to_json()}


@dataclass(frozen=True)
class DrawnEpisode:
    """The deceptive episode the figures and the replay draw, and the rule that chose it
    (docs/semantics.md §8 "The episode drawn"): results.json's ``episode``."""

    rule: str                       # "median", "shortest" or "seed=N"
    seed: int                       # the seed it was simulated with (one episode)
    steps: int                      # its transitions
    outcome: str                    # "task completed", "failed" or "cut by the horizon"
    chosen_as: str                  # the rule applied, in words
    seed_set: tuple[int, int] | None    # first and last seed searched (None for seed=N)
    completed_in_seed_set: int | None   # how many of them completed
    replay_frames: int              # frames of replay.gif

    def to_json(self) -> dict:
        return {"rule": self.rule, "seed": self.seed, "steps": self.steps,
                "outcome": self.outcome, "chosen_as": self.chosen_as,
                "seed_set": list(self.seed_set) if self.seed_set else None,
                "completed_in_seed_set": self.completed_in_seed_set,
                "replay_frames": self.replay_frames}


@dataclass(frozen=True)
class RunResults(CheckResults):
    """What `hg2prism run` computes: the check's results (with the timings of every stage of
    the run), the Nash baseline with its sound bracket (docs/semantics.md §7), what the
    deception is worth (§11) and the online simulations (§8)."""

    v_ne: float                     # V_NE at the initial state, inside v_ne_bounds (§7)
    v_ne_p1_guaranteed: float       # what P1's extracted Nash strategy guarantees: the lower end (§7)
    v_ne_bounds: tuple[float, float]  # sound bracket (lower, upper) around V_NE (§7)
    v_static: float                 # P2 never revises her first guess; P1 knows it (§11)
    v_naive: float                  # P1 plays the leader game against P2's inference (§11)
    value_of_deception: float       # deceptive_value - v_naive (§11)
    simulation: Simulations
    episode: DrawnEpisode | None = None     # the episode world.png and replay.gif draw

    @classmethod
    def extending(cls, check: CheckResults, *, timings: Timings, v_ne: float,
                  v_ne_p1_guaranteed: float, v_ne_bounds: tuple[float, float],
                  v_static: float, v_naive: float, value_of_deception: float,
                  simulation: Simulations, episode: DrawnEpisode | None = None) -> RunResults:
        """The check's results, with the run's timings and the run's additions."""
        inherited = {f.name: getattr(check, f.name) for f in fields(CheckResults)}
        inherited["timings"] = timings
        return cls(**inherited, v_ne=v_ne, v_ne_p1_guaranteed=v_ne_p1_guaranteed,
                   v_ne_bounds=tuple(v_ne_bounds), v_static=v_static, v_naive=v_naive,
                   value_of_deception=value_of_deception, simulation=simulation, episode=episode)

    def to_json(self) -> dict:
        """The content of results.json written by `run`: the check's keys (``timings`` keeps
        its place), then the baselines, what the deception is worth and the simulations."""
        return {
            **super().to_json(),
            "v_ne": self.v_ne,
            "v_ne_p1_guaranteed": self.v_ne_p1_guaranteed,
            "v_ne_bounds": list(self.v_ne_bounds),
            "v_static": self.v_static,
            "v_naive": self.v_naive,
            "value_of_deception": self.value_of_deception,
            "simulation": self.simulation.to_json(),
            **({"episode": self.episode.to_json()} if self.episode is not None else {}),
        }


# ---------------------------------------------------------------------------------------------
# What the stages hand on
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Analysis:
    """Everything P1 knows before the interaction starts: the games and the opponent model."""

    world: World
    ts: TransitionSystem
    task: DFA
    games: list[PerceptualGame]
    inference: Observer       # P2's inference: CUSUM (§5) or Bayesian (§12)
    leader: GameSolution      # the symmetric leader game G(phi), DFA state tracked (docs/semantics.md §7)
    v_lead: float
    timings: Timings = Timings()    # the analysis's stage (games); check's Analysis: check's too


@dataclass(frozen=True, eq=False)
class CheckResult:
    """What `check` computes for a world: the analysis, the model, the engine's answer and P1's
    strategy on the engine's states, and `results` (results.json's content)."""

    analysis: Analysis
    prism: PrismModel
    checked: CheckedModel
    decoded: DecodedStates
    strategy: StormChoices          # P1's choice in each of the engine's states
    results: CheckResults           # results.json's content: results.to_json()
    out: Path                       # the folder holding hypergame.prism, strategy.json, ...
    engine: ModelChecker            # the model checker that built and checked the model
    extras: RecordExtras | None = None     # keys the records gain after "action"
    dtmc: InducedDTMC | None = None        # the DTMC the exported strategy induces (induced.*)
    bounded: Bounded | None = None         # the step-dependent strategy of --objective bounded

    @functools.cached_property
    def records(self) -> tuple[dict, ...]:
        """The strategy's records (strategy.json's content, read-only `Record`s), built on first
        use: writing the file does not need them, and they cost seconds on million-state
        models."""
        from hg2prism.strategy.records import strategy_records

        built = self.engine.explicit(self.checked.model)
        return tuple(strategy_records(self.decoded, self.strategy, built.transitions,
                                      self.analysis.ts, self.extras, built.initial))

    def __getstate__(self) -> dict:
        # Pickled (a Solution sent to another process, copy.deepcopy), Storm's model stays
        # behind (engines/storm.py: StormChecked), so the records it gives are built first.
        self.records
        return self.__dict__

    def player(self, strategy: Strategy | None = None) -> tuple[Analysis, Policy]:
        """What plays P1's exported strategy in simulations: the analysis (P2's inference) and
        P1's policy, `strategy` or the one its records give. A step-bounded strategy's move
        depends on the steps taken: P1 counts them beside P2's memory (strategy/stepped.py)."""
        import dataclasses

        from hg2prism.strategy.records import Strategy
        from hg2prism.strategy.stepped import StepCounter, SteppedStrategy

        ts = self.analysis.ts
        if self.bounded is None:
            return self.analysis, (strategy if strategy is not None
                                   else Strategy.from_records(self.records, ts))
        records = strategy.records if strategy is not None else self.records
        return (dataclasses.replace(self.analysis, inference=StepCounter(
                    self.analysis.inference, self.bounded.bound - 1)),
                SteppedStrategy(records, ts, self.bounded.bound))


@dataclass(frozen=True, eq=False)
class RunResult:
    """What `run` computes for a world: the check, `results` (results.json's content) and the
    completion table."""

    check: CheckResult
    results: RunResults             # results.json's content: results.to_json()
    table: str                      # table.md's content
