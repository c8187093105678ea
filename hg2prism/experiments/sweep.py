"""Parameter sweeps (the paper's Fig. 4): the world re-solved at every point of a parameter grid.

:func:`sweep_grid` re-solves the world at every point of the cartesian product of one or more
parameters' values (the table :func:`sweep_parameters`, as the observer and front-end
registries stand: ``delay``, ``window``, ``threshold``, ``rationality``, ``traps``, ``prior``,
``decision``, ``initial_hypothesis``, ``inference`` and each front end's own) and records the deceptive value, V_lead and V_NE at the initial state
(docs/semantics.md §§6-7; the sweep itself: §7, Sweeps), with ``deception`` also V_static and
V_naive (§11). :func:`sweep` is the
one-parameter case. Writes ``OUT/sweep.json``, ``OUT/sweep.csv``, ``OUT/sweep.{png,svg}``; each
point's model, strategy and results stay in ``OUT/<parameter>_<value>/`` (one parameter) or
``OUT/<p1>_<v1>__<p2>_<v2>/`` (several).

The points run serially in this process (``workers=1``, the library's default) or on Dask
(``dask.distributed``): a LocalCluster of ``workers`` worker processes, or the cluster whose
scheduler is at ``scheduler``. Each point travels as the world file's text plus the fields the
point changes (:class:`PointTask`); the worker parses the text, solves, and sends back the
point's row and the bytes of its files, so that no stormpy object crosses processes and workers
need not share this machine's disk. Serial and Dask runs give the same rows in grid order.

A point that fails (the size guard, a solver or Storm error, a worker lost) is reported with its
parameters and the others go on; only when the size guard refuses every point is the sweep
refused as a whole, before anything is solved.

The action P2 has standing at the start when a point has a positive delay (docs/semantics.md §2
and §7, Sweeps): the world's own, `World.initial_standing`, which a world loaded with delay 0
keeps as its file's `[adversary] initial_traps` or `initial_action` names it (the first when it
names none; frontends.standing_candidates, frontends.standing_action). When ``traps`` is swept
to k, the standing set is the first k of those candidates (in candidate order), followed, when k
exceeds them, by the first other candidates in the arena's order. A delay of 0 has no standing
action (a point with delay 0 keeps it for a re-solve with delay). A point's row names it under
``standing`` (None when delay is 0).

A front end may add its own parameters (frontends.sweep_settings: the grid's robot); they are
refused, in one InputError line, on worlds of another kind. ``traps`` applies only when P2 sets
traps.
"""

from __future__ import annotations

import itertools
import math
import os
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from hg2prism.errors import COMMAND_LINE, InputError, MissingSetting
from hg2prism import frontends
from hg2prism.experiments.values import NOT_FORM, OUTSIDE, ValueList, number, parse_values
from hg2prism.frontends import arena_of
from hg2prism.model.world import World
from hg2prism.model.dynamics import carried_standing
from hg2prism.model.validation import TIE_BREAKS
from hg2prism.opponent.observer import ObserverKind
from hg2prism.opponent.registry import (KINDS, configure, observer_kind, owner, register,
                                        run_time_kinds)
from hg2prism import progress
from hg2prism.outputs import csv_text, write_bytes, write_json, write_text
from hg2prism.results import Parameters, provenance

__all__ = ["SweepParameter", "sweep_parameters", "owned_pattern", "parse_sweep_values",
           "parse_sweep_grid", "sweep_world", "sweep_point", "standing_at", "PointTask", "PointOutcome", "Solved", "solve_point", "check_point", "point_tasks", "run_points", "guard_points", "SweepRun", "sweep",
           "sweep_grid", "check_grid", "default_workers", "sweep_summary_lines", "point_label"]


Value = Any     # int | float today; a parameter's parser decides (e.g. a name, later)


# ---------------------------------------------------------------------------------------------
# The parameters: how each is parsed and how it rewrites the world
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SweepParameter:
    """One sweepable parameter. `parse` turns a value as given (a command-line string or a
    Python value) into the parameter's value, raising ValueError (experiments/values.py: NOT_FORM
    or OUTSIDE, the reason's words); `apply`
    returns the world with that value (InputError when the value does not fit this world);
    `moves_traps` says the standing traps must be worked out again (docs/semantics.md §7, Sweeps)."""

    name: str
    expected: str
    parse: Callable[[object], Value]
    apply: Callable[[World, Value], World]
    moves_traps: bool = False
    front_end: str | None = None    # a front end's own parameter: refused on other kinds
    observer: str | None = None     # the observer kind whose setting it is (the first's)

    def refuse_unless_applies(self, world: World) -> None:
        """InputError (one line) when this parameter does not apply to `world`."""
        kind = frontends.kind_of(world)
        if self.front_end is not None and self.front_end != kind:
            raise InputError(COMMAND_LINE, f"--param {self.name}", "applies to "
                             f"{frontends.kind_words(self.front_end, plural=True)} only; {world.name} is "
                             f"{frontends.kind_words(world)}")
        if self.name == "traps" and not arena_of(world).traps_mode:
            raise InputError(COMMAND_LINE, f"--param {self.name}",
                             f"applies to worlds whose P2 sets "
                             f"traps; {world.name} gives P2's actions ([adversary] actions)")


def _field(name: str) -> Callable[[World, Value], World]:
    return lambda world, value: replace(world, **{name: value})


def _observer_kind(value: object) -> str:
    if value not in KINDS:
        raise ValueError(OUTSIDE)
    return str(value)


def _tie_break(value: object) -> str:
    if value not in TIE_BREAKS:
        raise ValueError(OUTSIDE)
    return str(value)


