"""Adaptive deception for a world with P2's types (docs/semantics.md §16): each type's ordinary
check (V_k and its deceptive strategy), the adaptive hypergame checked by the engine (V_adapt),
the committed strategies against the prior (V_commit(j)), and what adaptivity is worth.

Outputs in the output folder: `adaptive.prism`/`.props` (the adaptive hypergame, an MDP),
`adaptive_pomdp.prism` (the same problem with the type hidden), `strategy.json` (P1's adaptive
strategy: records with the consistent types, P1's belief and their memories), `results.json`,
`table.md`,
and per type a folder `type<k>/` with that type's ordinary check (hypergame.prism,
strategy.json, results.json ...).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from hg2prism.analyses.adaptive import CommittedPolicy, committed_game
from hg2prism.analyses.deception_value import induced_chain, value_difference
from hg2prism.analyses.simulation import leader_fallback
from hg2prism.analyses.successor import Hypergame
from hg2prism.engines import default as default_engine
from hg2prism.engines.engine import BuiltModel, ModelChecker
from hg2prism.errors import COMMAND_LINE, InputError, probability
from hg2prism.experiments.values import ValueList, number, parse_values
from hg2prism.model.world import World
from hg2prism.outputs import write_csv, write_json, write_text
from hg2prism.prism.adaptive import PRISM_RESOLUTION, TypeModel, build_adaptive_model
from hg2prism.prism.hypergame import PROPERTY
from hg2prism.progress import each_warning_once, say, warn
from hg2prism.results import CheckResult, provenance
from hg2prism.strategy.adaptive import AdaptiveStrategy, adaptive_strategy
from hg2prism.strategy.records import Strategy
from hg2prism.worldfile.types import world_of_type

__all__ = ["AdaptiveResult", "check_adaptive", "adaptivity_table"]


PRISM_SECONDS = 600
# PRISM's value iterations stop at a relative difference of 1e-6 (its default -epsilon; a
# smaller one did not finish within 5 minutes on world4)
PRISM_PRECISION = 1e-6
NOT_ASKED = "not run: not asked (hg2prism run/check --prism-pomdp)"
NOT_FOUND = ("not run: PRISM not found (set PRISM=/path/to/prism or put prism on the PATH)")


@dataclass(frozen=True, eq=False)
class AdaptiveResult:
    """What adaptive deception is worth for a world with types (results.json's content in
    `results`), with each type's check."""

    results: dict
    checks: tuple[CheckResult, ...]
    table: str
    built: BuiltModel | None = None            # the engine's adaptive model
    strategy: AdaptiveStrategy | None = None   # P1's adaptive strategy, the states decoded


def _committed(checks: list[CheckResult], weights: list[float]) -> list[list[float]]:
    """value[j][k]: type j's deceptive strategy when P2 is of type k; where the strategy has no
    record P1 plays the leader-game move of docs/semantics.md §11 (the naive answer to the
    action type j predicts, with its tie rules: `leader_fallback`, as detection does)."""
    games = [Hypergame(c.analysis.ts, c.analysis.task, c.analysis.games, c.analysis.inference)
             for c in checks]
    values = []
    for j, check in enumerate(checks):
        strategy = Strategy.from_records(check.records, check.analysis.ts,
                                         fallback=leader_fallback(check.analysis, games[j]))
        row = []
        for k in range(len(checks)):
            if weights[k] == 0:
                row.append(float("nan"))
                continue
            chain = induced_chain(committed_game(games[j], games[k]), CommittedPolicy(strategy))
            row.append(chain.value(f"V_commit({j}) against type {k}"))
        values.append(row)
    return values


