"""The interface every model of P2's inference implements (docs/semantics.md §5, §12).

P2 observes P1's moves and keeps a memory from which she reads her current hypothesis about P1's
task. An observer says what that memory is, how one observation updates it and which hypothesis
P2 acts on. The hypergame, Storm's
decoding, the strategy export and the simulations use only this interface; `ObserverKind` is
what the rest of the package knows of each kind of observer (the world file's keys, how to
build it, its PRISM renderer, its memory's size), and `registry.py` holds one per kind, so a
new observer is one new module beside `inference.py` (CUSUM) and `bayes.py` (§12), with its
renderer (in the module, as its kind's `render`, or in prism/observers.py with a template), and
one registration line (docs/architecture.md, "How to add …", for the PRISM model's contract).
An observer may also implement `ReportsBelief`, the per-hypothesis numbers its decisions rest
on, which the figures and the replay of an episode show (§8 "The episode drawn").
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

    from hg2prism.model.world import World
    from hg2prism.opponent.perceptual_games import PerceptualGame

# (TS state, P1's action slot at that state, P2's action in force during the step).
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


def p2_action_count(world: "World") -> int:
    """|A2|: P2's general actions, or the number of trap sets (docs/semantics.md §15)."""
    import math

    from hg2prism.frontends import arena_of

    arena = arena_of(world)
    if not arena.traps_mode:
        return len(arena.p2_actions)
    return math.comb(len(arena.trap_candidates), world.traps)


# Within this of each other two numbers a rule compares are equal: CUSUM's scores against the
# threshold and against each other (§5), the Bayesian log-posteriors (§12), in Python and in
# the PRISM model alike.
TOLERANCE = 1e-9


class Observer(Protocol):
    """P2's inference: memory, update and the hypothesis she acts on (its PRISM rendering is
    its kind's `render`). One whose PRISM part keeps no `hyp` variable (the hypothesis a
    function of the window) also gives `window_hypotheses(window)`, by which the engine's
    states are decoded (prism/decoding.py)."""

    kind: str                  # the world file's `[inference] kind`
    window: int
    initial_hypothesis: int
    # P2 draws the hypothesis she plays at each step (`hypothesis_distribution` may give
    # several), so P1 predicts her traps by a mixture (§12 "sample")
    draws: bool

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


@dataclass(frozen=True)
class Setting:
    """One key of the world file's [inference] table that belongs to a kind of observer
    (docs/semantics.md §1), beside `kind`, `window` and `rationality`, which every kind has."""

    key: str
    expected: str              # what a value must be, for messages ("a number > 0")
    # (the world loader, the value as written, the number of hypotheses) -> the value kept in
    # World.settings; it raises the loader's InputError (loader.fail) on a bad value
    read: Callable[[Any, object, int], object]
    # the value when the key is absent, from the number of hypotheses; None: the key is required
    default: Callable[[int], object] | None = None
    # how `hg2prism sweep` reads its values (experiments/sweep.py); None: it cannot be swept
    swept: Swept | None = None


@dataclass(frozen=True)
class Swept:
    """How `hg2prism sweep --param KEY` reads a setting's values, typed on the command line or
    given in Python (experiments/sweep.py parses them; `Setting.read` then checks them against
    the world): a number (of `kind`, above `minimum`, or at least it unless `exclusive`), a
    word, or positive numbers (comma-separated when typed), turned by `normalise` into the
    value kept (a prior: normalised)."""

    form: str                  # "number", "word" or "numbers"
    expected: str              # what a swept value must be, for messages
    kind: type = float
    minimum: float = 0.0
    exclusive: bool = True
    normalise: Callable[[list[float]], object] | None = None


@dataclass(frozen=True)
class MemoryBound:
    """What the size guard (model/sizeguard.py) needs to bound P2's memories: beside the
    window of at most `observations` walks, how many hypotheses the memory holds (1 when the
    window determines it) and how many trap sets each observation may record (1: none)."""

    hypotheses: int
    observations: int
    sets_per_observation: int = 1
    # each observation records the set P2 played (so where she may play any set, as in robust
    # deception's interval model, it may record any of them)
    records: bool = False
    # where known (from P2's solved games): per TS state, how many sets an observation made
    # there may record; replaces sets_per_observation
    sets_at: np.ndarray | None = None


@dataclass(frozen=True)
class Mismatch:
    """P2's real inference in the detection experiment's other mismatch (docs/semantics.md §9):
    the world with her settings, the label and reason shown, and the setting the report shows
    beside her window (`p2_<setting>` in detection.json, ObserverKind.shown_setting: CUSUM's
    threshold, the Bayesian decision)."""

    label: str
    world: World
    why: str
    shown: object


def window_mismatches(world: World, shown: object) -> list[Mismatch]:
    """The variants every kind's detection experiment has: P2 remembers one more observation,
    and one fewer when she remembers more than one."""
    windows = [(world.window + 1, "window + 1")]
    if world.window - 1 >= 1:
        windows.append((world.window - 1, "window - 1"))
    return [Mismatch(f"window {window}", replace(world, window=window), why, shown)
            for window, why in windows]


@dataclass(frozen=True)
class ObserverKind:
    """Everything the package knows of one kind of observer, registered under the world
    file's `[inference] kind` (opponent/registry.py): its keys, how to build it from a world,
    its part of the PRISM model, its memory's size, and what the detection experiment varies."""

    name: str                                  # `[inference] kind`
    title: str                                 # "the <title> observer" in messages
    settings: tuple[Setting, ...]
    build: Callable[[World, list[PerceptualGame]], Observer]
    memory: Callable[[World], MemoryBound]
    # (world, the largest CUSUM score P2 reached when following the model, vary) -> P2's
    # variants; vary(world, **settings) is the world with other settings of its observer
    # (registry.configure: the opponent layer does not import the registry above it)
    mismatches: Callable[[World, float, Callable[..., World]], list[Mismatch]]
    report: Callable[[World], dict]            # P1's model of P2 in detection.json
    # the setting the detection experiment shows beside P2's window (a Mismatch's `shown`:
    # detection.json's `p2_<setting>`); None: her window alone
    shown_setting: str | None = None
    # the bound once P2's games are solved, when they make it tighter (None: `memory` only)
    solved_memory: Callable[[World, list[PerceptualGame]], MemoryBound] | None = None
    # P2's first hypothesis from the settings, and the rule in words ("the prior's most
    # probable hypothesis"); None: [adversary] initial_hypothesis
    first_guess: Callable[[dict], int] | None = None
    first_guess_rule: str = ""
    # (observer, ts, labels, observed, played) -> its part of the PRISM model, an
    # ObserverPrism: a renderer of prism/observers.py, attached by registry.register (so
    # that opponent/ does not import prism/, which imports it)
    render: Callable[..., Any] | None = None

    def keys(self) -> tuple[str, ...]:
        return tuple(setting.key for setting in self.settings)
