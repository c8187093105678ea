"""Parameter sweeps (the paper's Fig. 4): the world re-solved for each value of one parameter.

:func:`sweep` re-solves the world for each value of one parameter (``delay``, ``window``,
``threshold`` or ``rationality``) and records the deceptive value, V_lead and V_NE at the
initial state (docs/semantics.md §§6–7). Writes ``OUT/sweep.json``, ``OUT/sweep.csv``, ``OUT/sweep.png``;
each value's model, strategy and results stay in ``OUT/<parameter>_<value>/``.

Sweeping ``delay`` needs the traps standing at the start when the delay is positive
(docs/semantics.md §2). The rule: the world's own ``initial_traps`` when it has them (a world loaded with
delay > 0); otherwise the ``[adversary] initial_traps`` written in the world file (the loader
drops them when delay = 0; here they are checked as if delay were positive, and an empty list
counts as none); otherwise the first ``traps`` trap candidates in map reading order. A delay of
0 has no initial traps.
"""

from __future__ import annotations

import csv
import io
import math
import sys
import time
import tomllib
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from hg2prism.errors import InputError
from hg2prism.model.world import Cell, World, prior_argmax, uniform_prior
from hg2prism import progress
from hg2prism.outputs import write_json, write_text
from hg2prism.results import Parameters

__all__ = ["SWEEP_PARAMETERS", "parse_sweep_values", "sweep_world", "delay_initial_traps", "sweep",
           "sweep_summary_lines"]

# parameter -> (type, minimum, minimum is exclusive, what is expected)
SWEEP_PARAMETERS: dict[str, tuple[type, float, bool, str]] = {
    "delay": (int, 0, False, "an integer >= 0"),
    "window": (int, 1, False, "an integer >= 1"),
    "threshold": (float, 0.0, True, "a number > 0"),
    "rationality": (float, 0.0, True, "a number > 0"),
    # P2's observer (docs/semantics.md §12) and the Bayesian observer's prior
    "inference": (str, 0, False, '"cusum" or "bayes"'),
    "prior": (tuple, 0, False, "comma-separated positive numbers, one per hypothesis"),
}

_CLI = "command line"


# ---------------------------------------------------------------------------------------------
# Sweep
# ---------------------------------------------------------------------------------------------

def _parse_value(parameter: str, value: object) -> int | float | str | tuple[float, ...]:
    kind, minimum, exclusive, expected = SWEEP_PARAMETERS[parameter]
    shown = repr(value) if not isinstance(value, str) else value
    if kind is str:
        if value not in ("cusum", "bayes"):
            raise InputError(_CLI, "--values", f"{parameter} value {shown!r} must be {expected}")
        return value
    if kind is tuple:
        from hg2prism.model.world import normalise_prior

        parts = value.split(",") if isinstance(value, str) else value
        try:
            numbers = [float(p) for p in parts]
        except (TypeError, ValueError):
            raise InputError(_CLI, "--values", f"prior {shown!r} must be {expected}") from None
        if not numbers or not all(math.isfinite(p) and p > 0 for p in numbers):
            raise InputError(_CLI, "--values", f"prior {shown!r} must be {expected}")
        try:
            return normalise_prior(numbers)
        except ValueError as err:
            raise InputError(_CLI, "--values", f"prior {shown!r}: {err}") from None
    if isinstance(value, bool):
        raise InputError(_CLI, "--values", f"{parameter} value {shown} must be {expected}")
    number: float
    if isinstance(value, (int, float)):
        number = value
    elif isinstance(value, str):
        text = value.strip()
        try:
            number = int(text) if kind is int else float(text)
        except ValueError:
            raise InputError(_CLI, "--values",
                             f"{parameter} value {shown!r} is not {expected}") from None
    else:
        raise InputError(_CLI, "--values", f"{parameter} value {shown} must be {expected}")
    if kind is int:
        if isinstance(number, float):
            raise InputError(_CLI, "--values", f"{parameter} value {shown} must be {expected}")
        number = int(number)
    else:
        number = float(number)
        if not math.isfinite(number):
            raise InputError(_CLI, "--values", f"{parameter} value {shown} must be {expected}")
    if number < minimum or (exclusive and number == minimum):
        raise InputError(_CLI, "--values", f"{parameter} value {shown} must be {expected}")
    return number


def parse_sweep_values(parameter: str, values: Sequence[object]) -> list[int | float]:
    """Validate a sweep: a known parameter and a non-empty list of distinct valid values
    (strings as typed on the command line are parsed). Raises InputError (key --param or
    --values)."""
    if parameter not in SWEEP_PARAMETERS:
        raise InputError(_CLI, "--param", f"unknown parameter {parameter!r}; expected one of "
                                          + ", ".join(SWEEP_PARAMETERS))
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or not values:
        raise InputError(_CLI, "--values", f"expected at least one value of {parameter} "
                                           f"({SWEEP_PARAMETERS[parameter][3]})")
    parsed = [_parse_value(parameter, v) for v in values]
    for i, v in enumerate(parsed):
        if v in parsed[:i]:
            raise InputError(_CLI, "--values", f"{parameter} value {v} is repeated; expected "
                                               "distinct values")
    return parsed