def _numbers(normalise: Callable[[list[float]], object] | None) -> Callable[[object], object]:
    """A parser of positive numbers as typed (``0.5,0.25,0.25``) or given in Python (a
    sequence), then `normalise`d (a prior)."""
    def parse(value: object) -> object:
        parts = value.split(",") if isinstance(value, str) else value
        try:
            numbers = [float(p) for p in parts]           # type: ignore[union-attr]
        except (TypeError, ValueError):
            raise ValueError(NOT_FORM) from None
        if not numbers or not all(math.isfinite(p) and p > 0 for p in numbers):
            raise ValueError(OUTSIDE)
        return tuple(numbers) if normalise is None else normalise(numbers)
    return parse


def _with_observer(world: World, kind: str) -> World:
    """The world with P2's observer switched (docs/semantics.md §12), window and rationality
    kept, each of the new kind's settings at its default (to "bayes": a uniform prior and the
    "map" decision, so P2's first guess is hypothesis 0: the sweep warns where the world's was
    another, `_first_guess_notes`). Refused when the new kind has a required setting
    (switching to "cusum" needs a threshold)."""
    if kind == world.inference:
        return world
    try:
        switched = configure(world, kind)
    except MissingSetting as missing:
        raise InputError(COMMAND_LINE, "--values", f"switching a "
                         f"{observer_kind(world.inference).title} world to {kind} needs a "
                         f"{missing.setting}; sweep inference from a {kind} world") from None
    return switched


def _first_guess_notes(world: World, tasks: Sequence[PointTask]) -> None:
    """A warning for each point whose observer, swept, first guesses another hypothesis than
    the world's P2 (a uniform Bayesian prior first guesses x0: mir100's x1 became x0 without a
    word): the point compares first guesses as well as observers."""
    for task in tasks:
        assignment = dict(task.assignment)
        if "inference" not in assignment or "initial_hypothesis" in assignment:
            continue
        first = dict(task.changes).get("initial_hypothesis", world.initial_hypothesis)
        if first != world.initial_hypothesis:
            kind = observer_kind(assignment["inference"])
            progress.warn(f"sweep {point_label(assignment)}: P2's first guess is x{first} "
                          f"({kind.first_guess_rule or 'her observer'}), not the world's "
                          f"x{world.initial_hypothesis}: the point compares first guesses as "
                          "well as observers")


def _with_setting(name: str) -> Callable[[World, Value], World]:
    """Sets the observer's setting `name`, when the world's kind of observer has it; a value
    the observer refuses for this world (a prior of the wrong length) is a --values error."""
    def apply(world: World, value: Value) -> World:
        kind = observer_kind(world.inference)
        if name not in kind.keys():
            raise InputError(COMMAND_LINE, "--param", f"the {kind.title} observer has no {name}; "
                             f'sweeping {name} needs [inference] kind = "{owner(name).name}"')
        try:
            return configure(world, **{name: value})
        except InputError as err:
            setting = next(s for s in kind.settings if s.key == name)
            shown = _value_text(value) if isinstance(value, (list, tuple)) else value
            if setting.swept is not None and setting.swept.normalise is not None:
                shown = f"{shown} (normalised)"
            raise InputError(COMMAND_LINE, "--values", f"{name} {shown}: {err.reason}") from None
    return apply


def _observer_parameters() -> list[SweepParameter]:
    """The settings of the registered observers that a sweep may vary (Setting.swept), each
    once (a key two kinds share is swept by the first)."""
    parsers = {"number": lambda s: number(s.kind, s.minimum, s.exclusive),
               "word": lambda s: _word, "numbers": lambda s: _numbers(s.normalise)}
    found: dict[str, SweepParameter] = {}
    for kind in KINDS.values():
        for setting in kind.settings:
            if setting.swept is not None and setting.key not in found:
                found[setting.key] = SweepParameter(
                    setting.key, setting.swept.expected, parsers[setting.swept.form](
                        setting.swept), _with_setting(setting.key), observer=kind.name)
    return list(found.values())


def _word(value: object) -> str:
    """A setting's value that is a word (the Bayesian observer's decision); the observer reads
    and checks it when it is applied."""
    if not isinstance(value, str) or not value.strip():
        raise ValueError(OUTSIDE)
    return value.strip()


def _with_first_guess(world: World, first: int) -> World:
    """P2's first guess (an index into the hypotheses), for an observer whose first guess is
    the world's (a Bayesian one's follows her prior)."""
    kind = observer_kind(world.inference)
    if kind.first_guess is not None:
        raise InputError(COMMAND_LINE, "--param",
                         f"the {kind.title} observer's first guess follows "
                         f"her prior; sweep prior instead of initial_hypothesis")
    if first >= len(world.hypotheses):
        raise InputError(COMMAND_LINE, "--values", f"initial_hypothesis value {first} must be an "
                         f"index into the world's {len(world.hypotheses)} hypotheses")
    return replace(world, initial_hypothesis=first)


def _check_traps(world: World, traps: int) -> None:
    candidates = len(arena_of(world).trap_candidates)
    if traps > candidates:
        raise InputError(COMMAND_LINE, "--values",
                         f"traps value {traps} must be at most the world's "
                         f"{candidates} trap candidates")


def _with_traps(world: World, traps: int) -> World:
    _check_traps(world, traps)
    return replace(world, traps=traps)


