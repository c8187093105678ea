"""The interface every model of P2's inference implements (docs/semantics.md §5, §12).

P2 observes P1's moves and keeps a memory from which she reads her current hypothesis about P1's
task. An observer says what that memory is, how one observation updates it, which hypothesis P2
acts on, and how all of it is written into the hypergame's PRISM model. The hypergame, Storm's
decoding, the strategy export and the simulations use only this interface, so a new observer
(the Bayesian one of §12) is one new module beside `inference.py` (CUSUM) and its template.
An observer may also implement `ReportsBelief`, the per-hypothesis numbers its decisions rest
on, which the figures and the replay of an episode show (§8 "The episode drawn").
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from hg2prism.model.dynamics import TransitionSystem

# (TS state, P1's action index into dynamics.ACTIONS, the trap set in force during the step).
# The CUSUM observer reads only the first two (its memory has no trap sets, §5); the Bayesian
# one records all three (§12). A two-element observation is accepted where a2 is not needed.
Observation = tuple[int, ...]


@dataclass(frozen=True)
class Memory:
    """P2's memory as every observer keeps it: the hypothesis she acts on and her window of
    observations, oldest first. For CUSUM the hypothesis is state (§5) and the window holds
    (TS state, action) pairs; for the Bayesian observer the window is the whole memory, holding
    (TS state, action, trap set) triples, and the hypothesis is its MAP hypothesis (§12), kept
    beside it for reports (it is a function of the window, so equality is unaffected)."""

    hypothesis: int
    window: tuple[Observation, ...] = ()


@dataclass(frozen=True)
class ObserverPrism:
    """An observer's part of the hypergame model: PRISM text for the formulas (its tables,
    placed before the modules) and for its module, plus what decoding Storm's states needs."""

    formulas: str
    module: str
    slots: int                 # observation slots o1 (oldest) .. o{slots} in the module
    commands: int              # commands of its module (the module is "p2_inference")
    slot_sets: bool = False    # slots also hold the trap set in force (o<i>_set)
    hypothesis_variable: bool = True   # `hyp` is a variable (else derived from the slots)
    # Set when P2 draws her hypothesis at each step: the robot module that draws it jointly
    # with the move (it replaces the hypergame's robot and p2_traps modules).
    robot: str = ""
    header: str = ""           # the header line describing the inference, if not CUSUM's


class Observer(Protocol):
    """P2's inference: memory, update, the hypothesis she acts on, and its PRISM rendering."""

    kind: str                  # the world file's `[inference] kind`
    window: int
    initial_hypothesis: int

    @property
    def n_hypotheses(self) -> int: ...

    def initial_memory(self) -> Memory:
        """P2's memory before the first move."""

    def update(self, memory: Memory, observation: Observation) -> Memory:
        """P2's memory after P1 plays `observation[1]` from TS state `observation[0]` while
        the trap set `observation[2]` was in force."""

    def hypothesis(self, memory: Memory) -> int:
        """The hypothesis P2 acts on (for an observer that draws, the most probable one)."""

    def hypothesis_distribution(self, memory: Memory) -> tuple[tuple[int, float], ...]:
        """(hypothesis, probability) pairs P2 draws the hypothesis she plays from at this step;
        a single pair with probability 1 for a deterministic observer."""

    def prism(self, ts: TransitionSystem, labels: dict[str, str],
              observed: np.ndarray | None = None, played: str | None = None) -> ObserverPrism:
        """The observer written into the hypergame model over `ts`; `labels` maps each move
        to its synchronisation label; `observed` ([n_states - 1] bool, default all) marks the
        TS states the robot can reach, where its tables must be right (elsewhere they are free
        to take whatever values keep them short); `played`, when P2 may play another trap set
        than her prediction (the robust model of docs/semantics.md §13), the variable holding
        the set she played."""


@runtime_checkable
class ReportsBelief(Protocol):
    """An observer that can show, step by step, the per-hypothesis numbers its decision rests
    on (the replay and `belief.png` draw them; docs/semantics.md §8 "The episode drawn"). The
    CUSUM observer reports its scores Z_x, compared with its threshold; the Bayesian observer
    reports its posterior p(x | W), with no threshold."""

    belief_name: str           # what the numbers are, for axis labels ("CUSUM score Z_x")

    @property
    def belief_threshold(self) -> float | None:
        """The level at which P2 changes her mind (None when the rule has no threshold)."""

    def belief(self, memory: Hashable, observation: Observation) -> Sequence[float]:
        """One number per hypothesis: what P2 computes when she reads `observation` with
        memory `memory` (before her update)."""
