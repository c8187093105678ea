"""Storm through stormpy: build the hypergame model, check Pmax, export the strategy (SPEC §6).

Storm's states encode (v, q_prev, M) with the DFA one step behind, so several of them can be
one canonical state (v, q, M) of SPEC §6; `canonical_states` maps each to its canonical id.
"""

from __future__ import annotations

import json
import tarfile
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import stormpy
import stormpy.environments as environments
from stormpy import developer
from stormpy.core._io import export_to_umb

from hg2prism.automata import DFA
from hg2prism.dynamics import ACTIONS, TransitionSystem
from hg2prism.hypergame import Layout

PRECISION = "1/10000000000"   # 1e-10, SPEC §10


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
    choices: np.ndarray            # scheduler: local choice index of every Storm state
    scheduler: object              # stormpy scheduler (for the DTMC it induces)
    timings: dict[str, float]      # parse, build, check


def check(prism_path: Path, prop: str) -> CheckedModel:
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

    start = time.perf_counter()
    result = stormpy.model_checking(model, properties[0], extract_scheduler=True,
                                    environment=sound_environment())
    values = np.asarray(result.get_value_vector())
    scheduler = result.get_scheduler()
    choices = np.array([scheduler.get_choice(s).get_deterministic_choice()
                        for s in range(model.nr_states)], dtype=np.int64)
    timings["check"] = time.perf_counter() - start
    initial = model.initial_states[0]
    return CheckedModel(model=model, value=float(values[initial]), values=values,
                        choices=choices, scheduler=scheduler, timings=timings)


def induced_probability(checked: CheckedModel, prop: str = 'P=? [F "goal"]') -> float:
    """A property of the DTMC that the exported scheduler induces, checked by Storm."""
    dtmc = checked.model.apply_scheduler(checked.scheduler, True)
    formula = stormpy.parse_properties(prop)[0]
    result = stormpy.model_checking(dtmc, formula, environment=sound_environment())
    return float(result.get_value_vector()[dtmc.initial_states[0]])


@dataclass(frozen=True, eq=False)
class DecodedStates:
    """Storm's states as SPEC §6 hypergame states."""

    cell: np.ndarray          # cell index (layout.trapped_cell once trapped)
    traps: np.ndarray         # standing trap set (0 when delay is 0)
    countdown: np.ndarray
    q: np.ndarray             # DFA state after reading the current cell's label
    hypothesis: np.ndarray
    window: np.ndarray        # [n, slots, 2] (TS state, action), -1 for empty slots
    goal: np.ndarray          # bool
    fail: np.ndarray          # bool
    canonical: np.ndarray     # canonical id; goal states share one id, failure states another
    n_canonical: int


def decode_states(model: object, layout: Layout, ts: TransitionSystem, task: DFA) -> DecodedStates:
    valuations = model.state_valuations
    variables = {v.name: v for v in valuations.get_all_variables()}

    def column(name: str) -> np.ndarray:
        if name not in variables:
            return np.zeros(model.nr_states, dtype=np.int64)
        return np.asarray(valuations.get_int64_values(variables[name]), dtype=np.int64)

    cell = column("cell")
    label = np.append(ts.cell_label, 0)[cell]
    q = task.delta[column("q"), label]
    window = np.stack([np.stack([column(s), column(a)], axis=1)
                       for s, a in (layout.slot_variables(i) for i in range(1, layout.slots + 1))],
                      axis=1) if layout.slots else np.zeros((model.nr_states, 0, 2), dtype=np.int64)
    goal = _label_mask(model, "goal")
    fail = _label_mask(model, "fail")
    traps, countdown, hypothesis = column("traps"), column("countdown"), column("hyp")
    key = np.column_stack([cell, traps, countdown, q, hypothesis, window.reshape(model.nr_states, -1)])
    key[goal] = -2
    key[fail] = -3
    _, canonical = np.unique(key, axis=0, return_inverse=True)
    canonical = canonical.reshape(-1)
    return DecodedStates(cell=cell, traps=traps, countdown=countdown, q=q, hypothesis=hypothesis,
                         window=window, goal=goal, fail=fail, canonical=canonical,
                         n_canonical=int(canonical.max()) + 1 if canonical.size else 0)


