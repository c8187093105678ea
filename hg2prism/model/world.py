"""The world (docs/semantics.md §1) as an immutable value: what its front end reads (`front`: a
grid world's `Grid`, an arena world's `Arena`, any `Front`), the task, P2's traps, delay,
hypotheses and observer, and the simulation and detection settings. hg2prism/worldfile/ reads and
validates the TOML world files that make one; hg2prism/frontends/ turns each kind into the arena
the pipeline plays on; every World is validated when made (model/validation.py).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, Protocol

from hg2prism.model import validation

if TYPE_CHECKING:
    from hg2prism.model.arena import Arena
    from hg2prism.model.validation import Checks, Vocabulary


class Front(Protocol):
    """What the model asks of a world's front-end value (`World.front`): the part of the world
    only its kind's files say (a grid's map and robot, an arena world's arena). The front end
    (hg2prism/frontends/, one module per kind) reads it from a file and compiles it with the
    rest of the world to the arena; the model only validates it through these."""

    kind: ClassVar[str]                   # the front end's name (frontends/__init__.py: FRONT_ENDS)
    # the value's fields World.replace may change by name (a grid's robot); none for an arena
    replaceable: ClassVar[frozenset[str]]

    def vocabulary(self) -> Vocabulary:
        """The atomic propositions formulas may use, and how messages describe them."""

    def check(self, checks: Checks) -> None:
        """Raise checks.fail(key, reason) at the first own value no world file could give."""

    def count_p2_actions(self, checks: Checks, traps: object) -> tuple[int, str]:
        """Check P2's `traps` for this front (checks.fail on a bad one) and give the number of
        P2's actions A2 with the key naming her standing action in a world file."""


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


# Fields added after digests were first written, left out of the digest at their default, so
# that a world that does not use them keeps its digest (and its output folders).
_LATER = {"tie_break": "first", "of_type": ""}
_NONE = object()


@dataclass(frozen=True)
class World:
    path: Path
    name: str
    description: str
    # what the world's front end reads (a `Front`: a frontends.grid.Grid, a model.arena.Arena;
    # the model does not import the front ends)
    front: Front
    formula: str
    traps: int
    delay: int
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
    # P2's action standing at the start when delay > 0, an index into A2 (the trap sets in
    # combinations order, or the arena's P2 actions). With delay 0 nothing stands: it is then
    # the one a re-solve with a positive delay starts from (a sweep over delay), as the file
    # names it (initial_traps, initial_action), else 0
    initial_standing: int = 0
    # which of the tied actions P2 takes where the standing one is not tied (docs/semantics.md
    # §4): "first" (the rule: the lowest number) or "last", to see what the tie decides
    tie_break: str = "first"
    # P2's possible types (docs/semantics.md §16; empty: one, as [inference] sets it). The
    # world's own observer is then its first type's; `worldfile.types.world_of_type` gives each
    # type's ordinary world.
    types: tuple[PlayerType, ...] = ()
    # the name of P2's type this world was made for (`worldfile.types.world_of_type`: the world
    # of a file with [[type]] in which P2 is of that type), which its records name (`p2_type`);
    # empty for a world as its file gives it
    of_type: str = ""

    def __post_init__(self) -> None:
        # no World exists unvalidated, however made (docs/api.md): InputError naming the key
        validation.validate(self)

    def replace(self, **changes: object) -> World:
        """This world with `changes` (field names: rationality=2.0, window=3, ...; a grid
        world's own robot settings too), validated: InputError(file, key, reason) on a value
        no world file could give or on a name that is no setting of this world. Values are
        taken as Python gives them: a list where the World holds a tuple (hypotheses, types),
        numpy's numbers as Python's (window=np.int64(3)). Another number of traps without
        initial_standing keeps the standing traps as a sweep does: the first of them, then the
        first other candidates (dynamics.carried_standing). New `types` bring the world's own
        observer (inference, window, rationality, settings, initial_hypothesis) from the first
        type where those are not given too, since a world with types observes as its first."""
        changes = {name: plain(value) for name, value in changes.items()}
        if isinstance(changes.get("path"), str):       # as Python gives it: a path's text
            changes["path"] = Path(changes["path"])
        own = {name: value for name, value in changes.items() if name in _FIELDS}
        first = own.get("types") or ()
        if isinstance(first, tuple) and first and isinstance(first[0], PlayerType):
            for name in validation.OBSERVER_FIELDS:
                own.setdefault(name, getattr(first[0], name))
            own.setdefault("of_type", "")       # no longer the world of one of the types
        if "traps" in own and own["traps"] != self.traps and "initial_standing" not in own:
            own["initial_standing"] = self._carried_standing(own["traps"], "front" in own)
        front = {name: value for name, value in changes.items() if name not in _FIELDS}
        if front:
            replaceable = getattr(own.get("front", self.front), "replaceable", frozenset())
            if not set(front) <= replaceable:
                from hg2prism.errors import InputError

                known = _FIELDS | replaceable
                unknown = sorted(set(front) - known)[0]
                current = own.get("front", self.front)
                if unknown in {f.name for f in dataclasses.fields(current)}:
                    raise InputError(str(self.path), unknown, f"part of this {current.kind} "
                                     "world's own description (its map or graph), which replace "
                                     "does not change: write the changed world as a world "
                                     "file (or world_from_toml's text)"
                                     + (f"; its own settings: {', '.join(sorted(replaceable))}"
                                        if replaceable else ""))
                if unknown in dict(self.settings):
                    raise InputError(str(self.path), unknown, "a setting of P2's observer: "
                                     "change it with hg2prism.opponent.registry.configure("
                                     f"world, {unknown}=...)")
                raise InputError(str(self.path), unknown, "not a setting of this world; expected "
                                 "one of " + ", ".join(sorted(known)))
            own["front"] = dataclasses.replace(own.get("front", self.front), **front)
        return dataclasses.replace(self, **own)

    def _carried_standing(self, traps: object, new_front: bool) -> int:
        """The standing trap set for another number of traps, as a sweep carries it (the first
        of the world's standing traps, then the first other candidates); 0 when it cannot be
        (another front, a number of traps validation will refuse)."""
        from hg2prism.model.dynamics import carried_standing, trap_set_at

        n = len(getattr(self.front, "trap_candidates", ()))
        if (new_front or not isinstance(traps, int) or isinstance(traps, bool)
                or not 1 <= traps <= n or not 1 <= self.traps <= n):
            return 0
        return carried_standing(n, trap_set_at(n, self.traps, self.initial_standing), traps)

    @property
    def grid(self) -> object | None:
        """A grid world's map and robot (frontends/grid.py: Grid); None for another kind."""
        return self.front if getattr(self.front, "kind", None) == "grid" else None

    @property
    def arena(self) -> "Arena | None":
        """An arena world's arena (docs/semantics.md §15); None for another kind (the arena a
        world of any kind plays on is frontends.arena_of(world))."""
        return self.front if getattr(self.front, "kind", None) == "arena" else None

    def digest(self) -> str:
        """"sha256:<hex>" of everything the world says but where its file is (its path) and the
        name of the type it was made for (`of_type`: its description says so already, and a
        type's world had its digest before it had that field): two worlds with one digest are
        the same world. The records of an output folder carry it
        (`world_digest`), so that a command on an edited world file does not leave the old
        version's outputs beside its own (outputs.staged)."""
        import hashlib
        import json

        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                  if f.name not in ("path", "of_type")
                  and getattr(self, f.name) != _LATER.get(f.name, _NONE)}
        text = json.dumps(_canonical(fields), sort_keys=True, separators=(",", ":"))
        return "sha256:" + hashlib.sha256(text.encode()).hexdigest()

    def atomic_propositions(self) -> tuple[str, ...]:
        """AP, as the front end gives them: an arena's own, a grid map's obs and region letters."""
        return self.front.vocabulary().propositions

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


