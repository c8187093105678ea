"""Front ends: one module per kind of world file. Each reads its kind's own tables into the
world's front-end value (`World.front`, a model.world.Front) and compiles a world of its kind to
the arena (model/arena.py) that the pipeline plays on; nothing below the front ends sees more
than the arena. `grid` compiles grid worlds; an arena world's value is its arena.

A new kind of world is one module (any importable one, by its dotted name) with the names
below and one line in FRONT_ENDS (docs/architecture.md, "How to add …", "A world kind"):

  KIND                 its name: the `kind` of its front-end value
  FILE_TABLES          its files' own top-level tables, {table: required?}; the first marks a
                       file of this kind
  TABLE_KEYS           {table: {key: required?}} of those tables
  ADVERSARY_KEYS       its [adversary] keys, {key: required?} (hypotheses and
                       initial_hypothesis are every world's)
  MISSING_HINT         {"table.key": what a missing required key expects}
  DESCRIBED            its files in a message ("a grid world ([grid] and [robot])")
  read(ld, root)       the front-end value of a parsed file (`ld`: worldfile/loader.py's reader,
                       a model.validation.Checks whose typed getters string, integer, number,
                       array, traps, delay and fail raise the one-line errors, and whose
                       table(root, name) reads one of its tables with its keys checked; the
                       file's [adversary] is a table by then, for a kind whose own value needs
                       some of it, such as its trap candidates)
  read_adversary(ld, adv, front)   the World fields traps, delay, initial_standing
  to_arena(world)      the world's arena
  describe(world)      the world in a few words (`hg2prism validate`)
  outcome_name(action, outcome)    how an outcome of P1's action is named
  standing_candidates(world)       trap candidates standing at the start of a re-solved world
  parameters(world)    its own parameters, as results.json echoes them
  SETTINGS             its own sweep parameters (frontends/settings.py: Setting)
  STANDING_RULE        how a sweep point's standing action at the start is chosen
and optionally
  standing_action(world)           with general P2 actions: the action standing at the start of
                                   a re-solved world (an index into A2)
  DRAWER               "module.Class" of what draws its worlds, made with (world, ts)
                       (default: the arena as a graph, report/arena_graph.py)
"""

from __future__ import annotations

import importlib
from types import ModuleType

from hg2prism.model.arena import Arena
from hg2prism.model.dynamics import TransitionSystem, build_transition_system
from hg2prism.model.world import World

# The front ends by kind, in the order a world file's tables are tried and messages list them.
FRONT_ENDS = {
    "grid": "hg2prism.frontends.grid",
    "arena": "hg2prism.frontends.arena",
}


def front_ends() -> tuple[ModuleType, ...]:
    """Every front end's module, in FRONT_ENDS order."""
    return tuple(importlib.import_module(name) for name in FRONT_ENDS.values())


def front_end(world: World) -> ModuleType:
    """The module of the world's front end; InputError when no front end of its kind is
    registered (a World made while one was)."""
    kind = kind_of(world)
    if kind not in FRONT_ENDS:
        from hg2prism.errors import InputError

        raise InputError(str(world.path), "front", f"no front end of kind {kind!r} is registered "
                         "(hg2prism.frontends.FRONT_ENDS: " + ", ".join(FRONT_ENDS) + ")")
    return importlib.import_module(FRONT_ENDS[kind])


def kind_of(world: World) -> str:
    """The world's kind: its front end's name ("grid", "arena")."""
    return world.front.kind


def kind_words(world: World | str, plural: bool = False) -> str:
    """A world's kind (or a kind's name) in a sentence: "a grid world", "an arena world",
    plural "grid worlds" (its front end's DESCRIBED)."""
    module = (importlib.import_module(FRONT_ENDS[world]) if isinstance(world, str)
              else front_end(world))
    words = module.DESCRIBED.split(" (")[0]
    return words.split(" ", 1)[1] + "s" if plural else words


def counted(n: int, thing: str) -> str:
    """"1 trap candidate", "3 trap candidates"."""
    return f"{n} {thing}" + ("" if n == 1 else "s")


def describe(world: World) -> str:
    """What the world is made of, in a few words (`hg2prism validate`)."""
    return front_end(world).describe(world)


def outcome_name(world: World, action: str, outcome: int) -> str:
    """How the world's front end names outcome `outcome` of P1's action `action` (a grid: the
    direction the robot went; an arena: "outcome k")."""
    return front_end(world).outcome_name(action, outcome)


def sweep_settings():
    """(kind, Setting) for every front end's own sweep parameters."""
    return tuple((module.KIND, setting) for module in front_ends()
                 for setting in module.SETTINGS)


def arena_of(world: World) -> Arena:
    """The arena the world plays on (docs/semantics.md §15)."""
    return front_end(world).to_arena(world)


def transition_system(world: World) -> TransitionSystem:
    """The world's TS (docs/semantics.md §§2, 15)."""
    return build_transition_system(arena_of(world), world.traps, world.delay,
                                   world.initial_standing)


def standing_candidates(world: World) -> tuple[int, ...]:
    """In trap mode, the trap candidates (numbers) a re-solved world with a positive delay keeps
    standing at the start: the world's standing set (`initial_standing`, which a world with
    delay 0 keeps as its file names it, else the first)."""
    return front_end(world).standing_candidates(world)


def standing_action(world: World) -> int:
    """With general P2 actions (arena worlds only), the action a re-solved world with a
    positive delay keeps standing at the start: the world's `initial_standing` (a front end
    without `standing_action` too)."""
    own = getattr(front_end(world), "standing_action", None)
    if own is None:
        return world.initial_standing
    return own(world)


def standing_rule(world: World) -> str:
    """How a sweep point's standing action at the start is chosen, in the front end's words."""
    return front_end(world).STANDING_RULE


def parameters(world: World) -> dict[str, object]:
    """The front end's own parameters, as results.json echoes them (frontends/grid.py: parameters)."""
    return front_end(world).parameters(world)


def drawer(world: World, ts: TransitionSystem):
    """The front end's drawer of the world (its DRAWER, such as frontends/grid_drawing.py's),
    or None: the caller draws the arena as a graph."""
    name = getattr(front_end(world), "DRAWER", None)
    if name is None:
        return None
    module, _, cls = name.rpartition(".")
    return getattr(importlib.import_module(module), cls)(world, ts)
