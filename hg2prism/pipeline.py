"""Runs the stages for one world and writes its outputs (docs/semantics.md §§2–6)."""

from __future__ import annotations

import functools
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from hg2prism import memory
from hg2prism.engines.engine import CheckedModel, BuiltModel, ModelChecker, Transitions
from hg2prism.engines import default as default_engine
from hg2prism.model.automata import to_dot, to_hoa, translate
from hg2prism.frontends import transition_system
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.model.product import completable
from hg2prism.opponent.perceptual_games import (PerceptualGame, SharedParts, perceptual_game,
                                                solve_game)
from hg2prism.errors import COMMAND_LINE, InputError, probability
from hg2prism.progress import say, warn
from hg2prism.strategy.canonical import CanonicalMDP, canonical_mdp, canonical_values
from hg2prism.strategy.deceptive import StormChoices, deceptive_actions, storm_choices
from hg2prism.strategy.exports import (InducedDTMC, drn, expected_steps, goal_props,
                                       prism_explicit, stationary_dtmc, unfolded_dtmc)
from hg2prism.strategy.objectives import (OBJECTIVES, Bounded, bounded_actions,
                                          lexicographic_actions)
from hg2prism.strategy.records import (RecordExtras, Strategy, StrategyError,
                                       strategy_json_chunks)
from hg2prism.strategy.stepped import SteppedStrategy
from hg2prism.prism.decoding import DecodedStates, canonical_size, decode_states
from hg2prism.prism.hypergame import PROPERTY, PrismModel, build_model, write_model
from hg2prism.opponent.observer import Observer
from hg2prism.opponent import registry
from hg2prism.outputs import write_bytes, write_chunks, write_json, write_text
from hg2prism.model.world import World
from hg2prism.results import (Analysis, CheckResult, CheckResults, DrawnEpisode, Parameters,
                              RunResult, RunResults, SimulatedRow, Simulations, StrategyObjective,
                              Timings, provenance)

if TYPE_CHECKING:
    from hg2prism.model.automata import DFA
    from hg2prism.analyses.baselines import NashBaseline
    from hg2prism.analyses.deception_value import DeceptionValues
    from hg2prism.analyses.episodes import ChosenEpisode, EpisodeRule
    from hg2prism.analyses.simulation import SimulationSummary

# The step-bounded objective keeps a move per (state, step): this many at most (about 50 MB),
# and as many states in its induced DTMC.
MAX_BOUNDED_PAIRS = 50_000_000


class _Clock:
    """The seconds a stage takes: `seconds` once the `with` block is left."""

    def __enter__(self) -> _Clock:
        self.start = time.perf_counter()
        self.seconds = 0.0
        return self

    def __exit__(self, *exc: object) -> None:
        self.seconds = time.perf_counter() - self.start


def analyse(world: World) -> Analysis:
    with _Clock() as games_clock:
        ts = transition_system(world)
        task = translate(world.formula, ts.label_names, ts.letters)
        hypotheses = [translate(h, ts.label_names, ts.letters) for h in world.hypotheses]
        # The games are independent and numpy and SuperLU release the GIL, so two threads
        # solve them side by side (1.6x on delayed worlds), each exactly as alone. The largest
        # games (most DFA states; the leader game first among equals) are submitted first, so
        # that the largest does not start last and run alone at the end: on a delayed world
        # the leader game takes half the stage, the others share the second thread meanwhile.
        # Small games run one after the other, in this thread (SERIAL_GAMES).
        pool = ThreadPoolExecutor(max_workers=2) if ts.succ.size >= SERIAL_GAMES else _Inline()
        try:
            jobs = sorted([(task, -1)] + [(dfa, i) for i, dfa in enumerate(hypotheses)],
                          key=lambda job: -job[0].n_states)
            shared = SharedParts()      # a part two games have in common is solved once
            futures = {i: (pool.submit(solve_game, ts, dfa, shared, world.tie_break) if i < 0
                           else pool.submit(perceptual_game, ts, dfa, world.rationality, shared,
                                            world.tie_break))
                       for dfa, i in jobs}
            if ts.succ.size >= LONG_GAMES:      # seconds to minutes: say how it goes
                _say_games_progress(futures, ts)
            games = [futures[i].result() for i in range(len(hypotheses))]
            leader = futures[-1].result()
        finally:    # a failed game (or Ctrl-C) does not wait for the games still queued
            pool.shutdown(wait=True, cancel_futures=True)
        inference = build_observer(world, games)
        start_label = ts.state_label()[ts.start_state]
        v_lead = probability(leader.values[ts.start_state, task.delta[task.initial, start_label]],
                             "V_lead")
    say(f"games: {len(games)} perceptual game(s) and the leader game solved "
             f"({ts.n_states} TS states) in {games_clock.seconds:.2f} s")
    _say_undecided_choices(world, ts, games)
    if v_lead == 0.0:       # else some play completes it
        warn_if_not_completable(world, ts, task)
    return Analysis(world, ts, task, games, inference, leader, v_lead,
                    Timings().then(games=games_clock.seconds))


