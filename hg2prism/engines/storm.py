"""Storm through stormpy: build the hypergame model, check Pmax, export the strategy (docs/semantics.md §6).

Storm's states encode (v, q_prev, M) with the DFA one step behind, so several of them can be
one canonical state (v, q, M) of docs/semantics.md §6; `canonical_states` maps each to its canonical id.
"""

from __future__ import annotations

import functools
import json
import tarfile
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable
from pathlib import Path

import numpy as np
import stormpy
import stormpy.environments as environments
from stormpy import developer
from stormpy.io import export_to_umb

from hg2prism.engines import certify
from hg2prism.numeric import ExplicitModel
from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import ACTION_LABELS, ACTIONS, TransitionSystem
from hg2prism.errors import StormError, probability
from hg2prism.prism.hypergame import Layout

if TYPE_CHECKING:
    from hg2prism.strategy.deceptive import StormChoices

PRECISION = "1/10000000000"   # 1e-10, docs/semantics.md §10


def sound_environment() -> developer.Environment:
    env = environments.sound()
    solver = env.solver()
    solver.min_max().precision = stormpy.Rational(PRECISION)
    solver.min_max().relative_termination_criterion = False
    solver.native().precision = stormpy.Rational(PRECISION)
    solver.native().relative_termination_criterion = False
    return env


@dataclass(frozen=True, eq=False)
class CheckedModel:
    model: object                  # stormpy sparse MDP
    value: float
    values: np.ndarray             # value of every Storm state
    formula: object                # the checked property's formula
    timings: dict[str, float]      # parse, build, check
    alongside: object = None       # what check(..., alongside=...) computed beside Storm

    @functools.cached_property
    def scheduler(self) -> object:
        """A scheduler object of the model, for `induced_probability` to overwrite (stormpy
        cannot create one). Extracting it during the sound check costs about a fifth of the
        check at 1e6 states, so it comes from a quick plain value iteration, when needed."""
        result = stormpy.model_checking(self.model, self.formula, extract_scheduler=True,
                                        environment=solver_environment("fast"))
        return result.get_scheduler()


# How Pmax is solved (docs/semantics.md §10). "sound" (the default) is certified: Storm's fast
# topological value iteration proposes a strategy, engines/certify.py evaluates it exactly and
# improves it until its value is a fixed point of the Bellman operator; should that fail, Storm's
# sound solver ("storm-sound") answers instead, with a warning. The others run one Storm method:
# "storm-sound" is Storm's default sound solver (topological, optimistic value iteration per
# strongly connected component), precision 1e-10: 29x slower between two neighbouring benchmark
# worlds (1.8 s at 0.8e6 states, 51 s at 1e6) and more than two minutes on a 41k-state one.
# "sound-ovi" runs optimistic value iteration on the whole model, also sound to 1e-10, faster on
# some of those models but as stuck on others. "fast" is Storm's topological value iteration
# stopped at an absolute change of 1e-12, which is not sound (7e-6 short on one 42k-state model).
STORM_METHODS = ("sound", "storm-sound", "sound-ovi", "fast")
SOUND_METHODS = ("sound", "storm-sound", "sound-ovi")   # certified to 1e-10; "fast" is not


def solver_environment(method: str) -> developer.Environment:
    """Storm's solver settings for one of STORM_METHODS ("sound" starts from "fast")."""
    if method == "storm-sound":
        return sound_environment()
    if method == "sound-ovi":
        env = sound_environment()
        env.solver().min_max().method = environments.MinMaxMethod.OPTIMISTIC_VALUE_ITERATION
        return env
    if method in ("fast", "sound"):
        env = developer.Environment()
        env.solver().min_max().method = environments.MinMaxMethod.TOPOLOGICAL
        env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
        env.solver().min_max().relative_termination_criterion = False
        return env
    raise ValueError(f"unknown Storm method {method!r}; choose from {STORM_METHODS}")


def check(prism_path: Path, prop: str, method: str = "sound",
          alongside: Callable[[object], object] | None = None) -> CheckedModel:
    """Parse, build and solve `prop` (a Pmax reachability property) with one of STORM_METHODS.
    `alongside(model)`, when given, runs on a second thread while Storm solves (Storm releases
    the GIL): its result is the CheckedModel's `alongside`."""
    try:
        return _check(prism_path, prop, method, alongside)
    except RuntimeError as err:  # stormpy reports parse and build failures as RuntimeError
        raise StormError(f"{prism_path}: {err}") from err


