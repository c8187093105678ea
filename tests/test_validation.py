"""No World exists unvalidated (issue 25 item 3): every way the API offers to make a variant
(`world.replace`, `dataclasses.replace`, the constructor) refuses a value no world file could
give with one InputError naming the key, in well under a second, before any work."""

from __future__ import annotations

import dataclasses
import time

import pytest

import hg2prism
from conftest import MODELS
from hg2prism.errors import InputError
from hg2prism.model.world import World
from hg2prism.opponent import registry

GRID = hg2prism.load_world(MODELS / "world1.toml")
ARENA = hg2prism.load_world(MODELS / "mir100.toml")
BAYES = hg2prism.load_world(MODELS / "world3_bayes.toml")

GRID_SETTINGS = ("slip",)

# (world, field, invalid value, the key named)
INVALID = [
    (GRID, "rationality", -1.0, "inference.rationality"),
    (GRID, "rationality", float("nan"), "inference.rationality"),
    (GRID, "rationality", 1.7e308, "inference.rationality"),     # overflows P2's ratios
    (GRID, "slip", 0.7, "robot.slip"),
    (GRID, "window", 0, "inference.window"),
    (GRID, "window", 1.5, "inference.window"),
    (GRID, "initial_hypothesis", 7, "adversary.initial_hypothesis"),
    (GRID, "tie_break", "random", "adversary.tie_break"),
    (ARENA, "tie_break", None, "adversary.tie_break"),
    (GRID, "name", "", "name"),
    (GRID, "description", 3, "description"),
    (GRID, "formula", "G obs", "task.formula"),
    (GRID, "formula", "F Q", "task.formula"),
    (GRID, "hypotheses", ("F A", "F A"), "adversary.hypotheses[1]"),
    # the same language in other words (Spot writes "true U A" as "1 U A", not "F A")
    (GRID, "hypotheses", ("F A", "!obs U B", "true U A"), "adversary.hypotheses[2]"),
    (GRID, "hypotheses", (), "adversary.hypotheses"),
    (GRID, "traps", 0, "adversary.traps"),
    (GRID, "traps", 5, "adversary.traps"),
    (GRID, "delay", -1, "adversary.delay"),
    (GRID, "initial_standing", 4, "adversary.initial_traps"),      # 4 candidates, 1 trap
    (GRID, "initial_standing", 1.0, "adversary.initial_traps"),
    (GRID, "inference", "oracle", "inference.kind"),
    (GRID, "settings", (("threshold", 0.0),), "inference.threshold"),
    (GRID, "settings", (), "inference.threshold"),
    (GRID, "settings", (("threshold", 1.0), ("prior", (1.0,))), "inference.prior"),
    (GRID, "simulation", hg2prism.model.world.SimulationSettings(episodes=0), "simulation.episodes"),
    (GRID, "simulation", hg2prism.model.world.SimulationSettings(horizon=10**6),
     "simulation.horizon"),
    (GRID, "simulation", hg2prism.model.world.SimulationSettings(seed=-1), "simulation.seed"),
    (GRID, "detection", hg2prism.model.world.DetectionSettings(alpha=1.0), "detection.alpha"),
    (GRID, "detection", hg2prism.model.world.DetectionSettings(epsilon=0.0), "detection.epsilon"),
    (GRID, "detection", hg2prism.model.world.DetectionSettings(deviate_after=-2),
     "detection.deviate_after"),
    (GRID, "front", "8x8", "front"),                               # no front end's value
    (ARENA, "traps", 13, "adversary.traps"),
    (ARENA, "formula", "F asset99", "task.formula"),
    (ARENA, "initial_standing", -1, "adversary.initial_traps"),
    (BAYES, "initial_hypothesis", 1, "adversary.initial_hypothesis"),
    (BAYES, "settings", (("prior", (0.5, 0.25, 0.25)), ("decision", "map")), "inference.prior"),
    (BAYES, "settings", (("prior", (2.0, 1.0)), ("decision", "map")), "inference.prior"),
    (BAYES, "settings", (("prior", (0.5, 0.5)), ("decision", "vote")), "inference.decision"),
]


@pytest.mark.parametrize("world, name, value, key", INVALID,
                         ids=[f"{w.name}-{n}-{v!r}"[:60] for w, n, v, _ in INVALID])
def test_every_way_to_make_a_variant_validates(world: World, name: str, value: object,
                                               key: str) -> None:
    # a grid world's own settings (its robot's slip) live in its Grid (the grid front end):
    # dataclasses.replace and the constructor reach them through the `front` field
    change = ({"front": dataclasses.replace(world.grid, **{name: value})}
              if name in GRID_SETTINGS else {name: value})
    _every_way_refuses(world, {name: value}, change, key)


