"""hg2prism: deceptive strategies in dynamic hypergames, model-checked with Storm through
generated PRISM models. Each command takes a world file (TOML); docs/semantics.md defines every
quantity, docs/worlds.md the world format, docs/cli.md the commands and outputs."""

from __future__ import annotations

import argparse
import os
import signal
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from hg2prism import __version__, memory, plugins, progress
from hg2prism.engines import default as default_engine
from hg2prism.errors import COMMAND_LINE, InputError, SolverError, StormError
from hg2prism.strategy.records import StrategyError
from hg2prism.model import sizeguard
from hg2prism.experiments.sweep import sweep_parameters
from hg2prism.outputs import check_writable
from hg2prism.api import command_stage
from hg2prism.strategy.objectives import OBJECTIVES


def _out_dir(world_path: Path, out: str | None) -> Path:
    if out == "":       # not the default folder by accident (the API refuses out="" too)
        raise InputError(COMMAND_LINE, "--out", "an empty path; expected a folder (\".\" for "
                         "the current one), or leave --out out for the folder next to the "
                         "world file")
    return Path(out) if out is not None else world_path.parent / world_path.stem


def _exit_on_signal(signum: int, frame: object) -> None:
    print(f"hg2prism: stopped by signal {signum}{_what_was_written()}", file=sys.stderr)
    raise SystemExit(128 + signum)


def _what_was_written() -> str:
    """The end of a stopped command's line: its outputs are placed whole or not at all (a
    stop while they move into OUT waits for them, outputs.staged)."""
    from hg2prism.outputs import placement

    state, out = placement()
    if state == "done":
        return f" after placing its outputs in {out}"
    if state == "begun":
        return f"; {out} may hold some of the new outputs beside old ones"
    return "; nothing was written"


# ---------------------------------------------------------------------------------------------
# The parsers, one per command (the help texts are the documentation of the options)
# ---------------------------------------------------------------------------------------------

OUT_DEFAULT = (" OUT defaults to the folder next to the world file named after it "
               "(models/world1.toml -> models/world1/).")
Subparsers = argparse._SubParsersAction     # what add_subparsers returns


def _add(sub: Subparsers, name: str, help: str) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help, description=help)
    p.add_argument("world", help="world file (TOML, see docs/worlds.md)")
    return p


def _max_states_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--max-states", type=int, metavar="N",
                   help="refuse worlds whose estimated hypergame size exceeds N "
                        f"(default {sizeguard.DEFAULT_LIMIT:,}, about what 24 GiB holds at "
                        "4 KiB per estimated state)")


def _solver_options(p: argparse.ArgumentParser) -> None:
    _max_states_option(p)
    p.add_argument("--storm-method", choices=default_engine().methods, default="sound",
                   help="sound (default: a fast solver's strategy, evaluated exactly and "
                        "certified optimal to 1e-10, else Storm's sound solver), storm-sound "
                        "(Storm's sound solver alone, precision 1e-10), sound-ovi (Storm's "
                        "optimistic value iteration, also sound; occasionally stuck) or fast "
                        "(plain value iteration to 1e-12, not sound: flagged in the outputs)")


def _objective_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--objective", choices=OBJECTIVES, default="pmax",
                   help="what P1's exported strategy optimises (docs/semantics.md §6): "
                        "pmax (default: Pmax, the fastest optimal moves by a discounted "
                        "score), lexicographic (Pmax, then the fewest expected steps) or "
                        "bounded (Pmax of reaching the goal within --bound steps; a "
                        "strategy that depends on the steps taken)")
    p.add_argument("--bound", type=int, metavar="H",
                   help="steps of the bounded objective (default: the simulation horizon)")


def _type_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--type", metavar="NAME", help="on a world with P2's types ([[type]]): the "
                   "command on the world where P2 is of this type (its name or number); OUT "
                   "then defaults to the folder named after the world file and the type's "
                   "number, models/world4_type1/ (docs/adaptive.md)")


def _validate_parser(sub: Subparsers) -> None:
    _add(sub, "validate", "Check a world file and print a summary; writes nothing.")


