"""PRISM-games exports of the games of docs/semantics.md §§4 and 7, so PRISM-games can re-check the baselines.

  symmetric.prism       csg: the symmetric-information game on TS x DFA(phi) (docs/semantics.md §7). Both
                        players move at once; <<p1>>Pmax=? [F "goal"] is V_NE, the value of the
                        zero-sum concurrent game with mixed strategies (the paper's Table I).
  perceptual_<i>.prism  smg: P2's perceptual game G(x_i) on TS x DFA(x_i) (docs/semantics.md §4). Each step P2
                        places the traps first, then P1 moves (a turn variable); <<p1>>Pmax=? [F
                        "goal"] is V_x at the initial state (P1 maximises, P2 minimises).

The models are written the way hypergame.prism is (one module per component, tables as
decision trees over the state variables), in the PRISM-games language only:
  * action labels are lower-case words (north, east, south, west, place0, ...): PRISM reserves
    the single letters E, S, W, ... as keywords;
  * in the csg each player owns one module, the players' action sets are disjoint, and the
    robot's moves are commands labelled with joint actions [a1,a2] (PRISM-games 3: a command
    labelled with several actions fires when the players choose all of them);
  * in the smg the players are given by their action lists; every command is labelled.

Storm (stormpy 2.0) parses and builds the smg models (it cannot check them through stormpy, and
it has no parser for csg at all): tests/test_game_exports.py checks both in other ways.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hg2prism import __version__
from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.frontends.grid import ACTION_LABELS, ACTIONS, PERPENDICULAR
from hg2prism.prism.hypergame import cell_map
from hg2prism.prism.rendering import lookup, prism_number, region_labels, render_template
from hg2prism.model.world import World

if TYPE_CHECKING:
    from hg2prism.results import Analysis

PROPERTY = '<<p1>> Pmax=? [F "goal"]'



def _place(t: int) -> str:
    """P2's action label for trap set t."""
    return f"place{t}"


def _robot_commands(ts: TransitionSystem) -> list[dict]:
    """One command per P1 move and trap set in force: the outcome directions with their
    probabilities, and the cells of the trap set (landing on one traps the robot)."""
    commands = []
    for a in ACTIONS:
        if ts.slip > 0:
            outcomes = [("1-2*slip", a)] + [("slip", p) for p in PERPENDICULAR[a]]
        else:
            outcomes = [("1", a)]
        for t in range(ts.n_sets):
            commands.append({
                "action": a, "label": ACTION_LABELS[a], "set": t, "place": _place(t),
                "trap_cells": [ts.candidates[c] for c in ts.trap_sets[t]],
                "outcomes": outcomes,
            })
    return commands


def _context(world: World, ts: TransitionSystem, dfa: DFA) -> dict:
    """What both templates share: the world's tables and the DFA (one step behind)."""
    trapped = ts.n_cells
    cell_key = [("cell", 0)]
    start_cell, start_traps, _ = ts.decode(ts.start_state)
    return dict(
        version=__version__, world=world, ts=ts, dfa=dfa,
        actions=ACTIONS, action_labels=ACTION_LABELS,
        places=[_place(t) for t in range(ts.n_sets)],
        cell_map=cell_map(world, ts), trapped=trapped,
        moves={a: lookup(np.append(ts.move[:, d], trapped), cell_key) for d, a in enumerate(ACTIONS)},
        label_expr=lookup(np.append(ts.cell_label, 0), cell_key),
        q_now=lookup(dfa.delta, [("q", 0), ("label_class", 0)]),
        accepting=sorted(dfa.accepting), sink=sorted(dfa.sink),
        robot_commands=_robot_commands(ts),
        start_cell=start_cell, start_traps=start_traps, slip=prism_number(world.slip),
        region_labels=region_labels(ts),
        set_members=[", ".join(f"({x},{y})" for x, y in ts.trap_cells(t)) for t in range(ts.n_sets)],
    )


def render_symmetric(world: World, ts: TransitionSystem, task: DFA) -> tuple[str, str]:
    """The symmetric-information game of docs/semantics.md §7 as a PRISM-games csg, and its property file."""
    text = render_template("symmetric.prism.j2", **_context(world, ts, task))
    props = (f"// V_NE of world {world.name} (docs/semantics.md §7): the value of the concurrent zero-sum game in which\n"
             f"// P2 knows the task; P1 maximises, P2 minimises, both with mixed strategies.\n"
             f"{PROPERTY}\n")
    return text, props


def render_perceptual(world: World, ts: TransitionSystem, dfa: DFA, index: int) -> tuple[str, str]:
    """P2's perceptual game G(x_index) of docs/semantics.md §4 as a PRISM-games smg, and its property file."""
    text = render_template("perceptual.prism.j2", index=index, **_context(world, ts, dfa))
    props = (f"// V_x of world {world.name} for hypothesis x{index} = \"{dfa.formula}\" (docs/semantics.md §4): P2 places\n"
             f"// the traps first each step, P1 answers; P1 maximises, P2 minimises.\n"
             f"{PROPERTY}\n")
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
    for i, game in enumerate(analysis.games):
        text, props = render_perceptual(world, ts, game.dfa, i)
        files += [(f"perceptual_{i}.prism", text), (f"perceptual_{i}.props", props)]
    written = []
    for name, content in files:
        path = out_dir / name
        write_text(path, content)
        written.append(path)
    return written
