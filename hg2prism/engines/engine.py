"""What the pipeline needs from a model checker (docs/semantics.md §§6, 10, 13): the interface
every engine implements, and the engine-neutral values it hands back.

An engine builds a model from a PRISM file, checks a `Pmax` reachability property by one of its
methods (some of them sound), and hands back the built model explicitly: every choice with its
action and successors, the state labels, and the value of each PRISM variable in every state.
Decoding those values as hypergame states is the hypergame layout's business
(hg2prism/prism/decoding.py), choosing strategies the strategy package's: neither imports an
engine. engines/storm.py implements the interface with Storm; `hg2prism.engines.default()`
returns it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from collections.abc import Mapping
from typing import Callable, Protocol

import numpy as np


def action_label(slot: int) -> str:
    """The action label of P1's action slot `slot` in every model hg2prism writes: a<slot>
    (prism/arena_tables.py); an engine reads choice labels back with `slot_of_label`."""
    return f"a{slot}"


def slot_of_label(label: str) -> int:
    """The action slot of a choice label a<i>; -1 for any other label (unlabelled choices,
    the robust model's step_a<i>)."""
    if label.startswith("a") and label[1:].isdigit():
        return int(label[1:])
    return -1


@dataclass(frozen=True, eq=False)
class Transitions:
    """Every choice of a built model: source state, action index (-1 unlabelled), successors."""

    source: np.ndarray
    action: np.ndarray         # P1's action slot (choice label a<i>), -1 for other labels
    row_start: np.ndarray      # successors of choice i: target[row_start[i]:row_start[i+1]]
    target: np.ndarray
    probability: np.ndarray    # of an interval model: the lower bounds
    labels: dict[str, np.ndarray]   # state labels as boolean masks
    upper: np.ndarray | None = None   # of an interval model: the upper bounds


@dataclass(frozen=True, eq=False)
class BuiltModel:
    """A built model as arrays: its transitions and labels, its initial state, and the value of
    each integer PRISM variable in every state (read on demand: `variable`)."""

    n_states: int
    initial: int
    transitions: Transitions
    read_variable: Callable[[str], np.ndarray | None]   # None: the model has no such variable

    def variable(self, name: str, default: int | None = None) -> np.ndarray:
        """The value of PRISM variable `name` in every state. An engine may leave out a
        variable whose value never changes (Storm does): then every state has `default`, its
        initial value (the model's Layout knows it); without a default that is an error, not
        a silent 0."""
        values = self.read_variable(name)
        if values is not None:
            return values
        if default is None:
            raise KeyError(f"the built model has no variable {name!r}")
        return np.full(self.n_states, default, dtype=np.int64)


@dataclass(frozen=True, eq=False)
class CheckedModel:
    """A model built and checked: the property's value at the initial state and in every state."""

    model: object                  # the engine's own model (for the engine's other methods)
    value: float
    values: np.ndarray             # value of every state
    formula: object                # the checked property, as the engine parsed it
    timings: Mapping[str, float]   # parse, build, check (read-only)
    size: tuple[int, int, int]     # the engine's states, transitions and choices
    alongside: object = None       # what check(..., alongside=...) computed beside the engine


@dataclass(frozen=True)
class PomdpValue:
    """A POMDP's Pmax by belief exploration (docs/semantics.md §16): the value found (a lower
    bound of the maximum), whether the exploration of the reachable beliefs completed (then the
    value is the belief MDP's), the POMDP's size and the time taken."""

    value: float
    completed: bool
    states: int
    observations: int
    seconds: float


class ModelChecker(Protocol):
    """A model checker the pipeline, the experiments and the API can use."""

    methods: tuple[str, ...]         # how Pmax may be solved; the first is the default
    sound_methods: tuple[str, ...]   # those certified to 1e-10 (docs/semantics.md §10)
    # (optional) its name and version, for the records' `software` (results.software)

    def check(self, prism_path: Path, prop: str, method: str,
              alongside: Callable[[BuiltModel], object] | None = None) -> CheckedModel:
        """Build the PRISM model at `prism_path` and solve `prop` (Pmax=? [F "goal"]) with
        `method`; `alongside(explicit model)` runs while the engine solves."""

    def explicit(self, model: object) -> BuiltModel:
        """The engine's built model (CheckedModel.model, or an interval model) as arrays."""

    def induced_within(self, checked: CheckedModel, choice: np.ndarray, horizon: int) -> float:
        """P(goal within `horizon` steps) in the chain that fixing choice[state] (a global
        choice index per state) induces."""

    def induced_probability(self, checked: CheckedModel, choice: np.ndarray,
                            prop: str = 'P=? [F "goal"]') -> float:
        """A property of the chain that fixing choice[state] induces."""

    def build_interval(self, prism_path: Path, constants: str
                       ) -> tuple[object, dict[str, float]]:
        """The interval MDP of a PRISM model with interval probabilities (docs/semantics.md
        §13), its undefined constants defined by `constants` ("eps=0"), and the parse and
        build times."""

    def check_robust(self, prism_path: Path, prop: str, constants: str) -> float:
        """`prop` at the initial state of an interval model (its undefined constants defined
        by `constants`), the intervals resolved against P1: a cross-check, not a certified
        value."""