def _canonical(value: object) -> object:
    """`value` as plain JSON data, the same for equal values: dataclasses as tables of their
    fields, sets sorted, tuples as lists, numpy numbers as Python's, an array as its dtype,
    shape and the sha256 of its bytes (C order)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {"__" + type(value).__name__: {f.name: _canonical(getattr(value, f.name))
                                              for f in dataclasses.fields(value)}}
    if isinstance(value, dict):
        return {str(key): _canonical(item) for key, item in value.items()}
    if isinstance(value, (set, frozenset)):
        items = [_canonical(item) for item in value]
        return sorted(items, key=lambda item: json_text(item))
    if isinstance(value, (list, tuple)):
        return [_canonical(item) for item in value]
    if hasattr(value, "tolist") and getattr(value, "ndim", 0) > 0:      # a numpy array
        import hashlib

        import numpy as np

        data = np.ascontiguousarray(value)
        return {"__array": [data.dtype.str, list(data.shape),
                            hashlib.sha256(data.tobytes()).hexdigest()]}
    if hasattr(value, "tolist"):            # a numpy number
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return repr(value)


def json_text(value: object) -> str:
    import json

    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def plain(value: object, sequence: type = tuple) -> object:
    """A value given through the API as a world file would give it: a list or tuple as a
    `sequence` (tuple for a World's fields, list for world-file tables) of plain values, a
    table's values plain, a numpy number as the Python number it equals (np.int64(3) -> 3);
    anything else (a PlayerType, a settings dataclass, text) as it is, for validation to
    judge. The one place numpy's numbers become Python's."""
    if isinstance(value, dict):
        return {key: plain(item, sequence) for key, item in value.items()}
    if isinstance(value, (list, tuple)) and not hasattr(value, "_fields"):
        return sequence(plain(item, sequence) for item in value)
    if type(value).__module__ == "numpy" and getattr(value, "ndim", 1) == 0:
        return value.item()
    return value


def _fields(value: object) -> frozenset[str]:
    return frozenset(f.name for f in dataclasses.fields(value))


_FIELDS = _fields(World)
