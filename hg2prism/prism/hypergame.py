"""The hypergame MDP of docs/semantics.md §6, rendered as a structured PRISM model.

Storm builds the product of four components, so the number of commands grows with the
tables, never with the product:

  robot         cell (TRAPPED once caught): P1's moves with slip, and the trap check
  task          q: P1's task DFA, one step behind (it reads the label of the cell being left)
  p2_traps      (delay > 0 only) the traps standing and the countdown
  p2_inference  P2's memory: the sliding-window CUSUM of docs/semantics.md §5 (hyp and the
                observation window) or the Bayesian observer of §12 (the window; with
                decision "sample" the robot module draws P2's hypothesis with the move)

Tables (moves, labels, P2's trap choices, log-likelihood ratios) are formulas written as
decision trees over the state variables that bisect runs of equal entries, so Storm evaluates
each in logarithmic time; tables over TS states are exact where the robot can be (TS states
reachable with P2's choices) and free elsewhere, which keeps them small under delay.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hg2prism import __version__
from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.frontends.grid import ACTION_LABELS, ACTIONS
from hg2prism.opponent.observer import Observer
from hg2prism.opponent.registry import observer_kind
from hg2prism.opponent.perceptual_games import PerceptualGame
from hg2prism.model.world import World
from hg2prism.prism.rendering import cases, lookup, prism_number, region_labels, render_template

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


def cell_map(world: World, ts: TransitionSystem) -> list[str]:
    """The map with each free cell's index, for the header."""
    width = max(len(str(ts.n_cells - 1)), 2)
    lines = []
    for row, text in enumerate(world.grid.rows):
        y = world.grid.height - 1 - row
        cells = []
        for x, char in enumerate(text):
            index = ts.cell_index.get((x, y))
            cells.append(("#" * width) if index is None else f"{char}{index:>{width - 1}}"
                         if width > 2 else f"{char}{index}")
        lines.append(f"y={y:<3}" + " ".join(cells))
    return lines


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


def template_context(world: World, ts: TransitionSystem, task: DFA, games: list[PerceptualGame],
                     inference: Observer, trap_key: str = "trap_set",
                     observer_labels: dict[str, str] = ACTION_LABELS,
                     p2_deviates: bool = False) -> dict:
    """What the hypergame template (and the robust one, docs/semantics.md §13) is rendered
    with: the world's tables, P2's trap policy, the observer's part. `trap_key` is the
    expression whose trap set traps the robot (`trap_cell_j` looks it up); `observer_labels`
    the labels the observer's module synchronises on; `p2_deviates` whether P2 may play other
    trap sets than her hypotheses' choices (the robust model)."""
    n_cells, n_sets = ts.n_cells, ts.n_sets
    # The tables over TS states need only be right where the robot can be: the TS states
    # reachable when P2 plays her choice under some hypothesis (any set, if she may deviate).
    # With delay that is a few percent of cells x trap sets x phases, and the freedom elsewhere
    # keeps the tables' text, and Storm's parse, close to the size of the reachable part.
    reachable = ts.reachable(None if p2_deviates else np.array([g.trap_choice for g in games]))
    observed = reachable[:-1]            # the TRAPPED state is never observed
    trapped = n_cells
    cell_key = [("cell", 0)]

    # Robot dynamics tables.
    moves = {a: lookup(np.append(ts.move[:, d], trapped), cell_key) for d, a in enumerate(ACTIONS)}
    label_expr = lookup(np.append(ts.cell_label, 0), cell_key)
    q_now = lookup(task.delta, [("q", 0), ("label_class", 0)])
    accepting = sorted(task.accepting)
    sink = sorted(task.sink)

    # P2's trap choice per hypothesis: with delay, only where she may move them (countdown 0;
    # `trap_set` keeps the standing set otherwise), so the tables do not grow with the delay.
    choices = np.array([g.trap_choice[:-1] for g in games]).reshape(len(games), n_cells, -1)
    if ts.delay:
        choices = choices.reshape(len(games), n_cells, n_sets, ts.phases)[..., 0]
        trap_keys = [("cell", 0), ("traps", 0)]
        phases = observed.reshape(n_cells, n_sets, ts.phases)
        choosing, waiting = phases[..., 0], phases[..., 1:].any(axis=-1)
    else:
        choices = choices[..., 0]
        trap_keys = [("cell", 0)]
        choosing, waiting = observed, None
    trap_tables = [lookup(choice, trap_keys, choosing) for choice in choices]
    observer = observer_kind(inference.kind).render(inference, ts, observer_labels, observed,
                                                    trap_key if p2_deviates else None)
    # The trap set in force: P2's choice under her current hypothesis (while she may move them).
    by_hypothesis = cases([(f"hyp={x}", f"trap_choice_x{x}") for x in range(len(games) - 1)],
                          f"trap_choice_x{len(games) - 1}")
    trap_set = f"countdown>0 ? traps : ({by_hypothesis})" if ts.delay else by_hypothesis
    return dict(
        version=__version__, world=world, ts=ts, task=task, games=games, inference=inference,
        actions=ACTIONS, labels=ACTION_LABELS, cell_map=cell_map(world, ts), trapped=trapped,
        moves=moves, label_expr=label_expr, q_now=q_now, accepting=accepting, sink=sink,
        trap_tables=trap_tables, trap_set=trap_set, observer=observer,
        robot_outcomes=_robot_outcomes(ts), trap_cell_tables=_trap_cell_tables(ts, trap_key),
        trap_hits=_trap_hit_tables(ts, choices, trap_keys, choosing, waiting),
        n_trap_cells=world.traps, start_cell=ts.decode(ts.start_state)[0],
        start_traps=ts.decode(ts.start_state)[1], slip=prism_number(world.slip),
        region_labels=region_labels(ts),
        set_members=[", ".join(f"({x},{y})" for x, y in ts.trap_cells(t)) for t in range(n_sets)],
        fmt=prism_number,
    )


