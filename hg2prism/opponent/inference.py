"""P2's inference (docs/semantics.md §5): sliding-window CUSUM over log-likelihood ratios of P1's moves.

P2's memory is (current hypothesis, the last at most w-1 observations since the last change);
an observation is (TS state, P1's action index).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hg2prism.opponent.perceptual_games import PerceptualGame

TOLERANCE = 1e-9

Observation = tuple[int, int]   # (TS state, action index into dynamics.ACTIONS)


@dataclass(frozen=True)
class Memory:
    hypothesis: int
    window: tuple[Observation, ...] = ()


@dataclass(frozen=True, eq=False)
class InferenceModel:
    ratios: np.ndarray        # [X, X, n_ts, 4] r(x | xh; v, a1), indexed [xh, x, v, a1]
    window: int               # w: transitions in the sliding window
    threshold: float          # c
    initial_hypothesis: int

    @property
    def n_hypotheses(self) -> int:
        return self.ratios.shape[0]

    def initial_memory(self) -> Memory:
        return Memory(self.initial_hypothesis, ())

    def scores(self, memory: Memory, observation: Observation) -> np.ndarray:
        """CUSUM score Z_x over the window for every x (0 for the current hypothesis)."""
        current = memory.hypothesis
        recent = (memory.window + (observation,))[-self.window:]
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
        """eta: the memory after P1 plays `observation[1]` from TS state `observation[0]`."""
        recent = (memory.window + (observation,))[-self.window:]
        if self.n_hypotheses > 1:
            z = self.scores(memory, observation)
            others = [x for x in range(self.n_hypotheses) if x != memory.hypothesis]
            top = max(z[x] for x in others)
            if top >= self.threshold - TOLERANCE:
                best = next(x for x in others if z[x] >= top - TOLERANCE)
                return Memory(best, ())
        keep = recent[-(self.window - 1):] if self.window > 1 else ()
        return Memory(memory.hypothesis, keep)


def build_inference(games: list[PerceptualGame], window: int, threshold: float,
                    initial_hypothesis: int) -> InferenceModel:
    """r(x | xh; v, a1) = ln pi1_x(a1 | v, a2) - ln pi1_xh(a1 | v, a2) with a2 = pi2_xh(v)."""
    n_x = len(games)
    n_ts = games[0].trap_choice.shape[0]
    states = np.arange(n_ts)
    ratios = np.zeros((n_x, n_x, n_ts, 4))
    for xh, current in enumerate(games):
        a2 = current.trap_choice
        base = current.log_policy[states, a2]                         # [n_ts, 4]
        for x, other in enumerate(games):
            if x != xh:
                ratio = other.log_policy[states, a2] - base
                # Where both hypotheses predict the same move the difference is rounding noise.
                ratio[np.abs(ratio) < 1e-12] = 0.0
                ratios[xh, x] = ratio
    return InferenceModel(ratios=ratios, window=window, threshold=threshold,
                          initial_hypothesis=initial_hypothesis)
