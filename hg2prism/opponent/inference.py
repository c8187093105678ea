"""P2's inference (docs/semantics.md §5): sliding-window CUSUM over log-likelihood ratios of P1's moves.

P2's memory is (current hypothesis, the last at most w-1 observations since the last change);
an observation is (TS state, P1's action index). `InferenceModel` implements the observer
interface of `observer.py`; `KIND` registers it as kind "cusum" (its PRISM part is rendered by
prism/observers.render_cusum, templates/inference_cusum.prism.j2).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hg2prism.model.world import World
from hg2prism.numeric import first_near_best, first_near_best_of
from hg2prism.opponent.observer import (TOLERANCE, Memory, MemoryBound, Mismatch, Observation,
                                        ObserverKind, Setting, Swept, window_mismatches)
from hg2prism.opponent.perceptual_games import PerceptualGame

__all__ = ["Memory", "InferenceModel", "build_inference", "KIND"]


@dataclass(frozen=True, eq=False)
class InferenceModel:
    """Sliding-window CUSUM (the observer of kind "cusum")."""

    ratios: np.ndarray        # [X, X, n_ts, A1max] r(x | xh; v, a1), indexed [xh, x, v, a1]
    window: int               # w: transitions in the sliding window
    threshold: float          # c
    initial_hypothesis: int

    @property
    def n_hypotheses(self) -> int:
        return self.ratios.shape[0]

    kind = "cusum"
    draws = False
    belief_name = "CUSUM score Z_x"

    @property
    def belief_threshold(self) -> float:
        return self.threshold

    def belief(self, memory: Memory, observation: Observation) -> list[float]:
        """The CUSUM scores P2 compares with the threshold at this step (observer.ReportsBelief)."""
        return self.scores(memory, observation).tolist()

    def initial_memory(self) -> Memory:
        return Memory(self.initial_hypothesis, ())

    def hypothesis(self, memory: Memory) -> int:
        return memory.hypothesis

    def hypothesis_distribution(self, memory: Memory) -> tuple[tuple[int, float], ...]:
        return ((memory.hypothesis, 1.0),)

    def scores(self, memory: Memory, observation: Observation) -> np.ndarray:
        """CUSUM score Z_x over the window for every x (0 for the current hypothesis)."""
        current = memory.hypothesis
        recent = (memory.window + (tuple(observation[:2]),))[-self.window:]
        z = np.zeros(self.n_hypotheses)
        for x in range(self.n_hypotheses):
            if x == current:
                continue
            score = 0.0
            for state, action in recent:
                score = max(0.0, score + float(self.ratios[current, x, state, action]))
            z[x] = score
        return z

    def update(self, memory: Memory, observation: Observation) -> Memory:
        """eta: the memory after P1 plays `observation[1]` from TS state `observation[0]` (the
        trap set, `observation[2]` if given, is not part of CUSUM's memory: §5)."""
        observation = tuple(observation[:2])
        recent = (memory.window + (observation,))[-self.window:]
        if self.n_hypotheses > 1:
            z = self.scores(memory, observation)
            others = [x for x in range(self.n_hypotheses) if x != memory.hypothesis]
            top = max(z[x] for x in others)
            if top >= self.threshold - TOLERANCE:
                best = others[first_near_best_of([z[x] for x in others], TOLERANCE)]
                return Memory(best, ())
        keep = recent[-(self.window - 1):] if self.window > 1 else ()
        return Memory(memory.hypothesis, keep)

    def next_hypotheses(self, action: int) -> np.ndarray:
        """[X, observed TS states]: P2's hypothesis after P1 plays `action` from each TS state,
        when the window holds nothing before it (window 1), from each current hypothesis.
        The same arithmetic as `update`, so the table is exact."""
        n_x = self.n_hypotheses
        n_obs = self.ratios.shape[2] - 1
        after = np.repeat(np.arange(n_x)[:, None], n_obs, axis=1)
        for h in range(n_x):
            others = [x for x in range(n_x) if x != h]
            z = np.maximum(0.0, 0.0 + self.ratios[h, others, :n_obs, action])    # [others, v]
            top = z.max(axis=0)
            switch = top >= self.threshold - TOLERANCE
            first = first_near_best(z, TOLERANCE, axis=0, best=top)
            after[h] = np.where(switch, np.asarray(others)[first], h)
        return after


def build_inference(games: list[PerceptualGame], window: int, threshold: float,
                    initial_hypothesis: int) -> InferenceModel:
    """r(x | xh; v, a1) = ln pi1_x(a1 | v, a2) - ln pi1_xh(a1 | v, a2) with a2 = pi2_xh(v);
    0 at action slots not enabled at v (P1 never plays them, so P2 never observes them)."""
    n_x = len(games)
    n_ts, _, n_a1 = games[0].log_policy.shape
    states = np.arange(n_ts)
    ratios = np.zeros((n_x, n_x, n_ts, n_a1))
    for xh, current in enumerate(games):
        a2 = current.trap_choice
        base = current.log_policy[states, a2]                         # [n_ts, A1max]
        enabled = np.isfinite(base)
        for x, other in enumerate(games):
            if x != xh:
                ratio = np.where(enabled, other.log_policy[states, a2] - np.where(enabled, base, 0.0),
                                 0.0)
                # Where both hypotheses predict the same move the difference is rounding noise.
                ratio[np.abs(ratio) < 1e-12] = 0.0
                ratios[xh, x] = ratio
    return InferenceModel(ratios=ratios, window=window, threshold=threshold,
                          initial_hypothesis=initial_hypothesis)


# ---------------------------------------------------------------------------------------------
# The kind "cusum": its key in the world file, and what the size guard and detection need
# ---------------------------------------------------------------------------------------------

def _read_threshold(loader, value: object, n_hypotheses: int) -> float:
    threshold = loader.number(value, "inference.threshold")
    if threshold <= 0:
        raise loader.fail("inference.threshold", f"threshold must be > 0, got {threshold}")
    return threshold


def _build(world: World, games: list[PerceptualGame]) -> InferenceModel:
    return build_inference(games, world.window, world.setting("threshold"),
                           world.initial_hypothesis)


def _memory(world: World) -> MemoryBound:
    """P2 remembers her hypothesis and the last w-1 observations, without trap sets (§5)."""
    return MemoryBound(hypotheses=len(world.hypotheses), observations=world.window - 1)


def _mismatches(world: World, max_score: float, vary: Callable[..., World]
                ) -> list[Mismatch]:
    """Window +- 1, threshold / 2 and * 2, and half the largest score P2 reached."""
    threshold = world.setting("threshold")
    variants = window_mismatches(world, threshold)
    others = [(threshold / 2, "threshold / 2"), (threshold * 2, "threshold * 2")]
    # When P1's strategy keeps every CUSUM score far below the threshold (so that the variants
    # above change nothing), a P2 who changes her mind on half the largest score P1 lets her
    # reach certainly behaves differently somewhere.
    hasty = max_score / 2
    if 0.0 < hasty < threshold / 2:
        others.append((hasty, "half the largest CUSUM score reached when P2 follows the model"))
    for value, why in others:
        variants.append(Mismatch(f"threshold {value:.4g}", vary(world, threshold=value),
                                 why, value))
    return variants


KIND = ObserverKind(
    name="cusum", title="CUSUM",
    settings=(Setting("threshold", "a number > 0", _read_threshold,
                      swept=Swept("number", "a number > 0")),),
    build=_build, memory=_memory, mismatches=_mismatches,
    report=lambda world: {"window": world.window, "threshold": world.setting("threshold")},
    shown_setting="threshold")
