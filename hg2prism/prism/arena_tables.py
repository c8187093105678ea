"""The arena's part of every PRISM model hg2prism writes (docs/semantics.md §15): P1's action
slots, their outcomes, and the tables over the arena state that say where each outcome leads
and with which probability.

The names every model uses (one scheme for every arena, grids included; none can clash with a
PRISM keyword):

  place             the arena state's index (arena.states order); TRAPPED = the number of
                    states is the absorbing `trapped` (only when P2 sets traps)
  a<i>              the action label of P1's i-th action slot (its name at each state is in
                    the header); P2's j-th action is p2_<j> in the game exports
  to_<m>            the m-th distinct destination table: the arena state an outcome leads to
  p_<t>             the t-th distinct probability table (a constant probability is a literal)
  enabled_<i>       whether slot i exists at `place` (only when some live state lacks it)
  terminal          whether `place` is terminal (no P1 action: the episode ends there)
  label_class       the label class of `place`
  "ap_<p>"          the label of proposition p (PRISM rejects keywords such as "A" or "F" as
                    label names, even quoted); "goal", "fail" and, with traps, "trapped"

A table that depends on P2's action (general P2 actions with `p2` entries, and in trap mode
whether an outcome lands on the set in force) is a table over (place, P2's action); each model
says which action is in force (hypergame.py: P2's choice per hypothesis, or the standing one).
The number of tables grows with the distinct (slot, outcome) columns, never with the states:
a grid has 4 destination tables (one per direction) and constant probabilities.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from hg2prism.engines.engine import action_label
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.prism.rendering import lookup, prism_number


def p2_label(action: int) -> str:
    """The PRISM action label of P2's action `action` (the game exports)."""
    return f"p2_{action}"


def proposition_label(name: str) -> str:
    """The PRISM label of atomic proposition `name`."""
    return f"ap_{name}"


@dataclass(frozen=True)
class Outcome:
    prob: str          # a literal, or the name of a probability table
    dest: int          # the destination table


@dataclass(frozen=True)
class Slot:
    index: int
    label: str
    guard: str         # "" when every live state has the slot, else "enabled_<i>"
    outcomes: tuple[Outcome, ...]


@dataclass(frozen=True)
class ArenaTables:
    """The arena's tables, deduplicated: each is [n_places, n_a2 or 1]."""

    dest: tuple[np.ndarray, ...]       # destination tables to_<m>
    probs: tuple[np.ndarray, ...]      # probability tables p_<t>
    slots: tuple[Slot, ...]
    enabled: tuple[tuple[str, np.ndarray], ...]   # (name, [n_places] bool)
    terminal: np.ndarray | None        # [n_places] bool, None when no state is terminal
    live: np.ndarray                   # [n_places] bool: not terminal

    def dest_dependent(self, m: int) -> bool:
        return self.dest[m].shape[1] > 1

    def prob_dependent(self, t: int) -> bool:
        return self.probs[t].shape[1] > 1

    def users(self, m: int) -> list[str]:
        """The (slot, outcome) pairs that read destination table m, for comments."""
        return [f"a{s.index}.{k}" for s in self.slots for k, o in enumerate(s.outcomes)
                if o.dest == m]

    def prob_users(self, t: int) -> list[str]:
        """The (slot, outcome) pairs whose probability is table p_t, for comments."""
        return [f"a{s.index}.{k}" for s in self.slots for k, o in enumerate(s.outcomes)
                if o.prob == f"p_{t}"]


def _column(values: np.ndarray, care: np.ndarray) -> np.ndarray:
    """values [n_places, J] reduced to [n_places, 1] when it does not depend on P2's action
    where cared for; free rows copy the first cared row (so equal tables dedupe)."""
    if care.any():
        fill = values[np.flatnonzero(care)[0]]
        values = np.where(care[:, None], values, fill[None, :])
    if (values == values[:, :1]).all():
        return values[:, :1]
    return values