def check_adaptive(world: World, out: Path, storm_method: str = "sound",
                   engine: ModelChecker | None = None, prism: bool | str = False,
                   simulation: tuple[int, int, int] | None = None,
                   prism_resolution: int = PRISM_RESOLUTION) -> AdaptiveResult:
    """Every value of docs/semantics.md §16 for `world` (which lists P2's types); with `prism`
    (True: the PRISM that find_prism finds; or the path of a PRISM executable) also PRISM's
    POMDP bounds on the POMDP form (grid resolution `prism_resolution`); with
    `simulation` (episodes, horizon, seed) the adaptive strategy's simulated episodes beside
    the exact within-horizon numbers. A warning each type's check gives alike is shown once."""
    with each_warning_once():
        return _check_adaptive(world, out, storm_method, engine, prism, simulation,
                               prism_resolution)


def _check_adaptive(world: World, out: Path, storm_method: str, engine: ModelChecker | None,
                    prism: bool | str, simulation: tuple[int, int, int] | None,
                    prism_resolution: int) -> AdaptiveResult:
    from hg2prism import pipeline

    engine = engine or default_engine()
    start = time.perf_counter()
    weights = [t.weight for t in world.types]
    checks = []
    for k, t in enumerate(world.types):
        say(f"adaptive: type {k} ({t.name}) alone")
        checks.append(pipeline.check(world_of_type(world, k), out / f"type{k}", storm_method,
                                     engine=engine))
    analysis = checks[0].analysis
    types = [TypeModel(t.name, t.weight, t.rationality, c.analysis.inference,
                       tuple(c.analysis.games)) for t, c in zip(world.types, checks)]
    model = build_adaptive_model(world, analysis.ts, analysis.task, types)
    write_text(out / "adaptive.prism", model.text)
    write_text(out / "adaptive.props", model.properties)
    pomdp = build_adaptive_model(world, analysis.ts, analysis.task, types, hidden=True)
    write_text(out / "adaptive_pomdp.prism", pomdp.text)
    checked = engine.check(out / "adaptive.prism", PROPERTY, storm_method,
                           alongside=lambda built: built)
    v_adapt = probability(checked.value, "V_adapt")
    strategy = adaptive_strategy(
        checked.alongside, checked.values, model, analysis.ts, analysis.task,
        [t.name for t in world.types], weights,
        [getattr(c.analysis.inference, "window_hypotheses", None) for c in checks])
    write_text(out / "strategy.json", "[\n" + ",\n".join(
        json.dumps(r, separators=(",", ":"), allow_nan=False) for r in strategy.records) + "\n]\n")
    v_types = [c.results.deceptive_value for c in checks]
    v_oracle = sum(w * v for w, v in zip(weights, v_types))
    against = _committed(checks, weights)
    v_commit = [sum(w * v for w, v in zip(weights, row) if w > 0) for row in against]
    best = max(v_commit)
    if v_adapt < best - 1e-6 or v_adapt > v_oracle + 1e-6:
        warn(f"V_adapt {v_adapt:.9f} is not between max V_commit {best:.9f} and V_oracle "
             f"{v_oracle:.9f}")
    results = {
        **provenance(world, engine), "v_adapt": v_adapt, "v_oracle": v_oracle, "max_v_commit": best,
        "value_of_adaptivity": value_difference(v_adapt, best),
        "cost_of_not_knowing": value_difference(v_oracle, v_adapt),
        "storm_method": storm_method, "sound": storm_method in engine.sound_methods,
        "states": strategy.size[0], "transitions": strategy.size[1],
        "storm_states": checked.size[0], "storm_transitions": checked.size[1],
        "storm_choices": checked.size[2], "model_commands": dict(model.commands),
        "types": [{"name": t.name, "weight": t.weight, "inference": t.inference,
                   "window": t.window, "rationality": t.rationality,
                   "initial_hypothesis": t.initial_hypothesis,
                   "settings": {key: list(v) if isinstance(v, tuple) else v
                                for key, v in t.settings},
                   "deceptive_value": v_types[k], "v_commit": v_commit[k],
                   "committed_against": {world.types[i].name: None if weights[i] == 0 else
                                         against[k][i] for i in range(len(weights))},
                   "folder": f"type{k}"}
                  for k, t in enumerate(world.types)],
        "timings": {"total": time.perf_counter() - start, **checked.timings},
    }
    results["pomdp"] = _pomdp(engine, out / "adaptive_pomdp.prism", v_adapt)
    results["prism_pomdp"] = prism_pomdp(prism, out / "adaptive_pomdp.prism", v_adapt,
                                         prism_resolution)
    if "prism_version" in results["prism_pomdp"]:      # which PRISM gave the bounds
        results["software"]["prism"] = results["prism_pomdp"].pop("prism_version")
    if simulation is not None:
        results["simulation"] = _simulation(checks, weights, world, strategy.records, out,
                                            *simulation)
    table = adaptivity_table(results)
    write_json(out / "results.json", results)
    write_text(out / "table.md", table + "\n")
    say(f"adaptive: V_adapt {v_adapt:.6f}, V_oracle {v_oracle:.6f}, max V_commit {best:.6f}")
    return AdaptiveResult(results, tuple(checks), table, checked.alongside, strategy)


