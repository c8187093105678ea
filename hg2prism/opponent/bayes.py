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


def _exp(value: float) -> float:
    return math.exp(value) if value < 709.0 else math.inf


@dataclass(frozen=True, eq=False)
class BayesObserver:
    """The Bayesian observer (kind "bayes")."""

    log_likelihood: np.ndarray   # [X, n_ts, 4, n_sets] ln pi1_x(a1 | v, a2)
    log_prior: np.ndarray        # [X] ln prior(x)
    window: int                  # w: observations remembered
    decision: str                # "map" or "sample"
    trap_choice: np.ndarray      # [X, n_ts] pi2_x(v)

    kind = "bayes"
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
        scores = self.log_scores(window)
        top = max(scores)
        return next(x for x, s in enumerate(scores) if s >= top - TOLERANCE)

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
        top = scores.max(axis=1, keepdims=True)
        return np.argmax(scores >= top - TOLERANCE, axis=1)

    # -- the PRISM part ------------------------------------------------------------------------

    def prism(self, ts: TransitionSystem, labels: dict[str, str],
              observed: np.ndarray | None = None, played: str | None = None) -> ObserverPrism:
        """The window's slots o1 (oldest) .. o{w} and the decision, as formulas and the module
        p2_inference (4 commands whatever the window, the grid or the hypotheses).

        Storm and PRISM substitute formulas where they are used, so a posterior written over
        (state, move, trap set) tables would be copied into every expression that reads it. So
        each slot also holds the *class* of its observation, o<i>_cls: observations with the
        same log-likelihoods ln pi1_x(a1 | v, a2) for every x share a class (a function of the
        slot, so it adds no state), and the log-posterior sums small per-class tables. With
        "map", `hyp` is a variable set with the window (also a function of it). With "sample"
        the robot module draws P2's hypothesis jointly with the move (4 + 1 commands) and also
        holds the newest slot's trap set and class and, with delay > 0, the standing traps.
        With `played` (the robust model, "map" only) P2 records the set she played, held in
        that variable (docs/semantics.md §13), and the move's tables are over it instead of
        her prediction."""
        n_x, slots = self.n_hypotheses, self.window
        n_obs_states = ts.n_states - 1          # the TRAPPED state is never observed
        n_sets = ts.n_sets
        table = self.log_likelihood[:, :n_obs_states]                # [X, states, 4, sets]
        vectors = np.moveaxis(table, 0, -1).reshape(-1, n_x)         # one row per observation
        classes, class_of = np.unique(vectors, axis=0, return_inverse=True)
        class_of = class_of.reshape(n_obs_states, 4, n_sets)
        n_classes = len(classes)
        draws = self.decision == "sample"
        tolerance = prism_number(TOLERANCE)
        # The trap set in force is a function of (TS state, hypothesis): pi2_x(v), the standing
        # set while the countdown runs. So the move made now is looked up over (ts_state, hyp)
        # ("map") or over ts_state for each drawn x ("sample"), never over the trap set formula,
        # which would be copied into every comparison of the table.
        if played is not None and draws:
            raise ValueError("P2 draws her hypothesis (decision \"sample\"): the robust model "
                             "(docs/semantics.md §13) is written for decision \"map\"")
        states = np.arange(n_obs_states)
        in_force = self.trap_choice[:, :n_obs_states]                   # [X, states]
        care = np.ones(n_obs_states, dtype=bool) if observed is None else np.asarray(observed)
        # The move made now: over (ts_state, hyp), P2's prediction in force, or over
        # (ts_state, played) where she may play another set.
        if played is None:
            now_keys, now_sets = [("ts_state", 0), ("hyp", 0)], in_force.T        # [states, X]
        else:
            now_keys = [("ts_state", 0), (played, 0)]
            now_sets = np.broadcast_to(np.arange(n_sets), (n_obs_states, n_sets))
        class_now = {a: lookup(class_of[states[:, None], d, now_sets], now_keys, care[:, None])
                     for d, a in enumerate(ACTIONS)} if not draws else {}
        class_drawn = {(a, x): lookup(class_of[states, d, in_force[x]], [("ts_state", 0)], care)
                       for d, a in enumerate(ACTIONS) for x in range(n_x)} if draws else {}
        slot_ll = []                             # (name, expression) ln pi1_x of slot o<i>
        for x in range(n_x):
            padded = np.concatenate([[0.0], classes[:, x]])           # class -1 = empty slot
            first = 1 if draws else 2            # "map" reads the slots that stay in the window
            for i in range(first, slots + 1):
                slot_ll.append((f"ll_x{x}_o{i}", lookup(padded, [(f"o{i}_cls", -1)])))
        rules = []
        if not draws:
            # the new window: slots o2 .. o{w} and the move now; the new MAP hypothesis
            for d, a in enumerate(ACTIONS):
                scores = []
                for x in range(n_x):
                    now = lookup(table[x, states[:, None], d, now_sets], now_keys,
                                 care[:, None])
                    terms = [prism_number(float(self.log_prior[x]))]
                    terms += [f"ll_x{x}_o{i}" for i in range(2, slots + 1)] + [f"llnow_x{x}_{a}"]
                    scores.append({"x": x, "now": now, "sum": "+".join(terms)})
                names = [f"lpn_x{x}_{a}" for x in range(n_x)]
                best = cases([(f"{name}>=lpnmax_{a}-{tolerance}", str(x))
                              for x, name in enumerate(names[:-1])], str(n_x - 1))
                rules.append({"action": a, "scores": scores, "max": maximum(names),
                              "next": best})
        posterior = []
        if draws:
            for x in range(n_x):
                terms = [prism_number(float(self.log_prior[x]))]
                terms += [f"ll_x{x}_o{i}" for i in range(1, slots + 1)]
                posterior.append((f"lp_x{x}", "+".join(terms)))
            for x in range(n_x):
                total = "+".join("1.0" if y == x else f"pow({prism_number(E)}, lp_x{y}-lp_x{x})"
                                 for y in range(n_x))
                posterior.append((f"post_x{x}", f"1/({total})" if n_x > 1 else "1.0"))
        robot = []
        if draws:
            perpendicular = {"N": "EW", "E": "NS", "S": "EW", "W": "NS"}
            for a in ACTIONS:
                directions = ([("(1-2*slip)", a)] + [("slip", p) for p in perpendicular[a]]
                              if ts.slip > 0 else [("1", a)])
                robot.append({"action": a, "outcomes": [
                    (x, p, d) for x in range(n_x) for p, d in directions]})
        members = np.array([sorted(ts.candidates[c] for c in m) for m in ts.trap_sets],
                           dtype=np.int64).reshape(n_sets, -1)
        set_cells = [[lookup(members[:, j], [(f"set_x{x}", 0)]) for j in range(members.shape[1])]
                     for x in range(n_x)] if draws else []
        context = dict(
            ts_state=ts_state_expression(ts), slot_ll=slot_ll, rules=rules,
            posterior=posterior, class_now=class_now, class_drawn=class_drawn,
            draws=draws, robot_outcomes=robot, set_cells=set_cells,
            set_in_force=played or "trap_set",
            n_trap_cells=members.shape[1], delay=ts.delay, actions=ACTIONS, labels=labels,
            slots=slots, n_obs_states=n_obs_states, n_sets=n_sets, n_hypotheses=n_x,
            n_classes=n_classes, initial_hypothesis=self.initial_hypothesis,
            start_cell=ts.decode(ts.start_state)[0], start_traps=ts.decode(ts.start_state)[1])
        header = (f"// inference    Bayesian, window {self.window}, decision {self.decision}, "
                  f"prior " + ", ".join(f"{math.exp(p):.6g}" for p in self.log_prior))

        def part(macro: str) -> str:
            return render_macro("inference_bayes.prism.j2", macro, **context).rstrip("\n")

        return ObserverPrism(
            formulas=part("formulas"), module=part("module"), slots=slots,
            commands=len(ACTIONS), slot_sets=True, hypothesis_variable=not draws,
            robot=part("robot") if draws else "", header=header)


def build_bayes(games: list[PerceptualGame], window: int, prior: tuple[float, ...],
                decision: str) -> BayesObserver:
    """ln pi1_x(a1 | v, a2) for every hypothesis, TS state, move and trap set (§4's softmax),
    and ln prior."""
    log_likelihood = np.stack([np.transpose(g.log_policy, (0, 2, 1)) for g in games])
    return BayesObserver(log_likelihood=np.ascontiguousarray(log_likelihood),
                         log_prior=np.log(np.asarray(prior, dtype=float)), window=window,
                         decision=decision,
                         trap_choice=np.stack([g.trap_choice for g in games]))
