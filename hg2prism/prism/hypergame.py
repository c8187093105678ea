"""The hypergame MDP of docs/semantics.md §6, rendered as a structured PRISM model.

Storm builds the product of four components, so the number of commands grows with the largest
number of P1 actions at a state, the outcomes and the hypotheses, never with the product or
the number of arena states:

  robot         place (TRAPPED once caught, in trap mode): one command per action slot a<i>
                with its outcomes (prism/arena_tables.py names the arena's tables)
  task          q: P1's task DFA, one step behind (it reads the label of the state being left)
  p2_traps      (delay > 0 only) P2's standing action `traps` (a trap set in trap mode) and the
                countdown
  p2_inference  P2's memory: the sliding-window CUSUM of docs/semantics.md §5 (hyp and the
                observation window) or the Bayesian observer of §12 (the window; with
                decision "sample" the robot module draws P2's hypothesis with the move)

Tables (destinations, labels, P2's choices, log-likelihood ratios) are formulas written as
decision trees over the state variables that bisect runs of equal entries, so Storm evaluates
each in logarithmic time; tables over TS states are exact where P1 can be (TS states
reachable with P2's choices) and free elsewhere, which keeps them small under delay.
Variables, labels and formulas: `place`, `q`, `traps`, `countdown`, `hyp`, the slots
o<i>_state/_act(/_set/_cls); P2's action in force `trap_set` (her choice under each
hypothesis `trap_choice_x<x>`); "goal", "fail", "trapped" (trap mode) and "ap_<p>" per
proposition; action labels a<i> per slot (prism/arena_tables.py).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hg2prism import __version__
from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.opponent.observer import Observer
from hg2prism.opponent.registry import observer_kind
from hg2prism.opponent.perceptual_games import PerceptualGame
from hg2prism.model.world import World
from hg2prism.prism.arena_tables import (ArenaTables, arena_tables, goal_fail,
                                         header_lines,
                                         label_lines, p2_choices, place_table, InForce)
from hg2prism.prism.rendering import cases, lookup, prism_number, render_template

PROPERTY = 'Pmax=? [F "goal"]'


_DECLARATION = re.compile(r"^\s*(\w+)\s*:\s*\[[^\]]*\]\s*init\s+(-?\d+)\s*;", re.MULTILINE)


@dataclass(frozen=True)
class Layout:
    """How hypergame states are encoded in PRISM variables (for decoding Storm's states)."""

    slots: int                      # observation slots o1 (oldest) .. o{slots}
    delay: int
    slot_sets: bool = False         # slots also hold the trap set in force (Bayesian observer)
    hypothesis_variable: bool = True   # P2's hypothesis is the variable `hyp` (CUSUM)
    # every variable's initial value: Storm leaves out of its states a variable whose value
    # never changes (no command that writes it is ever enabled), which then keeps this value
    initial: tuple[tuple[str, int], ...] = ()

    def initial_value(self, name: str) -> int | None:
        return dict(self.initial).get(name)

    @staticmethod
    def initial_values(text: str) -> tuple[tuple[str, int], ...]:
        """(variable, initial value) of every integer variable declared in PRISM `text`."""
        return tuple((name, int(value)) for name, value in _DECLARATION.findall(text))

    def slot_variables(self, i: int) -> tuple[str, ...]:
        if self.slot_sets:
            return f"o{i}_state", f"o{i}_act", f"o{i}_set"
        return f"o{i}_state", f"o{i}_act"


@dataclass(frozen=True)
class PrismModel:
    text: str
    properties: str
    layout: Layout
    commands: dict[str, int]        # module name -> number of commands


def build_model(world: World, ts: TransitionSystem, task: DFA, games: list[PerceptualGame],
                inference: Observer) -> PrismModel:
    context = template_context(world, ts, task, games, inference)
    model_text = render_template("hypergame.prism.j2", **context)
    properties = render_template("hypergame.props.j2", property=PROPERTY, world=world)
    commands = count_commands(model_text)
    return PrismModel(text=model_text, properties=properties,
                      layout=Layout(slots=context["observer"].slots, delay=ts.delay,
                                    slot_sets=context["observer"].slot_sets,
                                    hypothesis_variable=context["observer"].hypothesis_variable,
                                    initial=Layout.initial_values(model_text)),
                      commands=commands)


def slot_labels(tables: ArenaTables, prefix: str = "") -> dict[int, str]:
    """The action label of each action slot that some live state has (prefix + a<i>)."""
    return {s.index: prefix + s.label for s in tables.slots}


def template_context(world: World, ts: TransitionSystem, task: DFA, games: list[PerceptualGame],
                     inference: Observer, played: str | None = None,
                     observer_prefix: str = "") -> dict:
    """What the hypergame template (and the robust one, docs/semantics.md §13) is rendered
    with: the arena's tables, P2's choices, the observer's part. With `played` (the robust
    model) P2's action in force is that variable's value, which may be any action, and the
    observer's module synchronises on the slot labels with `observer_prefix`."""
    n_places = ts.n_places
    # The tables over TS states need only be right where P1 can be: the TS states reachable
    # when P2 plays her choice under some hypothesis (any action, if she may deviate). With
    # delay that is a few percent of places x actions x phases, and the freedom elsewhere keeps
    # the tables' text, and Storm's parse, close to the size of the reachable part.
    reachable = ts.reachable(None if played else np.array([g.trap_choice for g in games]))
    observed = reachable[:-1]            # the TRAPPED state is never observed
    trapped = n_places if ts.traps_mode else None
    tables = arena_tables(ts)
    q_now = lookup(task.delta, [("q", 0), ("label_class", 0)])

    choices, keys, choosing, waiting = p2_choices(
        ts, np.array([g.trap_choice for g in games]), observed)
    choice_tables = [lookup(choice, keys, choosing) for choice in choices]
    labels = slot_labels(tables)
    observer = observer_kind(inference.kind).render(
        inference, ts, slot_labels(tables, observer_prefix), observed, played)
    force = InForce(ts, tables, choices, keys, choosing, waiting, played,
                    selector=not observer.robot)
    # P2's action in force: her choice under her current hypothesis (while she may move).
    by_hypothesis = cases([(f"hyp={x}", f"trap_choice_x{x}") for x in range(len(games) - 1)],
                          f"trap_choice_x{len(games) - 1}")
    trap_set = f"countdown>0 ? traps : ({by_hypothesis})" if ts.delay else by_hypothesis
    start_place, start_traps, _ = ts.decode(ts.start_state)
    goal, fail = goal_fail(sorted(task.accepting), sorted(task.sink), trapped,
                           tables.terminal is not None)
    return dict(
        version=__version__, world=world, ts=ts, task=task, games=games, inference=inference,
        tables=tables, labels=labels, header=header_lines(ts, trapped), trapped=trapped,
        world_formulas=world_formulas(tables, ts, trapped), force=force,
        q_now=q_now, accepting=sorted(task.accepting), sink=sorted(task.sink),
        goal=goal, fail=fail,
        trap_tables=choice_tables, trap_set=trap_set, observer=observer,
        start_place=start_place, start_traps=start_traps,
        proposition_labels=label_lines(ts), fmt=prism_number,
    )


def world_formulas(tables: ArenaTables, ts: TransitionSystem,
                   trapped: int | None) -> list[tuple[str, str]]:
    """(comment or "", formula text) of the arena's tables over `place` that do not depend on
    P2's action (those that do are force.formulas)."""
    zero = None if trapped is None else 0         # the value of a table at TRAPPED
    lines: list[tuple[str, str]] = []
    for m, dest in enumerate(tables.dest):
        if not tables.dest_dependent(m):
            lines.append((f"to_{m}: where {', '.join(tables.users(m))} lead (slot.outcome)",
                          f"formula to_{m} = {place_table(dest[:, 0], trapped)};"))
    for t, prob in enumerate(tables.probs):
        if not tables.prob_dependent(t):
            lines.append((f"p_{t}: the chance of {', '.join(tables.prob_users(t))} "
                          f"(slot.outcome)", f"formula p_{t} = {place_table(prob[:, 0], zero)};"))
    for name, care in tables.enabled:
        table = place_table(care.astype(np.int64), None, tables.live)
        lines.append(("", f"formula {name} = {table}=1;"))
    if tables.terminal is not None:
        table = place_table(tables.terminal.astype(np.int64), zero)
        lines.append(("terminal states (no P1 action): the episode ends there",
                      f"formula terminal = {table}=1;"))
    lines.append(("label class of the current state",
                  f"formula label_class = {place_table(ts.place_label, zero)};"))
    return lines


def count_commands(text: str) -> dict[str, int]:
    counts: dict[str, int] = {}
    module = None
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("module "):
            module = stripped.split()[1]
            counts[module] = 0
        elif stripped == "endmodule":
            module = None
        elif module and re.match(r"\[[\w,]*\](\s|$)", stripped):   # a command, not a wrapped line
            counts[module] += 1
    return counts


def write_model(model: PrismModel, folder: Path) -> tuple[Path, Path]:
    from hg2prism.outputs import write_text

    prism = folder / "hypergame.prism"
    props = folder / "hypergame.props"
    write_text(prism, model.text)
    write_text(props, model.properties)
    return prism, props