def _every_way_refuses(world: World, changes: dict, fields: dict, key: str,
                       reason: str = "") -> None:
    """`world.replace(**changes)`, and `dataclasses.replace` and the constructor with the
    World `fields` that say the same, each raise one InputError naming `key` (and `reason`)
    and the world's file, in under a second."""
    makers = {"World.replace": lambda: world.replace(**changes),
              "dataclasses.replace": lambda: dataclasses.replace(world, **fields),
              "World(...)": lambda: World(**{**{f.name: getattr(world, f.name)
                                                for f in dataclasses.fields(world)},
                                             **fields})}
    for how, make in makers.items():
        start = time.perf_counter()
        with pytest.raises(InputError) as caught:
            make()
        assert time.perf_counter() - start < 1.0, how
        assert caught.value.key == key, (how, str(caught.value))
        assert reason in str(caught.value), (how, str(caught.value))
        assert caught.value.file == str(world.path)
        assert "\n" not in str(caught.value)


def test_the_arena_standing_action_is_checked_when_it_stands() -> None:
    standing = ARENA.replace(delay=1, initial_standing=11)        # 12 candidates, 1 trap
    assert standing.initial_standing == 11
    with pytest.raises(InputError, match="adversary.initial_traps"):
        ARENA.replace(delay=1, initial_standing=12)
    # with delay 0 it is what a re-solve with delay starts from: checked alike
    assert ARENA.delay == 0 and ARENA.replace(initial_standing=11).initial_standing == 11
    with pytest.raises(InputError, match=r"adversary.initial_traps: P2's standing action a "
                                         r"re-solve with delay > 0 starts from \(delay is 0\) "
                                         r"\(initial_standing = 12\) must index one of her 12"):
        ARENA.replace(initial_standing=12)


def test_valid_variants_pass_and_keep_every_other_field() -> None:
    variant = GRID.replace(rationality=2.5, window=3, slip=0.0, initial_hypothesis=2)
    assert (variant.rationality, variant.window, variant.grid.slip,
            variant.initial_hypothesis) == (2.5, 3, 0.0, 2)
    assert variant.replace(rationality=GRID.rationality, window=GRID.window,
                           slip=GRID.grid.slip, initial_hypothesis=GRID.initial_hypothesis) == GRID
    delayed = GRID.replace(delay=2, initial_standing=0)
    assert delayed.delay == 2
    # the observer's own settings change through the registry, P2's first guess following
    skewed = registry.configure(BAYES, prior=(1.0, 3.0))
    assert skewed.initial_hypothesis == 1 and skewed.prior == (0.25, 0.75)


def test_the_loader_and_the_world_share_one_rule() -> None:
    """The same key and reason from a world file and from a variant."""
    text = (MODELS / "world1.toml").read_text().replace("slip = 0.1", "slip = 0.7")
    assert "slip = 0.7" in text
    with pytest.raises(InputError) as from_file:
        hg2prism.world_from_toml(text, name=str(GRID.path))
    with pytest.raises(InputError) as from_variant:
        GRID.replace(slip=0.7)
    assert str(from_file.value) == str(from_variant.value)


def test_a_name_that_is_no_setting_is_refused() -> None:
    """world.replace(name=...) for a name that no world (or no world of this kind) has."""
    with pytest.raises(InputError) as caught:
        GRID.replace(speed=2)
    assert caught.value.key == "speed" and "slip" in str(caught.value)
    with pytest.raises(InputError) as caught:
        ARENA.replace(slip=0.1)             # an arena's outcomes are its own: no slip
    assert caught.value.key == "slip"


# ---------------------------------------------------------------------------------------------
# A world with P2's types (docs/semantics.md §16): World.types is validated like the rest
# ---------------------------------------------------------------------------------------------

TYPED = hg2prism.load_world(MODELS / "world4.toml")
JUMPY, STUBBORN = TYPED.types


def _typed(*types):
    return tuple(types)


# (the types, the key named, a piece of the reason)
INVALID_TYPES = [
    (_typed(JUMPY), "type", "at least two types"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, weight=-0.5)), "type[1].weight", ">= 0"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, weight=float("inf"))), "type[1].weight",
     "finite"),
    (_typed(dataclasses.replace(JUMPY, weight=0.0), dataclasses.replace(STUBBORN, weight=0.0)),
     "type", "sum to 0"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, weight=0.25)), "type", "sum to 0.75"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, name="jumpy")), "type[1].name", "repeated"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, name=" ")), "type[1].name", "not be empty"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, window=0)), "type[1].inference.window", ">= 1"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, rationality=0.0)),
     "type[1].inference.rationality", "> 0"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, initial_hypothesis=2)),
     "type[1].initial_hypothesis", "index into hypotheses"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, settings=(("threshold", -1.0),))),
     "type[1].inference.threshold", "threshold"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, inference="oracle")), "type[1].inference.kind",
     "unknown inference kind"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, inference="bayes",
                                       settings=(("prior", (0.5, 0.5)), ("decision", "sample")))),
     "type[1].inference.decision", "not allowed for a type"),
    (_typed(JUMPY, dataclasses.replace(STUBBORN, weight=0.25), dataclasses.replace(
        STUBBORN, name="third", weight=0.25, window=2, rationality=-3.0)),
     "type[2].inference.rationality", "> 0"),
    (_typed(JUMPY, "stubborn"), "type[1]", "PlayerType"),
]


@pytest.mark.parametrize("types, key, reason", INVALID_TYPES,
                         ids=[f"{k}-{r}" for _, k, r in INVALID_TYPES])
