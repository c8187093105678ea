"""Front ends: each kind of world file compiles to the arena (model/arena.py) that the
pipeline plays on. `grid` compiles grid worlds; arena worlds carry their arena already."""

from __future__ import annotations

from hg2prism.model.arena import Arena
from hg2prism.model.dynamics import TransitionSystem, build_transition_system
from hg2prism.model.world import World


def kind_of(world: World) -> str:
    """The world's kind: "grid" or "arena"."""
    return "arena" if world.arena is not None else "grid"


def counted(n: int, thing: str) -> str:
    """"1 trap candidate", "3 trap candidates"."""
    return f"{n} {thing}" + ("" if n == 1 else "s")


def describe(world: World) -> str:
    """What the world is made of, in a few words (`hg2prism validate`)."""
    if world.arena is None:
        return world.grid.describe()
    arena = world.arena
    p2 = (counted(len(arena.trap_candidates), "trap candidate") if arena.traps_mode
          else counted(len(arena.p2_actions), "P2 action"))
    return f"arena of {arena.n_states} states, {p2}"


def outcome_name(world: World, action: str, outcome: int) -> str:
    """How the world's front end names outcome `outcome` of P1's action `action` (a grid: the
    direction the robot went); "outcome k" for an arena world."""
    if world.arena is None:
        from hg2prism.frontends import grid

        return grid.outcome_name(action, outcome)
    return f"outcome {outcome}"


def sweep_settings():
    """(kind, Setting) for every front end's own sweep parameters."""
    from hg2prism.frontends import grid

    return tuple(("grid", setting) for setting in grid.SETTINGS)


def arena_of(world: World) -> Arena:
    if world.arena is not None:
        return world.arena
    from hg2prism.frontends import grid

    return grid.to_arena(world)


def transition_system(world: World) -> TransitionSystem:
    """The world's TS (docs/semantics.md §§2, 15)."""
    return build_transition_system(arena_of(world), world.traps, world.delay,
                                   world.initial_standing)


def standing_candidates(world: World) -> tuple[int, ...]:
    """In trap mode, the trap candidates (numbers) a re-solved world with a positive delay keeps
    standing at the start: the world's own standing set when its delay is positive; a grid world
    with delay 0 may name them in its file (frontends/grid.py); otherwise none."""
    if world.arena is None:
        from hg2prism.frontends import grid

        return grid.standing_candidates(world)
    if not world.delay:
        return ()
    from hg2prism.model.dynamics import a2_actions

    return tuple(a2_actions(world.arena, world.traps)[1][world.initial_standing])


def parameters(world: World) -> dict[str, object]:
    """The front end's own parameters, as results.json echoes them (frontends/grid.py: parameters)."""
    if world.arena is None:
        from hg2prism.frontends import grid

        return grid.parameters(world)
    return {}
