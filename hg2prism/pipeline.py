"""Runs the stages for one world and writes its outputs (docs/semantics.md §§2–6)."""

from __future__ import annotations

import functools
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from hg2prism import __version__
from hg2prism.engines import storm
from hg2prism.model.automata import DFA, translate
from hg2prism.model.dynamics import TransitionSystem, build_transition_system
from hg2prism.opponent.perceptual_games import (GameSolution, PerceptualGame, fastest_answers, perceptual_game,
                            solve_game)
from hg2prism.errors import probability
from hg2prism.progress import say, warn
from hg2prism.strategy.deceptive import StormChoices, deceptive_strategy
from hg2prism.strategy.records import Strategy, strategy_json, strategy_records
from hg2prism.prism.hypergame import PROPERTY, PrismModel, build_model, write_model
from hg2prism.opponent.bayes import build_bayes
from hg2prism.opponent.inference import build_inference
from hg2prism.opponent.observer import Observer
from hg2prism.outputs import write_json, write_text
from hg2prism.model.world import World
from hg2prism.results import CheckResults, Parameters, RunResults, SimulatedRow, Simulations


@contextmanager
def _timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    start = time.perf_counter()
    yield
    timings[stage] = time.perf_counter() - start


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
    timings: dict[str, float] = field(default_factory=dict)


def analyse(world: World) -> Analysis:
    timings: dict[str, float] = {}
    with _timed(timings, "games"):
        ts = build_transition_system(world)
        task = translate(world.formula, ts.label_names, ts.letters)
        games = [perceptual_game(ts, translate(h, ts.label_names, ts.letters), world.rationality)
                 for h in world.hypotheses]
        inference = build_observer(world, games)
        leader = solve_game(ts, task)
        start_cell = ts.decode(ts.start_state)[0]
        v_lead = probability(leader.values[ts.start_state, task.delta[task.initial, ts.cell_label[start_cell]]],
                             "V_lead")
    say(f"games: {len(games)} perceptual game(s) and the leader game solved "
             f"({ts.n_states} TS states) in {timings['games']:.2f} s")
    return Analysis(world, ts, task, games, inference, leader, v_lead, timings)


def build_observer(world: World, games: list[PerceptualGame]) -> Observer:
    """P2's inference as the world file sets it (`[inference] kind`)."""
    if world.inference == "bayes":
        return build_bayes(games, world.window, world.prior, world.decision)
    return build_inference(games, world.window, world.threshold, world.initial_hypothesis)


def generate(analysis: Analysis, out: Path) -> PrismModel:
    start = time.perf_counter()
    model = build_model(analysis.world, analysis.ts, analysis.task, analysis.games, analysis.inference)
    prism, _ = write_model(model, out)
    analysis.timings["generate"] = time.perf_counter() - start
    say(f"generate: {prism.name} ({sum(model.commands.values())} commands) "
             f"in {analysis.timings['generate']:.2f} s")
    return model


def emit(world: World, out: Path) -> PrismModel:
    return generate(analyse(world), out)


@dataclass(frozen=True, eq=False)
class CheckResult:
    analysis: Analysis
    prism: PrismModel
    checked: storm.CheckedModel
    decoded: storm.DecodedStates
    strategy: StormChoices          # P1's choice in each of Storm's states
    results: CheckResults           # results.json's content: results.to_json()
    out: Path                       # the folder holding hypergame.prism, strategy.json, ...

    @functools.cached_property
    def records(self) -> list[dict]:
        """The strategy's records (strategy.json's content), built on first use: writing the
        file does not need them, and they cost seconds on million-state models."""
        return strategy_records(self.decoded, self.strategy, storm.transitions(
            self.checked.model), self.analysis.ts)


def check(world: World, out: Path, storm_method: str = "sound") -> CheckResult:
    analysis = analyse(world)
    prism = generate(analysis, out)
    say(f"storm: building and checking {PROPERTY} ({storm_method})")
    if storm_method not in storm.SOUND_METHODS:
        warn(f"Storm method {storm_method!r} is not sound: the deceptive value is not "
                 "certified to 1e-10")
    checked = storm.check(out / "hypergame.prism", PROPERTY, storm_method)
    analysis.timings.update(checked.timings)
    start = time.perf_counter()
    moves = storm.transitions(checked.model)
    decoded = storm.decode_states(checked.model, prism.layout, analysis.ts, analysis.task,
                                  getattr(analysis.inference, "window_hypotheses", None))
    states, transitions = storm.canonical_size(decoded, moves)
    strategy = deceptive_strategy(decoded, checked, moves)
    strategy_text = strategy_json(decoded, strategy, moves, analysis.ts)
    analysis.timings["export"] = time.perf_counter() - start
    results = CheckResults(
        world=world.name,
        world_file=str(world.path),
        hg2prism_version=__version__,
        deceptive_value=checked.value,
        storm_method=storm_method,
        sound=storm_method in storm.SOUND_METHODS,
        v_lead=analysis.v_lead,
        states=states,
        transitions=transitions,
        storm_states=checked.model.nr_states,
        storm_transitions=checked.model.nr_transitions,
        storm_choices=checked.model.nr_choices,
        model_commands=dict(prism.commands),
        parameters=Parameters.of(world),
        timings=dict(analysis.timings),   # a snapshot: run() goes on timing its own stages
    )
    # One record per line: compact for millions of states, still easy to grep and diff.
    write_text(out / "strategy.json", strategy_text)
    write_json(out / "results.json", results.to_json())
    say(f"storm: {checked.model.nr_states} states ({states} canonical), "
             f"build {checked.timings['build']:.2f} s, check {checked.timings['check']:.2f} s")
    return CheckResult(analysis, prism, checked, decoded, strategy, results, out)