def _check(prism_path: Path, prop: str, method: str,
           alongside: Callable[[object], object] | None) -> CheckedModel:
    solver_environment(method)   # an unknown method fails before the build
    model, formula, timings = build(prism_path, prop)
    start = time.perf_counter()
    with ThreadPoolExecutor(max_workers=1) as pool:
        beside = pool.submit(alongside, model) if alongside is not None else None
        values, scheduler = solve(model, formula, method)
        prepared = beside.result() if beside is not None else None
    timings["check"] = time.perf_counter() - start
    initial = model.initial_states[0]
    value = probability(values[initial], "Storm's value at the initial state")
    checked = CheckedModel(model=model, value=value, values=values, formula=formula,
                           timings=timings, alongside=prepared)
    if scheduler is not None:   # the certified route has one already: no second solve for it
        checked.__dict__["scheduler"] = scheduler
    return checked


def build(prism_path: Path, prop: str) -> tuple[object, object, dict[str, float]]:
    """Storm's sparse model of a PRISM file, the formula of `prop`, and the parse and build
    times."""
    timings = {}
    start = time.perf_counter()
    program = stormpy.parse_prism_program(str(prism_path))
    properties = stormpy.parse_properties(prop, program)
    timings["parse"] = time.perf_counter() - start

    start = time.perf_counter()
    options = developer.BuilderOptions([p.get_raw_formula() for p in properties])
    options.set_build_choice_labels(True)
    options.set_build_state_valuations(True)
    options.set_build_all_labels(True)
    model = stormpy.build_model(program, options=options)
    timings["build"] = time.perf_counter() - start
    return model, properties[0], timings


def solve(model: object, formula: object, method: str = "sound") -> tuple[np.ndarray, object]:
    """The value of every state of `model` for `formula` (Pmax=? [F "goal"] for "sound") by one
    of STORM_METHODS, and a scheduler object of the model when the method made one (else None)."""
    if method == "sound":
        return _certified_values(model, formula)
    result = stormpy.model_checking(model, formula, environment=solver_environment(method))
    return np.asarray(result.get_value_vector()), None


def certificate(model: object, formula: object, max_rounds: int = certify.MAX_ROUNDS,
                perturb: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
                ) -> certify.Certificate:
    """The values of `formula` (a Pmax reachability of the label "goal"), certified by
    engines/certify.py from the strategy that Storm's fast values suggest
    (`certify.initial_strategy`). `perturb(choice, group_start)` may replace that first
    strategy (global choice indices), for tests."""
    result = stormpy.model_checking(model, formula, environment=_rough_environment())
    estimate = np.asarray(result.get_value_vector())
    structure = read_structure(model)
    group_start = np.searchsorted(structure.source, np.arange(model.nr_states + 1))
    matrix = ExplicitModel.from_arrays(structure.row_start, structure.target,
                                       structure.probability, group_start).matrix
    goal = structure.labels["goal"]
    choice = certify.initial_strategy(matrix, group_start, goal, estimate)
    if perturb is not None:
        choice = perturb(choice, group_start)
    return certify.certify_reachability(matrix, group_start, goal, choice, max_rounds)


def _rough_environment() -> developer.Environment:
    """Value iteration to an absolute change of 1e-3: only a first strategy comes from it
    (Storm's own scheduler costs more than the values: 2 s at 0.27e6 states). On the 1e6-state
    benchmark world, 1e-3 and one more round of improvement cost 7.3 s, 1e-6 (topological) and
    one round 14 s."""
    env = developer.Environment()
    env.solver().min_max().method = environments.MinMaxMethod.VALUE_ITERATION
    env.solver().min_max().precision = stormpy.Rational("1/1000")
    env.solver().min_max().relative_termination_criterion = False
    return env


def _certified_values(model: object, formula: object) -> tuple[np.ndarray, object]:
    """The "sound" method: the certified values of `certificate`, or, when they cannot be
    certified, Storm's sound solver's (with a warning). No scheduler object (None)."""
    from hg2prism.progress import warn

    certified = certificate(model, formula)
    if certified.certified:
        return certified.values, None
    warn(f"could not certify the fast solver's strategy ({certified.reason}); "
         f"solving with Storm's sound solver instead")
    result = stormpy.model_checking(model, formula, environment=sound_environment())
    return np.asarray(result.get_value_vector()), None