def _simulation(checks: list[CheckResult], weights: list[float], world: World,
                records: list[dict], out: Path, episodes: int, horizon: int, seed: int) -> dict:
    """The adaptive strategy simulated (P2's type drawn per episode) and its exact numbers
    within the horizon: completion and identification of P2's type (docs/semantics.md §16);
    the figure of P1's belief along an episode drawn with `seed` (adaptive_belief.png)."""
    from statistics import median

    import numpy as np

    from hg2prism.analyses.adaptive import (AdaptiveGame, adaptive_chain, adaptive_policy,
                                            belief, play_episode, simulate_adaptive)
    from hg2prism.analyses.episodes import outcome_text
    from hg2prism.report.adaptive_plot import adaptive_belief_figure
    from hg2prism.analyses.simulation import TRUNCATED, warn_if_implausible, wilson_interval

    game = AdaptiveGame([Hypergame(c.analysis.ts, c.analysis.task, c.analysis.games,
                                   c.analysis.inference) for c in checks], weights)
    policy = adaptive_policy(records, game, [t.name for t in world.types])
    chain = adaptive_chain(game, policy)
    run = simulate_adaptive(game, policy, episodes, horizon, seed)
    for what, count, exact in (
            ("completion of the adaptive strategy", run.completed, chain.within(horizon)),
            ("identification of P2's type", run.identified, chain.identified_within(horizon)),
            ("identification of P2's type in play", run.identified_in_play,
             chain.identified_in_play_within(horizon))):
        warn_if_implausible(what, count, episodes, exact)
    rng = np.random.default_rng(seed)
    drawn = int(rng.choice(len(weights), p=np.array(weights) / sum(weights)))
    trace = play_episode(game, policy, drawn, horizon, rng)
    outcome = outcome_text(game.status(trace[-1]) if not game.running(trace[-1]) else TRUNCATED)
    adaptive_belief_figure(world.name, [t.name for t in world.types],
                           [belief(game, s) for s in trace], drawn, seed, outcome,
                           out / "adaptive_belief")
    return {
        "episodes": episodes, "horizon": horizon, "seed": seed,
        "completion_rate": run.completed / episodes,
        "completion_interval_95": list(wilson_interval(run.completed, episodes)),
        "exact_within_horizon": chain.within(horizon),
        "identified_share": run.identified / episodes,
        "identified_interval_95": list(wilson_interval(run.identified, episodes)),
        "identified_exact_within_horizon": chain.identified_within(horizon),
        "identified_in_play_share": run.identified_in_play / episodes,
        "identified_in_play_interval_95": list(wilson_interval(run.identified_in_play,
                                                               episodes)),
        "identified_in_play_exact_within_horizon": chain.identified_in_play_within(horizon),
        "median_identification_step": (median(run.identification_steps)
                                       if run.identification_steps else None),
        "by_type": {t.name: {"episodes": n, "completed": c}
                    for t, (n, c) in zip(world.types, run.by_type)},
        "drawn_episode": {"seed": seed, "type": world.types[drawn].name, "steps": len(trace) - 1,
                          "outcome": outcome},
    }


# Storm's belief exploration of the POMDP form stops after this many seconds (then it is
# reported as not complete).
POMDP_SECONDS = 120