def _convert_parser(sub: Subparsers) -> None:
    p = _add(sub, "convert", "Write the world's arena form (docs/semantics.md §15) as a world "
             "file: a grid world compiled to its states, P1's actions and their outcomes; an "
             "arena world normalised. `check` and every other command accept it.")
    p.add_argument("--out", metavar="FILE", help="the world file to write (atomically; "
                   "default: print it on standard output)")
    _type_option(p)


def _emit_parser(sub: Subparsers) -> None:
    p = _add(sub, "emit", "Write the hypergame PRISM model: OUT/hypergame.prism and "
             "OUT/hypergame.props." + OUT_DEFAULT)
    p.add_argument("--out", metavar="OUT", help="output folder")
    _type_option(p)
    _max_states_option(p)


def _episode_options(p: argparse.ArgumentParser, episodes_help: str) -> None:
    """--episodes, --horizon and --seed of the commands that simulate (run, detect)."""
    p.add_argument("--episodes", type=int, help=episodes_help)
    p.add_argument("--horizon", type=int, help="steps before an episode is cut (default: the world's)")
    p.add_argument("--seed", type=int, help="random seed (default: the world's)")


def _solving_parser(sub: Subparsers, name: str, help: str) -> argparse.ArgumentParser:
    """The parser of a command that solves the world and writes into OUT (check, run)."""
    p = _add(sub, name, help + OUT_DEFAULT)
    p.add_argument("--out", metavar="OUT", help="output folder")
    _type_option(p)
    _solver_options(p)
    _objective_options(p)
    p.add_argument("--prism-pomdp", action="store_true",
                   help="a world with P2's types (docs/adaptive.md): also run PRISM's POMDP "
                        "engine on adaptive_pomdp.prism and report its bounds (PRISM found "
                        "as $PRISM or on the PATH; about 10 s on world4)")
    return p


def _check_parser(sub: Subparsers) -> None:
    _solving_parser(sub, "check", "Emit, then check with Storm: writes OUT/strategy.json and "
                    "OUT/results.json too, the automata (task.hoa/.dot/.svg, hypothesis_<i>.hoa/.dot/.svg) "
                    "and the DTMC P1's strategy induces (induced.tra/.sta/.lab for PRISM, "
                    "induced.drn for Storm, goal.props the property that re-checks it). On a "
                    "world with P2's types ([[type]]): adaptive deception (adaptive.prism, "
                    "docs/adaptive.md).")


def _run_parser(sub: Subparsers) -> None:
    p = _solving_parser(sub, "run", "Everything computed for a world: check, the symmetric "
                        "baselines (Nash, leader), PRISM-games exports (symmetric.prism, "
                        "perceptual_<i>.prism), online simulation, the completion table "
                        "(table.md), the figures (world, belief, completion; PNG and SVG), the "
                        "replay of one episode (replay.gif) and explorer.html, a self-contained "
                        "page stepping through it and its candidate episodes. On a world "
                        "with P2's types ([[type]]): adaptive deception, its simulation and "
                        "adaptive_belief.png (docs/adaptive.md).")
    _episode_options(p, "simulated episodes (default: the world's)")
    p.add_argument("--episode", metavar="RULE", default=None,
                   help="the episode world.png, belief.png, replay.gif and explorer.html draw: median "
                        "(default: a median-length completed episode of the seeds "
                        "SEED..SEED+49), shortest (the shortest of them) or seed=N "
                        "(the episode of seed N)")