def _built_table() -> dict[str, SweepParameter]:
    """The sweep parameters, in the order `--help` lists them: every world's, the observers'
    own (opponent/registry.py) and the front ends' own (frontends/__init__.py)."""
    table: dict[str, SweepParameter] = {}
    owners: dict[str, str] = {}

    def owner(p: SweepParameter) -> str:
        if p.front_end is not None:
            return (f"front end {p.front_end!r} "
                    f"({frontends.FRONT_ENDS.get(p.front_end, '?')}, SETTINGS)")
        if p.observer is not None:
            return f"observer kind {p.observer!r} (its settings)"
        return "every world"

    for parameter in (
        # first: the other parameters apply to the observer it chooses
        SweepParameter("inference", " or ".join(f'"{kind}"' for kind in KINDS), _observer_kind,
                       _with_observer),
        SweepParameter("delay", "an integer >= 0", number(int, 0, False), _field("delay"),
                       moves_traps=True),
        SweepParameter("window", "an integer >= 1", number(int, 1, False), _field("window")),
        *_observer_parameters(),       # the observers' own: threshold, prior, decision
        SweepParameter("rationality", "a number > 0", number(float, 0.0, True),
                       _field("rationality")),
        *(SweepParameter(setting.name, setting.expected,
                         number(setting.kind, setting.minimum, setting.exclusive,
                                None if setting.at_most else setting.below,
                                setting.below if setting.at_most else None),
                         setting.apply, front_end=kind)
          for kind, setting in frontends.sweep_settings()),
        SweepParameter("traps", "an integer >= 1 (at most the trap candidates)",
                       number(int, 1, False), _with_traps, moves_traps=True),
        SweepParameter("initial_hypothesis", "an index into the hypotheses (P2's first guess)",
                       number(int, 0, False), _with_first_guess),
        SweepParameter("tie_break", " or ".join(f'"{rule}"' for rule in TIE_BREAKS)
                       + " (which of P2's tied actions she takes)", _tie_break,
                       _field("tie_break")),
    ):
        if parameter.name in table:
            # one namespace for every world's parameters, the observers' settings and every
            # front end's: a clash is a registration's mistake, said in one line (the command
            # line's help lists the table, so it was a traceback in every command)
            raise InputError("sweep parameters", parameter.name, f"defined by both "
                             f"{owners[parameter.name]} and {owner(parameter)}: a front "
                             "end's and an observer's own settings share one namespace with "
                             "the world's parameters; rename one (docs/architecture.md)")
        owners[parameter.name] = owner(parameter)
        table[parameter.name] = parameter
    return table


_TABLES: dict[tuple, dict[str, SweepParameter]] = {}


def sweep_parameters() -> dict[str, SweepParameter]:
    """The table of sweep parameters as the observer and front-end registries stand now (a
    kind registered after this module was imported has its settings here too)."""
    key = (tuple(KINDS), tuple(frontends.FRONT_ENDS.items()))
    if key not in _TABLES:
        _TABLES[key] = _built_table()
    return _TABLES[key]


def owned_pattern() -> str:
    """The names a sweep owns in its output folder (outputs.staged removes stale ones):
    sweep.json/.csv/figures and the per-point folders <name>_<value>, joined by "__", names
    from the table."""
    name = "(?:" + "|".join(sweep_parameters()) + ")"
    point = name + r"_[0-9A-Za-z][0-9A-Za-z.,+-]*"
    return r"sweep\.(json|csv|png|svg|pdf)|" + point + "(?:__" + point + ")*"


def __getattr__(name: str):
    """SWEEP_PARAMETERS and OWNED_PATTERN, read as the registries stand now."""
    if name == "SWEEP_PARAMETERS":
        return sweep_parameters()
    if name == "OWNED_PATTERN":
        return owned_pattern()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _values_of(parameter: str) -> ValueList:
    """--values of `parameter`, in the sweep's wording."""
    spec = sweep_parameters()[parameter]
    return ValueList("--values", f"{parameter} value", spec.expected, spec.parse,
                     empty=f"expected at least one value of {parameter} ({{expected}})")


def parse_sweep_values(parameter: str, values: Sequence[object]) -> list[Value]:
    """Validate a sweep: a known parameter and a non-empty list of distinct valid values
    (strings as typed on the command line are parsed). Raises InputError (key --param or
    --values)."""
    if parameter not in sweep_parameters():
        raise InputError(COMMAND_LINE, "--param",
                         f"unknown parameter {parameter!r}; expected one of "
                         + ", ".join(sweep_parameters()) + " (weight: for a world with P2's types)")
    return parse_values(_values_of(parameter), values)


def parse_sweep_grid(grid: Sequence[tuple[str, Sequence[object]]]
                     ) -> list[tuple[str, list[Value]]]:
    """Validate several (parameter, values) pairs: each as in :func:`parse_sweep_values`, and
    no parameter twice."""
    if not grid:
        raise InputError(COMMAND_LINE, "--param", "expected at least one parameter to sweep")
    parsed: list[tuple[str, list[Value]]] = []
    for parameter, values in grid:
        if any(parameter == seen for seen, _ in parsed):
            raise InputError(COMMAND_LINE, "--param",
                             f"{parameter} is given twice; give all its values "
                             "after one --values")
        parsed.append((parameter, parse_sweep_values(parameter, values)))
    return parsed


def standing_at(world: World, traps: int) -> int:
    """P2's action standing at the start of a point with a positive delay and `traps` traps
    (an index into A2; the rule in the module docstring)."""
    arena = arena_of(world)
    if not arena.traps_mode:
        return frontends.standing_action(world)
    return carried_standing(len(arena.trap_candidates), frontends.standing_candidates(world),
                            traps)


