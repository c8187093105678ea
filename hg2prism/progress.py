"""Progress reports: the `hg2prism` logger and the episode progress bar.

The library reports each stage at INFO level (warnings at WARNING) on the `hg2prism` logger.
It prints no report by itself: a notebook sees them after `logging.basicConfig(level=
logging.INFO)`, and the command line shows them on stderr (`on_stderr`). A warning is something
the user must know about a result, so where logging is not configured it reaches stderr all the
same (Python's handler of last resort: the logger has no NullHandler). Long simulations and
sweeps draw a bar on stderr (`Bar`, the one progress bar) only when asked to (`progress=True`,
`show_progress=True`).
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Iterator
from contextlib import contextmanager

LOGGER = logging.getLogger("hg2prism")


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


def bar_text(done: int, total: int, width: int) -> str:
    """`done` of `total` as a bar of `width` characters: ``#####.....``."""
    filled = int(round(width * min(done, total) / max(total, 1)))
    return "#" * filled + "." * (width - filled)


class Bar:
    """The package's one progress bar on stderr, of `total` units (episodes, sweep points),
    drawn only when asked to (`enabled`). On a terminal, `update` redraws it in place at most
    ~20 times and `pending` shows the unit under way until its line replaces it; `finished`
    writes a line per finished unit (``head (3/8) [###.....]: detail``) on any stream, and
    `close` ends the bar (a log, not a terminal, gets the final line alone)."""

    WIDTH = 30
    UPDATES = 20

    def __init__(self, label: str, total: int, enabled: bool, unit: str = "episodes",
                 width: int = WIDTH) -> None:
        self.label, self.total, self.enabled = label, max(int(total), 1), enabled
        self.unit, self.width = unit, width
        self.next_at = 0
        self.stream = sys.stderr
        self.live = enabled and self.stream.isatty()

    def update(self, done: int) -> None:
        if not self.live or done < self.next_at:
            return
        fraction = min(done / self.total, 1.0)
        self.stream.write(f"\r{self.label}: [{bar_text(done, self.total, self.width)}] "
                          f"{fraction:4.0%} {done}/{self.total} {self.unit}")
        self.stream.flush()
        step = max(1, -(-self.total // self.UPDATES))
        self.next_at = (done // step + 1) * step

    @contextmanager
    def pending(self, text: str) -> Iterator[None]:
        """On a terminal, ``text ...`` while the body runs, then the cursor back to the line's
        start (the unit's `finished` line writes over it)."""
        if self.live:
            self.stream.write(f"{text} ...")
            self.stream.flush()
        yield
        if self.live:
            self.stream.write("\r")

    def finished(self, done: int, head: str, detail: str) -> None:
        """The line of a finished unit, the `done`-th: ``head (done/total) [bar]: detail``;
        not drawn, ``head (done/total): detail`` is a report on the logger (the API's sweep)."""
        if self.enabled:
            self.stream.write(f"{head} ({done}/{self.total}) "
                              f"[{bar_text(done, self.total, self.width)}]: {detail}\n")
            self.stream.flush()
        else:
            say(f"{head} ({done}/{self.total}): {detail}")

    def close(self, seconds: float) -> None:
        if self.enabled:
            if self.live:
                self.next_at = 0
                self.update(self.total)
                self.stream.write(f" in {seconds:.2f} s\n")
            else:
                self.stream.write(f"{self.label}: {self.total} {self.unit} in {seconds:.2f} s\n")
            self.stream.flush()