def _robot_outcomes(ts: TransitionSystem) -> list[dict]:
    """One robot command per action: its outcomes as (probability, direction moved)."""
    perpendicular = {"N": "EW", "E": "NS", "S": "EW", "W": "NS"}
    commands = []
    for a in ACTIONS:
        outcomes = [("1-2*slip", a)] + [("slip", p) for p in perpendicular[a]] if ts.slip > 0 \
            else [("1", a)]
        commands.append({"action": a, "outcomes": outcomes})
    return commands


def _trap_cell_tables(ts: TransitionSystem, trap_key: str = "trap_set") -> list[str]:
    """trap_cell_j: the j-th cell of the trap set in force, as a table over `trap_set`. One
    robot command per move then serves every trap set, which halves Storm's build time against
    one command per (move, trap set)."""
    members = np.array([sorted(ts.candidates[c] for c in members) for members in ts.trap_sets],
                       dtype=np.int64).reshape(ts.n_sets, -1)
    return [lookup(members[:, j], [(trap_key, 0)]) for j in range(members.shape[1])]


def _trap_hit_tables(ts: TransitionSystem, choices: np.ndarray, keys: list[tuple[str, int]],
                     choosing: np.ndarray, waiting: np.ndarray | None) -> dict[str, dict]:
    """Per direction d, whether the cell reached by moving d lands on the trap set in force:
    tables over the keys of `choices` (P2's choice per hypothesis, [X, cells(, traps)]), one per
    hypothesis, and with delay one for the standing set (countdown > 0). The robot then asks
    one table per outcome, where looking the set's cells up from `trap_set` would repeat
    P2's tables in every comparison. `choosing` and `waiting` mark where each kind is read
    (the reachable states with countdown 0, and above 0)."""
    n_x = choices.shape[0]
    members = np.zeros((ts.n_sets, ts.n_cells + 1), dtype=bool)
    for t, chosen in enumerate(ts.trap_sets):
        members[t, [ts.candidates[c] for c in chosen]] = True
    hits = {}
    for d, a in enumerate(ACTIONS):
        landing = ts.move[:, d]
        landing = landing.reshape((-1,) + (1,) * (choices.ndim - 2))
        by_hypothesis = [lookup(members[choices[x], np.broadcast_to(landing, choices[x].shape)]
                                .astype(np.int64), keys, choosing) for x in range(n_x)]
        standing = None
        if ts.delay:
            traps = np.arange(ts.n_sets)[None, :]
            standing = lookup(members[np.broadcast_to(traps, choices[0].shape),
                                      np.broadcast_to(landing, choices[0].shape)]
                              .astype(np.int64), keys, waiting)
        hits[a] = {"by_hypothesis": by_hypothesis, "standing": standing}
    return hits


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
        elif module and stripped.startswith("["):
            counts[module] += 1
    return counts


def write_model(model: PrismModel, folder: Path) -> tuple[Path, Path]:
    from hg2prism.outputs import write_text

    prism = folder / "hypergame.prism"
    props = folder / "hypergame.props"
    write_text(prism, model.text)
    write_text(props, model.properties)
    return prism, props
