"""The one error type users see: a bad input, reported as file, key and reason."""

from __future__ import annotations


COMMAND_LINE = "command line"   # the InputError "file" of a bad option or option value


def listing(names, shown: int, count: bool = False, empty: str = "") -> str:
    """A message's list of names: the first `shown`, then "and N more" (`count`) or ", ..."
    when there are more; `empty` when there are none."""
    names = [str(name) for name in names]
    if not names:
        return empty
    more = len(names) - shown
    tail = "" if more <= 0 else f" and {more} more" if count else ", ..."
    return ", ".join(names[:shown]) + tail


def did_you_mean(name: object, names) -> str:
    """"; did you mean 'plc'?" when `name` is close to some of `names` (difflib, at most three),
    else ""."""
    import difflib

    if not isinstance(name, str):
        return ""
    close = difflib.get_close_matches(name, [str(n) for n in names], n=3, cutoff=0.75)
    return f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


WHOLE_FILE = "-"     # the key of an error about a whole file (not found, not TOML ...)


class InputError(Exception):
    """Bad user input. The CLI prints it as one line and exits with status 2: "file: key:
    reason", or "file: reason" for the whole file (key WHOLE_FILE)."""

    def __init__(self, file: str, key: str, reason: str) -> None:
        super().__init__(f"{file}: {reason}" if key == WHOLE_FILE else f"{file}: {key}: {reason}")
        self.file = file
        self.key = key
        self.reason = reason

    def __reduce__(self):
        # Unpickled (from a Dask worker, say) as it was, whatever the subclass's constructor
        # takes: Exception's own pickling calls the class with the message alone.
        return _restored, (type(self), self.args, self.__dict__)


def _restored(cls: type, args: tuple, state: dict) -> InputError:
    error = cls.__new__(cls)
    error.args = args
    error.__dict__.update(state)
    return error


class MissingSetting(InputError):
    """A setting P2's observer needs and nobody gave (`opponent.registry.configure` switching
    to a kind with a required setting: to "cusum" without a threshold); `setting` names it."""

    def __init__(self, file: str, kind: str, setting: str) -> None:
        super().__init__(file, f"inference.{setting}", f"the {kind} observer needs a {setting}, "
                         f"which has no default: give it (configure(world, {kind!r}, "
                         f"{setting}=...))")
        self.setting = setting


class SolverError(RuntimeError):
    """A numerical solver did not reach the precision docs/semantics.md §10 requires."""


class StormError(RuntimeError):
    """Storm refused or failed on a generated model."""


PROBABILITY_SLACK = 1e-9   # how far outside [0, 1] rounding may put an exact probability


def probability(value: float, what: str) -> float:
    """`value` clamped to [0, 1]. Rounding puts exact probabilities a few ulps outside (a
    leader value of 1.0000000000000353); more than 1e-9 outside is a bug, reported loudly
    rather than hidden by the clamp."""
    if not -PROBABILITY_SLACK <= value <= 1 + PROBABILITY_SLACK:
        raise SolverError(f"{what} = {value!r} is not a probability")
    return min(max(float(value), 0.0), 1.0)