def arena_tables(ts: TransitionSystem) -> ArenaTables:
    arena = ts.arena
    enabled = arena.enabled                          # [n_places, A1max]
    live = ~arena.terminal
    dest_tables: list[np.ndarray] = []
    prob_tables: list[np.ndarray] = []

    def index_of(tables: list[np.ndarray], table: np.ndarray) -> int:
        for m, known in enumerate(tables):
            if known.shape == table.shape and np.array_equal(known, table):
                return m
        tables.append(table)
        return len(tables) - 1

    slots, guards = [], []
    for i in range(arena.n_actions):
        care = enabled[:, i] & live
        if not care.any():
            continue
        guard = ""
        if not care[live].all():
            guard = f"enabled_{i}"
            guards.append((guard, care))
        outcomes = []
        for k in range(arena.dest.shape[3]):
            prob = arena.prob[:, i, :, k]
            if not (prob[care] > 0).any():
                continue
            dest = arena.dest[:, i, :, k].copy()
            # outside `care` the destination never matters: the place itself (in range)
            dest[~care] = np.arange(arena.n_states)[~care, None]
            dest = dest if (dest[care] != dest[care][:, :1]).any() else dest[:, :1]
            m = index_of(dest_tables, dest)
            values = _column(prob, care)
            if (values[care] == values[care][0, 0]).all():
                text = prism_number(float(values[care][0, 0]))
            else:
                text = f"p_{index_of(prob_tables, np.where(care[:, None], values, 0.0))}"
            outcomes.append(Outcome(prob=text, dest=m))
        slots.append(Slot(index=i, label=action_label(i), guard=guard, outcomes=tuple(outcomes)))
    terminal = arena.terminal if arena.terminal.any() else None
    return ArenaTables(dest=tuple(dest_tables), probs=tuple(prob_tables), slots=tuple(slots),
                       enabled=tuple(guards), terminal=terminal, live=live)


def place_table(values: np.ndarray, trapped: int | None, care: np.ndarray | None = None) -> str:
    """A table over `place` ([n_places]), with the value `trapped` at TRAPPED when given."""
    if trapped is not None:
        values = np.append(values, trapped)
        care = None if care is None else np.append(care, True)
    return lookup(values, [("place", 0)], care)


def header_lines(ts: TransitionSystem, trapped: int | None) -> list[str]:
    """The header's listing of the arena: its states with their index and P1's actions at each
    (slot a<i> = name), P2's actions with their index."""
    arena = ts.arena
    lines = ["Arena states (place = index" + (f"; place = {trapped} is TRAPPED" if trapped
                                                   is not None else "") + "), each with P1's "
             "actions by slot (a<i> = name; none: terminal):"]
    for s, name in enumerate(arena.states):
        acts = " ".join(f"a{i}={a}" for i, a in enumerate(arena.actions[s])) or "terminal"
        lines.append(f"  {s:>3} {name}: {acts}")
    kind = "trap sets" if ts.traps_mode else "actions"
    lines.append(f"P2's {kind}: " + ", ".join(f"{j} = {n}" for j, n in enumerate(ts.a2_names)))
    return lines


def label_lines(ts: TransitionSystem) -> list[tuple[str, str]]:
    """(label name, expression) of each proposition: the label classes that contain it."""
    classes, _ = ts.arena.label_classes()
    lines = []
    for p in ts.arena.propositions:
        members = [k for k, c in enumerate(classes) if p in c]
        expr = " | ".join(f"label_class={k}" for k in members) or "false"
        lines.append((proposition_label(p), expr))
    return lines


def goal_fail(accepting: list[int], sink: list[int], trapped: int | None,
              terminal: bool) -> tuple[str, str]:
    """The goal and failure formulas (docs/semantics.md §§6, 15): goal when q (after reading
    the label) is final and P1 is not trapped; failure when trapped, q a sink, or at a
    terminal state that is not the goal."""
    final = " | ".join(f"q_now={f}" for f in accepting) or "false"
    goal = f"place!=TRAPPED & ({final})" if trapped is not None else f"({final})"
    parts = (["place=TRAPPED"] if trapped is not None else []) + [f"q_now={s}" for s in sink]
    if terminal:
        parts.append("terminal & !goal")
    return goal, " | ".join(parts) or "false"


def p2_choices(ts: TransitionSystem, choice: np.ndarray, observed: np.ndarray
               ) -> tuple[np.ndarray, list[tuple[str, int]], np.ndarray, np.ndarray | None]:
    """P2's choice per hypothesis (choice [X, n_states] over TS states) as tables over the
    variables: [X, places] over `place`, or with delay [X, places, actions] over (place,
    traps), read where she may change her action (countdown 0). Returns the tables, their
    keys, where they are read (`choosing`, from the observed TS states) and, with delay, where
    the standing action is (`waiting`: countdown > 0)."""
    n_x, n_places, n_sets = len(choice), ts.n_places, ts.n_sets
    choices = np.asarray(choice)[:, :-1].reshape(n_x, n_places, -1)
    if ts.delay:
        choices = choices.reshape(n_x, n_places, n_sets, ts.phases)[..., 0]
        phases = observed.reshape(n_places, n_sets, ts.phases)
        return (choices, [("place", 0), ("traps", 0)], phases[..., 0],
                phases[..., 1:].any(axis=-1))
    return choices[..., 0], [("place", 0)], observed, None


