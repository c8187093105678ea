"""Online detection of a wrong opponent model (docs/semantics.md §9): a likelihood-ratio test of
H0 "P2 behaves as modelled" against H1 "P2 plays some other stationary policy on P1's
augmented states".

This module is pure and independent of the rest of the package: an observer feeds it, per
transition n = 1, 2, ..., the augmented state ``s~_n`` (any hashable key; in the simulation
P1's model state ``(v, q, M)``), the action P2 is predicted to play (``pi2_xh(v)``), the action
she actually played, and ``n_actions = |A2(v)|``.

The statistic, over the *counted* steps i (those with ``n_actions > 1``; a step with a single
available action carries no information and is left out of every count):

* predicted policy, smoothed: ``p0(a | s~) = 1 - epsilon`` for the predicted action and
  ``epsilon / (n_actions - 1)`` for each other action;
* ``ln L0 = sum_i ln p0(a_i | s~_i)``;
* ``ln L1 = sum_i ln phat(a_i | s~_i)`` with ``phat(a | s~) = #(s~, a) / #(s~)`` the
  maximum-likelihood estimate from *all* counted steps so far, re-evaluated at every step, i.e.
  ``ln L1 = sum_{(s~, a) seen} #(s~, a) ln(#(s~, a) / #(s~))``;
* ``G = 2 (ln L1 - ln L0)`` (>= 0: phat maximises the likelihood over policies of s~, p0 is one);
* ``df`` = number of distinct ``(s~, a2)`` pairs seen. This is the paper's choice. It exceeds
  the number of free parameters of the unrestricted model once every pair of positive
  probability has been seen (a state with k distinct observed actions has k - 1 free
  probabilities, and under H0 nothing is estimated), so the chi-square quantile used is larger
  than the asymptotically correct one: one test, made once on long data drawn from ``p0``,
  rejects with probability below ``alpha``. The test is repeated at every step, and while
  pairs are unseen df is smaller, so the share of episodes rejected at some step (the
  false-alarm rate) is not bounded by ``alpha`` (docs/semantics.md §9). (A P2 that plays the
  prediction deterministically is not a sample from ``p0``; see the caveat below.)
* No test while ``df = 0``; H0 is rejected at the first step n with
  ``G > chi2.ppf(1 - alpha, df)``.

Caveat (a property of this statistic, not a bug): when P2 follows the prediction exactly,
``phat = 1`` on every seen pair, so ``ln L1 = 0`` and ``G = -2 N ln(1 - epsilon)`` after N
counted steps, which grows linearly in N while ``df`` stays the number k of distinct states
visited. Since ``chi2.ppf(1 - alpha, k) > k`` (for alpha < 0.317, i.e. any usual level), no
false alarm is possible unless the states are
revisited on average more than ``1 / (-2 ln(1 - epsilon))`` times; it happens exactly when
``N > chi2.ppf(1 - alpha, k) / (-2 ln(1 - epsilon))``. With a single repeated state
(k = 1, the easiest case): epsilon = 0.1, alpha = 0.05 rejects at the 19th counted visit;
epsilon = 0.01, alpha = 0.05 (the defaults) at the 192nd. See :func:`compliant_rejection_count`.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterable, Sequence
from dataclasses import dataclass

from scipy.stats import chi2

__all__ = [
    "Mixture",
    "Step",
    "MismatchDetector",
    "first_rejection",
    "compliant_rejection_count",
    "DetectionSummary",
    "summarize_detection",
]


@dataclass(frozen=True)
class Step:
    """The detector's state after one transition.

    ``n`` numbers every observed transition (skipped ones included), starting at 1.
    ``counted`` is False for a step with a single available action (left out of all counts;
    ``statistic``, ``df`` and ``threshold`` then repeat the previous step's values).
    ``threshold`` is ``chi2.ppf(1 - alpha, df)``, None while ``df == 0`` (no test).
    ``rejected`` is this step's test outcome, ``G > threshold`` (False while ``df == 0``).
    The first step with ``rejected`` True is always a counted one.
    """

    n: int
    counted: bool
    statistic: float
    df: int
    threshold: float | None
    rejected: bool


@dataclass(frozen=True)
class Mixture:
    """A predicted action that is itself random: (action, probability) pairs. For a P2 who
    draws her hypothesis (Bayesian "sample", docs/semantics.md §12) the prediction is the
    posterior mixture, smoothed as ``(1 - epsilon) * mix(a) + epsilon / n_actions``."""

    probabilities: tuple[tuple[Hashable, float], ...]

    def of(self, action: Hashable) -> float:
        return sum(p for a, p in self.probabilities if a == action)


def _check_open_unit(name: str, value: float) -> float:
    value = float(value)
    if not 0.0 < value < 1.0:
        raise ValueError(f"{name} must lie in (0, 1), got {value!r}")
    return value


def _xlogx(count: int) -> float:
    return count * math.log(count) if count > 0 else 0.0


class MismatchDetector:
    """Incremental likelihood-ratio test of "P2 behaves as modelled" (see module docstring).

    >>> d = MismatchDetector(alpha=0.05, epsilon=0.1)
    >>> step = d.observe("s", "a", "a", 3)   # G = -2 ln 0.9, df = 1
    >>> step.df, round(step.statistic, 6), step.rejected
    (1, 0.210721, False)

    The same augmented state must always come with the same predicted action and number of
    actions (they are functions of it); otherwise :meth:`observe` raises ValueError, as it does
    when a state shows more distinct actions than ``n_actions``.
    """

    def __init__(self, alpha: float, epsilon: float) -> None:
        self.alpha = _check_open_unit("alpha", alpha)
        self.epsilon = _check_open_unit("epsilon", epsilon)
        self.n = 0                      # transitions observed (every call)
        self.n_counted = 0              # transitions counted (n_actions > 1)
        self.log_l0 = 0.0
        self.first_rejection: int | None = None
        self.steps: list[Step] = []
        self._pair_counts: dict[tuple[Hashable, Hashable], int] = {}
        self._state_counts: dict[Hashable, int] = {}
        self._state_actions: dict[Hashable, set[Hashable]] = {}
        self._state_model: dict[Hashable, tuple[Hashable, int]] = {}
        # ln L1 = sum_s ell(s), ell(s) = sum_a c(s,a) ln c(s,a) - c(s) ln c(s)
        self._state_ell: dict[Hashable, float] = {}
        self._log_l1 = 0.0
        self._thresholds: dict[int, float] = {}

    # -- derived quantities -------------------------------------------------------------
    @property
    def df(self) -> int:
        """Number of distinct (state, action) pairs seen in counted steps."""
        return len(self._pair_counts)

    @property
    def statistic(self) -> float:
        """G = 2 (ln L1 - ln L0); 0 before any counted step. Never negative."""
        return max(0.0, 2.0 * (self._log_l1 - self.log_l0))

    def threshold(self, df: int | None = None) -> float | None:
        """chi2.ppf(1 - alpha, df) (the current df by default); None when df == 0."""
        df = self.df if df is None else df
        if df == 0:
            return None
        if df not in self._thresholds:
            self._thresholds[df] = float(chi2.ppf(1.0 - self.alpha, df))
        return self._thresholds[df]

    @property
    def rejected(self) -> bool:
        """Whether H0 has been rejected at some step so far."""
        return self.first_rejection is not None

    def p0(self, predicted_action: Hashable, action: Hashable, n_actions: int) -> float:
        """The smoothed predicted probability of `action` (n_actions > 1)."""
        if isinstance(predicted_action, Mixture):
            return (1.0 - self.epsilon) * predicted_action.of(action) + self.epsilon / n_actions
        if action == predicted_action:
            return 1.0 - self.epsilon
        return self.epsilon / (n_actions - 1)

    # -- the update -----------------------------------------------------------------------
    def observe(self, augmented_state: Hashable, predicted_action: Hashable,
                observed_action: Hashable, n_actions: int) -> Step:
        """Record transition n (= number of calls so far) and test; returns its Step."""
        n_actions = int(n_actions)
        if n_actions < 1:
            raise ValueError(f"n_actions must be >= 1, got {n_actions}")
        self.n += 1
        counted = n_actions > 1
        if counted:
            self._count(augmented_state, predicted_action, observed_action, n_actions)
        df = self.df
        g = self.statistic
        threshold = self.threshold(df)
        rejected = threshold is not None and g > threshold
        if rejected and self.first_rejection is None:
            self.first_rejection = self.n
        step = Step(n=self.n, counted=counted, statistic=g, df=df, threshold=threshold,
                    rejected=rejected)
        self.steps.append(step)
        return step

    def _count(self, state: Hashable, predicted: Hashable, action: Hashable,
               n_actions: int) -> None:
        model = self._state_model.setdefault(state, (predicted, n_actions))
        if model != (predicted, n_actions):
            raise ValueError(
                f"augmented state {state!r} seen with predicted action / n_actions "
                f"{model!r} and now {(predicted, n_actions)!r}")
        actions = self._state_actions.setdefault(state, set())
        if action not in actions and len(actions) >= n_actions:
            raise ValueError(
                f"augmented state {state!r} shows more than n_actions = {n_actions} "
                f"distinct actions")
        actions.add(action)
        self.n_counted += 1
        self.log_l0 += math.log(self.p0(predicted, action, n_actions))

        pair = (state, action)
        c_pair = self._pair_counts.get(pair, 0)
        c_state = self._state_counts.get(state, 0)
        self._pair_counts[pair] = c_pair + 1
        self._state_counts[state] = c_state + 1
        old_ell = self._state_ell.get(state, 0.0)
        new_ell = old_ell + (_xlogx(c_pair + 1) - _xlogx(c_pair)) \
            - (_xlogx(c_state + 1) - _xlogx(c_state))
        # ell(s) <= 0, and == 0 exactly when a single action was seen at s
        new_ell = 0.0 if len(actions) == 1 else min(new_ell, 0.0)
        self._state_ell[state] = new_ell
        self._log_l1 += new_ell - old_ell


def first_rejection(steps: Iterable[Step]) -> int | None:
    """The step number n of the first rejection in `steps`, None if never rejected."""
    for step in steps:
        if step.rejected:
            return step.n
    return None


def compliant_rejection_count(alpha: float, epsilon: float, distinct_states: int = 1) -> int:
    """Counted steps after which a P2 that always plays the predicted action is rejected,
    when the steps visit `distinct_states` states (G = -2 N ln(1-epsilon), df = distinct_states):
    the least N with N * (-2 ln(1 - epsilon)) > chi2.ppf(1 - alpha, distinct_states)."""
    _check_open_unit("alpha", alpha)
    _check_open_unit("epsilon", epsilon)
    if distinct_states < 1:
        raise ValueError("distinct_states must be >= 1")
    per_step = -2.0 * math.log(1.0 - epsilon)
    threshold = float(chi2.ppf(1.0 - alpha, distinct_states))
    n = max(distinct_states, math.floor(threshold / per_step) + 1)
    # guard the floor against rounding at the boundary: step exactly as observe() decides
    while n > distinct_states and (n - 1) * per_step > threshold:
        n -= 1
    while not n * per_step > threshold:
        n += 1
    return n


# -- summaries over many episodes ------------------------------------------------------------

@dataclass(frozen=True)
class DetectionSummary:
    """Summary of first-rejection steps over episodes (None = never rejected).

    ``histogram`` maps detection step -> number of episodes, sorted by step. With
    ``deviate_after`` given, ``before_deviation`` counts episodes rejected at n <= deviate_after
    (while P2 still followed the model: false alarms of the deviation experiment) and
    ``delays`` are ``n - deviate_after`` for the others that were detected.
    """

    episodes: int
    detected: int
    not_detected: int
    share_detected: float
    share_not_detected: float
    detection_steps: tuple[int, ...]                 # sorted, one per detected episode
    histogram: tuple[tuple[int, int], ...]
    deviate_after: int | None = None
    before_deviation: int = 0
    delays: tuple[int, ...] = ()

    @property
    def mean_detection_step(self) -> float | None:
        s = self.detection_steps
        return sum(s) / len(s) if s else None

    @property
    def median_detection_step(self) -> float | None:
        s = self.detection_steps
        if not s:
            return None
        mid = len(s) // 2
        return float(s[mid]) if len(s) % 2 else (s[mid - 1] + s[mid]) / 2.0

    @property
    def mean_delay(self) -> float | None:
        return sum(self.delays) / len(self.delays) if self.delays else None


def summarize_detection(first_rejections: Sequence[int | None],
                        deviate_after: int | None = None) -> DetectionSummary:
    """Summarise first-rejection steps, one per episode (None = not detected)."""
    episodes = len(first_rejections)
    if episodes == 0:
        raise ValueError("no episodes to summarise")
    steps = tuple(sorted(int(n) for n in first_rejections if n is not None))
    hist: dict[int, int] = {}
    for n in steps:
        hist[n] = hist.get(n, 0) + 1
    detected = len(steps)
    before = 0
    delays: tuple[int, ...] = ()
    if deviate_after is not None:
        before = sum(1 for n in steps if n <= deviate_after)
        delays = tuple(n - deviate_after for n in steps if n > deviate_after)
    return DetectionSummary(
        episodes=episodes, detected=detected, not_detected=episodes - detected,
        share_detected=detected / episodes,
        share_not_detected=(episodes - detected) / episodes,
        detection_steps=steps, histogram=tuple(sorted(hist.items())),
        deviate_after=deviate_after, before_deviation=before, delays=delays)