@dataclass(frozen=True, eq=False)
class DecodedStates:
    """Storm's states as docs/semantics.md §6 hypergame states."""

    cell: np.ndarray          # cell index (the TRAPPED formula's value once trapped)
    traps: np.ndarray         # standing trap set (0 when delay is 0)
    countdown: np.ndarray
    q: np.ndarray             # DFA state after reading the current cell's label
    hypothesis: np.ndarray
    window: np.ndarray        # [n, slots, 2] (TS state, action), or [n, slots, 3] with the trap
                              # set in force (Bayesian observer); -1 for empty slots
    goal: np.ndarray          # bool
    fail: np.ndarray          # bool
    canonical: np.ndarray     # canonical id; goal states share one id, failure states another
    n_canonical: int


def decode_states(model: object, layout: Layout, ts: TransitionSystem, task: DFA,
                  window_hypotheses: Callable[[np.ndarray], np.ndarray] | None = None
                  ) -> DecodedStates:
    """Storm's states as hypergame states. When the layout has no `hyp` variable, P2's
    hypothesis is derived from each state's window by `window_hypotheses`."""
    def column(name: str) -> np.ndarray:
        return state_variable(model, name)

    cell = column("cell")
    label = np.append(ts.cell_label, 0)[cell]
    q = task.delta[column("q"), label]
    width = 3 if layout.slot_sets else 2
    window = np.stack([np.stack([column(name) for name in names], axis=1)
                       for names in (layout.slot_variables(i) for i in range(1, layout.slots + 1))],
                      axis=1) if layout.slots else np.zeros((model.nr_states, 0, width), dtype=np.int64)
    goal = _label_mask(model, "goal")
    fail = _label_mask(model, "fail")
    traps, countdown = column("traps"), column("countdown")
    if layout.hypothesis_variable:
        hypothesis = column("hyp")
    else:
        if window_hypotheses is None:
            raise ValueError("decoding this model needs the observer's window_hypotheses")
        hypothesis = np.asarray(window_hypotheses(window), dtype=np.int64)
    key = np.column_stack([cell, traps, countdown, q, hypothesis, window.reshape(model.nr_states, -1)])
    key[goal] = -2
    key[fail] = -3
    canonical = _dense_ids(_row_keys(key))
    return DecodedStates(cell=cell, traps=traps, countdown=countdown, q=q, hypothesis=hypothesis,
                         window=window, goal=goal, fail=fail, canonical=canonical,
                         n_canonical=int(canonical.max()) + 1 if canonical.size else 0)


def state_variable(model: object, name: str) -> np.ndarray:
    """The value of an integer PRISM variable in every Storm state (0 where the model has none)."""
    valuations = model.state_valuations
    variables = {v.name: v for v in valuations.get_all_variables()}
    if name not in variables:
        return np.zeros(model.nr_states, dtype=np.int64)
    return np.asarray(valuations.get_int64_values(variables[name]), dtype=np.int64)


def row_keys(rows: np.ndarray) -> np.ndarray:
    """One integer per row of `rows`, equal exactly when the rows are equal, numbered 0..n-1
    in key order: how canonical states are numbered."""
    return _dense_ids(_row_keys(rows))


def _row_keys(rows: np.ndarray) -> np.ndarray:
    """One integer per row, equal exactly when the rows are equal: sorting one column is far
    faster than np.unique(axis=0) on millions of rows."""
    shifted = rows - rows.min(axis=0)
    radix = shifted.max(axis=0) + 1
    if np.sum(np.log2(radix.astype(float))) < 62:
        key = np.zeros(len(rows), dtype=np.int64)
        for column, base in zip(shifted.T, radix):
            key = key * int(base) + column
        return key
    _, inverse = np.unique(rows, axis=0, return_inverse=True)   # keys too wide for int64
    return inverse.reshape(-1)


def _dense_ids(keys: np.ndarray) -> np.ndarray:
    """0..n-1 numbering of the distinct keys, in key order (np.unique's inverse, by sorting:
    numpy 2.4's np.unique is many times slower on millions of keys)."""
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    ids = np.empty(len(keys), dtype=np.int64)
    ids[order] = np.cumsum(np.r_[True, ordered[1:] != ordered[:-1]]) - 1
    return ids