def sweep_point(world: World, assignment: dict[str, Value]) -> World:
    """The world at one point of a sweep: each parameter of `assignment` (already parsed)
    applied in the table's order, then the standing traps worked out again when the delay or
    the number of traps is swept."""
    point = world
    moved = {}      # delay and traps, set with the standing traps in one (validated) World
    for name, parameter in sweep_parameters().items():
        if name in assignment:
            parameter.refuse_unless_applies(world)
            if parameter.moves_traps:
                moved[name] = assignment[name]
                continue
            try:
                point = parameter.apply(point, assignment[name])
            except InputError as err:
                if err.file != str(world.path):
                    raise
                # the world refuses the value (its own limits): the value's fault, not the file's
                raise InputError(COMMAND_LINE, "--values", err.reason if name in err.reason
                                 else f"{name} value {assignment[name]!r}: {err.reason}"
                                 ) from None
    if moved:
        traps, delay = moved.get("traps", point.traps), moved.get("delay", point.delay)
        if "traps" in moved:
            _check_traps(world, traps)
        # a point with delay 0 keeps it too, for a re-solve with delay (World.initial_standing)
        point = replace(point, traps=traps, delay=delay,
                        initial_standing=standing_at(world, traps))
    return point


def sweep_world(world: World, parameter: str, value: object) -> World:
    """The world with one parameter replaced (validated as in :func:`parse_sweep_values`)."""
    (value,) = parse_sweep_values(parameter, [value])
    return sweep_point(world, {parameter: value})


def _standing_name(world: World) -> str | None:
    """The name of P2's action standing at the start of a point (None when delay is 0)."""
    if not world.delay:
        return None
    from hg2prism.frontends import transition_system

    ts = transition_system(world)
    return ts.a2_names[ts.decode(ts.start_state)[1]]


def _value_text(value: Value) -> str:
    """A swept value in folder names and tables: integers and names plain, numbers in %g form,
    a prior as its %g numbers joined by commas."""
    if isinstance(value, (tuple, list)):
        return ",".join(f"{p:g}" for p in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


def _json_value(value: Value) -> object:
    return list(value) if isinstance(value, tuple) else value


def point_label(assignment: dict[str, Value]) -> str:
    """``delay=1 window=2``: a point as the progress lines and error messages show it."""
    return " ".join(f"{name}={_value_text(value)}" for name, value in assignment.items())


def _folder(assignment: dict[str, Value]) -> str:
    return "__".join(f"{name}_{_value_text(value)}" for name, value in assignment.items())


# v_ne_lower and v_ne_upper: the ends of the row's v_ne_bounds (a CSV cell holds one number)
_CSV_COLUMNS = ("deceptive_value", "v_lead", "v_ne", "v_ne_lower", "v_ne_upper",
                "v_ne_p1_guaranteed", "states", "transitions", "storm_states",
                "storm_transitions", "seconds")


def results_sound(storm_method: str) -> bool:
    """Whether values from `storm_method` are certified (docs/semantics.md §10)."""
    from hg2prism.engines import default

    return storm_method in default().sound_methods


# ---------------------------------------------------------------------------------------------
# One point, solved where it runs (this process or a Dask worker)
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PointTask:
    """What a worker needs to solve one point: the world file's text (or, for a world that has
    no file giving it, the World value itself; both are plain data) and the World fields the
    point changes."""

    index: int                              # position in the grid (rows come back in order)
    assignment: tuple[tuple[str, Value], ...]
    world_text: str | None
    world: World | None
    world_file: str
    changes: tuple[tuple[str, object], ...]  # World field -> value at this point
    folder: str
    storm_method: str
    max_states: int | None
    estimate: int = 0                       # the size guard's estimate: bigger starts earlier
    deception: bool = False                 # also V_static, V_naive (docs/semantics.md §11)
    # the front ends registered where the sweep runs (kind -> module): a worker process
    # registers those it lacks (a kind registered at run time, tests/frontend_line.py)
    front_ends: tuple[tuple[str, str], ...] = ()
    # the observer kinds registered at run time where a parallel sweep runs, which a worker
    # process (having only the built-in kinds) registers (tests/test_observer_registry.py)
    observer_kinds: tuple[ObserverKind, ...] = ()
    # what solving the point's world is (a module-level function, so that it reaches a Dask
    # worker by name): None for the hypergame's check and Nash baseline (`check_point`);
    # adaptive deception's weight sweep gives its own (experiments/adaptive.py)
    solver: Callable[[World, PointTask], Solved] | None = None


@dataclass(frozen=True)
class Solved:
    """What a point's solver hands back: its row after the point's parameters, its files (path
    relative to its folder -> content) and a note for its progress line."""

    values: dict
    files: tuple[tuple[str, bytes], ...] = ()
    note: str | None = None


@dataclass(frozen=True)
class PointOutcome:
    """A point's row (or the one-line reason it failed), its files as bytes (path relative to
    its folder -> content) and the warnings its stages gave."""

    index: int
    row: dict | None
    files: tuple[tuple[str, bytes], ...]
    error: str | None
    warnings: tuple[str, ...]
    note: str | None = None                 # shown after the point's progress line


def _world_of(task: PointTask) -> World:
    from hg2prism.worldfile import world_from_toml

    if task.world is not None:
        base = task.world
    else:
        # world_from_toml names the world after the "file" it is given when the text has no
        # name; the changes below restore the name and path the world was loaded with.
        base = world_from_toml(task.world_text, name=task.world_file)
    return replace(base, **dict(task.changes))


def point_error(err: Exception) -> str:
    """The one line a sweep records for a point that failed with `err`: the input's key and
    reason, the solver's or Storm's first line, else the exception's type and text."""
    from hg2prism.errors import SolverError, StormError

    if isinstance(err, InputError):
        return f"{err.key}: {err.reason}"
    if isinstance(err, (SolverError, StormError)):
        stage = "solver" if isinstance(err, SolverError) else "storm"
        return f"{stage}: {(str(err).strip().splitlines() or [type(err).__name__])[0]}"
    return f"{type(err).__name__}: {err}"


def solve_point(task: PointTask) -> PointOutcome:
    """Solve one point (docs/semantics.md §7, Sweeps): the size guard, then the task's solver
    (`check_point` unless it names another), its stage reports quiet; the row (the point's
    parameters, then the solver's values) and the files come back. Every error becomes the
    outcome's one-line `error`, so that one point's failure loses no other."""
    from hg2prism.model import sizeguard

    for kind, module in task.front_ends:
        frontends.FRONT_ENDS.setdefault(kind, module)
    for observer in task.observer_kinds:
        register(observer)
    with progress.collected_warnings() as warnings:
        try:
            world = _world_of(task)
            sizeguard.check_size(world, task.max_states)
            with progress.quiet():
                solved = (task.solver or check_point)(world, task)
        except Exception as err:     # a bug or the machine (MemoryError) too: still one point
            return PointOutcome(task.index, None, (), point_error(err), tuple(warnings))
    row = {**{name: _json_value(value) for name, value in task.assignment}, **solved.values}
    return PointOutcome(task.index, row, solved.files, None, tuple(warnings), solved.note)


def check_point(world: World, task: PointTask) -> Solved:
    """A point of a sweep of parameters: `check` into a private temporary folder, the Nash
    baseline (and with `task.deception` what the deception is worth); the folder's files."""
    from hg2prism import pipeline
    from hg2prism.analyses import baselines

    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="hg2prism-point-") as tmp:
        folder = Path(tmp) / task.folder
        checked = pipeline.check(world, folder, task.storm_method)
        nash = baselines.nash_baseline(checked.analysis.ts, checked.analysis.task)
        worth = _deception(checked) if task.deception else {}
        files = tuple(sorted((str(p.relative_to(folder)), p.read_bytes())
                             for p in folder.rglob("*") if p.is_file()))
    seconds = time.perf_counter() - start
    results = checked.results
    values = {
        "deceptive_value": results.deceptive_value,
        "v_lead": results.v_lead,
        "v_ne": nash.v_ne,
        "v_ne_p1_guaranteed": nash.v_ne_p1_guaranteed,
        "v_ne_bounds": list(nash.v_ne_bounds),
        "states": results.states,
        "transitions": results.transitions,
        "storm_states": results.storm_states,
        "storm_transitions": results.storm_transitions,
        "standing": _standing_name(world),
        **worth,
        "seconds": round(seconds, 3),
    }
    note = (f"P1's Nash strategy guarantees only {nash.v_ne_p1_guaranteed:.4f}" if nash.warn
            else None)
    return Solved(values, files, note)