def _file_initial_traps(world: World) -> tuple[Cell, ...] | None:
    """The `[adversary] initial_traps` of the world file, checked as if delay > 0; None when the
    file has none, an empty list, or cannot be read any more."""
    try:
        with open(world.path, "rb") as handle:
            data = tomllib.load(handle)
    except (OSError, tomllib.TOMLDecodeError):
        return None
    adversary = data.get("adversary")
    if not isinstance(adversary, dict) or "initial_traps" not in adversary:
        return None
    key = "adversary.initial_traps"
    value = adversary["initial_traps"]
    if value == []:          # what a delay-0 world writes: nothing given, so the rule goes on
        return None
    numbering = {cell: n for n, cell in enumerate(world.grid.trap_candidates)}
    cells: list[Cell] = []
    if isinstance(value, list):
        for item in value:
            if (isinstance(item, list) and len(item) == 2
                    and all(isinstance(c, int) and not isinstance(c, bool) for c in item)):
                cells.append((item[0], item[1]))
            else:
                cells = []
                break
        else:
            if (len(cells) == world.traps and len(set(cells)) == len(cells)
                    and all(c in numbering for c in cells)):
                return tuple(sorted(cells, key=numbering.__getitem__))
    candidates = ", ".join(f"[{x}, {y}]" for x, y in world.grid.trap_candidates)
    raise InputError(str(world.path), key,
                     f"sweeping delay > 0 needs initial_traps to be {world.traps} distinct trap "
                     f"candidate cells (candidates are {candidates}), got {value!r}")


def delay_initial_traps(world: World) -> tuple[Cell, ...]:
    """The traps standing at the start when the world is re-solved with a positive delay (the
    rule in the module docstring)."""
    if world.initial_traps:
        return tuple(world.initial_traps)
    from_file = _file_initial_traps(world)
    if from_file is not None:
        return from_file
    return tuple(world.grid.trap_candidates[:world.traps])


def sweep_world(world: World, parameter: str, value: object) -> World:
    """The world with one parameter replaced (validated as in :func:`parse_sweep_values`)."""
    (value,) = parse_sweep_values(parameter, [value])
    if parameter == "delay":
        traps = delay_initial_traps(world) if value > 0 else ()
        return replace(world, delay=value, initial_traps=traps)
    if parameter == "threshold" and world.inference == "bayes":
        raise InputError(_CLI, "--param", "the Bayesian observer has no threshold")
    if parameter == "prior":
        if world.inference != "bayes":
            raise InputError(_CLI, "--param", 'sweeping prior needs [inference] kind = "bayes"')
        if len(value) != len(world.hypotheses):
            raise InputError(_CLI, "--values", f"prior {_value_text(value)} has {len(value)} "
                             f"numbers; expected one per hypothesis ({len(world.hypotheses)})")
        return replace(world, prior=value, initial_hypothesis=prior_argmax(value))
    if parameter == "inference":
        return _with_observer(world, value)
    return replace(world, **{parameter: value})


def _with_observer(world: World, kind: str) -> World:
    """The world with P2's observer switched. To "bayes": a uniform prior and the "map"
    decision, window and rationality kept (so P2's first guess is hypothesis 0). To "cusum":
    the world's threshold and initial hypothesis, which a Bayesian world does not have."""
    if kind == world.inference:
        return world
    if kind == "bayes":
        prior = uniform_prior(len(world.hypotheses))
        return replace(world, inference="bayes", threshold=None, prior=prior, decision="map",
                       initial_hypothesis=prior_argmax(prior))
    raise InputError(_CLI, "--values", "switching a Bayesian world to cusum needs a threshold; "
                                       "sweep inference from a cusum world")


def _value_text(value: int | float | str | tuple[float, ...]) -> str:
    """A swept value in folder names and tables: integers plain, numbers in %g form, a prior
    as its %g numbers joined by commas."""
    if isinstance(value, tuple):
        return ",".join(f"{p:g}" for p in value)
    if isinstance(value, str):
        return value
    return str(value) if isinstance(value, int) else f"{value:g}"


def _bar(done: int, total: int, width: int = 20) -> str:
    filled = int(round(width * done / max(total, 1)))
    return "#" * filled + "." * (width - filled)


_CSV_COLUMNS = ("deceptive_value", "v_lead", "v_ne", "v_ne_p1_guaranteed", "states",
                "transitions", "storm_states", "storm_transitions", "seconds")


def results_sound(storm_method: str) -> bool:
    """Whether values from `storm_method` are certified (docs/semantics.md §10)."""
    from hg2prism.engines.storm import SOUND_METHODS

    return storm_method in SOUND_METHODS