def _pomdp(engine: ModelChecker, path: Path, v_adapt: float) -> dict | None:
    """Storm's POMDP engine on the POMDP form (docs/semantics.md §16): its value, whether its
    belief exploration completed, and whether the value is in [0, 1] and equals V_adapt
    within 1e-6; None when the engine has no POMDP method."""
    check = getattr(engine, "check_pomdp", None)
    if check is None:
        return None
    found = check(path, PROPERTY, POMDP_SECONDS)
    in_range = 0.0 <= found.value <= 1.0
    agrees = found.completed and in_range and abs(found.value - v_adapt) <= 1e-6
    if not found.completed:
        warn(f"Storm's POMDP engine: the belief exploration did not complete within "
             f"{POMDP_SECONDS} s; its value {found.value:.9f} is only a lower bound of V_adapt")
    elif not agrees:
        warn(f"Storm's POMDP engine gives {found.value:.9f}, V_adapt is {v_adapt:.9f}")
    return {"value": found.value, "completed_exploration": found.completed,
            "in_range": in_range, "equals_v_adapt": agrees, "states": found.states,
            "observations": found.observations, "seconds": found.seconds}


def find_prism() -> str | None:
    """The PRISM executable: $PRISM, else `prism` on the PATH; None when there is none."""
    import os
    import shutil

    return os.environ.get("PRISM") or shutil.which("prism")


def prism_pomdp(asked: bool | str, path: Path, v_adapt: float,
                resolution: int = PRISM_RESOLUTION, seconds: int = PRISM_SECONDS) -> dict:
    """results.json's `prism_pomdp`: PRISM's POMDP engine on the POMDP form when `asked` (True:
    the PRISM find_prism finds; a string: that executable), its bounds and whether they
    bracket V_adapt, or why it was not run."""
    if not asked:
        return {"status": NOT_ASKED}
    import shutil

    prism = asked if isinstance(asked, str) else find_prism()
    if prism is None or shutil.which(prism) is None:
        status = NOT_FOUND if prism is None else NOT_FOUND.replace(
            "not found", f"not found: {prism} is not an executable", 1)
        warn("PRISM's POMDP engine: " + status)
        return {"status": status}
    found = prism_pomdp_bounds(prism, path, seconds, resolution)
    if "error" in found:
        warn(f"PRISM's POMDP engine: {found['error']}")
        return {"status": f"error: {found['error']}", "resolution": resolution}
    lower, upper = found["lower"], found["upper"]
    outside = max(lower - v_adapt, v_adapt - upper, 0.0)
    precise = outside <= PRISM_PRECISION * v_adapt
    # PRISM's two value iterations stop at a relative 1e-6 each: its "lower" bound may come out
    # above its "upper" one, which is then no bracket at all
    inverted = lower > upper
    if not precise or inverted:
        why = [f"outside by {outside:.2g}, beyond PRISM's relative {PRISM_PRECISION:g}"] * (
            not precise) + [f"its lower bound above its upper one by {lower - upper:.2g}"] * inverted
        warn(f"PRISM's POMDP bounds [{lower:.9f}, {upper:.9f}] do not hold V_adapt "
             f"{v_adapt:.9f} ({'; '.join(why)}: its bounds are not certified)")
    return {"status": "run", "lower": lower, "upper": upper, "brackets_v_adapt": outside == 0,
            "inverted": inverted, "outside_by": outside, "within_prism_precision": precise,
            "resolution": resolution, "seconds": found["seconds"],
            **({"prism_version": found["version"]} if found.get("version") else {})}


