"""The arena: the two-player transition system of docs/semantics.md §15 (the paper's
Definition 1), the one form every world takes below its front end.

An arena lists its states by name, their labels, P1's actions at each state with the
distribution over successors (which may depend on P2's action), and P2's actions: either
general (named) or trap sets over candidate states (the trap rule then applies). How many
traps P2 sets, the delay and the standing action are the world's adversary settings; with
them `model.dynamics.build_transition_system` unfolds the arena into the TS the pipeline plays on.

Tables are numpy arrays padded to the largest number of actions and outcomes:

  dest[s, i, j, k]  the k-th successor of P1's i-th action at s when P2 plays j
  prob[s, i, j, k]  its probability (0 on padding, where dest is s itself)

j runs over P2's actions when some transition depends on them, else has length 1.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from hg2prism.model.validation import Checks, Vocabulary

# Why an arena world's P2 cannot set more traps than it has candidates (Checks.traps)
TRAPS_BEYOND = ("there are only {n} trap candidates; expected traps <= the number of "
                "trap_candidates")


@dataclass(frozen=True, eq=False)
class Arena:
    """The arena; also an arena world's front-end value (model.world.Front: `World.front`)."""

    kind: ClassVar[str] = "arena"
    replaceable: ClassVar[frozenset[str]] = frozenset()

    states: tuple[str, ...]                   # S, in order: the state numbering
    initial: int                              # s0
    propositions: tuple[str, ...]             # AP
    labels: tuple[frozenset[str], ...]        # L(s) per state
    actions: tuple[tuple[str, ...], ...]      # P1's actions at each state (none: terminal)
    # (left out of repr: a notebook shows a world in a few lines, its tables are shown by
    # hg2prism convert's world file)
    dest: np.ndarray = field(repr=False)      # [S, A1max, 1 or |A2|, K] successor state
    prob: np.ndarray = field(repr=False)      # [S, A1max, 1 or |A2|, K] its probability
    p2_actions: tuple[str, ...] = ()          # general P2 actions A2, in order (else traps)
    trap_candidates: tuple[int, ...] = ()     # trap mode: the states P2 may set traps on
    positions: tuple[tuple[float, float], ...] | None = None   # for drawing

    def __eq__(self, other: object) -> bool:
        """Equal tables make equal arenas (so two loads of one world file give equal Worlds;
        numpy's arrays compare by value here, not by identity)."""
        if not isinstance(other, Arena):
            return NotImplemented
        return all(np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b
                   for a, b in ((getattr(self, f.name), getattr(other, f.name))
                                for f in dataclasses.fields(self)))

    def __hash__(self) -> int:
        return hash((self.states, self.initial, self.propositions, self.p2_actions,
                     self.trap_candidates))

    @property
    def n_states(self) -> int:
        return len(self.states)

    @property
    def n_actions(self) -> int:
        """The largest number of P1 actions at a state (the tables' padding)."""
        return self.dest.shape[1]

    @property
    def traps_mode(self) -> bool:
        return not self.p2_actions

    @property
    def p2_dependent(self) -> bool:
        """Whether some transition depends on P2's action."""
        return self.dest.shape[2] > 1

    @property
    def enabled(self) -> np.ndarray:
        """[S, A1max] bool: is P1's i-th action available at s."""
        counts = np.array([len(a) for a in self.actions], dtype=np.int64)
        return np.arange(self.n_actions)[None, :] < counts[:, None]

    @property
    def terminal(self) -> np.ndarray:
        """[S] bool: states without actions, where an episode ends."""
        return np.array([not a for a in self.actions], dtype=bool)

    def index(self, name: str) -> int:
        return self.states.index(name)

    # -- as an arena world's front (model.world.Front) ------------------------------------------

    def vocabulary(self) -> Vocabulary:
        return Vocabulary(self.propositions, "the arena's propositions ("
                          + (", ".join(self.propositions) or "none") + ")")

    def check(self, checks: Checks) -> None:
        """The initial state is not terminal (an episode would end before P1 moves: nothing
        to decide); the rest the arena file's reader (frontends/arena.py) checked."""
        if not self.actions[self.initial]:
            raise checks.fail("arena.initial", f"{self.states[self.initial]!r} is terminal (no "
                              "[[arena.transition]] entry): the episode would end before P1 "
                              "moves; start at a state with an action")

    def count_p2_actions(self, checks: Checks, traps: object) -> tuple[int, str]:
        """|A2| and the key of P2's standing action: the traps-subsets of the candidates, or
        the general actions (traps must then be 0)."""
        if self.traps_mode:
            traps = checks.traps(traps, len(self.trap_candidates), TRAPS_BEYOND)
            return math.comb(len(self.trap_candidates), traps), "adversary.initial_traps"
        if traps != 0:
            raise checks.fail("adversary.traps", "P2 has general actions (adversary.actions): "
                                                 f"traps must be 0, got {traps!r}")
        return len(self.p2_actions), "adversary.initial_action"

    def label_classes(self) -> tuple[tuple[frozenset[str], ...], np.ndarray]:
        """The label classes and each state's class: class 0 is the empty label, then one
        class per proposition (that proposition alone) in the order of `propositions`, then
        any other label a state carries, by first occurrence over the states."""
        classes: list[frozenset[str]] = [frozenset()] + [frozenset({p}) for p in self.propositions]
        of = np.empty(self.n_states, dtype=np.int64)
        for s, label in enumerate(self.labels):
            if label not in classes:
                classes.append(label)
            of[s] = classes.index(label)
        return tuple(classes), of


def class_name(label: frozenset[str], order: tuple[str, ...]) -> str:
    """A label class's name: its propositions in `order`, joined by '&' ("" when empty)."""
    return "&".join(p for p in order if p in label)
