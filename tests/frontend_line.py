"""A third kind of world, a corridor, as a front end defined here alone (tests/test_front_ends.py
registers it): what a new kind of world is (hg2prism/frontends/__init__.py lists the names).

  [line]
  cells = ["", "", "B", "", "A"]   the corridor's cells, left to right, each with its letter
                                   (a proposition) or "" for none; at least two
  start = 0                        optional, the robot's first cell (default 0)
  advance = 0.9                    optional, in (0, 1]: a step goes to the next cell with this
                                   probability and stays otherwise
  [adversary]
  traps = 1                        as a grid's, over
  candidates = [1, 3]              the cells (numbers) P2 may set traps on; no delay

P1 walks "left" or "right" at every cell (the ends stop her: a step off the corridor stays).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from hg2prism.frontends.settings import Setting
from hg2prism.model.arena import Arena
from hg2prism.model.validation import Vocabulary

ACTIONS = ("left", "right")


@dataclass(frozen=True)
class Line:
    """A corridor world's own values: its front-end value (model.world.Front)."""

    kind: ClassVar[str] = "line"
    replaceable: ClassVar[frozenset[str]] = frozenset({"advance"})

    cells: tuple[str, ...]
    start: int
    candidates: tuple[int, ...]
    advance: float = 0.9

    def vocabulary(self) -> Vocabulary:
        letters = tuple(sorted({c for c in self.cells if c}))
        return Vocabulary(letters, "the corridor's letters (" + ", ".join(letters) + ")")

    def check(self, checks) -> None:
        advance = checks.number(self.advance, "line.advance")
        if not 0.0 < advance <= 1.0:
            raise checks.fail("line.advance", f"must be in (0, 1], got {advance}")

    def count_p2_actions(self, checks, traps: object) -> tuple[int, str]:
        traps = checks.traps(traps, len(self.candidates),
                             "the corridor has only {n} candidates")
        return math.comb(len(self.candidates), traps), "adversary.initial_traps"


# -- the front end (hg2prism/frontends/__init__.py) -------------------------------------------

KIND = Line.kind
FILE_TABLES = {"line": True}
TABLE_KEYS = {"line": {"cells": True, "start": False, "advance": False}}
ADVERSARY_KEYS = {"traps": True, "candidates": True}
MISSING_HINT = {"line.cells": "an array of the cells' letters (\"\" for none)",
                "adversary.candidates": "an array of cell numbers"}
DESCRIBED = "a corridor world ([line])"
SETTINGS = ()                          # set below: Setting("advance", ...)
STANDING_RULE = "none: a corridor world has no delay"


def read(ld, root: dict) -> Line:
    table = ld.table(root, "line")          # its keys: TABLE_KEYS["line"]
    cells = tuple(ld.string(c, f"line.cells[{i}]")
                  for i, c in enumerate(ld.array(table["cells"], "line.cells", "an array")))
    if len(cells) < 2:
        raise ld.fail("line.cells", f"a corridor has at least two cells, got {len(cells)}")
    start = ld.integer(table.get("start", 0), "line.start", 0)
    if start >= len(cells):
        raise ld.fail("line.start", f"must be a cell number below {len(cells)}, got {start}")
    adv = root["adversary"]                 # a table (the loader checked it)
    candidates = tuple(ld.integer(c, f"adversary.candidates[{i}]", 0)
                       for i, c in enumerate(ld.array(adv.get("candidates", []),
                                                      "adversary.candidates", "an array")))
    if any(c >= len(cells) for c in candidates) or len(set(candidates)) < len(candidates):
        raise ld.fail("adversary.candidates", "must be distinct cell numbers")
    return Line(cells=cells, start=start, candidates=candidates,
                advance=ld.number(table.get("advance", 0.9), "line.advance"))


def read_adversary(ld, adv: dict, line: Line) -> dict:
    traps = ld.traps(adv["traps"], len(line.candidates), "the corridor has only {n} candidates")
    return dict(traps=traps, delay=0, initial_standing=0)


def to_arena(world) -> Arena:
    line = world.front
    n = len(line.cells)
    dest = np.empty((n, 2, 1, 2), dtype=np.int64)
    prob = np.empty((n, 2, 1, 2))
    for s in range(n):
        for a, step in enumerate((-1, 1)):
            dest[s, a, 0] = (min(max(s + step, 0), n - 1), s)
            prob[s, a, 0] = (line.advance, 1.0 - line.advance)
    return Arena(states=tuple(f"c{s}" for s in range(n)), initial=line.start,
                 propositions=line.vocabulary().propositions,
                 labels=tuple(frozenset({c}) if c else frozenset() for c in line.cells),
                 actions=(ACTIONS,) * n, dest=dest, prob=prob,
                 trap_candidates=line.candidates,
                 positions=tuple((float(s), 0.0) for s in range(n)))


def describe(world) -> str:
    return f"corridor of {len(world.front.cells)} cells"


def outcome_name(action: str, outcome: int) -> str:
    return "moved" if outcome == 0 else "stayed"


def standing_candidates(world) -> tuple[int, ...]:
    return ()


def parameters(world) -> dict[str, object]:
    return {"advance": world.front.advance}


def with_advance(world, advance: float):
    return replace(world, front=replace(world.front, advance=advance))


# what sweeps may vary in a corridor world only (advance: at most 1, as the world allows)
SETTINGS = (Setting("advance", "a number in (0, 1]", float, 0.0, True, 1.0, with_advance,
                    at_most=True),)
