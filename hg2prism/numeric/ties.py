"""Tie rules: which of several (near-)tied options is taken (docs/semantics.md §§4, 6, 8, 11).

Every rule picks, among the options within a tolerance of the best, one by their order: the
first (or, for P2's `tie_break = "last"`, the last), or a preferred option when it is among
them (P2's standing set, the default strategy's move). The options come in two forms: dense,
a table whose `axis` lists each row's options (the caller marks absent ones with NaN or inf),
and grouped, the options of every state in one flat array with the state of each (Storm's
choices, CSR-like). The tolerance is absolute (`score >= best - tie`) or relative
(`score >= best - tie * |best|`), towards the largest score or, `lowest`, the smallest
(`score <= best + tie`): each caller says which, as its rule was defined, so that the same
doubles decide as before (a tie rule changed by one ulp can change a strategy)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def near_best(score: np.ndarray, tie: float = 0.0, *, axis: int = -1, relative: bool = False,
              lowest: bool = False, best: np.ndarray | None = None) -> np.ndarray:
    """bool like `score`: the options within `tie` of the best along `axis`, the largest or,
    `lowest`, the smallest. `best`, when given (broadcastable against `score`), is that best:
    a maximum the caller has already, or in the grouped form each option's state's best."""
    if best is None:
        best = (score.min(axis=axis, keepdims=True) if lowest
                else score.max(axis=axis, keepdims=True))
    if tie == 0 and not relative:       # the best itself, bit for bit (x - 0.0 is x, inf
        return score <= best if lowest else score >= best      # and NaN too): no temporary
    margin = tie * np.abs(best) if relative else tie
    return score <= best + margin if lowest else score >= best - margin


def first_near_best(score: np.ndarray, tie: float = 0.0, *, axis: int = -1,
                    relative: bool = False, lowest: bool = False,
                    best: np.ndarray | None = None) -> np.ndarray:
    """The index along `axis` of the first option within `tie` of the best (`near_best`), 0
    where none is (a NaN best or margin: a NaN score, 0 * inf, inf - inf)."""
    return near_best(score, tie, axis=axis, relative=relative, lowest=lowest,
                     best=best).argmax(axis=axis)


def first_near_best_of(values: Sequence[float], tie: float) -> int:
    """`first_near_best` of a short list of floats, in plain Python, for the observers' step
    by step updates (one small list per observation: no array is worth building): the
    position of the first value >= max - tie."""
    top = max(values)
    return next(i for i, value in enumerate(values) if value >= top - tie)


def keep_or_first(tied: np.ndarray, preferred: np.ndarray | None, last: bool = False
                  ) -> np.ndarray:
    """[rows] per row of `tied` ([rows, options] bool, `near_best`'s) the preferred option
    (preferred[row], -1 or `preferred` None for none) when it is tied, else the first tied
    option, or with `last` the last (0, or the last option, in a row with none tied)."""
    if last:
        choice = tied.shape[1] - 1 - tied[:, ::-1].argmax(axis=1)
    else:
        choice = tied.argmax(axis=1)
    if preferred is None:
        return choice
    keep = (preferred >= 0) & tied[np.arange(len(choice)), np.maximum(preferred, 0)]
    return np.where(keep, preferred, choice)


def first_index(keys: np.ndarray, n_keys: int, where: np.ndarray | None = None) -> np.ndarray:
    """[n_keys] the first position of each key 0..n_keys-1 in `keys` (-1 for a key absent):
    the representative, first Storm state, of each canonical state. With `where` [len(keys)]
    bool, the first position where it holds: the grouped form's rule, `keys` each option's
    state and `where` its options tied (`near_best`), -1 for a state with none."""
    positions = np.arange(len(keys)) if where is None else np.flatnonzero(where)
    chosen = keys if where is None else keys[positions]
    first = np.full(n_keys, -1, dtype=np.int64)
    first[chosen[::-1]] = positions[::-1]         # reversed: the first of each key is written last
    return first


def first_best(score: np.ndarray, group: np.ndarray, relative_tie: float = 0.0) -> np.ndarray:
    """Index of the first score in each run of equal `group` labels within `relative_tie`
    (relative) of the run's maximum, run after run."""
    if len(score) == 0:
        return np.zeros(0, dtype=np.int64)
    start = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    best = np.repeat(np.maximum.reduceat(score, start), np.diff(np.r_[start, len(score)]))
    # the first tied position of each run, without a run number per score (millions of
    # Storm choices: one array fewer than first_index(..., where=) would take)
    candidates = np.flatnonzero(near_best(score, relative_tie, relative=True, best=best))
    return candidates[np.r_[True, group[candidates[1:]] != group[candidates[:-1]]]]


def argmax_by_group(score: np.ndarray, group: np.ndarray, n_groups: int,
                    relative_tie: float = 0.0) -> np.ndarray:
    """Index of the first score in each group within `relative_tie` (relative) of the group's
    maximum (groups are contiguous, ordered and cover 0..n_groups-1: every Storm state has a
    choice)."""
    best = first_best(score, group, relative_tie)
    if len(best) != n_groups:
        raise ValueError("every group needs at least one member")
    return best


def choices_taking(choice_state: np.ndarray, choice_action: np.ndarray, wanted: np.ndarray,
                   n_states: int) -> np.ndarray:
    """The choice of each state whose action is wanted[state], its first choice where none is
    (choices grouped by state, as argmax_by_group's; an action < 0 is no move): how a strategy
    given by action, per state or canonical state, is laid on a model's choices."""
    match = (choice_action == wanted[choice_state]) & (choice_action >= 0)
    return argmax_by_group(np.where(match, 1.0, 0.0), choice_state, n_states)
