"""Arena worlds built in Python, for tests of the arena core (docs/semantics.md §15) that do
not go through a world file.

`arena_form(world)` is a grid world's arena form: the same world with its grid compiled to the
arena (and no grid), which must give the same values, sizes and strategies.
`lateral(...)` is a small attack-graph arena that is no grid: general P2 actions, a transition
that depends on P2's action, a terminal state, and states with one to three actions.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from hg2prism.frontends import grid
from hg2prism.model.arena import Arena
from hg2prism.model.world import World
from hg2prism.opponent import registry


def arena_form(world: World) -> World:
    return dataclasses.replace(world, front=grid.to_arena(world))


def tables(n_states: int, entries: dict[tuple[int, int, int], dict[int, float]],
           n_actions: int, n_p2: int) -> tuple[np.ndarray, np.ndarray]:
    """dest/prob tables [S, A1max, n_p2, K] from {(s, i, j): {s': p}}."""
    k = max(len(to) for to in entries.values())
    dest = np.zeros((n_states, n_actions, n_p2, k), dtype=np.int64)
    dest[:] = np.arange(n_states)[:, None, None, None]
    prob = np.zeros(dest.shape)
    for (s, i, j), to in entries.items():
        for slot, (target, p) in enumerate(to.items()):
            dest[s, i, j, slot], prob[s, i, j, slot] = target, p
    return dest, prob


def lateral(delay: int = 0, kind: str = "cusum", traps_mode: bool = False) -> World:
    """out -phish-> mail/web; mail -pivot-> db (blocked while P2 watches db) or hr; web -scan->
    db/hr; db and hr carry `crown` and `payroll`; `burnt` is terminal (no actions)."""
    states = ("out", "web", "mail", "db", "hr", "burnt")
    out, web, mail, db, hr, burnt = range(6)
    actions = (("phish", "exploit"), ("scan",), ("pivot_db", "pivot_hr", "wait"), (), (), ())
    p2 = ("idle", "watch_db", "watch_hr")
    entries = {}
    for j in range(3):
        entries[(out, 0, j)] = {mail: 0.6, out: 0.4}
        entries[(out, 1, j)] = {web: 0.5, burnt: 0.2, out: 0.3}
        entries[(web, 0, j)] = {db: 0.3, hr: 0.3, web: 0.4}
        entries[(mail, 0, j)] = {mail: 1.0} if j == 1 else {db: 0.5, mail: 0.5}
        entries[(mail, 1, j)] = {mail: 1.0} if j == 2 else {hr: 0.5, mail: 0.5}
        entries[(mail, 2, j)] = {mail: 1.0}
    n_p2 = 1 if traps_mode else 3
    entries = {key: to for key, to in entries.items() if key[2] < n_p2}
    dest, prob = tables(len(states), entries, 3, n_p2)
    arena = Arena(states=states, initial=out, propositions=("crown", "payroll"),
                  labels=(frozenset(), frozenset(), frozenset(), frozenset({"crown"}),
                          frozenset({"payroll"}), frozenset()),
                  actions=actions, dest=dest, prob=prob,
                  p2_actions=() if traps_mode else p2,
                  trap_candidates=(web, mail) if traps_mode else ())
    world = World(path=Path("lateral.toml"), name="lateral", description="", front=arena,
                  formula="F crown", traps=1 if traps_mode else 0, delay=delay,
                  hypotheses=("F crown", "F payroll"), initial_hypothesis=1,
                  window=2, rationality=1.0, initial_standing=0,
                  settings=(("threshold", 0.6),))
    settings = {"threshold": 0.6} if kind == "cusum" else {}
    return registry.configure(world, kind, **settings)