@dataclass(frozen=True, eq=False)
class RunResult:
    check: CheckResult
    results: RunResults             # results.json's content: results.to_json()
    table: str                      # table.md's content


def run(world: World, out: Path, episodes: int | None = None, horizon: int | None = None,
        seed: int | None = None, show_progress: bool = True,
        storm_method: str = "sound") -> RunResult:
    """Everything computed for a world: the check, the baselines (docs/semantics.md §7), the PRISM-games
    exports, the online simulations (docs/semantics.md §8), the completion table and the world picture."""
    from hg2prism.analyses import baselines
    from hg2prism.prism import game_models
    from hg2prism.report import plots
    from hg2prism.report import tables
    from hg2prism.analyses import simulation

    episodes = episodes or world.simulation.episodes
    horizon = horizon or world.simulation.horizon
    seed = world.simulation.seed if seed is None else seed
    checked = check(world, out, storm_method)
    analysis, timings = checked.analysis, checked.analysis.timings

    with _timed(timings, "exports"):
        written = game_models.write_game_models(analysis, out)
    say(f"exports: wrote {', '.join(p.name for p in written if p.suffix == '.prism')}")

    with _timed(timings, "nash"):
        nash = baselines.nash_baseline(analysis.ts, analysis.task)
    low, high = nash.v_ne_bounds
    say(f"nash: V_NE = {nash.v_ne:.6f} in [{low:.10f}, {high:.10f}], guaranteed by P1's "
             f"stationary strategy {nash.v_ne_p1_guaranteed:.6f} ({timings['nash']:.2f} s)")
    if nash.bracket_warn:
        warn(f"the bracket around V_NE is {high - low:.2e} wide (more than 1e-6)")
    if nash.warn:
        warn(f"P1's extracted Nash strategy guarantees {nash.v_ne_p1_guaranteed:.6f}, "
                 f"{nash.shortfall:.2e} below V_NE (it is only locally optimal, docs/semantics.md §7)")

    with _timed(timings, "simulation"):
        strategy = Strategy.from_records(checked.records, analysis.ts)
        deceptive = simulation.simulate_deceptive(analysis, strategy, episodes, horizon, seed,
                                                  progress=show_progress)
        n_q = analysis.task.n_states
        nash_sim = simulation.simulate_nash(
            analysis.ts, analysis.task, nash.p1.reshape(-1, 4),
            nash.p2.reshape(analysis.ts.n_states * n_q, -1), episodes, horizon, seed,
            progress=show_progress)
        leader_p1, leader_p2 = _leader_strategies(analysis)
        leader_sim = simulation.simulate_nash(analysis.ts, analysis.task, leader_p1, leader_p2,
                                              episodes, horizon, seed, progress=show_progress,
                                              label="simulate leader")
        within = {
            "deceptive": storm.induced_within(checked.checked, checked.strategy, horizon),
            "nash": simulation.exact_completion(analysis.ts, analysis.task, nash.p1.reshape(-1, 4),
                                                nash.p2.reshape(analysis.ts.n_states * n_q, -1),
                                                horizon),
            "leader": simulation.exact_completion(analysis.ts, analysis.task, leader_p1, leader_p2,
                                                  horizon),
        }

    with _timed(timings, "plots"):
        episode, outcome = _illustrative_episode(analysis, strategy, horizon, seed)
        plots.world_figure(world, analysis.ts, episode, outcome, out / "world.png")

    results = RunResults.extending(
        checked.results,
        timings=dict(timings),
        v_ne=nash.v_ne,
        v_ne_p1_guaranteed=nash.v_ne_p1_guaranteed,
        v_ne_bounds=nash.v_ne_bounds,
        simulation=Simulations(
            horizon=horizon, seed=seed,
            deceptive=SimulatedRow.of(deceptive, within["deceptive"]),
            nash=SimulatedRow.of(nash_sim, within["nash"]),
            leader=SimulatedRow.of(leader_sim, within["leader"]),
        ),
    )
    table = tables.completion_table(results)
    write_text(out / "table.md", table)
    write_json(out / "results.json", results.to_json())
    return RunResult(checked, results, table)


def _leader_strategies(analysis: Analysis) -> tuple[np.ndarray, np.ndarray]:
    """The leader game's pair as (degenerate) mixed strategies over g = s * n_q + q: P2's trap
    sets by docs/semantics.md §4's rule on the exact values (optimal up to its 1e-6 ties), P1's fastest
    optimal answers."""
    p2 = analysis.leader.p2_strategy
    p1 = fastest_answers(analysis.ts, analysis.task, analysis.leader)
    return np.eye(4)[p1], np.eye(analysis.ts.n_sets)[p2]


def _illustrative_episode(analysis: Analysis, strategy: Strategy, horizon: int,
                          seed: int) -> tuple[list, str]:
    """The shortest episode that completes the task among the seeds `seed`..`seed+49` (the
    clearest picture of the strategy), else the first one."""
    from hg2prism.analyses import simulation

    first: tuple[list, str] | None = None
    best: tuple[list, str] | None = None
    for attempt in range(50):
        steps: list = []
        summary = simulation.simulate_deceptive(analysis, strategy, 1, horizon, seed + attempt,
                                                observer=steps.append, progress=False)
        outcome = {simulation.GOAL: "task completed", simulation.FAIL: "failed"}.get(
            int(summary.outcomes[0]), "cut by the horizon")
        if first is None:
            first = (steps, f"{outcome}, seed {seed + attempt}")
        if summary.completed and (best is None or len(steps) < len(best[0])):
            best = (steps, f"{outcome}, seed {seed + attempt}")
    return best or first