def _label_mask(model: object, label: str) -> np.ndarray:
    return read_structure(model).labels[label]


@dataclass(frozen=True, eq=False)
class Transitions:
    """Every choice of Storm's model: source state, action index (-1 unlabelled), successors."""

    source: np.ndarray
    action: np.ndarray
    row_start: np.ndarray      # successors of choice i: target[row_start[i]:row_start[i+1]]
    target: np.ndarray
    probability: np.ndarray
    labels: dict[str, np.ndarray]   # state labels as boolean masks


_STRUCTURES: dict[int, Transitions] = {}


def read_structure(model: object) -> Transitions:
    """Storm's transition structure as numpy arrays.

    stormpy offers no array view of the sparse matrix, and walking it entry by entry from
    Python costs seconds per million transitions, so the model goes through Storm's binary
    UMB export (flat little-endian arrays in a tar file) once and is read back with numpy.
    """
    key = id(model)
    if key in _STRUCTURES and _STRUCTURES[key].source.size == model.nr_choices:
        return _STRUCTURES[key]
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
            action_ids = array("actions/choices/values.bin", np.uint32).astype(np.int64)
            offsets = array("actions/choices/string-mapping.bin", np.uint64).astype(np.int64)
            text = tar.extractfile("actions/choices/strings.bin").read().decode()
            names = [text[offsets[i]:offsets[i + 1]] for i in range(len(offsets) - 1)]
            index = json.loads(tar.extractfile("index.json").read())
            labels = {}
            for key_name, ap in index.get("annotations", {}).get("aps", {}).items():
                label = ap.get("alias", key_name)
                member = f"annotations/aps/{key_name}/states/values.bin"
                bits = np.unpackbits(array(member, np.uint8), bitorder="little")
                labels[label] = bits[:model.nr_states].astype(bool)
    action_index = np.array([ACTIONS.index(n) if n in ACTIONS else -1 for n in names])
    structure = Transitions(
        source=np.repeat(np.arange(model.nr_states), np.diff(state_choices)),
        action=action_index[action_ids], row_start=row_start, target=target,
        probability=probability, labels=labels)
    _STRUCTURES.clear()
    _STRUCTURES[key] = structure
    return structure


def transitions(model: object) -> Transitions:
    return read_structure(model)


def canonical_size(decoded: DecodedStates, moves: Transitions) -> tuple[int, int]:
    """SPEC §6: canonical states, and (state, action, successor) triples after merging."""
    absorbing = decoded.goal | decoded.fail
    counts = np.diff(moves.row_start)
    choice_of_entry = np.repeat(np.arange(len(moves.source)), counts)
    src = moves.source[choice_of_entry]
    keep = ~absorbing[src] & (moves.probability > 0)
    triples = np.column_stack([decoded.canonical[src[keep]], moves.action[choice_of_entry[keep]],
                               decoded.canonical[moves.target[keep]]])
    n_triples = len(np.unique(triples, axis=0)) if len(triples) else 0
    loops = int(decoded.goal.any()) + int(decoded.fail.any())
    return decoded.n_canonical, n_triples + loops


def strategy_records(decoded: DecodedStates, checked: CheckedModel, moves: Transitions,
                     ts: TransitionSystem) -> list[dict]:
    """P1's deceptive strategy: one record per reachable non-absorbing canonical state."""
    model = checked.model
    matrix = model.transition_matrix
    seen = set()
    records = []
    for s in range(model.nr_states):
        if decoded.goal[s] or decoded.fail[s]:
            continue
        c = int(decoded.canonical[s])
        if c in seen:
            continue
        seen.add(c)
        row = matrix.get_row_group_start(s) + int(checked.choices[s])
        cell = int(decoded.cell[s])
        state = ts.state(cell, int(decoded.traps[s]), int(decoded.countdown[s]))
        record = ts.describe_state(state)
        record["q"] = int(decoded.q[s])
        record["hypothesis"] = int(decoded.hypothesis[s])
        record["window"] = [dict(ts.describe_state(int(v)), action=ACTIONS[int(a)])
                            for v, a in decoded.window[s] if v >= 0]
        record["action"] = ACTIONS[int(moves.action[row])]
        records.append(record)
    return records
