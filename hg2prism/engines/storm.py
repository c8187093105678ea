"""Storm through stormpy, the engine of hg2prism/engines/engine.py: build a PRISM model, check
Pmax soundly (docs/semantics.md §§6, 10), hand the built model back as arrays, and check the
chains a fixed strategy induces and interval models (§13). The only module importing stormpy.
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
from types import MappingProxyType
from typing import Callable
from pathlib import Path

import numpy as np
import stormpy
import stormpy.environments as environments
from stormpy import developer
from stormpy.io import export_to_umb

from hg2prism.engines import certify
from hg2prism.engines.engine import (BuiltModel, CheckedModel, PomdpValue, Transitions,
                                    slot_of_label)
from hg2prism.numeric import ExplicitModel
from hg2prism.numeric.chains import CONVERGED
from hg2prism.errors import StormError, probability

PRECISION = "1/10000000000"   # 1e-10, docs/semantics.md §10
ROBUST_MAX_ITERATIONS = 100_000   # Storm's robust value iteration (the cross-check of §13)


def _interruptible(call: Callable[..., object], *args, **kwargs) -> object:
    """call(*args, **kwargs) (a long Storm computation) on a worker thread while the main
    thread waits in short slices, so that Ctrl-C and SIGTERM stop the command while Storm
    computes: Python runs signal handlers only in the main thread between its own steps, and a
    call into Storm is one step however long it runs (Storm's sound solver ran 13 minutes
    deaf to both). Storm releases the GIL. Interrupted, the command unwinds (its staging
    folder removed) and exits while the worker, a daemon thread, is abandoned. Off the main
    thread (a Dask worker, a pool) the call runs right there."""
    if threading.current_thread() is not threading.main_thread():
        return call(*args, **kwargs)
    outcome: dict[str, object] = {}

    def run() -> None:
        try:
            outcome["value"] = call(*args, **kwargs)
        except BaseException as error:     # handed to the main thread
            outcome["error"] = error

    worker = threading.Thread(target=run, name="storm", daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(0.25)
    if "error" in outcome:
        raise outcome["error"]
    return outcome["value"]


def sound_environment() -> developer.Environment:
    env = environments.sound()
    solver = env.solver()
    solver.min_max().precision = stormpy.Rational(PRECISION)
    solver.min_max().relative_termination_criterion = False
    solver.native().precision = stormpy.Rational(PRECISION)
    solver.native().relative_termination_criterion = False
    return env


@dataclass(frozen=True, eq=False)
class StormChecked(CheckedModel):
    """A CheckedModel whose model is a stormpy sparse MDP. Pickled (a Solution sent to another
    process, copy.deepcopy), it keeps its values and sizes but not Storm's model and formula,
    which live in Storm's memory: what needs them then raises a StormError (DETACHED)."""

    def __reduce__(self):
        return _detached, (self.value, self.values, dict(self.timings), self.size,
                           self.alongside)

    @functools.cached_property
    def scheduler(self) -> object:
        """A scheduler object of the model, for `induced_probability` to overwrite (stormpy
        cannot create one). Extracting it during the sound check costs about a fifth of the
        check at 1e6 states, so it comes from a quick plain value iteration, when needed."""
        result = stormpy.model_checking(_attached(self.model), self.formula,
                                        extract_scheduler=True,
                                        environment=solver_environment("fast"))
        return result.get_scheduler()


DETACHED = ("Storm's model is not kept when a solution is pickled or copied (it lives in "
            "Storm's memory): solve the world again in this process for what needs it")


def _detached(value: float, values: np.ndarray, timings: dict, size: tuple,
              alongside: object) -> StormChecked:
    return StormChecked(model=None, value=value, values=values, formula=None,
                        timings=MappingProxyType(timings), size=size, alongside=alongside)


