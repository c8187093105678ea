"""The world (docs/semantics.md §1) as an immutable value: its grid, task, P2's hypotheses and
observer, and the simulation and detection settings. hg2prism/worldfile/ reads and validates the
TOML world files that make one.

Coordinates: x is the column from the left, y the row from the BOTTOM (both 0-based).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hg2prism.model.arena import Arena

Cell = tuple[int, int]

# Region letters that Spot reads as temporal operators.
FORBIDDEN_REGION_LETTERS = frozenset("FGMRUWX")


@dataclass(frozen=True)
class Grid:
    rows: tuple[str, ...]                 # the map as written, top row first
    width: int
    height: int
    walls: frozenset[Cell]
    obstacles: frozenset[Cell]
    regions: tuple[tuple[str, frozenset[Cell]], ...]   # (letter, cells), letters sorted
    trap_candidates: tuple[Cell, ...]     # map reading order: top row first, left to right
    start: Cell

    def region_letters(self) -> tuple[str, ...]:
        return tuple(letter for letter, _ in self.regions)


@dataclass(frozen=True)
class SimulationSettings:
    episodes: int = 10000
    horizon: int = 200
    seed: int = 0


@dataclass(frozen=True)
class DetectionSettings:
    alpha: float = 0.05
    epsilon: float = 0.01
    deviate_after: int = 4


@dataclass(frozen=True)
class PlayerType:
    """One of P2's possible types (docs/semantics.md §16): her inference as an `[inference]`
    table sets it (kind, window, rationality, the kind's settings), her first guess and the
    prior probability of the type (normalised over the world's types)."""

    name: str
    weight: float
    initial_hypothesis: int
    inference: str
    window: int
    rationality: float
    settings: tuple[tuple[str, object], ...] = ()


@dataclass(frozen=True)
class World:
    path: Path
    name: str
    description: str
    grid: Grid | None                     # None for an arena world
    slip: float
    formula: str
    traps: int
    delay: int
    initial_traps: tuple[Cell, ...]       # empty when delay == 0
    hypotheses: tuple[str, ...]
    initial_hypothesis: int
    window: int
    rationality: float
    simulation: SimulationSettings = field(default_factory=SimulationSettings)
    detection: DetectionSettings = field(default_factory=DetectionSettings)
    inference: str = "cusum"              # P2's observer: its kind (opponent/registry.py)
    # the observer's own [inference] keys as its kind read them, in its kind's order: CUSUM's
    # threshold (§5), the Bayesian prior (normalised) and decision (§12)
    settings: tuple[tuple[str, object], ...] = ()
    # an arena world (docs/semantics.md §15) carries its arena (and `grid` is None), with P2's
    # action standing at the start as an index into A2
    arena: "Arena | None" = None
    initial_standing: int = 0
    # P2's possible types (docs/semantics.md §16; empty: one, as [inference] sets it). The
    # world's own observer is then its first type's; `worldfile.types.world_of_type` gives each
    # type's ordinary world.
    types: tuple[PlayerType, ...] = ()

    def atomic_propositions(self) -> tuple[str, ...]:
        """AP: a grid's are `obs`, then the region letters of the map in alphabetical order;
        an arena world's are its arena's."""
        if self.arena is not None:
            return self.arena.propositions
        return ("obs",) + self.grid.region_letters()

    def setting(self, key: str, default: object = None) -> object:
        """The observer's setting `key` (default when its kind has no such key)."""
        return dict(self.settings).get(key, default)

    # The built-in observers' settings by name, as results and reports read them.
    @property
    def threshold(self) -> float | None:
        return self.setting("threshold")

    @property
    def prior(self) -> tuple[float, ...]:
        return self.setting("prior", ())

    @property
    def decision(self) -> str:
        return self.setting("decision", "map")
