"""External model checkers behind one interface (engines/engine.py). Only engines/storm.py
imports stormpy."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hg2prism.engines.engine import ModelChecker


def default() -> ModelChecker:
    """The engine the command line, the pipeline and the API use: Storm."""
    from hg2prism.engines.storm import STORM

    return STORM