def test_every_way_to_make_a_typed_variant_validates(types, key, reason) -> None:
    _every_way_refuses(TYPED, {"types": types}, {"types": types}, key, reason)


def test_the_world_s_own_observer_is_its_first_type_s() -> None:
    """Types reordered: World.replace brings the new first type's observer (window,
    rationality, settings, ...) as the world's own, unless the call gives them too (then they
    must agree); dataclasses.replace and the constructor, which take the fields as given,
    refuse a world whose own observer is not its first type's."""
    reordered = _typed(STUBBORN, JUMPY)
    swapped = TYPED.replace(types=reordered)
    assert [getattr(swapped, name) for name in ("window", "rationality", "settings")] == \
        [STUBBORN.window, STUBBORN.rationality, STUBBORN.settings]
    with pytest.raises(InputError) as caught:
        TYPED.replace(types=reordered, window=JUMPY.window + 7)
    assert caught.value.key == "type[0]" and "first type's" in caught.value.reason
    for make in (lambda: dataclasses.replace(TYPED, types=reordered),
                 lambda: World(**{**{f.name: getattr(TYPED, f.name)
                                     for f in dataclasses.fields(TYPED)}, "types": reordered})):
        with pytest.raises(InputError) as caught:
            make()
        assert caught.value.key == "type[0]" and "first type's" in caught.value.reason


def test_a_list_of_types_is_taken_by_replace_only() -> None:
    """World.replace takes the types as a list too (values as Python gives them, docs/api.md);
    the constructor and dataclasses.replace want what a World holds, a tuple."""
    assert TYPED.replace(types=[JUMPY, STUBBORN]) == TYPED.replace(types=(JUMPY, STUBBORN))
    for make in (lambda: dataclasses.replace(TYPED, types=[JUMPY, STUBBORN]),
                 lambda: World(**{**{f.name: getattr(TYPED, f.name)
                                     for f in dataclasses.fields(TYPED)},
                                  "types": [JUMPY, STUBBORN]})):
        with pytest.raises(InputError) as caught:
            make()
        assert caught.value.key == "type" and "tuple" in str(caught.value)


def test_a_typed_world_keeps_its_own_observer_its_first_types() -> None:
    """A change of the world's own observer that its first type does not share is refused;
    the same change through the type passes; the prior may move (weights summing to 1)."""
    with pytest.raises(InputError) as caught:
        TYPED.replace(window=2)
    assert caught.value.key == "type[0]"
    assert caught.value.reason.startswith("the world's own window (2) and its first type's (")
    # settings as a world file writes them, not a tuple of pairs
    with pytest.raises(InputError) as caught:
        TYPED.replace(settings=(("threshold", 2.0),))
    assert caught.value.reason.startswith("the world's own settings (threshold = 2.0) and its "
                                          "first type's (threshold = "), caught.value.reason
    moved = TYPED.replace(window=2, types=(dataclasses.replace(JUMPY, window=2), STUBBORN))
    assert moved.types[0].window == 2
    weighted = TYPED.replace(types=(dataclasses.replace(JUMPY, weight=0.0),
                                    dataclasses.replace(STUBBORN, weight=1.0)))
    assert [t.weight for t in weighted.types] == [0.0, 1.0]


@pytest.mark.parametrize("old, new, key", [
    ("window = 3", "window = 0", "type[1].inference.window"),
    ("rationality = 10.0\n\n[[type]]", "rationality = -1.0\n\n[[type]]",
     "type[0].inference.rationality"),
    ('name = "stubborn"', 'name = "jumpy"', "type[1].name"),
])
def test_the_loader_and_a_typed_variant_share_one_rule(old, new, key) -> None:
    """The same key and reason from a world file and from a variant of its World (the file's
    says where its entry starts, which a World cannot)."""
    text = (MODELS / "world4.toml").read_text()
    assert old in text
    with pytest.raises(InputError) as from_file:
        hg2prism.world_from_toml(text.replace(old, new, 1), name=str(TYPED.path))
    field = {"type[1].inference.window": (1, "window", 0),
             "type[0].inference.rationality": (0, "rationality", -1.0),
             "type[1].name": (1, "name", "jumpy")}[key]
    types = list(TYPED.types)
    types[field[0]] = dataclasses.replace(types[field[0]], **{field[1]: field[2]})
    change = {"types": tuple(types)}
    if field[0] == 0:
        change[field[1]] = field[2]
    with pytest.raises(InputError) as from_variant:
        TYPED.replace(**change)
    assert from_file.value.key == key
    entry = [n for n, line in enumerate(text.splitlines(), 1) if line == "[[type]]"][field[0]]
    assert str(from_file.value) == f"{from_variant.value} (the entry at line {entry})"


def test_rationality_at_its_largest_is_accepted() -> None:
    """1e100 itself is allowed, the next double above it is not (P2's ratios stay finite)."""
    import math

    from hg2prism.errors import InputError

    assert GRID.replace(rationality=1e100).rationality == 1e100
    with pytest.raises(InputError, match="at most 1e"):
        GRID.replace(rationality=math.nextafter(1e100, math.inf))
