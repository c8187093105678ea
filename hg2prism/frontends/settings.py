"""A front end's own parameters: what a sweep may vary in worlds of that kind only (the grid's:
frontends/grid.py SETTINGS), with how values are checked and applied."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from hg2prism.model.world import World


@dataclass(frozen=True)
class Setting:
    name: str
    expected: str                   # what a value must be, as error messages say it
    kind: type                      # int or float
    minimum: float
    exclusive: bool                 # > minimum (else >=)
    below: float | None             # < below, when given (<= below when at_most)
    apply: Callable[[World, object], World]
    at_most: bool = False           # below is a value's largest (else its bound above)