def _count_distinct(keys: np.ndarray) -> int:
    ordered = np.sort(keys)
    return int(len(ordered) > 0) + int(np.count_nonzero(ordered[1:] != ordered[:-1]))


def _label_mask(model: object, label: str) -> np.ndarray:
    return read_structure(model).labels[label]


@dataclass(frozen=True, eq=False)
class Transitions:
    """Every choice of Storm's model: source state, action index (-1 unlabelled), successors."""

    source: np.ndarray
    action: np.ndarray
    row_start: np.ndarray      # successors of choice i: target[row_start[i]:row_start[i+1]]
    target: np.ndarray
    probability: np.ndarray    # of an interval model: the lower bounds
    labels: dict[str, np.ndarray]   # state labels as boolean masks
    upper: np.ndarray | None = None   # of an interval model: the upper bounds


# The last model read and its structure. The model is kept so that its id cannot be reused by
# another model while the entry exists (models of two deviation budgets have the same shape).
_STRUCTURES: dict[int, tuple[object, Transitions]] = {}


def read_structure(model: object) -> Transitions:
    """Storm's transition structure as numpy arrays.

    stormpy offers no array view of the sparse matrix, and walking it entry by entry from
    Python costs seconds per million transitions, so the model goes through Storm's binary
    UMB export (flat little-endian arrays in a tar file) once and is read back with numpy.
    """
    with _STRUCTURE_LOCK:      # two threads asking for one model read it once
        return _read_structure(model)


_STRUCTURE_LOCK = threading.Lock()


def _read_structure(model: object) -> Transitions:
    key = id(model)
    if key in _STRUCTURES and _STRUCTURES[key][0] is model:
        return _STRUCTURES[key][1]
    options = developer.storage.UmbExportOptions()
    options.compression = type(options.compression).NO_COMPRESSION
    with tempfile.TemporaryDirectory(prefix="hg2prism-umb-") as folder:
        archive = Path(folder) / "model.umb"
        export_to_umb(model, str(archive), options=options)
        with tarfile.open(archive) as tar:
            def array(name: str, dtype: type) -> np.ndarray:
                return np.frombuffer(tar.extractfile(name).read(), dtype=dtype)

            state_choices = array("state-to-choices.bin", np.uint64).astype(np.int64)
            row_start = array("choice-to-branches.bin", np.uint64).astype(np.int64)
            target = array("branch-to-target.bin", np.uint64).astype(np.int64)
            probability = array("branch-to-probability.bin", np.float64).copy()
            index = json.loads(tar.extractfile("index.json").read())
            kind = index["transition-system"].get("branch-probability-type", {}).get("type")
            upper = None
            if kind == "double-interval":     # (lower, upper) pairs
                probability, upper = probability[0::2].copy(), probability[1::2].copy()
            action_ids = array("actions/choices/values.bin", np.uint32).astype(np.int64)
            offsets = array("actions/choices/string-mapping.bin", np.uint64).astype(np.int64)
            text = tar.extractfile("actions/choices/strings.bin").read().decode()
            names = [text[offsets[i]:offsets[i + 1]] for i in range(len(offsets) - 1)]
            labels = {}
            for key_name, ap in index.get("annotations", {}).get("aps", {}).items():
                label = ap.get("alias", key_name)
                member = f"annotations/aps/{key_name}/states/values.bin"
                bits = np.unpackbits(array(member, np.uint8), bitorder="little")
                labels[label] = bits[:model.nr_states].astype(bool)
    by_label = {label: i for i, label in enumerate(ACTION_LABELS[a] for a in ACTIONS)}
    action_index = np.array([by_label.get(n, -1) for n in names])
    structure = Transitions(
        source=np.repeat(np.arange(model.nr_states), np.diff(state_choices)),
        action=action_index[action_ids], row_start=row_start, target=target,
        probability=probability, labels=labels, upper=upper)
    _STRUCTURES.clear()
    _STRUCTURES[key] = (model, structure)
    return structure


def transitions(model: object) -> Transitions:
    return read_structure(model)


