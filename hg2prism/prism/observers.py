"""Each observer's part of the hypergame's PRISM model (docs/semantics.md §6): the CUSUM
observer of §5 (templates/inference_cusum.prism.j2) and the Bayesian one of §12
(templates/inference_bayes.prism.j2).

A renderer takes the observer, the TS, the labels its module synchronises on, the TS states the
robot can reach (its tables must be right there and are free elsewhere, so they stay short) and,
in the robust model of §13, the variable holding the trap set P2 played; it returns an
`ObserverPrism`, which the hypergame template places. Each observer's kind names its renderer
(opponent/registry.py), so the templates and the rest of prism/ never ask which observer it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hg2prism.model.dynamics import TransitionSystem
from hg2prism.opponent.observer import TOLERANCE
from hg2prism.prism.arena_tables import InForce, arena_tables, p2_choices
from hg2prism.prism.rendering import cases, lookup, maximum, prism_number, render_macro, upper

if TYPE_CHECKING:
    from hg2prism.opponent.bayes import BayesObserver
    from hg2prism.opponent.inference import InferenceModel

__all__ = ["ObserverPrism", "render_cusum", "render_bayes", "ts_table", "ts_state_expression"]

E = math.e                # PRISM has no exp(): the Bayesian posterior is written pow(E, ...)


@dataclass(frozen=True)
class ObserverPrism:
    """An observer's part of the hypergame model: PRISM text for the formulas (its tables,
    placed before the modules) and for its module, plus what decoding Storm's states needs."""

    formulas: str
    module: str
    slots: int                 # observation slots o1 (oldest) .. o{slots} in the module
    commands: int              # commands of its module (the module is "p2_inference")
    header: str                # the header line describing the inference ("// inference ...")
    slot_sets: bool = False    # slots also hold the trap set in force (o<i>_set)
    hypothesis_variable: bool = True   # `hyp` is a variable (else derived from the slots)
    # Set when P2 draws her hypothesis at each step: the robot module that draws it jointly
    # with the move (it replaces the hypergame's robot and p2_traps modules).
    robot: str = ""


def ts_table(ts: TransitionSystem, values: np.ndarray, observed: np.ndarray | None = None) -> str:
    """A table over the observed TS states (values[v] for v < ts.n_states - 1) as a decision
    tree over place (then traps and countdown when delay > 0): comparisons on the variables
    themselves, not on `ts_state`, which Storm would recompute at every comparison. Where
    `observed` is False the table may take any value (see rendering.lookup)."""
    if not ts.delay:
        return lookup(values, [("place", 0)], observed)
    keys = [("place", 0), ("traps", 0), ("countdown", 0)]
    shape = (ts.n_places, ts.n_sets, ts.phases)
    return lookup(np.asarray(values).reshape(shape), keys,
                  None if observed is None else np.asarray(observed).reshape(shape))


def ts_state_expression(ts: TransitionSystem) -> str:
    """The TS state as one PRISM expression over place (and traps, countdown when delay > 0),
    numbered as dynamics.TransitionSystem numbers its states."""
    if not ts.delay:
        return "place"
    # with one trap set, traps is always 0 (but declared [0..1]: see rendering.upper)
    return (f"(place*{ts.n_sets}+traps)*{ts.phases}+countdown" if ts.n_sets > 1
            else f"place*{ts.phases}+countdown")


def live_guard(ts: TransitionSystem) -> str:
    """A guard that keeps ts_state an observation wherever it holds: P1 not trapped (PRISM
    checks updates in range in every state, reachable or not)."""
    return "place!=TRAPPED" if ts.traps_mode else "true"


# ---------------------------------------------------------------------------------------------
# CUSUM (docs/semantics.md §5)
# ---------------------------------------------------------------------------------------------

