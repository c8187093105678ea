"""Robust deception (docs/semantics.md §13): `hg2prism robust WORLD --deltas ...`.

For each deviation budget delta the world's interval model (hg2prism.prism.robust_model) is
rendered into ``OUT/robust_<delta>/robust.prism`` (with ``robust.props``), built by Storm and
solved exactly in numpy (hg2prism.strategy.robust). Per delta:

- ``robust_value``: R_delta at the initial state;
- ``nominal_worst_case``: what the deceptive strategy of docs/semantics.md §6 guarantees under the
  same budget (its records, and where they have none — states only a deviation reaches — the
  leader-game answer the simulations use, hg2prism.analyses.simulation.leader_fallback);
- ``robust_strategy_nominal_value``: what the robust strategy completes when P2 does not deviate
  (the deceptive value minus this is what robustness costs);
- the robust strategy, ``OUT/robust_<delta>/strategy.json`` (the format of strategy.json);
- cross-checks: Storm's robust mode and the same numpy solver on the model whose deviations
  have probability at least eps = 1e-9 (Storm needs positive lower bounds).

Writes ``OUT/robust.json``, ``OUT/robust.csv``, ``OUT/robust.png`` and ``OUT/robust.svg``.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hg2prism import progress
from hg2prism.engines import default
from hg2prism.engines.engine import ModelChecker
from hg2prism.errors import COMMAND_LINE, InputError, probability
from hg2prism.experiments.values import ValueList, number, parse_values
from hg2prism.numeric import choices_taking, first_index
from hg2prism.model.world import World
from hg2prism.outputs import write_bytes, write_csv, write_json
from hg2prism.strategy.policy import Policy
from hg2prism.results import provenance

if TYPE_CHECKING:
    from hg2prism.prism.hypergame import Layout
    from hg2prism.results import Analysis, CheckResult

__all__ = ["parse_deltas", "RobustSolved", "solve_budget", "solve_budgets", "robust_strategy_for",
           "robust", "robust_summary_lines"]

WORST_CASE_TOLERANCE = 1e-9    # the exported strategy must guarantee R_delta within this
_CSV_COLUMNS = ("robust_value", "nominal_worst_case", "robust_strategy_nominal_value", "states",
                "storm_states", "storm_robust_value_eps", "seconds")


# --deltas: distinct budgets in [0, 1)
DELTAS = ValueList("--deltas", "deviation budget", "in [0, 1)", number(float, 0.0, below=1.0),
                   empty="expected at least one {name} {expected}",
                   not_form="{value!r} is not a {name} {expected}",
                   outside="{value!r} is not a {name} {expected}",
                   not_finite="{value!r} is not a {name} {expected}",
                   repeated="{value} is repeated; expected distinct budgets")


def parse_deltas(values: Sequence[object]) -> list[float]:
    """Distinct budgets in [0, 1), as typed on the command line; InputError (key --deltas)."""
    return parse_values(DELTAS, values)


@dataclass(frozen=True, eq=False)
class RobustSolved:
    """One budget solved: the values, and what exporting and re-checking the strategy needs."""

    delta: float
    robust_value: float
    nominal_worst_case: float
    robust_strategy_nominal_value: float
    states: int                    # canonical hypergame states (goal and failure merged)
    storm_states: int              # the interval model's states (intermediate ones included)
    rounds: int
    residual: float
    records_json: bytes            # the robust strategy, strategy.json's text
    storm_check: dict | None       # Storm's robust mode on the eps-model, and numpy on it


def _nominal_game(game, action: np.ndarray):
    """The interval game with P2 following the prediction: the intervals of P1's choices (those
    with a move) become 1 for the predicted set (upper bound 1) and 0 for the others."""
    from hg2prism.strategy.robust import IntervalGame

    interval = action[game.branch_choice] >= 0
    fixed = np.where(game.upper >= 1.0, 1.0, 0.0)
    return IntervalGame.build(choice_start=game.choice_start, row_start=game.row_start,
                        target=game.target, lower=np.where(interval, fixed, game.lower),
                        upper=np.where(interval, fixed, game.upper), goal=game.goal,
                        stop=game.stop, initial=game.initial, chance=game.chance)


def _choices_of(game, action: np.ndarray, wanted: np.ndarray, decides: np.ndarray) -> np.ndarray:
    """The choice of every state: the one with move wanted[state] where P1 `decides`
    (numeric.choices_taking: the state's first where none is), the first (only) one in the
    intermediate states."""
    return np.where(decides, choices_taking(game.choice_state, action, wanted, game.n_states),
                    game.choice_start[:-1])


def _policy_choices(game, moves, decoded, canonical: np.ndarray, representative: np.ndarray,
                    decides: np.ndarray, ts, policy: Policy) -> np.ndarray:
    """The choice of every state of the interval model `game` when P1 plays `policy`: its move
    in the hypergame state of each canonical state (read off the representative's decoded
    state), and the one choice of the intermediate states (not `decides`)."""
    wanted = np.full(int(canonical.max()) + 1, -1, dtype=np.int64)
    rows = representative[~game.stop[representative]]
    for s, v, q, memory in zip(rows.tolist(), decoded.ts_states(ts, rows).tolist(),
                               decoded.q[rows].tolist(), decoded.memories(rows)):
        wanted[canonical[s]] = policy.action(v, q, memory)
    return _choices_of(game, moves.action, wanted[canonical], decides)


def _cross_check(engine: ModelChecker, prism_path: Path, layout: Layout, value: float) -> dict:
    """The interval model at `prism_path` (laid out as `layout`) with eps > 0
    (`CHECK_CONSTANTS`) checked by the engine's robust mode and by numpy, beside the exact
    value R_delta."""
    from hg2prism.prism.robust_model import (CHECK_CONSTANTS, CHECK_EPS, MOVE_VARIABLE,
                                             STORM_PROPERTY)
    from hg2prism.strategy.robust import IntervalGame, solve_robust

    progress.say("robust: cross-checking with the model checker's robust mode on the model "
                 f"with eps = {CHECK_EPS:g} (a value iteration, not sound, with a cap)")
    storm_value = engine.check_robust(prism_path, STORM_PROPERTY, CHECK_CONSTANTS)
    eps_model = engine.explicit(engine.build_interval(prism_path, CHECK_CONSTANTS)[0])
    eps_moves = eps_model.transitions
    eps_game = IntervalGame.of(eps_moves, eps_moves.labels["goal"], eps_moves.labels["fail"],
                               eps_model.initial, chance=eps_model.variable(
                                   MOVE_VARIABLE, layout.initial_value(MOVE_VARIABLE)) >= 0)
    numpy_value = solve_robust(eps_game).value(eps_game.initial)
    return {"storm_robust_value_eps": storm_value, "numpy_value_eps": numpy_value,
            "storm_minus_numpy": storm_value - numpy_value, "eps_minus_exact": numpy_value - value}


def solve_budget(analysis: Analysis, deceptive: Policy, prism_path: Path, layout: Layout,
                 delta: float, cross_check: bool = False,
                 engine: ModelChecker | None = None) -> RobustSolved:
    """Solve the interval model at `prism_path` (rendered for `delta`) with eps = 0, built by
    the model checker `engine` (default: Storm). `deceptive` is the deceptive strategy (a
    Policy: a records.Strategy with its fallback). With `cross_check`, the same model with
    eps > 0 is checked by the engine's robust mode and by numpy (at delta = 0, or where P2 has
    one set, min(eps, delta) leaves the model itself)."""
    from hg2prism.prism.decoding import decode_states, row_keys
    from hg2prism.strategy.deceptive import StormChoices
    from hg2prism.strategy.records import RecordExtras, strategy_json
    from hg2prism.strategy.robust import (IntervalGame, adversary_response, fastest_choices,
                                          move_values, solve_robust)
    from hg2prism.prism.robust_model import EXACT_CONSTANTS, MOVE_VARIABLE, PLAYED_VARIABLE

    engine = engine or default()
    ts, task = analysis.ts, analysis.task
    model = engine.explicit(engine.build_interval(prism_path, EXACT_CONSTANTS)[0])
    moves = model.transitions
    decoded = decode_states(model, layout, ts, task)
    def column(name: str) -> np.ndarray:
        return model.variable(name, layout.initial_value(name))

    decides = column(MOVE_VARIABLE) == -1
    game = IntervalGame.of(moves, decoded.goal, decoded.fail, model.initial, chance=~decides)
    solution = solve_robust(game)
    value = probability(solution.value(game.initial), f"R_{delta} at the initial state")

    # Canonical states: the hypergame state, and for intermediate states the move and set.
    canonical = row_keys(np.column_stack([
        decoded.canonical, column(MOVE_VARIABLE), column(PLAYED_VARIABLE)]))
    n_canonical = int(canonical.max()) + 1
    representative = first_index(canonical, n_canonical)[np.unique(canonical[decides])]
    states = int(len(representative))

    # The exported strategy: the fastest optimal move of each canonical state, for all copies.
    chosen = fastest_choices(game, solution, decides, moves.action)
    wanted = np.full(n_canonical, -1, dtype=np.int64)
    wanted[canonical[representative]] = moves.action[chosen[representative]]
    strategy = _choices_of(game, moves.action, wanted[canonical], decides)
    guaranteed = adversary_response(game, strategy)[game.initial]
    if guaranteed < value - WORST_CASE_TOLERANCE:
        # the fastest rule lost optimality somewhere: export strategy iteration's own choices
        progress.warn(f"delta {delta}: the fastest optimal moves guarantee {guaranteed:.10f} < "
                      f"R = {value:.10f}; exporting strategy iteration's moves")
        wanted[canonical[representative]] = moves.action[solution.strategy[representative]]
        strategy = _choices_of(game, moves.action, wanted[canonical], decides)
        guaranteed = adversary_response(game, strategy)[game.initial]
        if guaranteed < value - WORST_CASE_TOLERANCE:
            from hg2prism.errors import SolverError
            raise SolverError(f"delta {delta}: the robust strategy guarantees {guaranteed} < {value}")
    robust_nominal = adversary_response(_nominal_game(game, moves.action), strategy)[game.initial]
    worst_cases = np.full((n_canonical, ts.n_actions), np.nan)
    worst_cases[canonical[representative]] = move_values(game, solution, representative,
                                                         moves.action, ts.n_actions)
    records_json = strategy_json(
        replace(decoded, canonical=canonical, n_canonical=n_canonical),
        StormChoices(representative=representative, choice=strategy), moves, ts,
        RecordExtras(worst_cases), model.initial)

    # The deceptive strategy under the budget: its records, the leader answer elsewhere.
    nominal = _policy_choices(game, moves, decoded, canonical, representative, decides,
                              ts, deceptive)
    nominal_worst = adversary_response(game, nominal)[game.initial]

    check = _cross_check(engine, prism_path, layout, value) if cross_check else None
    return RobustSolved(
        delta=delta, robust_value=value,
        nominal_worst_case=probability(nominal_worst, "the deceptive strategy's worst case"),
        robust_strategy_nominal_value=probability(robust_nominal, "the robust strategy's value"),
        states=states, storm_states=int(model.n_states), rounds=solution.rounds,
        residual=solution.residual, records_json=records_json, storm_check=check)


def solve_budgets(world: World, check_result: CheckResult, deltas: Sequence[float], folder: Path,
                  storm_check: bool = True) -> list[tuple[RobustSolved, float]]:
    """Render and solve the interval model of every budget, each into
    ``folder/robust_<delta>/`` (robust.prism, robust.props): (solution, seconds) per budget.
    `check_result` is pipeline.check(world, ...). With `storm_check`, Storm's robust mode and
    numpy check the model with eps > 0 too (RobustSolved.storm_check), which needs every
    positive budget at least eps * (|A2| - 1) (InputError otherwise, before any work)."""
    from hg2prism.analyses.simulation import leader_fallback
    from hg2prism.prism.robust_model import (CHECK_EPS, build_robust_model, delta_text,
                                             write_robust_model)
    from hg2prism.strategy.records import Strategy

    if storm_check:
        _check_cross_checkable(world, list(deltas), CHECK_EPS)
    analysis = check_result.analysis
    deceptive = Strategy.from_records(check_result.records, analysis.ts,
                                      fallback=leader_fallback(analysis))
    solved = []
    for delta in deltas:
        start = time.perf_counter()
        model = build_robust_model(world, analysis.ts, analysis.task, analysis.games,
                                   analysis.inference, delta)
        prism_path, _ = write_robust_model(model, Path(folder) / f"robust_{delta_text(delta)}")
        result = solve_budget(analysis, deceptive, prism_path, model.prism.layout, delta,
                              storm_check, check_result.engine)
        solved.append((result, time.perf_counter() - start))
    return solved


def robust_strategy_for(world: World, check_result: CheckResult, delta: float, folder: Path
                        ) -> bytes:
    """The robust strategy's records (strategy.json's text) for one budget; the model is
    rendered below `folder`. `check_result` is pipeline.check(world, ...)."""
    ((solved, _),) = solve_budgets(world, check_result, [delta], folder, storm_check=False)
    return solved.records_json


def _check_cross_checkable(world: World, deltas: list[float], eps: float) -> None:
    """InputError (--deltas) for a positive budget too small for the cross-check's model, which
    gives each of P2's other sets at least `eps` out of the budget."""
    from hg2prism.opponent.observer import p2_action_count

    least = eps * (p2_action_count(world) - 1)
    for delta in deltas:
        if 0 < delta < least:
            raise InputError(COMMAND_LINE, "--deltas",
                             f"{delta:g} is below {least:g}, the least budget "
                             f"the cross-check's model can give each of P2's other sets "
                             f"eps = {eps:g}; use 0, a larger budget, or --no-cross-check")


