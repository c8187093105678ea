"""PRISM-games exports of the games of docs/semantics.md §§4 and 7, so PRISM-games can re-check the baselines.

  symmetric.prism       csg: the symmetric-information game on TS x DFA(phi) (docs/semantics.md §7). Both
                        players move at once; <<p1>>Pmax=? [F "goal"] is V_NE, the value of the
                        zero-sum concurrent game with mixed strategies (the paper's Table I).
  perceptual_<i>.prism  smg: P2's perceptual game G(x_i) on TS x DFA(x_i) (docs/semantics.md §4). Each step P2
                        places the traps first, then P1 moves (a turn variable); <<p1>>Pmax=? [F
                        "goal"] is V_x at the initial state (P1 maximises, P2 minimises).

The models are written the way hypergame.prism is (one module per component, tables as
decision trees over the state variables, the names of prism/arena_tables.py), in the
PRISM-games language only:
  * action labels: a<i> for P1's action slot i, p2_<j> for P2's action j (PRISM reserves
    single letters such as E, S, W as keywords); the header lists what each one is;
  * in the csg each player owns one module, the players' action sets are disjoint, and the
    robot's moves are commands labelled with joint actions [a<i>,p2_<j>] (PRISM-games 3: a
    command labelled with several actions fires when the players choose all of them);
  * in the smg the players are given by their action lists; every command is labelled.
The robot has one command per (action slot, P2 action), so the commands grow with the actions,
never with the states.

Storm (stormpy 2.0) parses and builds the smg models (it cannot check them through stormpy, and
it has no parser for csg at all): tests/test_game_exports.py checks both in other ways.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from hg2prism import __version__
from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.prism.arena_tables import (ArenaTables, arena_tables, goal_fail, header_lines,
                                         label_lines, p2_label, place_table)
from hg2prism.prism.hypergame import slot_labels, world_formulas
from hg2prism.prism.rendering import lookup, render_template
from hg2prism.model.world import World

if TYPE_CHECKING:
    from hg2prism.results import Analysis

PROPERTY = '<<p1>> Pmax=? [F "goal"]'



def _robot_commands(ts: TransitionSystem, tables: ArenaTables) -> list[dict]:
    """One command per P1 action slot and P2 action in force: its guard and its outcomes
    (probability, update of `place`)."""
    commands = []
    for slot in tables.slots:
        for j in range(ts.n_sets):
            trap = sorted(ts.trap_places(j))
            outcomes = []
            for o in slot.outcomes:
                dest = f"to_{o.dest}" + (f"_{j}" if tables.dest_dependent(o.dest) else "")
                prob = o.prob
                if prob.startswith("p_") and tables.prob_dependent(int(prob[2:])):
                    prob = f"{prob}_{j}"
                hit = " | ".join(f"{dest}={t}" for t in trap)
                outcomes.append((prob, f"(place'=({hit}) ? TRAPPED : {dest})" if trap
                                 else f"(place'={dest})"))
            commands.append({"label": slot.label, "guard": slot.guard, "set": j,
                             "place": p2_label(j), "outcomes": outcomes})
    return commands


def _column_formulas(ts: TransitionSystem, tables: ArenaTables) -> list[tuple[str, str]]:
    """The tables that depend on P2's action, one per (table, P2 action)."""
    lines = []
    for m, dest in enumerate(tables.dest):
        if tables.dest_dependent(m):
            for j in range(ts.n_sets):
                lines.append(("", f"formula to_{m}_{j} = {place_table(dest[:, j], None)};"))
    for t, prob in enumerate(tables.probs):
        if tables.prob_dependent(t):
            for j in range(ts.n_sets):
                lines.append(("", f"formula p_{t}_{j} = {place_table(prob[:, j], None)};"))
    return lines


def _context(world: World, ts: TransitionSystem, dfa: DFA) -> dict:
    """What both templates share: the arena's tables and the DFA (one step behind)."""
    trapped = ts.n_places if ts.traps_mode else None
    tables = arena_tables(ts)
    start_place, start_traps, _ = ts.decode(ts.start_state)
    goal, fail = goal_fail(sorted(dfa.accepting), sorted(dfa.sink), trapped,
                           tables.terminal is not None)
    return dict(
        version=__version__, world=world, ts=ts, dfa=dfa, tables=tables,
        labels=slot_labels(tables), places=[p2_label(t) for t in range(ts.n_sets)],
        header=header_lines(ts, trapped), trapped=trapped,
        world_formulas=world_formulas(tables, ts, trapped) + _column_formulas(ts, tables),
        q_now=lookup(dfa.delta, [("q", 0), ("label_class", 0)]),
        accepting=sorted(dfa.accepting), sink=sorted(dfa.sink), goal=goal, fail=fail,
        robot_commands=_robot_commands(ts, tables),
        start_place=start_place, start_traps=start_traps,
        proposition_labels=label_lines(ts),
    )


def render_symmetric(world: World, ts: TransitionSystem, task: DFA) -> tuple[str, str]:
    """The symmetric-information game of docs/semantics.md §7 as a PRISM-games csg, and its property file."""
    text = render_template("symmetric.prism.j2", **_context(world, ts, task))
    props = (f"// V_NE of world {world.name} (docs/semantics.md §7): the value of the concurrent zero-sum game in which\n"
             f"// P2 knows the task; P1 maximises, P2 minimises, both with mixed strategies.\n"
             f"{PROPERTY}\n")
    return text, props


def render_perceptual(world: World, ts: TransitionSystem, dfa: DFA, index: int,
                      value: float | None = None) -> tuple[str, str]:
    """P2's perceptual game G(x_index) of docs/semantics.md §4 as a PRISM-games smg, and its
    property file (saying hg2prism's `value` of the game at its initial state, when given)."""
    text = render_template("perceptual.prism.j2", index=index, **_context(world, ts, dfa))
    said = ("" if value is None else
            f"// hg2prism's value, certified (docs/semantics.md §10): V_x = {float(value)!r}\n")
    props = (f"// V_x of world {world.name} for hypothesis x{index} = \"{dfa.formula}\" (docs/semantics.md §4): P2 places\n"
             f"// the traps first each step, P1 answers; P1 maximises, P2 minimises.\n"
             f"{said}{PROPERTY}\n")
    return text, props


def write_game_models(analysis: Analysis, out_dir: Path) -> list[Path]:
    """Write symmetric.prism/.props and perceptual_<i>.prism/.props (i = hypothesis index).

    `analysis` is a results.Analysis (world, ts, task, games)."""
    from hg2prism.outputs import write_text

    out_dir = Path(out_dir)
    world, ts = analysis.world, analysis.ts
    files: list[tuple[str, str]] = []
    text, props = render_symmetric(world, ts, analysis.task)
    files += [("symmetric.prism", text), ("symmetric.props", props)]
    start = ts.start_state
    for i, game in enumerate(analysis.games):
        text, props = render_perceptual(world, ts, game.dfa, i,
                                        game.values[start, game.fresh_q[start]])
        files += [(f"perceptual_{i}.prism", text), (f"perceptual_{i}.props", props)]
    written = []
    for name, content in files:
        path = out_dir / name
        write_text(path, content)
        written.append(path)
    return written
