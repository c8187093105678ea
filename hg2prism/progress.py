"""Progress reports: the `hg2prism` logger and the episode progress bar.

The library reports each stage at INFO level (warnings at WARNING) on the `hg2prism` logger and
prints nothing by itself: a notebook sees the reports after `logging.basicConfig(level=
logging.INFO)`, and the command line shows them on stderr (`on_stderr`). Long simulations draw
a bar on stderr only when asked to (`progress=True`).
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Iterator
from contextlib import contextmanager

LOGGER = logging.getLogger("hg2prism")
LOGGER.addHandler(logging.NullHandler())


def say(message: str) -> None:
    """A stage's report (INFO)."""
    LOGGER.info(message)


def warn(message: str) -> None:
    """Something the user must know about a result (WARNING): shown even by `quiet`."""
    LOGGER.warning(f"warning: {message}")


class _Stderr(logging.StreamHandler):
    """Writes to whatever sys.stderr is when a record is emitted."""

    def __init__(self) -> None:
        super().__init__()
        self.setFormatter(logging.Formatter("%(message)s"))

    @property
    def stream(self):            # noqa: D401 - logging's attribute
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


@contextmanager
def on_stderr() -> Iterator[None]:
    """Show the reports on stderr, one line each (what the command line does)."""
    handler = _Stderr()
    level, propagate = LOGGER.level, LOGGER.propagate
    LOGGER.addHandler(handler)
    LOGGER.setLevel(logging.INFO)
    LOGGER.propagate = False
    try:
        yield
    finally:
        LOGGER.removeHandler(handler)
        LOGGER.setLevel(level)
        LOGGER.propagate = propagate


@contextmanager
def quiet() -> Iterator[None]:
    """Only warnings (a sweep shows one line per value, not every stage of every value)."""
    level = LOGGER.level
    LOGGER.setLevel(logging.WARNING)
    try:
        yield
    finally:
        LOGGER.setLevel(level)


_COLLECTING = [0]       # collected_warnings is active (nested: a count)


@contextmanager
def each_warning_once() -> Iterator[None]:
    """Inside, a warning given again word for word is not shown again (adaptive deception checks
    each of P2's types alike: "Storm method 'fast' is not sound" came once per type)."""
    seen: set[str] = set()

    def first(record: logging.LogRecord) -> bool:
        # a warning being collected is not shown yet: it counts when it is replayed (a sweep's
        # points', run on one process, were dropped as seen when replayed)
        if record.levelno < logging.WARNING or _COLLECTING[0]:
            return True
        message = record.getMessage()
        if message in seen:
            return False
        seen.add(message)
        return True

    LOGGER.addFilter(first)
    try:
        yield
    finally:
        LOGGER.removeFilter(first)


@contextmanager
def collected_warnings() -> Iterator[list[str]]:
    """Warnings given inside are collected into the yielded list instead of shown (a sweep's
    point, possibly in another process, hands them back to be shown with `replay_warning`)."""
    collected: list[str] = []

    class _Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            collected.append(record.getMessage())

    handler = _Collect(level=logging.WARNING)
    handlers, propagate = LOGGER.handlers[:], LOGGER.propagate
    LOGGER.handlers = [handler]
    LOGGER.propagate = False
    _COLLECTING[0] += 1
    try:
        yield collected
    finally:
        _COLLECTING[0] -= 1
        LOGGER.handlers = handlers
        LOGGER.propagate = propagate


def replay_warning(message: str) -> None:
    """Show a warning collected by `collected_warnings`, as it was given."""
    LOGGER.warning(message)


class Bar:
    """A text progress bar of episodes on stderr, redrawn at most ~20 times on a terminal; a
    log (not a terminal) gets the final line alone."""

    WIDTH = 30
    UPDATES = 20

    def __init__(self, label: str, total: int, enabled: bool) -> None:
        self.label, self.total, self.enabled = label, max(int(total), 1), enabled
        self.next_at = 0
        self.stream = sys.stderr
        self.live = enabled and self.stream.isatty()

    def update(self, done: int) -> None:
        if not self.live or done < self.next_at:
            return
        fraction = min(done / self.total, 1.0)
        filled = int(round(fraction * self.WIDTH))
        self.stream.write(f"\r{self.label}: [{'#' * filled}{'.' * (self.WIDTH - filled)}] "
                          f"{fraction:4.0%} {done}/{self.total} episodes")
        self.stream.flush()
        step = max(1, -(-self.total // self.UPDATES))
        self.next_at = (done // step + 1) * step

    def close(self, seconds: float) -> None:
        if self.enabled:
            if self.live:
                self.next_at = 0
                self.update(self.total)
                self.stream.write(f" in {seconds:.2f} s\n")
            else:
                self.stream.write(f"{self.label}: {self.total} episodes in {seconds:.2f} s\n")
            self.stream.flush()