def _check_line(row: dict) -> str:
    """A checked point's progress line, after its parameters and count."""
    return (f"deceptive {row['deceptive_value']:.4f}, V_lead {row['v_lead']:.4f}, V_NE "
            f"{row['v_ne']:.4f}, {row['states']} states ({row['seconds']:.1f} s)")


def _deception(checked) -> dict:
    """What the deception is worth at a point (docs/semantics.md §11), as `run` reports it."""
    from hg2prism.analyses.deception_value import deception_values

    worth = deception_values(checked.analysis, checked.results.deceptive_value)
    return {"v_static": worth.v_static, "v_naive": worth.v_naive,
            "value_of_deception": worth.value_of_deception}


# ---------------------------------------------------------------------------------------------
# Running the points
# ---------------------------------------------------------------------------------------------

def default_workers() -> int:
    """The cores this process may use: the default number of Dask workers."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:      # not on Linux
        return max(1, os.cpu_count() or 1)


def _world_text(world: World) -> str | None:
    """The world file's text when it gives exactly `world` (less name, path and the swept
    fields, which travel as changes); None for a world built in Python."""
    from hg2prism.worldfile import world_from_toml

    try:
        text = Path(world.path).read_text(encoding="utf-8")
        parsed = world_from_toml(text, name=str(world.path))
    except (OSError, UnicodeDecodeError, InputError):
        return None
    return text if replace(parsed, name=world.name, path=world.path) == world else None


def observer_kinds(world: World, points: list[dict[str, Value]]
                   ) -> tuple[ObserverKind, ...]:
    """The observer kinds registered at run time here, for a parallel sweep's workers, which
    have only the built-in ones: those Dask can send (by cloudpickle, as it sends the points).
    One the points use (the world's, its types', a swept `inference`) that cannot be sent (a
    lock in a closure) refuses the sweep in one line (each point failed on its worker);
    another is left behind, as no point needs it."""
    import cloudpickle

    used = {world.inference, *(t.inference for t in world.types),
            *(point["inference"] for point in points if "inference" in point)}
    carried = []
    for kind in run_time_kinds():
        try:
            cloudpickle.dumps(kind)
        except Exception as err:    # pickling raises TypeError, PicklingError, AttributeError...
            if kind.name not in used:
                continue
            reason = (str(err).strip().splitlines() or [""])[0]
            raise InputError(COMMAND_LINE, "--workers", f"the {kind.title} observer (kind "
                             f"{kind.name!r}, registered at run time) cannot be sent to worker "
                             f"processes ({type(err).__name__}: {reason}); sweep it with one "
                             "worker") from None
        carried.append(kind)
    return tuple(carried)


def point_tasks(world: World, points: list[dict[str, Value]], storm_method: str,
                max_states: int | None, deception: bool = False,
                at: Callable[[World, dict[str, Value]], World] = sweep_point,
                solver: Callable[[World, PointTask], Solved] | None = None,
                observer_kinds: tuple[ObserverKind, ...] = ()) -> list[PointTask]:
    """The points' tasks: each point's world is `at(world, assignment)` (a sweep's parameters
    by default), solved by `solver` (None: `check_point`); `observer_kinds` go to a parallel
    sweep's workers (`observer_kinds`)."""
    from hg2prism.model import sizeguard

    text = _world_text(world)
    tasks = []
    for index, assignment in enumerate(points):
        point = at(world, assignment)
        estimate = (sizeguard.estimate_adaptive(point) if point.types
                    else sizeguard.estimate_states(point))
        # name and path always travel: the text alone names the world after its file
        changes = tuple((f.name, getattr(point, f.name)) for f in fields(World)
                        if f.name in ("name", "path") or getattr(point, f.name) != getattr(world, f.name))
        tasks.append(PointTask(index, tuple(assignment.items()), text,
                               None if text is not None else world, str(world.path), changes,
                               _folder(assignment), storm_method, max_states,
                               min(estimate, 2**62), deception,
                               tuple(frontends.FRONT_ENDS.items()), observer_kinds, solver))
    return tasks