def _sweep_parser(sub: Subparsers) -> None:
    p = _add(sub, "sweep", "Re-solve the world at every point of a grid of parameter values and "
             "compare the deceptive value with V_lead and V_NE; writes OUT/sweep.json, sweep.csv, "
             "sweep.png/.svg and a folder per point (its model and strategy). Points run in "
             "parallel on Dask (docs/semantics.md §7, Sweeps).")
    p.add_argument("--param", required=True, action="append", metavar="NAME",
                   help="a parameter to sweep: " + ", ".join(sweep_parameters())
                        + "; repeat --param NAME --values V... to sweep the grid of several; "
                        "a world with P2's types ([[type]]) sweeps weight (its first type's "
                        "prior weight) only, unless --type picks one type's world")
    p.add_argument("--values", required=True, action="append", nargs="+", metavar="V",
                   help="the values of the --param before it")
    p.add_argument("--out", metavar="OUT", help="output folder (default: next to the world file)")
    p.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of the local Dask cluster (default: the number of "
                        "cores); 1 solves the points one after another in this process")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the points on the Dask cluster whose scheduler is at ADDRESS "
                        "(e.g. tcp://host:8786) instead of a local one")
    p.add_argument("--deception", action="store_true",
                   help="also compute V_static and V_naive at each point (what the deception "
                        "is worth, docs/semantics.md §11)")
    _type_option(p)
    _solver_options(p)


def _detect_parser(sub: Subparsers) -> None:
    p = _add(sub, "detect", "Detect a wrong opponent model (docs/semantics.md §9): the seeded "
             "episode where P2 deviates after detection.deviate_after steps, the detection-step "
             "distribution, the false-alarm rate, and P2 running another window or threshold; "
             "writes OUT/detection.json and OUT/detection.png and detection.svg.")
    p.add_argument("--out", metavar="OUT", help="output folder (default: next to the world file)")
    _type_option(p)
    _episode_options(p, "episodes per batch (default: min(world's, 2000))")
    p.add_argument("--fallback", choices=("robust", "leader"),
                   help="re-planning (docs/semantics.md §14): after the detector's first rejection P1 "
                        "plays this strategy; reports completion with and without re-planning")
    p.add_argument("--fallback-delta", metavar="DELTA",
                   help="deviation budget of the robust fallback, in [0, 1) (default 0.1)")
    _solver_options(p)


def _robust_parser(sub: Subparsers) -> None:
    p = _add(sub, "robust", "Robust deception (docs/semantics.md §13): for each deviation budget "
             "delta, the interval model (OUT/robust_<delta>/robust.prism), the robust value, the "
             "deceptive strategy's worst case and the robust strategy "
             "(OUT/robust_<delta>/strategy.json); writes OUT/robust.json, robust.csv, robust.png "
             "and robust.svg.")
    p.add_argument("--deltas", nargs="+", metavar="DELTA", default=["0", "0.02", "0.05", "0.1", "0.2"],
                   help="deviation budgets in [0, 1) (default: 0 0.02 0.05 0.1 0.2)")
    p.add_argument("--out", metavar="OUT", help="output folder (default: next to the world file)")
    _type_option(p)
    p.add_argument("--no-cross-check", dest="cross_check", action="store_false",
                   help="skip the cross-check of each budget by Storm's robust mode and numpy on "
                        "the model with eps = 1e-9 (storm_check null in robust.json): most of the "
                        "time on mid-size worlds; the values are solved and certified without it")
    _max_states_option(p)


def _bench_parser(sub: Subparsers) -> None:
    sub.add_parser("bench", add_help=False,
                   help="Scaling benchmark: worlds of growing size through every stage; writes "
                        "bench/results.csv and bench/scaling.png and .svg (see `hg2prism bench --help`).")


# ---------------------------------------------------------------------------------------------
# What each command checks before any work, and what it does
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Outcome:
    """What a command hands back to be printed: `check`/`run` results for the summary, else a
    table of its own; sweep points that failed."""

    results: object | None = None
    table: str | None = None
    failed: tuple[dict, ...] = ()


def _guard_size(args: argparse.Namespace, world: object) -> None:
    sizeguard.check_size(world, args.max_states)