def _attached(model: object) -> object:
    """`model`, unless it was left behind by pickling (None): then a StormError."""
    if model is None:
        raise StormError(DETACHED)
    return model


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
          alongside: Callable[[BuiltModel], object] | None = None) -> StormChecked:
    """Parse, build and solve `prop` (a Pmax reachability property) with one of STORM_METHODS.
    `alongside(explicit model)`, when given, runs on a second thread while Storm solves (Storm
    releases the GIL): its result is the CheckedModel's `alongside`."""
    try:
        return _check(prism_path, prop, method, alongside)
    except RuntimeError as err:  # stormpy reports parse and build failures as RuntimeError
        raise StormError(f"{prism_path}: {err}") from err


def _check(prism_path: Path, prop: str, method: str,
           alongside: Callable[[BuiltModel], object] | None) -> StormChecked:
    solver_environment(method)   # an unknown method fails before the build
    model, formula, timings = build(prism_path, prop)
    start = time.perf_counter()
    with ThreadPoolExecutor(max_workers=1) as pool:
        beside = (pool.submit(lambda: alongside(explicit(model))) if alongside is not None
                  else None)
        values, scheduler = solve(model, formula, method)
        prepared = beside.result() if beside is not None else None
    timings["check"] = time.perf_counter() - start
    initial = model.initial_states[0]
    value = probability(values[initial], "Storm's value at the initial state")
    checked = StormChecked(model=model, value=value, values=values, formula=formula,
                           timings=MappingProxyType(timings), alongside=prepared,
                           size=(model.nr_states, model.nr_transitions, model.nr_choices))
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
    model = _interruptible(stormpy.build_model, program, options=options)
    timings["build"] = time.perf_counter() - start
    return model, properties[0], timings


def solve(model: object, formula: object, method: str = "sound") -> tuple[np.ndarray, object]:
    """The value of every state of `model` for `formula` (Pmax=? [F "goal"] for "sound") by one
    of STORM_METHODS, and a scheduler object of the model when the method made one (else None)."""
    if method == "sound":
        return _certified_values(model, formula)
    result = _interruptible(stormpy.model_checking, model, formula,
                            environment=solver_environment(method))
    return np.asarray(result.get_value_vector()), None


def certificate(model: object, formula: object, max_rounds: int = certify.MAX_ROUNDS,
                perturb: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
                ) -> certify.Certificate:
    """The values of `formula` (a Pmax reachability of the label "goal"), certified by
    engines/certify.py from the strategy that Storm's fast values suggest
    (`certify.initial_strategy`). `perturb(choice, group_start)` may replace that first
    strategy (global choice indices), for tests."""
    result = _interruptible(stormpy.model_checking, model, formula,
                            environment=_rough_environment())
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
    result = _interruptible(stormpy.model_checking, model, formula,
                            environment=sound_environment())
    return np.asarray(result.get_value_vector()), None


