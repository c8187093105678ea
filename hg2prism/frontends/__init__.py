"""Front ends: each kind of world file compiles to the arena (model/arena.py) that the
pipeline plays on. `grid` compiles grid worlds; arena worlds carry their arena already."""

from __future__ import annotations

from hg2prism.model.arena import Arena
from hg2prism.model.dynamics import TransitionSystem, build_transition_system
from hg2prism.model.world import World


def arena_of(world: World) -> Arena:
    if world.arena is not None:
        return world.arena
    from hg2prism.frontends import grid

    return grid.to_arena(world)


def initial_standing(world: World) -> int:
    """P2's action standing at the start (an index into A2; 0 when delay is 0)."""
    if world.arena is not None:
        return world.initial_standing
    from hg2prism.frontends import grid

    return grid.initial_standing(world)


def transition_system(world: World) -> TransitionSystem:
    """The world's TS (docs/semantics.md §§2, 15)."""
    return build_transition_system(arena_of(world), world.traps, world.delay,
                                   initial_standing(world))