def sweep(world: World, parameter: str, values: Sequence[object], out: Path,
          show_progress: bool = True, storm_method: str = "sound") -> list[dict]:
    """Solve the world for each value of `parameter` and record the values at the initial
    state: ``{parameter: value, deceptive_value, v_lead, v_ne, v_ne_p1_guaranteed, states,
    transitions, storm_states, storm_transitions, initial_traps, seconds}`` per value.

    Each value is checked into ``out/<parameter>_<value>/`` (hypergame.prism, strategy.json,
    results.json); ``out/sweep.json``, ``out/sweep.csv`` and ``out/sweep.png`` summarise them.
    Progress: one line per value on stderr (the stages' own messages are not shown).
    """
    from hg2prism import pipeline
    from hg2prism.analyses import baselines
    from hg2prism.report import plots

    parsed = parse_sweep_values(parameter, values)
    worlds = [sweep_world(world, parameter, v) for v in parsed]   # all errors before any work
    out = Path(out)
    rows: list[dict] = []
    total_start = time.perf_counter()
    for i, (value, w) in enumerate(zip(parsed, worlds), start=1):
        label = f"sweep {parameter}={_value_text(value)} ({i}/{len(parsed)}) [{_bar(i - 1, len(parsed))}]"
        live = show_progress and sys.stderr.isatty()
        if live:
            sys.stderr.write(label + " ...")
            sys.stderr.flush()
        start = time.perf_counter()
        finished = False
        try:
            with progress.quiet():     # one line per value, not every stage's
                checked = pipeline.check(w, out / f"{parameter}_{_value_text(value)}", storm_method)
                nash = baselines.nash_baseline(checked.analysis.ts, checked.analysis.task)
            finished = True
        finally:
            if live and not finished:
                sys.stderr.write(" failed\n")
                sys.stderr.flush()
        seconds = time.perf_counter() - start
        results = checked.results
        row = {
            parameter: list(value) if isinstance(value, tuple) else value,
            "deceptive_value": results.deceptive_value,
            "v_lead": results.v_lead,
            "v_ne": nash.v_ne,
            "v_ne_p1_guaranteed": nash.v_ne_p1_guaranteed,
            "v_ne_bounds": list(nash.v_ne_bounds),
            "states": results.states,
            "transitions": results.transitions,
            "storm_states": results.storm_states,
            "storm_transitions": results.storm_transitions,
            "initial_traps": [list(c) for c in w.initial_traps],
            "seconds": round(seconds, 3),
        }
        rows.append(row)
        if show_progress:
            warn = (f"; warning: P1's Nash strategy guarantees only {nash.v_ne_p1_guaranteed:.4f}"
                    if nash.warn else "")
            sys.stderr.write(f"{chr(13) if live else ''}{label.rsplit(' [', 1)[0]} "
                             f"[{_bar(i, len(parsed))}]: deceptive "
                             f"{row['deceptive_value']:.4f}, V_lead {row['v_lead']:.4f}, V_NE "
                             f"{row['v_ne']:.4f}, {row['states']} states ({seconds:.1f} s){warn}\n")
            sys.stderr.flush()

    fixed = Parameters.of(world).to_json()
    fixed.pop(parameter, None)
    summary = {
        "world": world.name,
        "world_file": str(world.path),
        "parameter": parameter,
        "values": [list(v) if isinstance(v, tuple) else v for v in parsed],
        "fixed_parameters": fixed,
        "storm_method": storm_method,
        "sound": results_sound(storm_method),
        "initial_traps_rule": ("delay > 0: the world's initial_traps, else the file's "
                               "[adversary] initial_traps, else the first `traps` candidates"
                               if parameter == "delay" else None),
        "rows": rows,
        "seconds": round(time.perf_counter() - total_start, 3),
    }
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow((parameter,) + _CSV_COLUMNS)
    for row in rows:
        writer.writerow([_value_text(tuple(row[parameter])) if isinstance(row[parameter], list)
                         else row[parameter]] + [repr(row[c]) if isinstance(row[c], float) else row[c]
                                            for c in _CSV_COLUMNS])
    write_json(out / "sweep.json", summary)
    write_text(out / "sweep.csv", buffer.getvalue())
    plots.sweep_figure(parameter, rows, out / "sweep.png")
    return rows


def sweep_summary_lines(parameter: str, rows: Sequence[dict], world_name: str | None = None) -> list[str]:
    """The sweep as a Markdown table."""
    title = f"Completion probability at the initial state against {parameter}"
    if world_name:
        title += f" ({world_name})"
    lines = [title, "",
             f"| {parameter} | deceptive value | V_lead | V_NE | hypergame states | transitions |",
             "|---|---|---|---|---|---|"]
    for row in rows:
        value = tuple(row[parameter]) if isinstance(row[parameter], list) else row[parameter]
        lines.append(f"| {_value_text(value)} | {row['deceptive_value']:.4f} "
                     f"| {row['v_lead']:.4f} | {row['v_ne']:.4f} | {row['states']} "
                     f"| {row['transitions']} |")
    return lines