def _closing(outcomes: Iterator[PointOutcome]) -> Iterator[PointOutcome]:
    """`outcomes`, closed (its cluster shut down) even when the caller stops early."""
    try:
        yield from outcomes
    finally:
        close = getattr(outcomes, "close", None)
        if close is not None:
            close()


def _run_serial(tasks: list[PointTask], bar: progress.Bar,
                label_of: Callable[[PointTask], str]) -> Iterator[PointOutcome]:
    for task in tasks:
        with bar.pending(f"sweep {label_of(task)}"):
            outcome = solve_point(task)
        yield outcome


def _run_dask(tasks: list[PointTask], workers: int, scheduler: str | None
              ) -> Iterator[PointOutcome]:
    """The points on a Dask cluster, as they complete. A LocalCluster of `workers` processes
    (one thread each: Storm is single-threaded) unless `scheduler` names a running one; the
    cluster this starts is closed on the way out, whatever happens."""
    import logging
    import warnings

    import dask
    from dask.distributed import Client, LocalCluster, as_completed

    # The workers' and the scheduler's logs (start-up, shutdown, heartbeats) are noise here;
    # what matters reaches the user as the points' outcomes.
    quiet_loggers = [logging.getLogger(name)
                     for name in ("distributed", "tornado", "bokeh", "asyncio")]
    levels = [logger.level for logger in quiet_loggers]
    for logger in quiet_loggers:
        logger.setLevel(logging.CRITICAL)
    from distributed.deploy.spec import SpecCluster

    class SweepCluster(LocalCluster):
        """This call's LocalCluster: the one cluster `_abandon` closes (not another thread's)."""

    cluster = None
    futures: list = []
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if scheduler is None:
                # A worker lost on a point (its share of the memory exceeded) fails that point
                # at once rather than after Dask's retries of the same heavy point.
                with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
                    cluster = SweepCluster(n_workers=workers, threads_per_worker=1,
                                           processes=True, dashboard_address=None,
                                           silence_logs=logging.CRITICAL)
                client = Client(cluster)
            else:
                try:
                    client = Client(scheduler, timeout="10s")
                except (OSError, TimeoutError, ValueError) as err:
                    raise InputError(COMMAND_LINE, "--scheduler",
                                     f"cannot reach a Dask scheduler at "
                                     f"{scheduler}: {err}") from None
        try:
            # largest first (by the size estimate), so that a big point does not start last
            # and leave the other workers idle; the scheduler hands out tasks as they arrive
            by_size = sorted(tasks, key=lambda task: (-task.estimate, task.index))
            futures = client.map(solve_point, by_size, pure=False)
            index_of = {future.key: task.index for future, task in zip(futures, by_size)}
            for future in as_completed(futures):
                try:
                    yield future.result()
                except Exception as err:    # the worker died (KilledWorker) or was cancelled
                    yield PointOutcome(index_of[future.key], None, (),
                                       f"dask: {type(err).__name__}: {err}", ())
        finally:
            for future in futures:
                future.cancel()
            client.close()
    except (Exception, KeyboardInterrupt, SystemExit):
        # Stopped (Ctrl-C, a signal) or failed while the cluster started or ran: Dask's own
        # exit hook would close it again and print its traceback (a worker still starting
        # fails its assertion), with its shutdown logs after ours.
        _abandon({c for c in getattr(SpecCluster, "_instances", ())
                  if isinstance(c, SweepCluster)})
        cluster = None
        raise
    finally:
        if cluster is not None:
            cluster.close()
        for logger, level in zip(quiet_loggers, levels):
            logger.setLevel(level)


def _abandon(started: set) -> None:
    """Close the clusters this sweep started (its start may not have returned) after a stop
    or a failure, quietly, and keep Dask's exit hook off them. One that does not close is left
    to the process's exit, which ends its worker processes (daemons of multiprocessing); the
    program says nothing more once stopped (cli.entry)."""
    for each in started:
        try:
            each.close(timeout=5)
        except (Exception, KeyboardInterrupt):
            pass
        each.shutdown_on_close = False          # Dask's exit hook skips it


# ---------------------------------------------------------------------------------------------
# The sweep
# ---------------------------------------------------------------------------------------------

def check_grid(world: World, grid: Sequence[tuple[str, Sequence[object]]],
               max_states: int | None = None
               ) -> tuple[list[tuple[str, list[Value]]], list[dict[str, Value]]]:
    """Everything a sweep checks before solving: the parameters and values, every point's world
    (InputError for a value that does not fit the world, or bad initial traps in the file), and
    the size guard, which refuses the sweep only when it refuses every point (a single refused
    point fails alone when it is reached). Returns the parsed grid and its points in grid order
    (the first parameter varies slowest)."""
    parsed = parse_sweep_grid(grid)
    names = [name for name, _ in parsed]
    for name in names:
        sweep_parameters()[name].refuse_unless_applies(world)
    points = [dict(zip(names, combination))
              for combination in itertools.product(*(values for _, values in parsed))]
    guard_points(world, points, max_states)
    return parsed, points