def prism_pomdp_bounds(prism: str, path: Path, seconds: int = PRISM_SECONDS,
                       resolution: int = PRISM_RESOLUTION) -> dict:
    """PRISM's POMDP engine (its fixed-resolution grid approximation) on the POMDP form: the
    bounds it reports on Pmax ("Result bounds: [lower,upper]") and its time, or the error it
    gave. PRISM's bounds come from value iterations stopped at a relative 1e-6: not
    certified. A progress line every 30 s while it runs."""
    import re
    import subprocess

    start = time.perf_counter()
    say(f"adaptive: PRISM's POMDP engine on {path.name} (grid resolution {resolution}; "
        f"at most {seconds} s)")
    try:
        process = subprocess.Popen([prism, str(path), "-pf", PROPERTY, "-gridresolution",
                                    str(resolution)], stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True)
    except OSError as err:
        return {"error": str(err).splitlines()[0]}
    while True:
        elapsed = time.perf_counter() - start
        try:
            stdout, stderr = process.communicate(timeout=max(0.1, min(30.0, seconds - elapsed)))
            break
        except subprocess.TimeoutExpired:
            if time.perf_counter() - start >= seconds:
                process.kill()
                process.communicate()
                return {"error": f"PRISM did not finish within {seconds} s"}
            say(f"adaptive: PRISM's POMDP engine still running ({time.perf_counter() - start:.0f} s)")
    found = re.search(r"Result bounds: \[([-0-9.eE]+),\s*([-0-9.eE]+)\]", stdout)
    if found is None:
        lines = [ln for ln in stdout.splitlines() + stderr.splitlines()
                 if "rror" in ln] or ["no bounds in PRISM's output"]
        return {"error": lines[0].strip()}
    title = stdout.lstrip().split("\n", 1)[0].strip()          # "PRISM-games" or "PRISM"
    version = re.search(r"^Version: (.+)$", stdout, re.M)
    return {"lower": float(found[1]), "upper": float(found[2]),
            "seconds": time.perf_counter() - start,
            "version": f"{title} {version[1].strip()}" if version else None}


def adaptivity_table(results: dict) -> str:
    """The values of §16 as a markdown table: a row per type, then the adaptive strategy."""
    lines = [f"Adaptive deception in {results['world']} (docs/semantics.md §16)", "",
             "| strategy | against | value |", "|---|---|---|"]
    for t in results["types"]:
        name = _cell(t["name"])
        lines.append(f"| type {name}'s deceptive strategy | type {name} "
                     f"(weight {t['weight']:.4g}) | V_k = {t['deceptive_value']:.6f} |")
    for t in results["types"]:
        lines.append(f"| committed to type {_cell(t['name'])} | the prior | V_commit = "
                     f"{t['v_commit']:.6f} |")
    lines += [f"| adaptive | the prior | V_adapt = {results['v_adapt']:.6f} |",
              f"| oracle (knows the type) | the prior | V_oracle = {results['v_oracle']:.6f} |",
              *_pomdp_rows(results.get("pomdp"), results.get("prism_pomdp")),
              *_simulation_rows(results.get("simulation")),
              "", f"value of adaptivity (V_adapt - max V_commit): "
                  f"{_difference(results['value_of_adaptivity'])}",
              f"cost of not knowing (V_oracle - V_adapt): "
              f"{_difference(results['cost_of_not_knowing'])}"]
    return "\n".join(lines)


def _in_play_row(sim: dict) -> list[str]:
    """The identification row of the episodes that went on after it (results of an older
    version have none)."""
    if "identified_in_play_share" not in sim:
        return []
    low, high = sim["identified_in_play_interval_95"]
    return [f"| ... with the episode going on (P1 acts on it) | "
            f"{sim['identified_in_play_share']:.4f} | [{low:.4f}, {high:.4f}] | "
            f"{sim['identified_in_play_exact_within_horizon']:.6f} |"]


def _cell(text: str) -> str:
    """A type's name in a markdown table cell: `\\` and `|` escaped, so that it does not end
    the cell."""
    return text.replace("\\", "\\\\").replace("|", "\\|")


def _difference(value: float) -> str:
    """A difference of two values to 6 decimals; one that rounds to zero is 0.000000, not the
    -0.000000 of a rounding-level negative (V_adapt 0.7999999999999999 against 0.8)."""
    text = f"{value:.6f}"
    return "0.000000" if float(text) == 0.0 else text