def robust(world: World, deltas: Sequence[object], out: Path, show_progress: bool = True,
           check_result=None, cross_check: bool = True) -> dict:
    """Solve the world for every budget; write the outputs (module docstring) into `out` and
    return robust.json's content. `check_result` (pipeline.check of the world) is computed in a
    scratch folder when not given. Without `cross_check`, the eps-model is not built nor
    checked (`storm_check` null in every row): on mid-size worlds that check is most of the
    time."""
    from hg2prism import pipeline
    from hg2prism.prism.robust_model import CHECK_EPS, delta_text, refuse_drawing
    from hg2prism.report import plots

    parsed = parse_deltas(deltas)
    if cross_check:
        _check_cross_checkable(world, parsed, CHECK_EPS)
    out = Path(out)
    start_all = time.perf_counter()

    def say(message: str) -> None:
        if show_progress:
            progress.say(message)

    if check_result is None:
        with tempfile.TemporaryDirectory(prefix="hg2prism-robust-") as scratch, progress.quiet():
            check_result = pipeline.check(world, Path(scratch))
    refuse_drawing(world, check_result.analysis.inference)
    say(f"robust: {world.name}'s hypergame checked (deceptive value "
        f"{check_result.results.deceptive_value:.6f}, {time.perf_counter() - start_all:.1f} s)")
    rows = []
    for delta in parsed:
        say(f"robust: delta {delta:g}: building the interval model and solving it "
            "(P1's strategy iteration against the adversary's best resolution)")
        ((solved, seconds),) = solve_budgets(world, check_result, [delta], out,
                                             storm_check=cross_check)
        write_bytes(out / f"robust_{delta_text(delta)}" / "strategy.json", solved.records_json)
        rows.append({
            "delta": delta,
            "robust_value": solved.robust_value,
            "nominal_worst_case": solved.nominal_worst_case,
            "robust_strategy_nominal_value": solved.robust_strategy_nominal_value,
            "states": solved.states,
            "storm_states": solved.storm_states,
            "strategy_iteration_rounds": solved.rounds,
            "fixed_point_residual": solved.residual,
            "storm_check": solved.storm_check,
            "seconds": round(seconds, 3),
        })
        say(f"robust: delta {delta:g}: R = {solved.robust_value:.6f}, deceptive strategy's "
            f"worst case {solved.nominal_worst_case:.6f}, {solved.states} states "
            f"({seconds:.1f} s)")

    result = {
        **provenance(world, check_result.engine),
        "parameters": check_result.results.parameters.to_json(),
        "storm_method": check_result.results.storm_method, "sound": check_result.results.sound,
        "deceptive_value": check_result.results.deceptive_value,
        "v_lead": check_result.results.v_lead,
        "deltas": parsed,
        "method": ("robust values solved exactly in numpy on Storm's build of the interval model "
                   "(strategy iteration, adversary by policy iteration with sparse solves, "
                   "fixed point certified to 1e-10); storm_check: Storm's robust mode (not sound, "
                   "absolute precision 1e-10) and the same numpy solver on the model whose "
                   f"deviations have probability at least eps = {CHECK_EPS:g}"),
        "storm_check_eps": CHECK_EPS if cross_check else None,
        "rows": rows,
        "seconds": round(time.perf_counter() - start_all, 3),
    }
    write_json(out / "robust.json", result)
    write_csv(out / "robust.csv", ("delta",) + _CSV_COLUMNS, map(_csv_row, rows))
    plots.robust_figure(result, out / "robust.png")
    return result


def _csv_row(row: dict) -> list:
    """robust.csv's line of a robust.json row: delta, then _CSV_COLUMNS."""
    check = row["storm_check"] or {}
    values = {**row, "storm_robust_value_eps": check.get("storm_robust_value_eps", "")}
    return [row["delta"]] + [values[c] for c in _CSV_COLUMNS]


def robust_summary_lines(result: dict) -> list[str]:
    """What `hg2prism robust` prints: the robustness curve as a Markdown table."""
    lines = [
        f"Robust deception in {result['world']} (deceptive value "
        f"{result['deceptive_value']:.4f}, V_lead {result['v_lead']:.4f})",
        "",
        "| delta | robust value R_delta | deceptive strategy's worst case | robust strategy "
        "when P2 does not deviate | hypergame states |",
        "|---|---|---|---|---|",
    ]
    for row in result["rows"]:
        lines.append(f"| {row['delta']:g} | {row['robust_value']:.4f} "
                     f"| {row['nominal_worst_case']:.4f} "
                     f"| {row['robust_strategy_nominal_value']:.4f} | {row['states']} |")
    return lines