def _guard_sweep(args: argparse.Namespace, world: object) -> None:
    from hg2prism.experiments import sweep

    if len(args.param) != len(args.values):
        raise InputError(COMMAND_LINE, "--values", "each --param needs its own "
                         "--values, right after it")
    if args.workers is not None and args.workers < 1:
        raise InputError(COMMAND_LINE, "--workers", "must be at least 1")
    if args.workers is not None and args.scheduler is not None:
        raise InputError(COMMAND_LINE, "--scheduler", "the cluster at --scheduler has "
                         "its own workers; leave out --workers")
    if world.types:         # adaptive deception: the prior is swept (docs/adaptive.md)
        from hg2prism.experiments.adaptive import check_weights

        if args.param != ["weight"]:
            raise InputError(COMMAND_LINE, "--param", "weight is given twice; give all its "
                             "values after one --values" if set(args.param) == {"weight"} else
                             "a world with P2's types sweeps --param weight (the first "
                             "type's prior weight) only, or with --type NAME the parameters "
                             "of the world where P2 is of that type")
        if args.deception:
            raise InputError(COMMAND_LINE, "--deception", "V_static and V_naive are of a world "
                             "with one [inference]; a world with P2's types reports V_adapt, "
                             "V_oracle and each V_commit per weight (docs/adaptive.md)")
        check_weights(world, args.values[0], args.max_states)
        return
    # every point is guarded before the first is solved: all refused refuses the sweep
    sweep.check_grid(world, list(zip(args.param, args.values)), args.max_states)


def _guard_robust(args: argparse.Namespace, world: object) -> None:
    from hg2prism.experiments import robust

    sizeguard.check_robust_size(world, args.max_states)
    robust.parse_deltas(args.deltas)


def _guard_detect(args: argparse.Namespace, world: object) -> None:
    from hg2prism.experiments import detect

    detect.parse_fallback(args.fallback, args.fallback_delta)
    if args.fallback == "robust":
        sizeguard.check_robust_size(world, args.max_states)
    else:
        _guard_size(args, world)


def _simulation_options(args: argparse.Namespace, world: object) -> None:
    """--episodes, --horizon and --seed within the limits a world file's [simulation] has (one
    rule and one wording: model/validation.py's)."""
    from hg2prism import worldfile as world_mod
    from hg2prism.model.validation import Checks

    checks = Checks(COMMAND_LINE)
    for option, least, most in (("episodes", 1, world_mod.MAX_EPISODES),
                                ("horizon", 1, world_mod.MAX_HORIZON),
                                ("seed", 0, world_mod.MAX_SEED)):
        if getattr(args, option) is not None:
            checks.integer(getattr(args, option), f"--{option}", least, most)


def _bound_option(args: argparse.Namespace, world: object) -> None:
    from hg2prism.worldfile import MAX_HORIZON

    if args.bound is None:
        return
    if args.objective != "bounded":
        raise InputError(COMMAND_LINE, "--bound", "needs --objective bounded")
    from hg2prism.model.validation import Checks

    Checks(COMMAND_LINE).integer(args.bound, "--bound", 1, MAX_HORIZON)
    if args.command == "run" and args.bound != (args.horizon or world.simulation.horizon):
        raise InputError(COMMAND_LINE, "--bound", "with run, the bound is the "
                         "simulation horizon; use --horizon instead")


def _run_options(args: argparse.Namespace, world: object) -> None:
    from hg2prism.analyses.episodes import parse_episode_rule

    _simulation_options(args, world)
    parse_episode_rule(args.episode)
    _bound_option(args, world)


def _emit(args: argparse.Namespace, world: object, stage: Path) -> Outcome:
    from hg2prism import pipeline

    pipeline.emit(world, stage)
    return Outcome()


def _check(args: argparse.Namespace, world: object, stage: Path) -> Outcome:
    from hg2prism import pipeline

    if world.types:             # P2's type unknown: adaptive deception (docs/semantics.md §16)
        return _adaptive(args, world, stage)

    return Outcome(pipeline.check(world, stage, args.storm_method, args.objective,
                                  args.bound).results)


def _run(args: argparse.Namespace, world: object, stage: Path) -> Outcome:
    from hg2prism import pipeline

    if world.types:
        return _adaptive(args, world, stage)

    result = pipeline.run(world, stage, args.episodes, args.horizon, args.seed,
                          storm_method=args.storm_method, episode=args.episode,
                          objective=args.objective, bound=args.bound)
    return Outcome(result.results, result.table)