def render_cusum(observer: InferenceModel, ts: TransitionSystem, labels: dict[int, str],
                 observed: np.ndarray | None = None, played: str | None = None) -> ObserverPrism:
    """The ratio tables, the CUSUM scores and the module p2_inference: hyp and the window's
    slots o1 (oldest) .. o{w-1}, each a TS state and a move (-1 when empty). The scores are
    formulas over the slots, so the module has 2 commands per (hypothesis, move), 1 with a
    single hypothesis, whatever the window or the grid. `played` changes nothing: a ratio
    reads P2's predicted trap set by definition (docs/semantics.md §5)."""
    n_x, slots = observer.n_hypotheses, observer.window - 1
    header = f"// inference    window {observer.window}, threshold {observer.threshold}"
    if slots == 0 and n_x > 1:
        return _cusum_window_one(observer, ts, labels, observed, header)
    tables = _CusumTables(observer, ts, observed)
    rules = [rule for h in range(n_x) for rule in tables.rules(h, labels)]
    context = dict(
        ts_state=ts_state_expression(ts), ratio_formulas=tables.ratio_formulas,
        inference_rules=rules, class_tables=tables.class_tables, n_classes=tables.n_classes,
        switch_threshold=prism_number(observer.threshold - TOLERANCE),
        tolerance=prism_number(TOLERANCE), labels=labels, slots=slots, live=live_guard(ts),
        n_actions=ts.n_actions,
        n_obs_states=ts.n_states - 1, n_hypotheses=n_x,
        initial_hypothesis=observer.initial_hypothesis)
    return ObserverPrism(
        formulas=render_macro("inference_cusum.prism.j2", "formulas", **context).rstrip("\n"),
        module=render_macro("inference_cusum.prism.j2", "module", **context).rstrip("\n"),
        slots=slots, commands=sum(2 if rule["others"] else 1 for rule in rules), header=header)


class _CusumTables:
    """The formulas of the CUSUM model, hypothesis by hypothesis: the observation classes of
    each hypothesis, the ratios of each slot and of the move made now, and per (hypothesis,
    move) the scores and the switch (`rules`, collected in `ratio_formulas` and
    `class_tables` as they are written)."""

    def __init__(self, observer: InferenceModel, ts: TransitionSystem,
                 observed: np.ndarray | None) -> None:
        self.observer, self.ts, self.observed = observer, ts, observed
        self.ratio_formulas: list[tuple[str, str, str]] = []     # (name, comment, expression)
        self.class_tables: list[tuple[str, str, str]] = []
        self.n_classes = 1

    def rules(self, h: int, labels: dict[int, str]) -> list[dict]:
        """Hypothesis h's formulas, and its rule per move (the scores and the next hypothesis:
        the first, in order, whose score ties the maximum)."""
        observer, ts = self.observer, self.ts
        n_x, slots = observer.n_hypotheses, observer.window - 1
        others = [x for x in range(n_x) if x != h]
        if others and slots:
            classes, class_ratios = ratio_classes(observer, h, self.observed)
            self.n_classes = max(self.n_classes, len(class_ratios))
            for d in labels:
                a = f"a{d}"
                self.class_tables.append((f"cls_h{h}_{a}", f"class of playing {a} now when hyp = {h}",
                                          ts_table(ts, classes[:, d], self.observed)))
        for x in others:
            ratios = observer.ratios[h, x, :ts.n_states - 1]                 # [states, slots]
            for i in range(1, slots + 1):
                padded = np.r_[0.0, class_ratios[:, x]]                     # class -1 = empty
                self.ratio_formulas.append((
                    f"r_h{h}_x{x}_o{i}", f"r(x{x} | x{h}) of the move in slot o{i}",
                    lookup(padded, [(f"o{i}_cls", -1)])))
            for d in labels:
                a = f"a{d}"
                self.ratio_formulas.append((
                    f"r_h{h}_x{x}_{a}", f"r(x{x} | x{h}) of playing {a} now",
                    ts_table(ts, ratios[:, d], self.observed)))
        rules = []
        for d, label in labels.items():
            a = f"a{d}"
            scores = {}
            for x in others:
                z = "0.0"
                for term in [f"r_h{h}_x{x}_o{i}" for i in range(1, slots + 1)] + [f"r_h{h}_x{x}_{a}"]:
                    z = f"max(0.0, {z}+{term})" if z != "0.0" else f"max(0.0, {term})"
                scores[x] = z
            z_names = [f"z_h{h}_x{x}_{a}" for x in others]
            best = cases([(f"{z} >= zmax_h{h}_{a} - {prism_number(TOLERANCE)}", str(x))
                          for z, x in zip(z_names[:-1], others[:-1])], str(others[-1])
                         ) if others else ""
            rules.append({"h": h, "action": a, "slot": d, "label": label, "others": others,
                          "scores": scores,
                          "zmax": maximum(z_names) if others else "", "next": best})
        return rules