class InForce:
    """The arena's tables that depend on P2's action in force, as a model reads them: per
    hypothesis over P2's choice (and over the standing action while she must wait), with a
    formula that picks the one in force (`selector`); or, with `played`, over that variable.
    In trap mode every destination has such a table: whether it lands on the set in force."""

    def __init__(self, ts: TransitionSystem, tables: ArenaTables, choices: np.ndarray,
                 keys: list[tuple[str, int]], choosing: np.ndarray, waiting: np.ndarray | None,
                 played: str | None = None, selector: bool = True) -> None:
        self.ts, self.tables, self.played = ts, tables, played
        self.choices, self.keys, self.choosing, self.waiting = choices, keys, choosing, waiting
        self.n_x = choices.shape[0]
        self.selector = selector

    @functools.cached_property
    def formulas(self) -> list[tuple[str, str]]:
        """(comment, text) of every table, in order."""
        ts, tables = self.ts, self.tables
        self._formulas: list[tuple[str, str]] = []
        members = None
        if ts.traps_mode:
            members = np.zeros((ts.n_sets, ts.n_places), dtype=np.int64)
            for t in range(ts.n_sets):
                members[t, list(ts.trap_places(t))] = 1
        for m, dest in enumerate(tables.dest):
            if tables.dest_dependent(m):
                self._add(f"to_{m}", dest, f"to_{m}", "")
            if members is not None:
                hit = members[:, dest[:, 0]].T                  # [n_places, n_sets]
                self._add(f"hit_{m}", hit, f"trap_hit_{m}", "=1")
        for t, prob in enumerate(tables.probs):
            if tables.prob_dependent(t):
                self._add(f"p_{t}", prob, f"p_{t}", "", exact=True)
        return self._formulas

    def _add(self, name: str, table: np.ndarray, selected: str, suffix: str,
             exact: bool = False) -> None:
        """Formulas of `table` [n_places, n_a2]: per hypothesis, standing and the selector.
        A probability table is `exact` everywhere: PRISM checks that a command's
        probabilities sum to 1 in every state its guard allows, reachable or not."""
        ts = self.ts
        if self.played is not None:
            self._formulas.append(("", f"formula {selected} = "
                                  f"{lookup(table, [('place', 0), (self.played, 0)])}{suffix};"))
            return
        places = np.arange(ts.n_places).reshape((-1,) + (1,) * (self.choices.ndim - 2))
        for x in range(self.n_x):
            values = table[np.broadcast_to(places, self.choices[x].shape), self.choices[x]]
            self._formulas.append(("", f"formula {name}_x{x} = "
                                  f"{lookup(values, self.keys, None if exact else self.choosing)};"))
        if ts.delay:
            standing = np.broadcast_to(np.arange(ts.n_sets)[None, :], self.choices[0].shape)
            values = table[np.broadcast_to(places, standing.shape), standing]
            self._formulas.append(("", f"formula {name}_standing = "
                                  f"{lookup(values, self.keys, None if exact else self.waiting)};"))
        if self.selector:
            pick = "".join(f"hyp={x} ? {name}_x{x} : " for x in range(self.n_x - 1))
            pick += f"{name}_x{self.n_x - 1}"
            if ts.delay:
                pick = f"countdown>0 ? {name}_standing : {pick}"
            self._formulas.append(("", f"formula {selected} = ({pick}){suffix};"))

    def _drawn(self, name: str, x: int, suffix: str) -> str:
        """The table `name` under the action P2 draws with hypothesis x."""
        if self.ts.delay:
            return f"(countdown>0 ? {name}_standing : {name}_x{x}){suffix}"
        return f"{name}_x{x}{suffix}" if not suffix else f"({name}_x{x}{suffix})"

    def update(self, outcome: Outcome, x: int | None = None) -> str:
        """The robot's update for `outcome`, under P2's action in force (x None) or under the
        one she draws with hypothesis x."""
        m = outcome.dest
        dest = f"to_{m}"
        if self.tables.dest_dependent(m) and x is not None:
            dest = self._drawn(f"to_{m}", x, "")
        if not self.ts.traps_mode:
            return f"(place'={dest})"
        hit = f"trap_hit_{m}" if x is None else self._drawn(f"hit_{m}", x, "=1")
        return f"(place'={hit} ? TRAPPED : {dest})"

    def prob(self, outcome: Outcome, x: int | None = None) -> str:
        text = outcome.prob
        if text.startswith("p_") and x is not None and self.tables.prob_dependent(int(text[2:])):
            return self._drawn(text, x, "")
        return text