def _adaptive(args: argparse.Namespace, world: object, stage: Path) -> Outcome:
    from hg2prism.experiments import adaptive

    simulation = None
    if args.command == "run":
        settings = world.simulation
        simulation = (args.episodes or settings.episodes, args.horizon or settings.horizon,
                      settings.seed if args.seed is None else args.seed)
    return Outcome(table=adaptive.check_adaptive(world, stage, args.storm_method,
                                                 simulation=simulation,
                                                 prism=args.prism_pomdp).table)


def _sweep(args: argparse.Namespace, world: object, stage: Path) -> Outcome:
    from hg2prism.experiments import sweep

    workers = args.workers if args.workers is not None else sweep.default_workers()
    if world.types:
        from hg2prism.experiments.adaptive import parse_weights, sweep_weights

        table, failed = sweep_weights(world, parse_weights(args.values[0]), stage,
                                      args.storm_method, workers=workers,
                                      scheduler=args.scheduler, max_states=args.max_states)
        return Outcome(table="\n".join(table), failed=failed)
    run = sweep.sweep_grid(world, list(zip(args.param, args.values)), stage,
                           storm_method=args.storm_method, workers=workers,
                           scheduler=args.scheduler, max_states=args.max_states,
                           deception=args.deception)
    return Outcome(table="\n".join(sweep.sweep_summary_lines(
        [name for name, _ in run.parameters], run.rows, world.name)), failed=run.failed)


def _robust(args: argparse.Namespace, world: object, stage: Path) -> Outcome:
    from hg2prism.experiments import robust

    result = robust.robust(world, args.deltas, stage, cross_check=args.cross_check)
    return Outcome(table="\n".join(robust.robust_summary_lines(result)))


def _detect(args: argparse.Namespace, world: object, stage: Path) -> Outcome:
    from hg2prism.experiments import detect

    detection = detect.detect(world, stage, args.episodes, args.seed, args.horizon,
                              storm_method=args.storm_method, fallback=args.fallback,
                              fallback_delta=args.fallback_delta)
    return Outcome(table="\n".join(detect.detection_summary_lines(detection)))


Check = Callable[[argparse.Namespace, object], None]


@dataclass(frozen=True)
class Command:
    """One command: its parser, what it refuses before the output folder is probed (`guard`)
    and after (`options`), and what it does in the staging folder (`act`), or what it does
    without an output folder (`alone`)."""

    parser: Callable[[Subparsers], object]
    guard: Check | None = None
    options: Check | None = None
    act: Callable[[argparse.Namespace, object, Path], Outcome] | None = None
    # a command without an output folder (validate, convert): does everything, gives the status
    alone: Callable[[argparse.Namespace, object], int] | None = None


def _nothing(args: argparse.Namespace, world: object) -> None:
    """Nothing more to refuse."""


def _validate(args: argparse.Namespace, world: object) -> int:
    from hg2prism import frontends

    types = (f", P2's types {', '.join(t.name for t in world.types)} (adaptive deception)"
             if world.types else "")
    print(f"{args.world}: ok ({world.name}: {frontends.describe(world)}, "
          f"{len(world.hypotheses)} hypothes{'is' if len(world.hypotheses) == 1 else 'es'}"
          f"{types})")
    print(_validate_details(world))
    from hg2prism.model import sizeguard

    # as `check` would warn (a world with types: each type's check), where the tables it takes
    # are small: validate stays quick, and never builds what the size guard would refuse
    if not world.types and sizeguard.game_table_bytes(world) <= VALIDATE_TABLE_BYTES:
        from hg2prism.pipeline import warn_if_not_completable

        warn_if_not_completable(world)
    return 0


# The largest tables (P2's games' estimate) `validate` builds to see whether some play completes
# the task: 256 MiB, a fraction of a second.
VALIDATE_TABLE_BYTES = 256 * 2**20


