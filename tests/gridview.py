"""A grid world's TS read in cells, for tests of the grid semantics (docs/semantics.md §2).

Below the grid front end the TS knows arena states only; these tests speak of cells (x, y), so
they read them through the front end's geometry, as the grid drawing does."""

from __future__ import annotations

from hg2prism.frontends import grid


def initial_trap_cells(world) -> tuple:
    """The cells of the traps standing at the start (empty when delay is 0)."""
    if not world.delay:
        return ()
    chosen = grid.trap_sets(world.grid, world.traps)[world.initial_standing]
    return tuple(world.grid.trap_candidates[c] for c in chosen)


class GridView:
    def __init__(self, world, ts) -> None:
        self.ts = ts
        geo = grid.geometry(world)
        self.cells, self.cell_index = geo.cells, geo.cell_index

    def trap_cells(self, a2: int) -> tuple:
        return tuple(self.cells[p] for p in self.ts.trap_places(a2))

    def describe_state(self, state: int) -> dict:
        """The grid form of a TS state: {cell, traps, countdown} (all None for trapped)."""
        ts = self.ts
        if state == ts.trapped:
            return {"cell": None, "traps": None, "countdown": None}
        cell, traps, countdown = ts.decode(state)
        if ts.delay == 0:
            return {"cell": list(self.cells[cell]), "traps": None, "countdown": None}
        return {"cell": list(self.cells[cell]),
                "traps": [list(c) for c in self.trap_cells(traps)], "countdown": countdown}

    def __getattr__(self, name: str):
        return getattr(self.ts, name)        # everything else is the TS's


def view(analysis) -> GridView:
    """The grid view of an analysis's TS."""
    return GridView(analysis.world, analysis.ts)