def _prism_row(prism: dict | None) -> list[str]:
    """PRISM's POMDP bounds as a row of the table, or why they are not there."""
    if prism is None:
        return []
    if prism["status"] != "run":
        return [f"| adaptive, POMDP form (PRISM, grid approximation) | the prior | "
                f"{prism['status']} |"]
    held = ("hold V_adapt" if prism["brackets_v_adapt"] else
            f"V_adapt outside by {prism['outside_by']:.2g}, "
            + ("within PRISM's precision" if prism["within_prism_precision"]
               else "beyond PRISM's precision: not certified"))
    return [f"| adaptive, POMDP form (PRISM, grid resolution {prism['resolution']}) "
            f"| the prior | [{prism['lower']:.6f}, "
            f"{prism['upper']:.6f}] ({held}) |"]


def _pomdp_rows(pomdp: dict | None, prism: dict | None = None) -> list[str]:
    rows = _prism_row(prism)
    if pomdp is None:
        return rows
    how = ("exploration complete" if pomdp["completed_exploration"]
           else "exploration NOT complete: a lower bound")
    if not pomdp["in_range"]:
        how += "; OUTSIDE [0, 1]"
    return [f"| adaptive, POMDP form (Storm, belief unfolding; {how}) | the prior | "
            f"{pomdp['value']:.6f} |"] + rows


def _simulation_rows(sim: dict | None) -> list[str]:
    if sim is None:
        return []
    low, high = sim["completion_interval_95"]
    i_low, i_high = sim["identified_interval_95"]
    median = sim["median_identification_step"]
    return ["", f"Adaptive strategy simulated ({sim['episodes']} episodes, horizon "
                f"{sim['horizon']}, P2's type drawn from the prior):", "",
            "| | simulated | 95 % interval | exact within horizon |", "|---|---|---|---|",
            f"| completion | {sim['completion_rate']:.4f} | [{low:.4f}, {high:.4f}] | "
            f"{sim['exact_within_horizon']:.6f} |",
            f"| P1's belief singles out P2's type | {sim['identified_share']:.4f} | "
            f"[{i_low:.4f}, {i_high:.4f}] | {sim['identified_exact_within_horizon']:.6f} |",
            *_in_play_row(sim),
            "", "median step of identification: "
                + ("never" if median is None else f"{median:g}")]


# ---------------------------------------------------------------------------------------------
# Sweeping the prior: `hg2prism sweep --param weight` on a world with types
# ---------------------------------------------------------------------------------------------

def with_first_weight(world: World, weight: float) -> World:
    """The world whose first type has prior `weight` (in [0, 1]) and the others share 1 - weight
    in the proportions of their weights (equally when theirs are all 0)."""
    from dataclasses import replace

    rest = world.types[1:]
    total = sum(t.weight for t in rest)
    shares = ([t.weight / total for t in rest] if total > 0 else [1.0 / len(rest)] * len(rest))
    types = (replace(world.types[0], weight=weight),) + tuple(
        replace(t, weight=(1.0 - weight) * s) for t, s in zip(rest, shares))
    return replace(world, types=types)


# --values of --param weight: numbers in [0, 1]
WEIGHTS = ValueList("--values", "weight", "a number in [0, 1]",
                    number(float, 0.0, maximum=1.0),
                    not_form="a {name} is {expected}, got {value!r}",
                    outside="a {name} is {expected}, got {value!r}", repeated=None)


def parse_weights(values: list[str]) -> list[float]:
    """--values of --param weight: numbers in [0, 1]."""
    return parse_values(WEIGHTS, values)


def check_weights(world: World, values: list[str], max_states: int | None = None
                  ) -> list[float]:
    """Everything a weight sweep checks before solving: the weights (`parse_weights`) and the
    size guard over them, which refuses the sweep only when it refuses every weight."""
    from hg2prism.experiments.sweep import guard_points

    weights = parse_weights(values)
    guard_points(world, [{"weight": weight} for weight in weights], max_states, at=_at_weight)
    return weights