def _validate_details(world) -> str:
    """`validate`'s second line: P2's observer and traps, and the size guard's bound on the
    hypergame, with whether the solving commands would refuse it."""
    from hg2prism import frontends
    from hg2prism.model import sizeguard

    settings = "".join(f", {key} {value}" for key, value in world.settings)
    observer = (f"P2's types: {len(world.types)}" if world.types else
                f"P2's observer: {world.inference}, window {world.window}, rationality "
                f"{world.rationality:g}{settings}")
    bound = (sizeguard.estimate_adaptive(world) if world.types
             else sizeguard.estimate_states(world))
    size = ("more than 10^18" if bound >= sizeguard.BEYOND else f"at most {bound:,}")
    verdict = ""
    if bound > sizeguard.DEFAULT_LIMIT:
        from hg2prism.opponent.registry import observer_kind

        tighter = (not world.types and observer_kind(world.inference).solved_memory)
        verdict = (f"; above the size guard's limit of {sizeguard.DEFAULT_LIMIT:,}: the solving "
                   "commands refuse it unless "
                   + ("the tighter bound from P2's games fits or " if tighter else "")
                   + "--max-states allows it")
    need = sizeguard.game_table_bytes(world)
    if need > sizeguard.DEFAULT_LIMIT * sizeguard.BYTES_PER_STATE:
        verdict += (f"; P2's games would need about {sizeguard.gib(need)}, above the size "
                    "guard's memory limit: the solving commands refuse it unless --max-states "
                    "allows it")
    traps = (f"{world.traps} trap{'' if world.traps == 1 else 's'}"
             if frontends.arena_of(world).traps_mode else "P2's own actions")
    ties = "" if world.tie_break == "first" else f", ties to the {world.tie_break}"
    return (f"  {observer}; {traps}, delay {world.delay}{ties}; hypergame: {size} canonical states "
            f"(the size guard's bound from the world alone){verdict}")


def _convert(args: argparse.Namespace, world: object) -> int:
    from hg2prism.frontends import arena_of
    from hg2prism.frontends.arena import to_toml
    from hg2prism.outputs import write_text

    text = to_toml(world)
    if args.out is None:
        sys.stdout.write(text)
        return 0
    if args.out == "":
        raise InputError(COMMAND_LINE, "--out", "an empty path; expected a file name, or "
                         "leave --out out to print the arena form")
    out = Path(args.out)
    if out.is_dir():
        raise InputError(COMMAND_LINE, "--out", f"{out} is a folder; expected a file name")
    check_writable(out.parent, staged=False)
    write_text(out, text)
    print(f"{out}: written, the arena form of {world.name} ({arena_of(world).n_states} states)")
    return 0


COMMANDS: dict[str, Command] = {     # in the order `hg2prism --help` lists them
    "validate": Command(_validate_parser, alone=_validate),
    "convert": Command(_convert_parser, alone=_convert),
    "emit": Command(_emit_parser, _guard_size, _nothing, _emit),
    "check": Command(_check_parser, _guard_size, _bound_option, _check),
    "run": Command(_run_parser, _guard_size, _run_options, _run),
    "sweep": Command(_sweep_parser, _guard_sweep, _nothing, _sweep),
    "detect": Command(_detect_parser, _guard_detect, _simulation_options, _detect),
    "robust": Command(_robust_parser, _guard_robust, _nothing, _robust),
    "bench": Command(_bench_parser),      # bench.main parses its own options
}


# ---------------------------------------------------------------------------------------------
# The program
# ---------------------------------------------------------------------------------------------

