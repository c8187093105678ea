"""Runs the stages for one world and writes its outputs (SPEC §§2–6)."""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from hg2prism import __version__, storm
from hg2prism.automata import DFA, translate
from hg2prism.dynamics import TransitionSystem, build_transition_system
from hg2prism.games import PerceptualGame, perceptual_game, solve_game
from hg2prism.hypergame import PROPERTY, PrismModel, build_model, write_model
from hg2prism.inference import InferenceModel, build_inference
from hg2prism.outputs import write_json
from hg2prism.world import World


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


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
    inference: InferenceModel
    v_lead: float
    timings: dict[str, float] = field(default_factory=dict)


def analyse(world: World) -> Analysis:
    timings: dict[str, float] = {}
    with _timed(timings, "games"):
        ts = build_transition_system(world)
        task = translate(world.formula, ts.label_names)
        games = [perceptual_game(ts, translate(h, ts.label_names), world.rationality)
                 for h in world.hypotheses]
        inference = build_inference(games, world.window, world.threshold, world.initial_hypothesis)
        leader = solve_game(ts, task)
        start_cell = ts.decode(ts.start_state)[0]
        v_lead = float(leader.values[ts.start_state, task.delta[task.initial, ts.cell_label[start_cell]]])
    progress(f"games: {len(games)} perceptual game(s) and the leader game solved "
             f"({ts.n_states} TS states) in {timings['games']:.2f} s")
    return Analysis(world, ts, task, games, inference, v_lead, timings)


def generate(analysis: Analysis, out: Path) -> PrismModel:
    start = time.perf_counter()
    model = build_model(analysis.world, analysis.ts, analysis.task, analysis.games, analysis.inference)
    prism, _ = write_model(model, out)
    analysis.timings["generate"] = time.perf_counter() - start
    progress(f"generate: wrote {prism} ({sum(model.commands.values())} commands) "
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
    strategy: storm.Strategy
    records: list[dict]
    results: dict


def check(world: World, out: Path) -> CheckResult:
    analysis = analyse(world)
    prism = generate(analysis, out)
    progress("storm: building and checking " + PROPERTY)
    checked = storm.check(out / "hypergame.prism", PROPERTY)
    analysis.timings.update(checked.timings)
    start = time.perf_counter()
    moves = storm.transitions(checked.model)
    decoded = storm.decode_states(checked.model, prism.layout, analysis.ts, analysis.task)
    states, transitions = storm.canonical_size(decoded, moves)
    strategy = storm.deceptive_strategy(decoded, checked, moves)
    records = storm.strategy_records(decoded, strategy, moves, analysis.ts)
    analysis.timings["export"] = time.perf_counter() - start
    results = {
        "world": world.name,
        "world_file": str(world.path),
        "hg2prism_version": __version__,
        "deceptive_value": checked.value,
        "v_lead": analysis.v_lead,
        "states": states,
        "transitions": transitions,
        "storm_states": checked.model.nr_states,
        "storm_transitions": checked.model.nr_transitions,
        "storm_choices": checked.model.nr_choices,
        "model_commands": prism.commands,
        "parameters": {
            "slip": world.slip, "traps": world.traps, "delay": world.delay,
            "hypotheses": list(world.hypotheses), "initial_hypothesis": world.initial_hypothesis,
            "window": world.window, "threshold": world.threshold, "rationality": world.rationality,
        },
        "timings": {k: round(v, 4) for k, v in analysis.timings.items()},
    }
    write_json(out / "strategy.json", records)
    write_json(out / "results.json", results)
    progress(f"storm: {checked.model.nr_states} states ({states} canonical), "
             f"build {checked.timings['build']:.2f} s, check {checked.timings['check']:.2f} s")
    return CheckResult(analysis, prism, checked, decoded, strategy, records, results)