# TS tables (state x P1's action x P2's action x outcome) below which the games run in this
# thread (`_Inline`), not two: on the benchmark's worlds without delay of 13k-114k entries two
# threads took 5-20% longer than one (their numpy calls too short to release the GIL for
# long); the delay worlds (from 200k entries) keep two.
SERIAL_GAMES = 150_000


class _Inline:
    """An executor that runs each job as it is submitted, in the calling thread (a failed job
    raises at once: the jobs after it never start)."""

    def submit(self, fn: Callable, /, *args: object) -> Future:
        future: Future = Future()
        future.set_result(fn(*args))
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        pass


def warn_if_not_completable(world: World, ts: TransitionSystem | None = None,
                            task: DFA | None = None) -> bool:
    """A warning when no play completes the world's task from the start, whatever either
    player does (`check` and `validate`); whether it was given. `ts` and `task`: the world's
    own, built here when not given."""
    if ts is None:
        ts = transition_system(world)
    if task is None:
        task = translate(world.formula, ts.label_names, ts.letters)
    if completable(ts, task):
        return False
    warn(f"no play completes the task {world.formula!r} from the start, whatever either "
         "player does (no state where it holds can be reached with positive probability): "
         "every value is 0; check the " + ("map's walls, regions and trap candidates"
                                           if world.grid else
                                           "arena's edges, labels and P2's actions"))
    return True


def _say_undecided_choices(world: World, ts: TransitionSystem, games) -> None:
    """A line for each hypothesis under which P2's actions all tie wherever she chooses (P1
    could not complete x whatever she did, say its region is walled off): she keeps the
    standing one or takes the first (the last with tie_break "last", docs/semantics.md §4), and
    her moves under it do not
    defend anything, which a reader of the values should know (a review's warehouse: the
    deceptive value 1 where V_lead is 0). A value of 0 alone does not say it: it may be 0
    because she plays the one action that stops P1."""
    chooses = ~ts.terminal & (ts.allowed.sum(axis=1) > 1)
    what = "trap sets" if world.traps else "actions"
    for i, game in enumerate(games):
        # where she chooses and the task is not done already (its own region: value 1)
        rows = np.flatnonzero(chooses & ~np.isin(game.fresh_q, list(game.dfa.accepting)))
        if rows.size and game.all_tied is not None and game.all_tied[rows].all():
            say(f"games: under hypothesis x{i} ({world.hypotheses[i]}) P2's {what} all tie "
                "wherever she chooses (none changes P1's chance of completing it): under it she "
                f"keeps the standing one or takes the {world.tie_break} (docs/semantics.md §4)")


# TS tables (state x P1's action x P2's action x outcome) from which the games take seconds:
# a progress line as each game is solved (a 37k-TS-state world with 455 trap sets was silent
# for a minute).
LONG_GAMES = 5_000_000


def _say_games_progress(futures: dict, ts: TransitionSystem) -> None:
    from concurrent.futures import as_completed

    start = time.perf_counter()
    say(f"games: solving {len(futures)} games on {ts.n_states:,} TS states x {ts.n_sets:,} "
        f"P2 actions")
    names = {future: ("the leader game" if i < 0 else f"the game of hypothesis x{i}")
             for i, future in futures.items()}
    for done, future in enumerate(as_completed(names), 1):
        if future.exception() is None:
            say(f"games: {names[future]} solved ({done} of {len(futures)}, "
                f"{time.perf_counter() - start:.1f} s)")


def build_observer(world: World, games: list[PerceptualGame]) -> Observer:
    """P2's inference as the world file sets it (`[inference] kind`)."""
    return registry.build_observer(world, games)