def ratio_classes(observer: InferenceModel, hypothesis: int, observed: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Observations that P2 cannot tell apart under `hypothesis`: those whose ratios
    r(x | hypothesis) agree for every x. Returns each observed (TS state, move)'s class
    [states, slots] and each class's ratios [classes, X] (0 for x = hypothesis). A window slot
    of the PRISM model keeps its observation's class, so the slot's ratios are a table over
    the classes (a few hundred) instead of over every observation. Only the TS states
    marked `observed` (default all) are classified; the others get class 0."""
    n_obs = observer.ratios.shape[2] - 1
    kept = np.ones(n_obs, dtype=bool) if observed is None else np.asarray(observed, dtype=bool)
    vectors = observer.ratios[hypothesis, :, :n_obs, :][:, kept].transpose(1, 2, 0)
    vectors = vectors.reshape(-1, observer.n_hypotheses) + 0.0   # -0.0 and 0.0 are the same ratio
    class_ratios, found = np.unique(vectors, axis=0, return_inverse=True)
    n_actions = observer.ratios.shape[-1]
    classes = np.zeros((n_obs, n_actions), dtype=np.int64)
    classes[kept] = found.reshape(-1, n_actions)
    return classes, class_ratios


def _cusum_window_one(observer: InferenceModel, ts: TransitionSystem, labels: dict[int, str],
                      observed: np.ndarray | None, header: str) -> ObserverPrism:
    """Window 1: P2's memory is her hypothesis alone, so the hypothesis after each move is
    a table over the TS state (InferenceModel.next_hypotheses); Storm evaluates one table per
    command instead of the CUSUM formulas, each of which repeats every ratio table it uses."""
    n_x = observer.n_hypotheses
    tables = []              # (name, comment, expression)
    for d in labels:
        after = observer.next_hypotheses(d)
        for h in range(n_x):
            tables.append((f"hyp_after_h{h}_a{d}",
                           f"P2's hypothesis after P1 plays a{d} when hyp = {h}",
                           ts_table(ts, after[h], observed)))
    context = dict(next_tables=tables, labels=labels, live=live_guard(ts),
                   n_hypotheses=n_x, initial_hypothesis=observer.initial_hypothesis)
    return ObserverPrism(
        formulas=render_macro("inference_cusum.prism.j2", "formulas_window_one",
                              **context).rstrip("\n"),
        module=render_macro("inference_cusum.prism.j2", "module_window_one",
                            **context).rstrip("\n"),
        slots=0, commands=len(labels) * n_x, header=header)


# ---------------------------------------------------------------------------------------------
# Bayesian (docs/semantics.md §12)
# ---------------------------------------------------------------------------------------------

def render_bayes(observer: BayesObserver, ts: TransitionSystem, labels: dict[int, str],
                 observed: np.ndarray | None = None, played: str | None = None) -> ObserverPrism:
    """The window's slots o1 (oldest) .. o{w} and the decision, as formulas and the module
    p2_inference (4 commands whatever the window, the grid or the hypotheses).

    Storm and PRISM substitute formulas where they are used, so a posterior written over
    (state, move, trap set) tables would be copied into every expression that reads it. So
    each slot also holds the *class* of its observation, o<i>_cls: observations with the
    same log-likelihoods ln pi1_x(a1 | v, a2) for every x share a class (a function of the
    slot, so it adds no state), and the log-posterior sums small per-class tables. With
    "map", `hyp` is a variable set with the window (also a function of it). With "sample"
    the robot module draws P2's hypothesis jointly with the move where the hypotheses' actions
    differ (at most 2 x 4 + 1 commands: `_drawing_robot`), is placed after the modules whose
    commands have one outcome, and also holds the newest slot's trap set and class and, with
    delay > 0, the standing traps.
    With `played` (the robust model, "map" only) P2 records the set she played, held in
    that variable (docs/semantics.md §13), and the move's tables are over it instead of
    her prediction."""
    draws = observer.decision == "sample"
    if played is not None and draws:
        raise ValueError("P2 draws her hypothesis (decision \"sample\"): the robust model "
                         "(docs/semantics.md §13) is written for decision \"map\"")
    tables = _BayesTables(observer, ts, observed, played)
    robot_commands, drawn_alike = (_drawing_robot(observer, ts, labels, observed) if draws
                                   else ([], ""))
    context = dict(
        ts_state=ts_state_expression(ts), slot_ll=tables.slot_log_likelihoods(),
        rules=[] if draws else tables.map_rules(labels),
        posterior=tables.posterior() if draws else [],
        class_now={} if draws else tables.classes_now(labels),
        class_drawn=tables.classes_drawn(labels) if draws else {},
        draws=draws, robot_commands=robot_commands, drawn_alike=drawn_alike,
        set_in_force=played or "trap_set", delay=ts.delay, live=live_guard(ts),
        labels=labels, slots=observer.window, n_obs_states=ts.n_states - 1,
        n_actions=ts.n_actions, place_upper=upper(ts.n_places + int(ts.traps_mode)),
        n_sets=ts.n_sets, n_hypotheses=observer.n_hypotheses, n_classes=len(tables.classes),
        initial_hypothesis=observer.initial_hypothesis,
        start_place=ts.decode(ts.start_state)[0], start_traps=ts.decode(ts.start_state)[1])
    header = (f"// inference    Bayesian, window {observer.window}, decision "
              f"{observer.decision}, prior "
              + ", ".join(f"{math.exp(p):.6g}" for p in observer.log_prior))

    def part(macro: str) -> str:
        return render_macro("inference_bayes.prism.j2", macro, **context).rstrip("\n")

    return ObserverPrism(
        formulas=part("formulas"), module=part("module"), slots=observer.window,
        commands=len(labels), header=header, slot_sets=True, hypothesis_variable=not draws,
        robot=part("robot") if draws else "")


class _BayesTables:
    """The formulas of the Bayesian model: the observation classes, the log-likelihoods of
    the slots and of the move made now, the MAP rule ("map") or the posterior ("sample")."""

    def __init__(self, observer: BayesObserver, ts: TransitionSystem,
                 observed: np.ndarray | None, played: str | None) -> None:
        self.observer = observer
        n_x, n_obs_states = observer.n_hypotheses, ts.n_states - 1   # TRAPPED is never observed
        self.table = observer.log_likelihood[:, :n_obs_states]     # [X, states, slots, sets]
        vectors = np.moveaxis(self.table, 0, -1).reshape(-1, n_x)      # one row per observation
        self.classes, class_of = np.unique(vectors, axis=0, return_inverse=True)
        self.class_of = class_of.reshape(n_obs_states, self.table.shape[2], ts.n_sets)
        # The trap set in force is a function of (TS state, hypothesis): pi2_x(v), the standing
        # set while the countdown runs. So the move made now is looked up over (ts_state, hyp)
        # ("map") or over ts_state for each drawn x ("sample"), never over the trap set
        # formula, which would be copied into every comparison of the table.
        self.states = np.arange(n_obs_states)
        self.in_force = observer.trap_choice[:, :n_obs_states]                    # [X, states]
        self.care = (np.ones(n_obs_states, dtype=bool) if observed is None
                     else np.asarray(observed))
        # The move made now: over (ts_state, hyp), P2's prediction in force, or over
        # (ts_state, played) where she may play another set.
        if played is None:
            self.now_keys, self.now_sets = [("ts_state", 0), ("hyp", 0)], self.in_force.T
        else:
            self.now_keys = [("ts_state", 0), (played, 0)]
            self.now_sets = np.broadcast_to(np.arange(ts.n_sets), (n_obs_states, ts.n_sets))

    def classes_now(self, labels: dict[int, str]) -> dict[str, str]:
        """"map": the class of each move made now, over (ts_state, the set in force)."""
        return {f"a{d}": lookup(self.class_of[self.states[:, None], d, self.now_sets],
                                self.now_keys, self.care[:, None]) for d in labels}

    def classes_drawn(self, labels: dict[int, str]) -> dict[tuple[str, int], str]:
        """"sample": the class of each move made now under each drawn hypothesis."""
        return {(f"a{d}", x): lookup(self.class_of[self.states, d, self.in_force[x]],
                                     [("ts_state", 0)], self.care)
                for d in labels for x in range(self.observer.n_hypotheses)}

    def slot_log_likelihoods(self) -> list[tuple[str, str]]:
        """(name, expression): ln pi1_x of slot o<i>'s observation, 0 when empty. "map" reads
        only the slots that stay in the window (o2 ..)."""
        first = 1 if self.observer.decision == "sample" else 2
        slot_ll = []
        for x in range(self.observer.n_hypotheses):
            padded = np.concatenate([[0.0], self.classes[:, x]])       # class -1 = empty slot
            for i in range(first, self.observer.window + 1):
                slot_ll.append((f"ll_x{x}_o{i}", lookup(padded, [(f"o{i}_cls", -1)])))
        return slot_ll

    def map_rules(self, labels: dict[int, str]) -> list[dict]:
        """Per move: the new window (slots o2 .. o{w} and the move now), each hypothesis's
        log-posterior up to the normaliser, and the new MAP hypothesis."""
        observer, rules = self.observer, []
        n_x, tolerance = observer.n_hypotheses, prism_number(TOLERANCE)
        for d, label in labels.items():
            a = f"a{d}"
            scores = []
            for x in range(n_x):
                now = lookup(self.table[x, self.states[:, None], d, self.now_sets], self.now_keys,
                             self.care[:, None])
                terms = [prism_number(float(observer.log_prior[x]))]
                terms += [f"ll_x{x}_o{i}" for i in range(2, observer.window + 1)]
                terms += [f"llnow_x{x}_{a}"]
                scores.append({"x": x, "now": now, "sum": "+".join(terms)})
            names = [f"lpn_x{x}_{a}" for x in range(n_x)]
            rules.append({"action": a, "slot": d, "label": label, "scores": scores,
                          "next": first_within(names, tolerance)})
        return rules

    def posterior(self) -> list[tuple[str, str]]:
        """"sample": each hypothesis's log-posterior up to the normaliser over the window,
        then p(x | W) = 1 / sum_y exp(lp_y - lp_x), as BayesObserver.posterior computes it."""
        observer, n_x = self.observer, self.observer.n_hypotheses
        posterior = []
        for x in range(n_x):
            terms = [prism_number(float(observer.log_prior[x]))]
            terms += [f"ll_x{x}_o{i}" for i in range(1, observer.window + 1)]
            posterior.append((f"lp_x{x}", "+".join(terms)))
        for x in range(n_x):
            total = "+".join("1.0" if y == x else f"pow({prism_number(E)}, lp_x{y}-lp_x{x})"
                             for y in range(n_x))
            posterior.append((f"post_x{x}", f"1/({total})" if n_x > 1 else "1.0"))
        return posterior


def first_within(names: list[str], tolerance: str) -> str:
    """The index of the first of the scores `names` within `tolerance` of their maximum, as a
    PRISM expression that reads each score as few times as it can: score k (reached when
    every earlier one is below the maximum of those after it by more than the tolerance, so
    that the maximum of all is that of k and the later ones) is compared with the maximum of
    the later ones only. The same index, in floating point too, as comparing each with the
    maximum of all (the last within the tolerance wins where none before is), with
    (n + 2) (n - 1) / 2 reads of the scores instead of (n + 1) (n - 1): Storm and PRISM
    substitute every formula where it is used, so each read repeats the score's tables."""
    return cases([(f"{name}>={maximum(names[k + 1:])}-{tolerance}", str(k))
                  for k, name in enumerate(names[:-1])], str(len(names) - 1))


def _drawing_robot(observer: BayesObserver, ts: TransitionSystem, labels: dict[int, str],
                   observed: np.ndarray | None) -> tuple[list[dict], str]:
    """"sample": the robot's commands per action slot and the table `drawn_alike` over the
    TS state (1 where every hypothesis plays the same action, else 0; "" when it is one or
    the other at every observed state, and then only that command is written).

    Where the hypotheses' actions differ, the command draws x: its outcomes are (x,
    probability, update of `place`) under the action P2 plays with each x, with probability
    post_x times the outcome's. Where they agree the draw changes nothing (the successor of
    every x is the same state) and the command has the slot's outcomes alone ("alike":
    (probability, update)): sum_x p(x | W) P(v' | v, a1, a2) = P(v' | v, a1, a2), which Storm
    then gets without evaluating the posterior for each outcome (the sum of the products it
    computed before differs from P(v' | v, a1, a2) by a rounding at most, 2.2e-16 on the
    benchmark). That is most states: P2's actions differ only near the traps."""
    tables = arena_tables(ts)
    observed = np.ones(ts.n_states - 1, dtype=bool) if observed is None else observed
    force = InForce(ts, tables, *p2_choices(ts, observer.trap_choice, observed), selector=False)
    in_force = np.asarray(observer.trap_choice)[:, :ts.n_states - 1]
    alike = (in_force == in_force[0]).all(axis=0)
    guards = {"alike": observed[alike].any(), "drawn": observed[~alike].any()}
    robot = []
    for slot in tables.slots:
        robot.append({"label": labels[slot.index], "action": f"a{slot.index}", "guard": slot.guard,
                      "alike": [(force.prob(o, 0), force.update(o, 0)) for o in slot.outcomes]
                      if guards["alike"] else None,
                      "outcomes": [(x, force.prob(o, x), force.update(o, x))
                                   for x in range(observer.n_hypotheses) for o in slot.outcomes]
                      if guards["drawn"] else None})
    condition = ts_table(ts, alike.astype(np.int64), observed) if all(guards.values()) else ""
    return robot, condition