def guard_points(world: World, points: Sequence[dict[str, Value]], max_states: int | None,
                 at: Callable[[World, dict[str, Value]], World] = sweep_point) -> None:
    """The size guard over a sweep's points (each point's world `at(world, point)`; a value
    that does not fit the world counts as refused): the sweep is refused only when every point
    is, by the InputError of the point estimated largest (so that its --max-states lets every
    point through); a single refused point fails alone when reached."""
    from hg2prism.model import sizeguard

    refusals = []
    for point in points:
        try:
            sizeguard.check_size(at(world, point), max_states)
        except InputError as err:
            refusals.append(err)
    if refusals and len(refusals) == len(points):
        # the --max-states each asks for (the size guard's refusals carry it; a value the
        # world refuses asks for none)
        at_most = [getattr(err, "estimate", None) for err in refusals]
        if len(points) == 1 or all(size is None for size in at_most):
            raise refusals[0]
        largest = max(range(len(points)), key=lambda i: at_most[i] or 0)   # the first of equals
        err = refusals[largest]
        raise InputError(err.file, err.key, f"every point is refused; the largest, "
                         f"{point_label(points[largest])}: {err.reason}")


def _standing_rule(world: World, traps_swept: bool) -> str:
    """How a point's standing action (traps) at the start is chosen (the module docstring)."""
    rule = frontends.standing_rule(world)
    return rule + ("; traps = k keeps the first k of them, then the first other candidates"
                   if traps_swept else "")


@dataclass(frozen=True)
class SweepRun:
    """A finished sweep: the swept parameters with their values, the rows of the points that
    were solved (grid order) and the points that failed (their parameters and ``error``)."""

    parameters: tuple[tuple[str, tuple[Value, ...]], ...]
    rows: tuple[dict, ...]
    failed: tuple[dict, ...]


def sweep_grid(world: World, grid: Sequence[tuple[str, Sequence[object]]], out: Path,
               show_progress: bool = True, storm_method: str = "sound", *, workers: int = 1,
               scheduler: str | None = None, max_states: int | None = None,
               deception: bool = False) -> SweepRun:
    """Solve the world at every point of the cartesian product of `grid`'s values (the first
    parameter varies slowest) and record the values at the initial state: per point
    ``{<parameter>: value, ..., deceptive_value, v_lead, v_ne, v_ne_p1_guaranteed, v_ne_bounds,
    states, transitions, storm_states, storm_transitions, standing, seconds}``; with
    `deception`, also ``v_static, v_naive, value_of_deception`` (docs/semantics.md §11).

    Points run serially here when ``workers == 1`` and no `scheduler` is given, otherwise on
    Dask (module docstring). Each point is checked into ``out/<folder>/`` (hypergame.prism,
    strategy.json, results.json); ``out/sweep.json``, ``sweep.csv`` and ``sweep.png`` summarise
    them (docs/semantics.md §7, Sweeps, gives their format). Progress: one line per finished point on
    stderr, with the count of points done. Raises InputError for a bad parameter or value, or
    when the size guard (`max_states`) refuses every point; other failures are per point.
    A script that calls this with ``workers > 1`` needs the ``if __name__ == "__main__":``
    guard, as any program starting processes by spawning does. A warning repeated word for word
    (by the check of the grid and by the point's solve) is shown once.
    """
    if workers < 1:
        raise InputError(COMMAND_LINE, "--workers", f"must be at least 1, got {workers}")
    with progress.each_warning_once():
        return _sweep_grid(world, grid, out, show_progress, storm_method, workers, scheduler,
                           max_states, deception)


def _sweep_grid(world: World, grid: Sequence[tuple[str, Sequence[object]]], out: Path,
                show_progress: bool, storm_method: str, workers: int, scheduler: str | None,
                max_states: int | None, deception: bool) -> SweepRun:
    parsed, points = check_grid(world, grid, max_states)
    serial = workers == 1 and scheduler is None
    tasks = point_tasks(world, points, storm_method, max_states, deception,
                        observer_kinds=() if serial else observer_kinds(world, points))
    _first_guess_notes(world, tasks)
    out = Path(out)
    total_start = time.perf_counter()
    rows, failed = run_points(tasks, out, show_progress, workers, scheduler, _check_line)
    run = SweepRun(tuple((name, tuple(values)) for name, values in parsed), rows, failed)
    _write_summary(world, run, out, storm_method, time.perf_counter() - total_start)
    return run


def run_points(tasks: list[PointTask], out: Path, show_progress: bool, workers: int,
               scheduler: str | None, line: Callable[[dict], str]
               ) -> tuple[tuple[dict, ...], tuple[dict, ...]]:
    """Every sweep's driver: the points solved serially here (``workers == 1``, no `scheduler`)
    or on Dask, each point's files written into ``out/<its folder>/`` as it finishes, its
    warnings shown (naming the point), a progress line per point (`line(row)` after the
    point's parameters and count, or why it failed). Returns the solved points' rows and the
    failed points (their parameters and ``error``), in the tasks' order."""
    out = Path(out)
    serial = workers == 1 and scheduler is None
    bar = progress.Bar("sweep", len(tasks), show_progress, unit="points", width=20)

    def label_of(task: PointTask) -> str:
        return point_label(dict(task.assignment))

    outcomes: dict[int, PointOutcome] = {}
    running = (_run_serial(tasks, bar, label_of) if serial
               else _run_dask(tasks, min(workers, len(tasks)), scheduler))
    for outcome in _closing(running):
        outcomes[outcome.index] = outcome
        task = tasks[outcome.index]
        for name, data in outcome.files:
            write_bytes(out / task.folder / name, data)
        for message in outcome.warnings:        # which point says it (points may say alike)
            progress.replay_warning(f"sweep {label_of(task)}: {message}")
        row = outcome.row
        bar.finished(len(outcomes), f"sweep {label_of(task)}",
                     f"failed: {outcome.error}" if row is None else
                     line(row) + (f"; warning: {outcome.note}" if outcome.note else ""))
    rows = tuple(outcomes[i].row for i in range(len(tasks)) if outcomes[i].row is not None)
    failed = tuple({**dict(tasks[i].assignment), "error": outcomes[i].error}
                   for i in range(len(tasks)) if outcomes[i].row is None)
    return rows, failed