def generate(analysis: Analysis, out: Path) -> PrismModel:
    """The hypergame's PRISM model, written into `out` (hypergame.prism, .props)."""
    return _generate(analysis, out)[0]


def _generate(analysis: Analysis, out: Path) -> tuple[PrismModel, float]:
    """`generate`, and the seconds it took."""
    with _Clock() as clock:
        model = build_model(analysis.world, analysis.ts, analysis.task, analysis.games,
                            analysis.inference)
        prism, _ = write_model(model, out)
    say(f"generate: {prism.name} ({sum(model.commands.values())} commands) "
             f"in {clock.seconds:.2f} s")
    return model, clock.seconds


def emit(world: World, out: Path) -> PrismModel:
    return generate(analyse(world), out)


def automata_files(analysis: Analysis) -> dict[str, str]:
    """task.hoa/.dot/.svg and hypothesis_<i>.hoa/.dot/.svg: every DFA, numbered as hg2prism
    numbers it (the SVG drawn without Graphviz: report/automaton_svg.py)."""
    from hg2prism.report.automaton_svg import to_svg

    names = analysis.ts.label_names
    files = {"task.hoa": to_hoa(analysis.task, names), "task.dot": to_dot(analysis.task, names),
             "task.svg": to_svg(analysis.task, names)}
    for i, game in enumerate(analysis.games):
        files[f"hypothesis_{i}.hoa"] = to_hoa(game.dfa, names)
        files[f"hypothesis_{i}.dot"] = to_dot(game.dfa, names)
        files[f"hypothesis_{i}.svg"] = to_svg(game.dfa, names)
    return files


@dataclass(frozen=True, eq=False)
class ModelStructure:
    """What the export stage reads off the engine's model, independent of the values (so it is
    read while the engine solves)."""

    moves: Transitions
    decoded: DecodedStates
    mdp: CanonicalMDP
    size: tuple[int, int]          # canonical states and transitions (docs/semantics.md §6)
    initial: int                   # the engine's initial state


def read_model(model: BuiltModel, prism: PrismModel, analysis: Analysis) -> ModelStructure:
    """The engine's transitions, its states decoded, the canonical MDP and its size."""
    moves = model.transitions
    decoded = decode_states(model, prism.layout, analysis.ts, analysis.task,
                            getattr(analysis.inference, "window_hypotheses", None))
    return ModelStructure(moves, decoded, canonical_mdp(decoded, moves, analysis.ts.n_actions),
                          canonical_size(decoded, moves), model.initial)


def _objective_strategy(objective: str, bound: int | None, structure: ModelStructure,
                        checked: CheckedModel, ts: TransitionSystem
                        ) -> tuple[StormChoices, RecordExtras, Callable[[], InducedDTMC],
                                   Bounded | None, float]:
    """P1's strategy for the objective, the records' extra keys, the maker of its induced DTMC,
    the step-dependent strategy (bounded only) and the objective's value (docs/semantics.md
    §6)."""
    decoded, moves, mdp = structure.decoded, structure.moves, structure.mdp
    values = canonical_values(decoded, checked.values)
    initial = int(decoded.canonical[structure.initial])
    move_values = mdp.by_state(mdp.choice_values(values))
    action = deceptive_actions(mdp, values)
    if objective == "pmax":
        strategy = storm_choices(decoded, moves, mdp.representative, action)
        dtmc = functools.partial(stationary_dtmc, mdp, action, decoded, ts, initial)
        return strategy, RecordExtras(move_values), dtmc, None, checked.value
    if objective == "lexicographic":
        action = lexicographic_actions(mdp, values, action).action
        strategy = storm_choices(decoded, moves, mdp.representative, action)
        dtmc = functools.partial(stationary_dtmc, mdp, action, decoded, ts, initial)
        return strategy, RecordExtras(move_values), dtmc, None, checked.value
    if mdp.n * bound > MAX_BOUNDED_PAIRS:
        raise InputError(COMMAND_LINE, "--bound",
                         f"{mdp.n:,} hypergame states x {bound:,} steps is more than the "
                         f"{MAX_BOUNDED_PAIRS:,} (state, step) pairs the bounded objective keeps")
    bounded = bounded_actions(mdp, action, initial, bound)
    strategy = storm_choices(decoded, moves, mdp.representative, bounded.action_at(0))

    def dtmc() -> InducedDTMC:
        try:
            return unfolded_dtmc(mdp, bounded.action_at, decoded, ts, initial, bound,
                                 MAX_BOUNDED_PAIRS)
        except ValueError as err:
            raise InputError(COMMAND_LINE, "--bound", str(err)) from None

    extras = RecordExtras(move_values, bounded.schedules(), bounded.move_values)
    return strategy, extras, dtmc, bounded, bounded.value


