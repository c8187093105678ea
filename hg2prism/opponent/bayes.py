"""P2's Bayesian inference (docs/semantics.md §12): a posterior over hypotheses from the last w
observations, acted on by its most probable hypothesis ("map") or by a draw from it ("sample").

P2's memory is the window of the last at most w observations (TS state, P1's action, the trap
set in force), oldest first; `Memory.hypothesis` carries the window's MAP hypothesis beside it.
`BayesObserver` implements the observer interface of `observer.py`; `KIND` registers it as kind
"bayes" (its PRISM part is rendered by prism/observers.render_bayes,
templates/inference_bayes.prism.j2).

The log-posterior of x, up to the normaliser, is summed in one fixed order, oldest observation
first, `ln prior(x) + ll(o1) + ll(o2) + ...`, in Python and in the PRISM formulas alike, so both
compute the same doubles and the 1e-9 tie rule decides identically.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from hg2prism.model.world import World
from hg2prism.numeric import first_near_best, first_near_best_of
from hg2prism.opponent.observer import (TOLERANCE, Memory, MemoryBound, Mismatch, Observation,
                                        ObserverKind, Setting, Swept, p2_action_count,
                                        window_mismatches)
from hg2prism.opponent.perceptual_games import PerceptualGame

__all__ = ["BayesObserver", "build_bayes", "KIND", "DECISIONS", "uniform_prior",
           "normalise_prior", "prior_argmax"]

DECISIONS = ("map", "sample")


def _exp(value: float) -> float:
    return math.exp(value) if value < 709.0 else math.inf


@dataclass(frozen=True, eq=False)
class BayesObserver:
    """The Bayesian observer (kind "bayes")."""

    log_likelihood: np.ndarray   # [X, n_ts, A1max, n_a2] ln pi1_x(a1 | v, a2) (0 at slots not
                                 # enabled at v: never observed)
    log_prior: np.ndarray        # [X] ln prior(x)
    window: int                  # w: observations remembered
    decision: str                # "map" or "sample"
    trap_choice: np.ndarray      # [X, n_ts] pi2_x(v)

    kind = "bayes"

    @property
    def draws(self) -> bool:
        return self.decision == "sample"
    belief_name = "posterior p(x | W)"

    @property
    def belief_threshold(self) -> None:
        return None

    def belief(self, memory: Memory, observation: Observation) -> list[float]:
        """P2's posterior once she has read `observation` (observer.ReportsBelief): the
        numbers her next hypothesis (MAP) or draw ("sample") rests on."""
        return self.posterior(self.update(memory, observation).window)

    @property
    def n_hypotheses(self) -> int:
        return self.log_likelihood.shape[0]

    @property
    def initial_hypothesis(self) -> int:
        return self.map_hypothesis(())

    # -- the posterior -------------------------------------------------------------------------

    def log_scores(self, window: tuple[Observation, ...]) -> list[float]:
        """ln prior(x) + sum of ln pi1_x(a1 | v, a2) over the window (oldest first), per x:
        the log-posterior up to the normaliser ln Z."""
        scores = []
        for x in range(self.n_hypotheses):
            total = float(self.log_prior[x])
            for state, action, trap_set in window:
                total = total + float(self.log_likelihood[x, state, action, trap_set])
            scores.append(total)
        return scores

    def map_hypothesis(self, window: tuple[Observation, ...]) -> int:
        """The first hypothesis (in order) within TOLERANCE of the largest log-posterior."""
        return first_near_best_of(self.log_scores(window), TOLERANCE)

    def posterior(self, window: tuple[Observation, ...]) -> list[float]:
        """p(x | W) = 1 / sum_y exp(ln p(y | W) - ln p(x | W)) for every x: the normaliser
        cancels, and a term that overflows only drives p(x | W) to 0 (the PRISM model computes
        the same expression)."""
        scores = self.log_scores(window)
        result = []
        for x, own in enumerate(scores):
            total = 0.0
            for y, other in enumerate(scores):
                total = total + (1.0 if y == x else _exp(other - own))
            result.append(1.0 / total)
        return result

    # -- the observer interface ----------------------------------------------------------------

    def initial_memory(self) -> Memory:
        return Memory(self.map_hypothesis(()), ())

    def hypothesis(self, memory: Memory) -> int:
        return memory.hypothesis

    def hypothesis_distribution(self, memory: Memory) -> tuple[tuple[int, float], ...]:
        if self.decision == "map":
            return ((memory.hypothesis, 1.0),)
        return tuple((x, p) for x, p in enumerate(self.posterior(memory.window)) if p > 0.0)

    def update(self, memory: Memory, observation: Observation) -> Memory:
        """The window with the new observation (v, a1, a2) appended, the last w kept."""
        if len(observation) != 3:
            raise ValueError("the Bayesian observer needs observations (v, a1, a2)")
        window = (memory.window + (tuple(int(o) for o in observation),))[-self.window:]
        return Memory(self.map_hypothesis(window), window)

    def window_hypotheses(self, windows: np.ndarray) -> np.ndarray:
        """The MAP hypothesis of each of many windows [n, w, 3] (-1 entries: empty slots),
        vectorised; the sums are taken in the same order as `log_scores`."""
        n = windows.shape[0]
        scores = np.repeat(self.log_prior[None, :], n, axis=0).astype(float)
        for i in range(windows.shape[1]):
            state, action, trap_set = windows[:, i, 0], windows[:, i, 1], windows[:, i, 2]
            full = state >= 0
            terms = np.zeros((n, self.n_hypotheses))
            terms[full] = self.log_likelihood[:, state[full], action[full], trap_set[full]].T
            scores = scores + terms
        return first_near_best(scores, TOLERANCE, axis=1)


def build_bayes(games: list[PerceptualGame], window: int, prior: tuple[float, ...],
                decision: str) -> BayesObserver:
    """ln pi1_x(a1 | v, a2) for every hypothesis, TS state, P1 action and P2 action (§4's
    softmax; 0 at action slots not enabled at v, which P1 never plays), and ln prior."""
    log_likelihood = np.stack([np.transpose(g.log_policy, (0, 2, 1)) for g in games])
    log_likelihood[np.isneginf(log_likelihood)] = 0.0
    return BayesObserver(log_likelihood=np.ascontiguousarray(log_likelihood),
                         log_prior=np.log(np.asarray(prior, dtype=float)), window=window,
                         decision=decision,
                         trap_choice=np.stack([g.trap_choice for g in games]))


# ---------------------------------------------------------------------------------------------
# The kind "bayes": its keys in the world file, and what the size guard and detection need
# ---------------------------------------------------------------------------------------------

def uniform_prior(n_hypotheses: int) -> tuple[float, ...]:
    return tuple([1.0 / n_hypotheses] * n_hypotheses)


def normalise_prior(numbers: list[float]) -> tuple[float, ...]:
    """Positive finite numbers scaled to sum 1 (ValueError when that is impossible)."""
    try:
        total = math.fsum(numbers)
    except OverflowError:           # fsum raises where its partial sums overflow
        total = math.inf
    if not math.isfinite(total):
        raise ValueError("the prior's numbers are too large to add up; scale them down")
    scaled = tuple(p / total for p in numbers)
    if any(p <= 0 for p in scaled):
        raise ValueError("a prior probability vanishes once normalised; use less extreme numbers")
    return scaled


def prior_argmax(prior: tuple[float, ...]) -> int:
    """P2's first guess: the most probable hypothesis, the first among ties; ties as in the
    decision rule (within TOLERANCE in log space), so that this is also the MAP hypothesis of
    an empty memory."""
    return first_near_best_of([math.log(p) for p in prior], TOLERANCE)


def _read_prior(loader, value: object, n_hypotheses: int) -> tuple[float, ...]:
    """The prior over hypotheses, normalised."""
    key = "inference.prior"
    items = loader.array(value, key, f"an array of {n_hypotheses} positive numbers (one per "
                                     "hypothesis)")
    if len(items) != n_hypotheses:
        raise loader.fail(key, f"prior has {len(items)} numbers but there are "
                               f"{n_hypotheses} hypotheses; expected one per hypothesis")
    numbers = [loader.number(p, f"{key}[{i}]") for i, p in enumerate(items)]
    for i, p in enumerate(numbers):
        if p <= 0:
            raise loader.fail(f"{key}[{i}]", f"prior probabilities must be > 0, got {p:g}")
    try:
        return normalise_prior(numbers)
    except ValueError as err:
        raise loader.fail(key, str(err)) from None


def _read_decision(loader, value: object, n_hypotheses: int) -> str:
    return loader.choice(value, "inference.decision", "decision", DECISIONS)


def _build(world: World, games: list[PerceptualGame]) -> BayesObserver:
    return build_bayes(games, world.window, world.setting("prior"), world.setting("decision"))


def _memory(world: World) -> MemoryBound:
    """The memory is the window alone (no hypothesis): w observations, each with P2's action.
    The action an observation at state v records is P2's choice there, pi2_x(v) for the
    hypothesis x she acted on (drawn or not), or with delay, while the countdown runs, the
    standing action, which v itself holds: one of at most as many actions as hypotheses
    given v. (With delay the bound used to allow every action here: 1.45e6 against 23k
    canonical states on a 6 x 6 world with delay 1 and window 3.)"""
    actions = p2_action_count(world)
    return MemoryBound(hypotheses=1, observations=world.window,
                       sets_per_observation=min(actions, len(world.hypotheses)), records=True)


def _solved_memory(world: World, games: list[PerceptualGame]) -> MemoryBound:
    """`_memory` once P2's games are solved: an observation made at state v records pi2_x(v)
    for some hypothesis x, one of the distinct sets her hypotheses choose at v (one set at
    most states: wherever they agree; with delay, while the countdown runs, the standing
    set, which every hypothesis keeps). Per arena state: with delay, the most over the TS
    states at it (its standing sets and countdowns)."""
    bound = _memory(world)
    if len(games) < 2:
        return bound
    choices = np.sort(np.stack([game.trap_choice for game in games]), axis=0)
    distinct = 1 + (choices[1:] != choices[:-1]).sum(axis=0)           # per TS state
    if world.delay:                 # TS state (place * |A2| + standing) * (delay + 1) + countdown
        per_place = p2_action_count(world) * (world.delay + 1)
        distinct = distinct[:-1].reshape(-1, per_place).max(axis=1)    # (`trapped` last)
    return replace(bound, sets_at=distinct)


def _mismatches(world: World, max_score: float, vary: Callable[..., World]
                ) -> list[Mismatch]:
    """Window +- 1 and the other decision."""
    decision = world.setting("decision")
    variants = window_mismatches(world, decision)
    flipped = "sample" if decision == "map" else "map"
    variants.append(Mismatch(f"decision {flipped}", vary(world, decision=flipped),
                             "the other decision", flipped))
    return variants


KIND = ObserverKind(
    name="bayes", title="Bayesian",
    settings=(Setting("prior", "an array of positive numbers, one per hypothesis", _read_prior,
                      uniform_prior,
                      swept=Swept("numbers", "comma-separated positive numbers, one per "
                                             "hypothesis", normalise=normalise_prior)),
              Setting("decision", '"map" or "sample"', _read_decision, lambda n: "map",
                      swept=Swept("word", '"map" or "sample" (a Bayesian observer\'s)'))),
    build=_build, memory=_memory, solved_memory=_solved_memory, mismatches=_mismatches,
    report=lambda world: {"inference": "bayes", "window": world.window, "threshold": None,
                          "decision": world.setting("decision"),
                          "prior": list(world.setting("prior"))},
    shown_setting="decision",
    first_guess=lambda settings: prior_argmax(settings["prior"]),
    first_guess_rule="the prior's most probable hypothesis")