# With --deception, after v_ne_p1_guaranteed (docs/semantics.md §11).
_DECEPTION_COLUMNS = ("v_static", "v_naive", "value_of_deception")


def sweep_csv(names: Sequence[str], rows: Sequence[dict]) -> str:
    """sweep.csv: the swept parameters, then _CSV_COLUMNS (with the deception's values where
    the rows have them: `sweep --deception`), one line per solved point."""
    columns = _CSV_COLUMNS
    if rows and all("v_static" in row for row in rows):
        at = columns.index("v_ne_p1_guaranteed") + 1
        columns = columns[:at] + _DECEPTION_COLUMNS + columns[at:]
    if _with_standing(rows):
        columns = ("standing",) + columns
    return csv_text(tuple(names) + columns,
                    ([_value_text(row[n]) if isinstance(row[n], list) else row[n]
                      for n in names] + [csv_cell(row, c) for c in columns] for row in rows))


def csv_cell(row: dict, column: str) -> object:
    """A row's value in sweep.csv's `column` (None where the row has none): v_ne_lower and
    v_ne_upper are the ends of its v_ne_bounds (a CSV cell holds one number)."""
    if column in ("v_ne_lower", "v_ne_upper"):
        bounds = row.get("v_ne_bounds")
        return None if bounds is None else bounds[column == "v_ne_upper"]
    return row.get(column)


def _with_standing(rows: Sequence[dict]) -> bool:
    """Whether sweep.csv and the printed table give P2's action standing at the start: when
    some point has one (a positive delay), since the values depend on it."""
    return any(row.get("standing") is not None for row in rows)


def _write_summary(world: World, run: SweepRun, out: Path, storm_method: str,
                   seconds: float) -> None:
    from hg2prism.report import plots

    names = [name for name, _ in run.parameters]
    fixed = Parameters.of(world).to_json()
    for name in names:
        fixed.pop(name, None)
    summary: dict[str, object] = provenance(world)
    if len(names) == 1:        # the one-parameter format, as before grids existed
        summary.update(parameter=names[0], values=[_json_value(v) for v in run.parameters[0][1]])
    else:
        summary["grid"] = {name: [_json_value(v) for v in values] for name, values in run.parameters}
    summary.update({
        "parameters": names,
        "fixed_parameters": fixed,
        "storm_method": storm_method,
        "sound": results_sound(storm_method),
        "initial_traps_rule": (_standing_rule(world, "traps" in names)
                               if any(sweep_parameters()[n].moves_traps for n in names) else None),
        "rows": list(run.rows),
        "failed": list(run.failed),
        "seconds": round(seconds, 3),
    })
    write_json(out / "sweep.json", summary)
    write_text(out / "sweep.csv", sweep_csv(names, run.rows))
    if len(names) == 1:
        plots.sweep_figure(names[0], list(run.rows), out / "sweep.png", world.name)
    else:
        plots.sweep_grid_figure(names, list(run.rows), out / "sweep.png", world.name)


def sweep(world: World, parameter: str, values: Sequence[object], out: Path,
          show_progress: bool = True, storm_method: str = "sound", *, workers: int = 1,
          scheduler: str | None = None, max_states: int | None = None) -> list[dict]:
    """:func:`sweep_grid` over one parameter; returns the solved points' rows (the failed ones
    are in ``out/sweep.json`` under ``failed``)."""
    return list(sweep_grid(world, [(parameter, values)], out, show_progress, storm_method,
                           workers=workers, scheduler=scheduler, max_states=max_states).rows)


def sweep_summary_lines(parameter: str | Sequence[str], rows: Sequence[dict],
                        world_name: str | None = None) -> list[str]:
    """The sweep as a Markdown table (one column per swept parameter)."""
    names = [parameter] if isinstance(parameter, str) else list(parameter)
    title = f"Completion probability at the initial state against {' and '.join(names)}"
    if world_name:
        title += f" ({world_name})"
    # with the deception's values where every row has them (`sweep --deception`), as sweep.csv
    worth = bool(rows) and all("v_static" in row for row in rows)
    extra = " V_static | V_naive | value of deception |" if worth else ""
    standing = _with_standing(rows)
    lines = [title, "",
             "| " + " | ".join(names) + (" | standing at the start" if standing else "")
             + " | deceptive value | V_lead | V_NE |" + extra + " hypergame states | transitions |",
             "|" + "---|" * (len(names) + standing + 5 + 3 * worth)]
    for row in rows:
        values = "".join(f" {row[c]:.4f} |" for c in _DECEPTION_COLUMNS) if worth else ""
        shown = (" | " + (row.get("standing") or "-")) if standing else ""
        lines.append("| " + " | ".join(_value_text(row[n]) for n in names) + shown
                     + f" | {row['deceptive_value']:.4f} | {row['v_lead']:.4f} "
                     f"| {row['v_ne']:.4f} |{values} {row['states']} | {row['transitions']} |")
    return lines