def canonical_size(decoded: DecodedStates, moves: Transitions) -> tuple[int, int]:
    """docs/semantics.md §6: canonical states, and (state, action, successor) triples after merging."""
    absorbing = decoded.goal | decoded.fail
    counts = np.diff(moves.row_start)
    choice_of_entry = np.repeat(np.arange(len(moves.source)), counts)
    src = moves.source[choice_of_entry]
    keep = ~absorbing[src] & (moves.probability > 0)
    n = decoded.n_canonical   # one integer per (state, action, successor): n*n*5 < 2**63
    key = ((decoded.canonical[src[keep]] * 5 + moves.action[choice_of_entry[keep]] + 1) * n
           + decoded.canonical[moves.target[keep]])
    n_triples = _count_distinct(key)
    loops = int(decoded.goal.any()) + int(decoded.fail.any())
    return decoded.n_canonical, n_triples + loops


def _induced_dtmc(checked: CheckedModel, strategy: StormChoices) -> object:
    matrix = checked.model.transition_matrix
    scheduler = checked.scheduler
    for s in range(checked.model.nr_states):
        local = int(strategy.choice[s]) - matrix.get_row_group_start(s)
        scheduler.set_choice(developer.storage.SchedulerChoice[float](local), s)
    return checked.model.apply_scheduler(scheduler, True)


def _dtmc_value(dtmc: object, prop: str) -> float:
    formula = stormpy.parse_properties(prop)[0]
    result = stormpy.model_checking(dtmc, formula, environment=sound_environment())
    return float(result.get_value_vector()[dtmc.initial_states[0]])


def induced_probability(checked: CheckedModel, strategy: StormChoices,
                        prop: str = 'P=? [F "goal"]') -> float:
    """A property of the DTMC that P1's strategy induces, checked by Storm."""
    return _dtmc_value(_induced_dtmc(checked, strategy), prop)


CONVERGED = 1e-12   # a bounded probability this close to the unbounded one is taken as final


def induced_within(checked: CheckedModel, strategy: StormChoices, horizon: int) -> float:
    """P(goal within `horizon` steps) under P1's strategy. Storm's bounded reachability costs
    one sweep per step, so the bound doubles from 1024 and stops at the horizon or as soon as
    the bounded probability is within CONVERGED of the unbounded one (it only increases
    towards it): a horizon of millions of steps costs what convergence needs."""
    dtmc = _induced_dtmc(checked, strategy)
    unbounded = _dtmc_value(dtmc, 'P=? [F "goal"]')
    bound = min(horizon, 1024)
    while True:
        value = _dtmc_value(dtmc, f'P=? [F<={bound} "goal"]')
        if bound == horizon or value >= unbounded - CONVERGED:
            return value
        bound = min(2 * bound, horizon)


# ---------------------------------------------------------------------------------------------
# Interval models (docs/semantics.md §13)
# ---------------------------------------------------------------------------------------------

def build_interval_model(prism_path: Path) -> tuple[object, dict[str, float]]:
    """Storm's interval MDP of a PRISM model with interval probabilities, with choice labels,
    state valuations and every label; and the parse and build times."""
    timings = {}
    try:
        start = time.perf_counter()
        program = stormpy.parse_prism_program(str(prism_path))
        timings["parse"] = time.perf_counter() - start
        start = time.perf_counter()
        options = developer.BuilderOptions([])
        options.set_build_choice_labels(True)
        options.set_build_state_valuations(True)
        options.set_build_all_labels(True)
        model = stormpy.build_model[stormpy.Interval](program, options=options)
        timings["build"] = time.perf_counter() - start
    except RuntimeError as err:
        raise StormError(f"{prism_path}: {err}") from err
    return model, timings


def check_robust(prism_path: Path, prop: str) -> float:
    """Storm's robust mode on an interval model: the property's value at the initial state, P1
    optimising as `prop` says and the intervals resolved against it. Storm needs every lower
    bound positive, and its robust value iteration is not sound: it stops when an iteration
    changes the values by less than 1e-10 (absolute). A cross-check, not a certified value."""
    try:
        model, _ = build_interval_model(prism_path)
        formula = stormpy.parse_properties(prop)[0]
        env = developer.Environment()
        env.solver().min_max().precision = stormpy.Rational(PRECISION)
        env.solver().min_max().relative_termination_criterion = False
        # Storm warns that it falls back to robust value iteration, its only method here
        level = developer.get_log_level()
        developer.set_log_level(developer.LogLevel.ERR)
        try:
            result = stormpy.model_checking(
                model, formula, environment=env,
                uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.ROBUST)
        finally:
            developer.set_log_level(level)
    except RuntimeError as err:
        raise StormError(f"{prism_path}: {err}") from err
    return float(result.get_value_vector()[model.initial_states[0]])
