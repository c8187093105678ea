"""P2's inference (docs/semantics.md §5): sliding-window CUSUM over log-likelihood ratios of P1's moves.

P2's memory is (current hypothesis, the last at most w-1 observations since the last change);
an observation is (TS state, P1's action index). `InferenceModel` implements the observer
interface of `observer.py`, its PRISM part included (templates/inference_cusum.prism.j2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hg2prism.model.dynamics import ACTIONS, TransitionSystem
from hg2prism.opponent.observer import Memory, Observation, ObserverPrism
from hg2prism.opponent.perceptual_games import PerceptualGame
from hg2prism.prism.rendering import cases, lookup, maximum, prism_number, render_macro

TOLERANCE = 1e-9


__all__ = ["Memory", "InferenceModel", "build_inference", "ts_state_expression", "ts_table"]


@dataclass(frozen=True, eq=False)
class InferenceModel:
    """Sliding-window CUSUM (the observer of kind "cusum")."""

    ratios: np.ndarray        # [X, X, n_ts, 4] r(x | xh; v, a1), indexed [xh, x, v, a1]
    window: int               # w: transitions in the sliding window
    threshold: float          # c
    initial_hypothesis: int

    @property
    def n_hypotheses(self) -> int:
        return self.ratios.shape[0]

    kind = "cusum"
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
                best = next(x for x in others if z[x] >= top - TOLERANCE)
                return Memory(best, ())
        keep = recent[-(self.window - 1):] if self.window > 1 else ()
        return Memory(memory.hypothesis, keep)


    def prism(self, ts: TransitionSystem, labels: dict[str, str],
              observed: np.ndarray | None = None, played: str | None = None) -> ObserverPrism:
        """The ratio tables, the CUSUM scores and the module p2_inference: hyp and the window's
        slots o1 (oldest) .. o{w-1}, each a TS state and a move (-1 when empty). The scores are
        formulas over the slots, so the module has 2 commands per (hypothesis, move), 1 with a
        single hypothesis, whatever the window or the grid. `played` changes nothing: a ratio
        reads P2's predicted trap set by definition (docs/semantics.md §5)."""
        n_x, slots = self.n_hypotheses, self.window - 1
        n_obs_states = ts.n_states - 1          # the TRAPPED state is never observed
        ratio_formulas = []      # (name, comment, expression)
        rules = []               # per (hypothesis, action): switch and best formulas
        if slots == 0 and n_x > 1:
            return self._prism_window_one(ts, labels, observed)
        class_tables = []        # (name, comment, expression)
        n_classes = 1
        for h in range(n_x):
            others = [x for x in range(n_x) if x != h]
            if others and slots:
                classes, class_ratios = self.ratio_classes(h, observed)
                n_classes = max(n_classes, len(class_ratios))
                for d, a in enumerate(ACTIONS):
                    class_tables.append((f"cls_h{h}_{a}", f"class of moving {a} now when hyp = {h}",
                                         ts_table(ts, classes[:, d], observed)))
            for x in others:
                ratios = self.ratios[h, x, :n_obs_states]                    # [states, 4]
                for i in range(1, slots + 1):
                    padded = np.r_[0.0, class_ratios[:, x]]                   # class -1 = empty
                    ratio_formulas.append((
                        f"r_h{h}_x{x}_o{i}", f"r(x{x} | x{h}) of the move in slot o{i}",
                        lookup(padded, [(f"o{i}_cls", -1)])))
                for d, a in enumerate(ACTIONS):
                    ratio_formulas.append((
                        f"r_h{h}_x{x}_{a}", f"r(x{x} | x{h}) of moving {a} now",
                        ts_table(ts, ratios[:, d], observed)))
            for a in ACTIONS:
                scores = {}
                for x in others:
                    z = "0.0"
                    for term in [f"r_h{h}_x{x}_o{i}" for i in range(1, slots + 1)] + [f"r_h{h}_x{x}_{a}"]:
                        z = f"max(0.0, {z}+{term})" if z != "0.0" else f"max(0.0, {term})"
                    scores[x] = z
                z_names = [f"z_h{h}_x{x}_{a}" for x in others]
                # the new hypothesis: the first (in order) whose score ties the maximum
                best = cases([(f"{z} >= zmax_h{h}_{a} - {prism_number(TOLERANCE)}", str(x))
                              for z, x in zip(z_names[:-1], others[:-1])], str(others[-1])
                             ) if others else ""
                rules.append({"h": h, "action": a, "others": others, "scores": scores,
                              "zmax": maximum(z_names) if others else "", "next": best})
        context = dict(
            ts_state=ts_state_expression(ts), ratio_formulas=ratio_formulas, inference_rules=rules,
            class_tables=class_tables, n_classes=n_classes,
            switch_threshold=prism_number(self.threshold - TOLERANCE),
            tolerance=prism_number(TOLERANCE), actions=ACTIONS, labels=labels, slots=slots,
            n_obs_states=n_obs_states, n_hypotheses=n_x, initial_hypothesis=self.initial_hypothesis)
        return ObserverPrism(
            formulas=render_macro("inference_cusum.prism.j2", "formulas", **context).rstrip("\n"),
            module=render_macro("inference_cusum.prism.j2", "module", **context).rstrip("\n"),
            slots=slots, commands=sum(2 if rule["others"] else 1 for rule in rules))


    def ratio_classes(self, hypothesis: int, observed: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Observations that P2 cannot tell apart under `hypothesis`: those whose ratios
        r(x | hypothesis) agree for every x. Returns each observed (TS state, move)'s class
        [states, 4] and each class's ratios [classes, X] (0 for x = hypothesis). A window slot
        of the PRISM model keeps its observation's class, so the slot's ratios are a table over
        the classes (a few hundred) instead of over every observation. Only the TS states
        marked `observed` (default all) are classified; the others get class 0."""
        n_obs = self.ratios.shape[2] - 1
        kept = np.ones(n_obs, dtype=bool) if observed is None else np.asarray(observed, dtype=bool)
        vectors = self.ratios[hypothesis, :, :n_obs, :][:, kept].transpose(1, 2, 0)
        vectors = vectors.reshape(-1, self.n_hypotheses) + 0.0   # -0.0 and 0.0 are the same ratio
        class_ratios, found = np.unique(vectors, axis=0, return_inverse=True)
        classes = np.zeros((n_obs, 4), dtype=np.int64)
        classes[kept] = found.reshape(-1, 4)
        return classes, class_ratios

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
            first = (z >= top - TOLERANCE).argmax(axis=0)
            after[h] = np.where(switch, np.asarray(others)[first], h)
        return after

    def _prism_window_one(self, ts: TransitionSystem, labels: dict[str, str],
                          observed: np.ndarray | None) -> ObserverPrism:
        """Window 1: P2's memory is her hypothesis alone, so the hypothesis after each move is
        a table over the TS state, computed here; Storm evaluates one table per command instead
        of the CUSUM formulas, each of which repeats every ratio table it uses."""
        n_x = self.n_hypotheses
        tables = []              # (name, comment, expression)
        for d, a in enumerate(ACTIONS):
            after = self.next_hypotheses(d)
            for h in range(n_x):
                tables.append((f"hyp_after_h{h}_{a}",
                               f"P2's hypothesis after P1 moves {a} when hyp = {h}",
                               ts_table(ts, after[h], observed)))
        context = dict(next_tables=tables, actions=ACTIONS, labels=labels,
                       n_hypotheses=n_x, initial_hypothesis=self.initial_hypothesis)
        return ObserverPrism(
            formulas=render_macro("inference_cusum.prism.j2", "formulas_window_one",
                                  **context).rstrip("\n"),
            module=render_macro("inference_cusum.prism.j2", "module_window_one",
                                **context).rstrip("\n"),
            slots=0, commands=len(ACTIONS) * n_x)


def ts_table(ts: TransitionSystem, values: np.ndarray, observed: np.ndarray | None = None) -> str:
    """A table over the observed TS states (values[v] for v < ts.n_states - 1) as a decision
    tree over cell (then traps and countdown when delay > 0): comparisons on the variables
    themselves, not on `ts_state`, which Storm would recompute at every comparison. Where
    `observed` is False the table may take any value (see rendering.lookup)."""
    if not ts.delay:
        return lookup(values, [("cell", 0)], observed)
    keys = [("cell", 0), ("traps", 0), ("countdown", 0)]
    shape = (ts.n_cells, ts.n_sets, ts.phases)
    return lookup(np.asarray(values).reshape(shape), keys,
                  None if observed is None else np.asarray(observed).reshape(shape))


def ts_state_expression(ts: TransitionSystem) -> str:
    """The TS state as one PRISM expression over cell (and traps, countdown when delay > 0),
    numbered as dynamics.TransitionSystem numbers its states."""
    if not ts.delay:
        return "cell"
    # with one trap set, traps is always 0 (but declared [0..1]: see rendering.upper)
    return (f"(cell*{ts.n_sets}+traps)*{ts.phases}+countdown" if ts.n_sets > 1
            else f"cell*{ts.phases}+countdown")


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