class _Parser(argparse.ArgumentParser):
    """argparse's parser, its errors one line like every other bad input (argparse prints its
    usage block first): `hg2prism: error: command line: <what> (hg2prism run --help: ...)`."""

    def error(self, message: str):
        print(f"hg2prism: error: command line: {message} (`{self.prog} --help` lists the "
              "options)", file=sys.stderr)
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="hg2prism", description=__doc__)
    parser.add_argument("--version", action="version", version=f"hg2prism {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS.values():
        command.parser(sub)
    return parser


def _printable_streams() -> None:
    """stdout and stderr replace what their encoding cannot write (the tables' π under
    PYTHONIOENCODING=latin-1 ended a run that had written every file with a traceback)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(errors="replace")
        except (AttributeError, ValueError, OSError):     # not a text stream we may change
            pass


def entry() -> int:
    """The program (`hg2prism`, `python -m hg2prism`): main(), then the exit. A command
    stopped while Storm computed left its worker thread running (engines/storm.py); Python's
    exit would then tear the interpreter down under it, and Storm's C++ aborted the process
    (SIGABRT instead of the exit status of the signal): such an exit skips that teardown."""
    import threading

    try:
        status = main()
    except SystemExit as stop:      # a signal's handler, argparse's --help and usage errors
        if isinstance(stop.code, str):
            print(stop.code, file=sys.stderr)
        status = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
    except KeyboardInterrupt:       # a second Ctrl-C while the first was being reported
        status = 130
    if status in (130, 143):
        # stopped: the program has said so in its one line; what a library logs while Python
        # ends (Dask's cancelled tasks, collected: "Task exception was never retrieved") is not
        # for the user
        import logging

        for name in ("asyncio", "distributed", "tornado"):
            logging.getLogger(name).setLevel(logging.CRITICAL)
    if any(t.name == "storm" for t in threading.enumerate()):     # ending or not: abandoned
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(status)
    return status


def main(argv: list[str] | None = None) -> int:
    _printable_streams()
    try:
        plugins.load_plugins()      # HG2PRISM_PLUGINS: observers, world kinds from outside
        parser = build_parser()
    except KeyboardInterrupt:       # while a plugin loaded: nothing was begun
        print("hg2prism: interrupted", file=sys.stderr)
        return 130
    except InputError as err:       # a plugin that fails, or a setting's name taken twice
        print(f"hg2prism: error: {err}", file=sys.stderr)
        return 2
    argv = sys.argv[1:] if argv is None else argv
    memory.release_large_arrays()
    if argv[:1] == ["bench"]:
        from hg2prism.experiments import bench

        try:
            return bench.main(argv[1:])
        except KeyboardInterrupt:
            print("hg2prism bench: interrupted", file=sys.stderr)
            return 130
    args = parser.parse_args(argv)
    # SIGTERM (a killed job, a CI timeout) unwinds like Ctrl-C, so that the staging folder of a
    # half-done command is removed instead of left beside its output folder.
    try:
        previous = signal.signal(signal.SIGTERM, _exit_on_signal)
    except ValueError:      # not the main thread: leave signals alone
        previous = None
    try:
        with progress.on_stderr(), progress.each_warning_once():
            return _command(args)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _quiet_stdout() -> None:
    """stdout to the null device (its reader has gone)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def _command(args: argparse.Namespace) -> int:
    """Run the command `args` names; errors become one line on stderr and an exit status."""
    try:
        return _perform(args)
    except InputError as err:
        print(f"hg2prism: error: {err}", file=sys.stderr)
        return 2
    except SolverError as err:
        print(f"hg2prism: error: {args.world}: solver: {err}", file=sys.stderr)
        return 1
    except StormError as err:
        print(f"hg2prism: error: {args.world}: storm: {str(err).strip().splitlines()[0]}",
              file=sys.stderr)
        return 1
    except StrategyError as err:
        # a strategy that has no move where an episode went: an internal error, said in one
        # line (with what and where) rather than a traceback
        print(f"hg2prism: error: {args.world}: strategy: {err}", file=sys.stderr)
        return 1
    except BrokenPipeError:
        # what reads stdout went away (`| head`, `| true`): stop without a word, as Unix tools
        # do, and let Python's final flush write nowhere
        _quiet_stdout()
        return 141
    except OSError as err:
        # the output folder was checked up front; this is the disk filling up or a folder
        # changing under us. The staging folder is gone; where it failed while moving the
        # outputs into OUT, some are there (and MANIFEST lists old and new: outputs.staged)
        from hg2prism.outputs import MANIFEST, placement

        where = err.filename or getattr(args, "out", None) or args.world
        state, out = placement()
        partly = (f"; {out} may hold some of the new outputs beside old ones (its {MANIFEST} "
                  f"lists both, so the next command into it removes the stale ones)"
                  if state == "begun" else "")
        print(f"hg2prism: error: {where}: {err.strerror or err}{partly}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        written = _what_was_written()
        print("hg2prism: interrupted" + ("" if written.endswith("nothing was written")
                                         else written), file=sys.stderr)
        return 130


def _one_type(world: object, chosen: str, path: str) -> tuple[object, int]:
    """--type: the world in which P2 is of the type named (or numbered) `chosen`, and its
    number."""
    from hg2prism.worldfile.types import world_of_type

    names = [t.name for t in world.types]
    if not names:
        raise InputError(COMMAND_LINE, "--type", f"{path} lists no [[type]] of P2; --type picks "
                         "one of the types of a world that has them (docs/adaptive.md)")
    if chosen in names:
        k = names.index(chosen)
    elif chosen.strip().isdigit() and int(chosen) < len(names):
        k = int(chosen)
    else:
        raise InputError(COMMAND_LINE, "--type", f"no type {chosen!r} in {path}; expected one "
                         f"of {', '.join(repr(n) for n in names)} or a number from 0 to "
                         f"{len(names) - 1}")
    return world_of_type(world, k), k


def _perform(args: argparse.Namespace) -> int:
    """Load the world, refuse what the command cannot do before any work, then do it in a
    staging folder that becomes OUT, and print what was written."""
    from hg2prism.worldfile import load_world
    from hg2prism.report import tables

    world = load_world(args.world)
    command = COMMANDS[args.command]
    typed = None
    if getattr(args, "type", None) is not None:
        world, typed = _one_type(world, args.type, args.world)
    if world.types and (args.command not in ("validate", "check", "run", "sweep")
                        or getattr(args, "objective", "pmax") != "pmax"):
        raise InputError(args.world, "type", f"a world with P2's types (adaptive deception, "
                         f"docs/semantics.md §16) is handled by check and run with the pmax "
                         f"objective and by sweep --param weight only, not by {args.command}"
                         + (f" --objective {args.objective}" if args.command in ("check", "run")
                            else "") + f"; --type NAME runs {args.command} on one type's world")
    if world.types and getattr(args, "episode", None) is not None:
        from hg2prism.analyses.episodes import parse_episode_rule

        parse_episode_rule(args.episode)      # a bad rule is said as such first
        raise InputError(COMMAND_LINE, "--episode", "a world with P2's types draws the episode "
                         "of adaptive_belief.png with --seed (its type too, from the prior); "
                         "--episode picks the figures' episode of a world with one [inference]")
    if getattr(args, "prism_pomdp", False) and not world.types:
        raise InputError(COMMAND_LINE, "--prism-pomdp", "PRISM's POMDP engine runs on the "
                         "POMDP form of a world with P2's types ([[type]], docs/semantics.md "
                         "§16); this world has one [inference]")
    if command.alone is not None:
        return command.alone(args, world)
    out = _out_dir(Path(args.world), args.out)
    if typed is not None and args.out is None:
        out = out.with_name(f"{out.name}_type{typed}")     # models/world4_type1/
    if args.max_states is not None and args.max_states < 1:
        raise InputError(COMMAND_LINE, "--max-states", "must be at least 1")
    command.guard(args, world)
    check_writable(out)
    command.options(args, world)
    with command_stage(args.command, out, world) as stage:
        outcome = command.act(args, world, stage)
        files = sorted(p.name for p in stage.iterdir())
    print(tables.summary(outcome.results, out, files) if outcome.results is not None
          else tables.written(out, files))
    if outcome.table:
        print()
        print(outcome.table)
    for point in outcome.failed:     # the other points' outputs are written; these have none
        from hg2prism.experiments.sweep import point_label

        where = point_label({k: v for k, v in point.items() if k != "error"})
        print(f"hg2prism: error: {args.world}: sweep point {where}: {point['error']}",
              file=sys.stderr)
    return 1 if outcome.failed else 0
