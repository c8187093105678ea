"""P2's Bayesian inference (docs/semantics.md §12): a posterior over hypotheses from the last w
observations, acted on by its most probable hypothesis ("map") or by a draw from it ("sample").

P2's memory is the window of the last at most w observations (TS state, P1's action, the trap
set in force), oldest first; `Memory.hypothesis` carries the window's MAP hypothesis beside it.
`BayesObserver` implements the observer interface of `observer.py`, its PRISM part included
(templates/inference_bayes.prism.j2).

The log-posterior of x, up to the normaliser, is summed in one fixed order, oldest observation
first, `ln prior(x) + ll(o1) + ll(o2) + ...`, in Python and in the PRISM formulas alike, so both
compute the same doubles and the 1e-9 tie rule decides identically.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hg2prism.model.dynamics import ACTIONS, TransitionSystem
from hg2prism.opponent.inference import ts_state_expression
from hg2prism.opponent.observer import Memory, Observation, ObserverPrism
from hg2prism.opponent.perceptual_games import PerceptualGame
from hg2prism.prism.rendering import cases, lookup, maximum, prism_number, render_macro

__all__ = ["BayesObserver", "build_bayes", "TOLERANCE", "E"]

TOLERANCE = 1e-9          # hypotheses within this of the largest log-posterior tie
E = math.e                # PRISM has no exp(): the posterior is written pow(E, ...)


@dataclass(frozen=True, eq=False)
class BayesObserver:
    """The Bayesian observer (kind "bayes")."""

    log_likelihood: np.ndarray   # [X, n_ts, 4, n_sets] ln pi1_x(a1 | v, a2)
    log_prior: np.ndarray        # [X] ln prior(x)
    window: int                  # w: observations remembered
    decision: str                # "map" or "sample"
    trap_choice: np.ndarray      # [X, n_ts] pi2_x(v)

    kind = "bayes"

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
        scores = self.log_scores(window)
        top = max(scores)
        return next(x for x, s in enumerate(scores) if s >= top - TOLERANCE)

    def posterior(self, window: tuple[Observation, ...]) -> list[float]:
        """p(x | W) for every x, computed from the log-scores relative to their maximum."""
        scores = self.log_scores(window)
        top = max(scores)
        weights = [math.exp(s - top) for s in scores]
        total = 0.0
        for w in weights:
            total = total + w
        return [w / total for w in weights]

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
        top = scores.max(axis=1, keepdims=True)
        return np.argmax(scores >= top - TOLERANCE, axis=1)

    # -- the PRISM part ------------------------------------------------------------------------

    def prism(self, ts: TransitionSystem, labels: dict[str, str]) -> ObserverPrism:
        """The log-likelihood tables, the log-posterior and the decision as formulas over the
        window's slots o1 (oldest) .. o{w}, and the module p2_inference that shifts the window
        (4 commands whatever the window, the grid or the hypotheses). With "sample" the robot
        module draws P2's hypothesis jointly with the move (4 + 1 commands) and also holds the
        newest slot's trap set and, with delay > 0, the standing traps."""
        n_x, slots = self.n_hypotheses, self.window
        n_obs_states = ts.n_states - 1          # the TRAPPED state is never observed
        n_sets = ts.n_sets
        tables = []                              # (name, comment, expression)
        if n_x > 1:
            for x in range(n_x):
                table = self.log_likelihood[x, :n_obs_states]                # [states, 4, sets]
                padded = np.zeros((n_obs_states + 1, 5, n_sets + 1))        # -1 = empty slot
                padded[1:, 1:, 1:] = table
                for i in range(1, slots + 1):
                    tables.append((f"ll_x{x}_o{i}", f"ln pi1_x{x}(a1 | v, a2) of slot o{i}",
                                   lookup(padded, [(f"o{i}_state", -1), (f"o{i}_act", -1),
                                                   (f"o{i}_set", -1)])))
        scores = []
        for x in range(n_x):
            terms = [prism_number(float(self.log_prior[x]))]
            if n_x > 1:
                terms += [f"ll_x{x}_o{i}" for i in range(1, slots + 1)]
            scores.append((f"lp_x{x}", "+".join(terms)))
        lp_names = [name for name, _ in scores]
        tolerance = prism_number(TOLERANCE)
        decision = cases([(f"{name}>=lpmax-{tolerance}", str(x))
                          for x, name in enumerate(lp_names[:-1])], str(n_x - 1))
        posterior = []
        if self.decision == "sample":
            if n_x == 1:
                posterior = [("post_x0", "1.0")]
            else:
                posterior = [(f"ex_x{x}", f"pow({prism_number(E)}, lp_x{x}-lpmax)")
                             for x in range(n_x)]
                total = "+".join(f"ex_x{x}" for x in range(n_x))
                posterior += [(f"post_x{x}", f"ex_x{x}/({total})") for x in range(n_x)]
        robot = []
        if self.decision == "sample":
            perpendicular = {"N": "EW", "E": "NS", "S": "EW", "W": "NS"}
            for a in ACTIONS:
                directions = ([("(1-2*slip)", a)] + [("slip", p) for p in perpendicular[a]]
                              if ts.slip > 0 else [("1", a)])
                robot.append({"action": a, "outcomes": [
                    (x, p, d) for x in range(n_x) for p, d in directions]})
        members = np.array([sorted(ts.candidates[c] for c in m) for m in ts.trap_sets],
                           dtype=np.int64).reshape(n_sets, -1)
        set_cells = [[lookup(members[:, j], [(f"set_x{x}", 0)]) for j in range(members.shape[1])]
                     for x in range(n_x)]
        context = dict(
            ts_state=ts_state_expression(ts), tables=tables, scores=scores,
            lpmax=maximum(lp_names), decision_expr=decision, posterior=posterior,
            draws=self.decision == "sample", robot_outcomes=robot, set_cells=set_cells,
            n_trap_cells=members.shape[1], delay=ts.delay, actions=ACTIONS, labels=labels,
            slots=slots, n_obs_states=n_obs_states, n_sets=n_sets, n_hypotheses=n_x,
            start_cell=ts.decode(ts.start_state)[0], start_traps=ts.decode(ts.start_state)[1])
        header = (f"// inference    Bayesian, window {self.window}, decision {self.decision}, "
                  f"prior " + ", ".join(f"{math.exp(p):.6g}" for p in self.log_prior))

        def part(macro: str) -> str:
            return render_macro("inference_bayes.prism.j2", macro, **context).rstrip("\n")

        return ObserverPrism(
            formulas=part("formulas"), module=part("module"), slots=slots,
            commands=len(ACTIONS), slot_sets=True, hypothesis_variable=False,
            robot=part("robot") if self.decision == "sample" else "", header=header)


def build_bayes(games: list[PerceptualGame], window: int, prior: tuple[float, ...],
                decision: str) -> BayesObserver:
    """ln pi1_x(a1 | v, a2) for every hypothesis, TS state, move and trap set (§4's softmax),
    and ln prior."""
    log_likelihood = np.stack([np.transpose(g.log_policy, (0, 2, 1)) for g in games])
    return BayesObserver(log_likelihood=np.ascontiguousarray(log_likelihood),
                         log_prior=np.log(np.asarray(prior, dtype=float)), window=window,
                         decision=decision,
                         trap_choice=np.stack([g.trap_choice for g in games]))