def _objective_bound(world: World, objective: str, bound: int | None) -> int | None:
    """The bound of the bounded objective (by default the world's simulation horizon), None for
    the others; an unknown objective or a bound below 1 is refused."""
    if objective not in OBJECTIVES:
        raise InputError(COMMAND_LINE, "--objective",
                         f"must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    if objective != "bounded":
        return None
    bound = world.simulation.horizon if bound is None else bound
    if bound < 1:
        raise InputError(COMMAND_LINE, "--bound", "must be at least 1")
    return bound


def check(world: World, out: Path, storm_method: str = "sound", objective: str = "pmax",
          bound: int | None = None, engine: ModelChecker | None = None) -> CheckResult:
    """Emit, check with the model checker `engine` (default: Storm) by its method
    `storm_method` and export P1's strategy for `objective` (docs/semantics.md §6: "pmax", the
    default, "lexicographic" or "bounded" with `bound` steps, by default the world's simulation
    horizon)."""
    engine = engine or default_engine()
    bound = _objective_bound(world, objective, bound)
    analysis = analyse(world)
    prism, generating = _generate(analysis, out)
    say(f"storm: building and checking {PROPERTY} ({storm_method})")
    if storm_method not in engine.sound_methods:
        warn(f"Storm method {storm_method!r} is not sound: the deceptive value is not "
                 "certified to 1e-10")
    checked = engine.check(out / "hypergame.prism", PROPERTY, storm_method,
                           alongside=lambda model: read_model(model, prism, analysis))
    start = time.perf_counter()
    structure: ModelStructure = checked.alongside
    memory.trim()       # what reading Storm's model freed, before the strategy's arrays
    decoded, moves = structure.decoded, structure.moves
    states, transitions = structure.size
    strategy, extras, make_dtmc, bounded, objective_value = _objective_strategy(
        objective, bound, structure, checked, analysis.ts)
    memory.trim()       # the strategy's temporaries, before the exports
    comment = (f"the DTMC P1's strategy ({objective}) induces on the hypergame of {world.name}; "
               "states as in induced.sta")

    def write_explicit(dtmc: InducedDTMC) -> None:
        for suffix, text in prism_explicit(dtmc).items():
            write_chunks(out / f"induced.{suffix}", text)
        write_bytes(out / "goal.props", goal_props())

    # The exports are independent: they are formatted and written side by side (numpy and
    # scipy release the GIL in their loops). One record per line in strategy.json: compact
    # for millions of states, still easy to grep and diff.
    with ThreadPoolExecutor(max_workers=3) as pool:
        jobs = [pool.submit(lambda: write_chunks(out / "strategy.json", strategy_json_chunks(
            decoded, strategy, moves, analysis.ts, extras, structure.initial)))]
        dtmc = make_dtmc()
        jobs += [pool.submit(write_explicit, dtmc),
                 pool.submit(lambda: write_chunks(out / "induced.drn", drn(dtmc, comment)))]
        steps = expected_steps(dtmc)
        for job in jobs:
            job.result()
    # the Analysis check hands on carries the check's stages too (run goes on from them)
    analysis = replace(analysis, timings=analysis.timings.then(
        {"generate": generating, **checked.timings}, export=time.perf_counter() - start))
    if abs(steps.goal_probability - objective_value) > 1e-6:
        warn(f"the exported strategy reaches the goal with probability "
             f"{steps.goal_probability:.9f}, not the {objective} value {objective_value:.9f}")
    results = CheckResults(
        **provenance(world, engine),
        deceptive_value=checked.value,
        storm_method=storm_method,
        sound=storm_method in engine.sound_methods,
        v_lead=analysis.v_lead,
        states=states,
        transitions=transitions,
        storm_states=checked.size[0],
        storm_transitions=checked.size[1],
        storm_choices=checked.size[2],
        model_commands=dict(prism.commands),
        parameters=Parameters.of(world),
        timings=analysis.timings,
        objective=StrategyObjective(
            name=objective, bound=bound, value=objective_value,
            goal_probability=steps.goal_probability, expected_steps=steps.to_end,
            expected_steps_to_goal=steps.to_goal),
    )
    write_json(out / "results.json", results.to_json())
    for name, text in automata_files(analysis).items():
        write_text(out / name, text)
    say(f"storm: {checked.size[0]} states ({states} canonical), "
             f"build {checked.timings['build']:.2f} s, check {checked.timings['check']:.2f} s")
    return CheckResult(analysis, prism, checked, decoded, strategy, results, out, engine,
                       extras=extras, dtmc=dtmc, bounded=bounded)


def run(world: World, out: Path, episodes: int | None = None, horizon: int | None = None,
        seed: int | None = None, show_progress: bool = True,
        storm_method: str = "sound", episode: str | None = None, objective: str = "pmax",
        bound: int | None = None) -> RunResult:
    """Everything computed for a world: the check, the baselines (docs/semantics.md §7), the PRISM-games
    exports, V_static and V_naive (docs/semantics.md §11), the online simulations
    (docs/semantics.md §8), the completion table, the figures and the replay of the episode
    `episode` names ("median", the default, "shortest" or "seed=N": docs/semantics.md §8
    "The episode drawn").
    With the bounded objective the bound is the simulation's horizon (the default), so that the
    simulated rate estimates the bounded value."""
    from hg2prism.analyses.episodes import parse_episode_rule
    from hg2prism.prism import game_models
    from hg2prism.report import tables

    n_episodes = episodes or world.simulation.episodes
    horizon = horizon or world.simulation.horizon
    seed = world.simulation.seed if seed is None else seed
    rule = parse_episode_rule(episode)     # before any work: a bad rule is one line
    if objective == "bounded":
        if bound is not None and bound != horizon:
            raise InputError(COMMAND_LINE, "--bound",
                             f"with run, the bound is the simulation horizon ({horizon}); "
                             f"got {bound}")
        bound = horizon
    checked = check(world, out, storm_method, objective, bound)
    analysis = checked.analysis
    _warn_if_slow(checked.results.objective, horizon)
    with _Clock() as exports:
        written = game_models.write_game_models(analysis, out)
    say(f"exports: wrote {', '.join(p.name for p in written if p.suffix == '.prism')}")
    with _Clock() as nash_clock:
        nash = _nash_stage(analysis)
    with _Clock() as deception_clock:
        worth = _deception_stage(checked)
    with _Clock() as simulating:
        played = _simulations(checked, nash, worth, n_episodes, horizon, seed, show_progress)
    _warn_if_simulations_disagree(played)
    drawn, frames, drawing = _figures(world, out, analysis, played, horizon, seed, rule)
    timings = checked.results.timings.then(
        exports=exports.seconds, nash=nash_clock.seconds, deception=deception_clock.seconds,
        simulation=simulating.seconds).then(drawing)
    results = RunResults.extending(
        checked.results, timings=timings, v_ne=nash.v_ne,
        v_ne_p1_guaranteed=nash.v_ne_p1_guaranteed, v_ne_bounds=nash.v_ne_bounds,
        v_static=worth.v_static, v_naive=worth.v_naive,
        value_of_deception=worth.value_of_deception,
        simulation=played.rows(horizon, seed), episode=DrawnEpisode(
            rule=str(drawn.rule), seed=drawn.seed, steps=drawn.n_steps, outcome=drawn.outcome,
            chosen_as=drawn.describe(), seed_set=drawn.seeds,
            completed_in_seed_set=len(drawn.completed_lengths) if drawn.seeds else None,
            replay_frames=frames))
    table = tables.completion_table(results)
    write_text(out / "table.md", table)
    write_json(out / "results.json", results.to_json())
    return RunResult(checked, results, table)


def _warn_if_slow(objective: StrategyObjective, horizon: int) -> None:
    """A warning when P1's strategy needs more steps on average to complete the task than the
    simulations allow (a review's office world: 3,378 expected steps, horizon 150, 4 % of the
    episodes completed, below the naive row): the table's rates are then about the horizon."""
    steps = objective.expected_steps_to_goal
    if objective.name != "bounded" and steps is not None and steps > horizon:
        warn(f"P1's strategy takes {steps:,.0f} steps on average to complete the task, more "
             f"than the simulations' horizon of {horizon}: many episodes are cut by it "
             "(table.md's exact within-horizon column says how many); the bounded objective "
             "(--objective bounded; objective=\"bounded\" in Python) maximises the "
             "probability within the horizon instead")


def _warn_if_simulations_disagree(played: _Played) -> None:
    """A warning for each simulated pair whose count of completed episodes is implausible under
    its exact probability of completing within the horizon (analyses.simulation
    .warn_if_implausible). A registered observer whose Python update differed from its PRISM
    part's showed 0.0000 [0, 0.0004] simulated beside 0.9982 exact, without a word."""
    from hg2prism.analyses.simulation import warn_if_implausible
    from hg2prism.report.tables import COMPLETION_ROWS

    for row in COMPLETION_ROWS:
        summary, exact = played.summaries[row.key], played.within[row.key]
        warn_if_implausible(f"completion of \"{row.information}\"", summary.completed,
                            summary.episodes, exact,
                            " (for an observer of your own: does its Python update do what "
                            "its PRISM part does? docs/architecture.md, \"An observer\")")


def _nash_stage(analysis: Analysis) -> NashBaseline:
    """The symmetric Nash baseline with its sound bracket (docs/semantics.md §7), reported."""
    from hg2prism.analyses import baselines

    with _Clock() as clock:
        nash = baselines.nash_baseline(analysis.ts, analysis.task)
    low, high = nash.v_ne_bounds
    say(f"nash: V_NE = {nash.v_ne:.6f} in [{low:.10f}, {high:.10f}], guaranteed by P1's "
             f"stationary strategy {nash.v_ne_p1_guaranteed:.6f} ({clock.seconds:.2f} s)")
    if nash.bracket_warn:
        warn(f"the bracket around V_NE is {high - low:.2e} wide (more than 1e-6)")
    if nash.warn:
        warn(f"P1's extracted Nash strategy guarantees {nash.v_ne_p1_guaranteed:.6f}, "
                 f"{nash.shortfall:.2e} below V_NE (it is only locally optimal, docs/semantics.md §7)")
    return nash


def _deception_stage(checked: CheckResult) -> DeceptionValues:
    """V_static and V_naive (docs/semantics.md §11), reported."""
    from hg2prism.analyses import deception_value

    with _Clock() as clock:
        worth = deception_value.deception_values(checked.analysis,
                                                 checked.results.deceptive_value)
    say(f"deception: V_static = {worth.v_static:.6f}, V_naive = {worth.v_naive:.6f} "
        f"({worth.naive_chain.size} states), value of deception "
        f"{worth.value_of_deception:.6f} ({clock.seconds:.2f} s)")
    return worth


@dataclass(frozen=True, eq=False)
class _Played:
    """The online simulations of `run` (docs/semantics.md §8): each pair's summary and its exact
    probability of completing within the horizon, and what the deceptive episodes were played
    with (the figures draw one of them)."""

    analysis: Analysis             # P2's observer counts P1's steps under a bounded strategy
    strategy: Strategy | SteppedStrategy
    summaries: dict[str, SimulationSummary]   # deceptive, nash, leader, static, naive
    within: dict[str, float]

    def rows(self, horizon: int, seed: int) -> Simulations:
        def row(name: str, switches: bool = False) -> SimulatedRow:
            return SimulatedRow.of(self.summaries[name], self.within[name], switches=switches)

        return Simulations(horizon=horizon, seed=seed, deceptive=row("deceptive", True),
                           nash=row("nash"), leader=row("leader"), static=row("static"),
                           naive=row("naive", True))


def _simulations(checked: CheckResult, nash: NashBaseline, worth: DeceptionValues,
                 n_episodes: int, horizon: int, seed: int, show_progress: bool) -> _Played:
    """Every strategy pair played online, and exactly within the horizon."""
    from hg2prism.analyses import simulation

    analysis = checked.analysis
    ts, task = analysis.ts, analysis.task
    played, strategy = checked.player()
    deceptive_within = (checked.engine.induced_within(checked.checked, checked.strategy.choice,
                                                      horizon) if checked.bounded is None
                        else checked.results.objective.goal_probability)
    pairs = {"nash": (nash.p1.reshape(-1, ts.n_actions), nash.p2.reshape(ts.n_states * task.n_states, -1)),
             "leader": _leader_strategies(analysis),
             "static": (worth.static.policy.mixed(), np.eye(ts.n_sets)[worth.static.p2])}
    try:
        summaries = {"deceptive": simulation.simulate_deceptive(
            played, strategy, n_episodes, horizon, seed, progress=show_progress)}
    except StrategyError as err:
        # the records of this run's own strategy cover every state the model reaches, and the
        # episodes follow P1's model of P2: her observer's memory went where its PRISM part
        # does not go
        raise StrategyError(f"{err} (the records cover every state the model reaches: does "
                            "P2's observer update her memory in Python as its PRISM part does? "
                            "docs/architecture.md, \"An observer\")") from None
    for name, (p1, p2) in pairs.items():
        summaries[name] = simulation.simulate_nash(
            ts, task, p1, p2, n_episodes, horizon, seed, progress=show_progress,
            **({} if name == "nash" else {"label": f"simulate {name}"}))
    summaries["naive"] = simulation.simulate_deceptive(
        analysis, worth.naive, n_episodes, horizon, seed, progress=show_progress,
        label="simulate naive")
    within = {"deceptive": deceptive_within}
    within.update({name: simulation.exact_completion(ts, task, p1, p2, horizon)
                   for name, (p1, p2) in pairs.items()})
    within["naive"] = worth.naive_chain.within(horizon)
    return _Played(played, strategy, summaries, within)


def _figures(world: World, out: Path, analysis: Analysis, played: _Played, horizon: int,
             seed: int, rule: EpisodeRule) -> tuple[ChosenEpisode, int, Timings]:
    """world.png, belief.png, completion.png (and .svg) and replay.gif of the episode `rule`
    names (P2's belief as `analysis`'s observer holds it); the episode, the replay's frames
    and the seconds of the plots and the replay."""
    from hg2prism.analyses.episodes import belief_trace, choose_episode
    from hg2prism.report import plots, replay
    from hg2prism.report.tables import COMPLETION_ROWS

    with _Clock() as plotting:
        drawn = choose_episode(played.analysis, played.strategy, horizon, seed, rule)
        trace = belief_trace(analysis.inference, drawn.steps)
        plots.world_figure(world, analysis.ts, drawn, trace, out / "world.png")
        plots.belief_figure(world, trace, drawn, out / "belief.png")
        plots.completion_figure(world.name, [
            (row.information, played.summaries[row.key], played.within[row.key])
            for row in COMPLETION_ROWS], out / "completion.png")
    say(f"plots: {drawn.describe()}: seed {drawn.seed}, {drawn.n_steps} steps, {drawn.outcome}")
    with _Clock() as replaying:
        frames = replay.replay_gif(world, analysis.ts, drawn, trace, out / "replay.gif")
    say(f"replay: replay.gif, {frames} frames ({replaying.seconds:.2f} s)")
    _explorer(world, out, analysis, played, drawn, horizon, seed)
    return drawn, frames, Timings().then(plots=plotting.seconds, replay=replaying.seconds)


def _explorer(world: World, out: Path, analysis: Analysis, played: _Played,
              drawn: ChosenEpisode, horizon: int, seed: int) -> None:
    """explorer.html: the drawn episode and its candidates, state by state (report/explorer.py)."""
    from hg2prism.report.explorer import write_explorer

    start = time.perf_counter()
    write_explorer(world, analysis, played.analysis, played.strategy, drawn, horizon, seed,
                   out / "explorer.html")
    say(f"explorer: explorer.html ({time.perf_counter() - start:.2f} s)")


def _leader_strategies(analysis: Analysis) -> tuple[np.ndarray, np.ndarray]:
    """The leader game's pair as (degenerate) mixed strategies over g = s * n_q + q: P2's trap
    sets by docs/semantics.md §4's rule on the exact values (optimal up to its 1e-6 ties), P1's fastest
    optimal answers (simulation.LeaderStrategy)."""
    from hg2prism.analyses.simulation import LeaderStrategy

    p2 = analysis.leader.p2_strategy
    return LeaderStrategy(analysis).mixed(), np.eye(analysis.ts.n_sets)[p2]