def _state_variable(model: object, name: str) -> np.ndarray | None:
    """The value of an integer PRISM variable in every Storm state (None: no such variable)."""
    valuations = model.state_valuations
    variables = {v.name: v for v in valuations.get_all_variables()}
    if name not in variables:
        return None
    return np.asarray(valuations.get_int64_values(variables[name]), dtype=np.int64)


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
    index_type = np.int32 if model.nr_states < 2 ** 31 else np.int64   # states, choices: one copy
    with tempfile.TemporaryDirectory(prefix="hg2prism-umb-") as folder:
        archive = Path(folder) / "model.umb"
        export_to_umb(model, str(archive), options=options)
        with tarfile.open(archive) as tar:
            members = {member.name: member for member in tar.getmembers()}

            def array(name: str, dtype: type) -> np.ndarray:
                """A member's array, read straight from the (uncompressed) archive."""
                member = members[name]
                return np.fromfile(archive, dtype=dtype, offset=member.offset_data,
                                   count=member.size // np.dtype(dtype).itemsize)

            state_choices = array("state-to-choices.bin", np.uint64).view(np.int64)
            row_start = array("choice-to-branches.bin", np.uint64).view(np.int64)
            if row_start[-1] < 2 ** 31:     # as scipy's matrices index them: no copy there
                row_start = row_start.astype(np.int32)
            target = array("branch-to-target.bin", np.uint64).astype(index_type)
            probability = array("branch-to-probability.bin", np.float64)
            index = json.loads(tar.extractfile("index.json").read())
            kind = index["transition-system"].get("branch-probability-type", {}).get("type")
            upper = None
            if kind == "double-interval":     # (lower, upper) pairs
                probability, upper = probability[0::2].copy(), probability[1::2].copy()
            action_ids = array("actions/choices/values.bin", np.uint32)
            offsets = array("actions/choices/string-mapping.bin", np.uint64).astype(np.int64)
            text = tar.extractfile("actions/choices/strings.bin").read().decode()
            names = [text[offsets[i]:offsets[i + 1]] for i in range(len(offsets) - 1)]
            labels = {}
            for key_name, ap in index.get("annotations", {}).get("aps", {}).items():
                label = ap.get("alias", key_name)
                member = f"annotations/aps/{key_name}/states/values.bin"
                bits = np.unpackbits(array(member, np.uint8), bitorder="little")
                labels[label] = bits[:model.nr_states].astype(bool)
    action_index = np.array([slot_of_label(n) for n in names] + [-1], dtype=index_type)
    structure = Transitions(
        source=np.repeat(np.arange(model.nr_states, dtype=index_type), np.diff(state_choices)),
        action=action_index[action_ids], row_start=row_start, target=target,
        probability=probability, labels=labels, upper=upper)
    _STRUCTURES.clear()
    _STRUCTURES[key] = (model, structure)
    return structure


def explicit(model: object) -> BuiltModel:
    """Storm's model as arrays (engines/engine.py): its structure, read once through the UMB
    export, and its state valuations, read per variable when asked."""
    model = _attached(model)
    return BuiltModel(n_states=model.nr_states, initial=int(model.initial_states[0]),
                         transitions=read_structure(model),
                         read_variable=functools.partial(_state_variable, model))


def _induced_dtmc(checked: StormChecked, choice: np.ndarray) -> object:
    matrix = _attached(checked.model).transition_matrix
    scheduler = checked.scheduler
    for s in range(checked.model.nr_states):
        local = int(choice[s]) - matrix.get_row_group_start(s)
        scheduler.set_choice(developer.storage.SchedulerChoice[float](local), s)
    return checked.model.apply_scheduler(scheduler, True)


def _dtmc_value(dtmc: object, prop: str) -> float:
    formula = stormpy.parse_properties(prop)[0]
    result = _interruptible(stormpy.model_checking, dtmc, formula,
                            environment=sound_environment())
    return float(result.get_value_vector()[dtmc.initial_states[0]])


def induced_probability(checked: StormChecked, choice: np.ndarray,
                        prop: str = 'P=? [F "goal"]') -> float:
    """A property of the DTMC that fixing choice[state] (global choice indices) induces,
    checked by Storm."""
    return _dtmc_value(_induced_dtmc(checked, choice), prop)


def induced_within(checked: StormChecked, choice: np.ndarray, horizon: int) -> float:
    """P(goal within `horizon` steps) when P1 takes choice[state] (global choice indices). Storm's bounded reachability costs
    one sweep per step, so the bound doubles from 1024 and stops at the horizon or as soon as
    the bounded probability is within CONVERGED of the unbounded one (it only increases
    towards it): a horizon of millions of steps costs what convergence needs."""
    dtmc = _induced_dtmc(checked, choice)
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

def build_interval_model(prism_path: Path, constants: str
                         ) -> tuple[object, dict[str, float]]:
    """Storm's interval MDP of a PRISM model with interval probabilities, its undefined
    constants defined by `constants` ("eps=0", as Storm's --constants), with choice labels,
    state valuations and every label; and the parse and build times."""
    timings = {}
    try:
        start = time.perf_counter()
        program = stormpy.parse_prism_program(str(prism_path))
        if constants:
            program, _ = stormpy.instantiate_constants(program, constants)
        timings["parse"] = time.perf_counter() - start
        start = time.perf_counter()
        options = developer.BuilderOptions([])
        options.set_build_choice_labels(True)
        options.set_build_state_valuations(True)
        options.set_build_all_labels(True)
        model = _interruptible(stormpy.build_model[stormpy.Interval], program, options=options)
        timings["build"] = time.perf_counter() - start
    except RuntimeError as err:
        raise StormError(f"{prism_path}: {err}") from err
    return model, timings


def check_robust(prism_path: Path, prop: str, constants: str) -> float:
    """Storm's robust mode on an interval model: the property's value at the initial state, P1
    optimising as `prop` says and the intervals resolved against it. Storm needs every lower
    bound positive, and its robust value iteration is not sound: it stops when an iteration
    changes the values by less than 1e-10 (absolute), or after ROBUST_MAX_ITERATIONS
    iterations, its value then as far as it got. A cross-check, not a certified value."""
    try:
        model, _ = build_interval_model(prism_path, constants)
        formula = stormpy.parse_properties(prop)[0]
        env = developer.Environment()
        env.solver().min_max().precision = stormpy.Rational(PRECISION)
        env.solver().min_max().relative_termination_criterion = False
        # capped: on a delay-3 world it was seen iterating for more than ten minutes
        env.solver().min_max().maximal_number_of_iterations = ROBUST_MAX_ITERATIONS
        # Storm warns that it falls back to robust value iteration, its only method here
        level = developer.get_log_level()
        developer.set_log_level(developer.LogLevel.ERR)
        try:
            result = _interruptible(
                stormpy.model_checking, model, formula, environment=env,
                uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.ROBUST)
        finally:
            developer.set_log_level(level)
    except RuntimeError as err:
        raise StormError(f"{prism_path}: {err}") from err
    return float(result.get_value_vector()[model.initial_states[0]])


class StormEngine:
    """Storm as the pipeline's model checker (engines/engine.py ModelChecker)."""

    methods = STORM_METHODS
    sound_methods = SOUND_METHODS

    @property
    def version(self) -> str:
        """Which Storm, for the records (results.software)."""
        import importlib.metadata

        import stormpy.info

        return (f"Storm {stormpy.info.storm_version()} (stormpy "
                f"{importlib.metadata.version('stormpy')})")

    def check(self, prism_path: Path, prop: str, method: str = "sound",
              alongside: Callable[[BuiltModel], object] | None = None) -> StormChecked:
        return check(prism_path, prop, method, alongside)

    def explicit(self, model: object) -> BuiltModel:
        return explicit(model)

    def induced_within(self, checked: StormChecked, choice: np.ndarray, horizon: int) -> float:
        return induced_within(checked, choice, horizon)

    def induced_probability(self, checked: StormChecked, choice: np.ndarray,
                            prop: str = 'P=? [F "goal"]') -> float:
        return induced_probability(checked, choice, prop)

    def build_interval(self, prism_path: Path, constants: str
                       ) -> tuple[object, dict[str, float]]:
        return build_interval_model(prism_path, constants)

    def check_robust(self, prism_path: Path, prop: str, constants: str) -> float:
        return check_robust(prism_path, prop, constants)

    def check_pomdp(self, prism_path: Path, prop: str,
                    max_exploration_time: int | None = None) -> PomdpValue:
        return check_pomdp(prism_path, prop, max_exploration_time)


def check_pomdp(prism_path: Path, prop: str, max_exploration_time: int | None = None
                ) -> PomdpValue:
    """`prop` (a Pmax) on the POMDP of a PRISM file by Storm's belief unfolding
    (stormpy.pomdp.verify_with_belief_unfolding, no clipping): the beliefs reachable from the
    initial one are explored (within `max_exploration_time` seconds, if given) and the belief
    MDP they span is solved."""
    import stormpy.pomdp

    start = time.perf_counter()
    try:
        model, formula, _ = build(prism_path, prop)
        result = stormpy.pomdp.verify_with_belief_unfolding(
            model, formula, max_exploration_time=max_exploration_time)
    except RuntimeError as err:
        raise StormError(f"{prism_path}: {err}") from err
    return PomdpValue(value=float(result.value), completed=bool(result.completed_exploration),
                      states=model.nr_states, observations=model.nr_observations,
                      seconds=time.perf_counter() - start)


STORM = StormEngine()