def sweep_weights(world: World, weights: list[float], out: Path,
                  storm_method: str = "sound", *, show_progress: bool = True, workers: int = 1,
                  scheduler: str | None = None, max_states: int | None = None
                  ) -> tuple[list[str], tuple[dict, ...]]:
    """V_adapt, V_oracle and every V_commit against the first type's prior weight: sweep.json,
    sweep.csv, sweep.{png,svg}. The weights are points of a sweep, run by its driver
    (experiments/sweep.py:run_points: serially or on Dask, a progress line per weight, the size
    guard with `max_states`); a weight whose solve fails is recorded under `failed` (its weight
    and the one-line error) and the others go on. Returns the summary table's lines and the
    failed points."""
    from hg2prism.experiments import sweep
    from hg2prism.report.adaptive_plot import weight_sweep_figure

    if workers < 1:
        raise InputError(COMMAND_LINE, "--workers", f"must be at least 1, got {workers}")
    if not weights:
        raise InputError(COMMAND_LINE, "--values", "no weight given")
    names = [t.name for t in world.types]
    start = time.perf_counter()
    points = [{"weight": weight} for weight in weights]
    sweep.guard_points(world, points, max_states, at=_at_weight)
    serial = workers == 1 and scheduler is None
    tasks = sweep.point_tasks(world, points, storm_method, max_states, at=_at_weight,
                              solver=weight_point,
                              observer_kinds=() if serial else sweep.observer_kinds(world, points))
    with each_warning_once():
        rows, failed = sweep.run_points(tasks, out, show_progress, workers, scheduler,
                                        _weight_line)
    write_json(out / "sweep.json", {
        **provenance(world), "parameter": "weight",
        "values": weights, "parameters": ["weight"], "type": names[0],
        "storm_method": storm_method, "sound": sweep.results_sound(storm_method),
        "rows": list(rows), "failed": list(failed),
        "seconds": round(time.perf_counter() - start, 3)})
    write_csv(out / "sweep.csv",
              ["weight", "v_adapt", "v_oracle"] + [f"v_commit_{n}" for n in names],
              ([row["weight"], row["v_adapt"], row["v_oracle"], *row["v_commit"].values()]
               for row in rows))
    if rows:
        weight_sweep_figure(world.name, names, list(rows), out / "sweep")
    table = [f"{world.name}: adaptive deception against the prior weight of {names[0]}", "",
             "| weight | V_adapt | V_oracle | " + " | ".join(f"V_commit({n})" for n in names)
             + " |", "|---" * (3 + len(names)) + "|"]
    for row in rows:
        table.append(f"| {row['weight']:g} | {row['v_adapt']:.6f} | {row['v_oracle']:.6f} | "
                     + " | ".join(f"{v:.6f}" for v in row["v_commit"].values()) + " |")
    return table, failed


def _at_weight(world: World, point: dict) -> World:
    """A point of the weight sweep: the world with its first type's prior weight."""
    return with_first_weight(world, point["weight"])


def weight_point(world: World, task):
    """One weight of the sweep, where it runs (this process or a Dask worker): adaptive
    deception checked in a scratch folder, its values (no files: the weight sweep writes
    none per point)."""
    import tempfile

    from hg2prism.experiments.sweep import Solved

    with tempfile.TemporaryDirectory(prefix="hg2prism-weight-") as scratch:
        r = check_adaptive(world, Path(scratch) / "point", task.storm_method).results
    return Solved({"v_adapt": r["v_adapt"], "v_oracle": r["v_oracle"],
                   "v_commit": {t["name"]: t["v_commit"] for t in r["types"]},
                   "value_of_adaptivity": r["value_of_adaptivity"],
                   "cost_of_not_knowing": r["cost_of_not_knowing"]})


def _weight_line(row: dict) -> str:
    """A weight's progress line, after the weight and the count."""
    return (f"V_adapt {row['v_adapt']:.4f}, V_oracle {row['v_oracle']:.4f}, "
            + ", ".join(f"V_commit({name}) {v:.4f}" for name, v in row["v_commit"].items()))
