"""The hypergame MDP of docs/semantics.md §6, rendered as a structured PRISM model.

Storm builds the product of four components, so the number of commands grows with the
tables, never with the product:

  robot         cell (TRAPPED once caught): P1's moves with slip, and the trap check
  task          q: P1's task DFA, one step behind (it reads the label of the cell being left)
  p2_traps      (delay > 0 only) the traps standing and the countdown
  p2_inference  hyp and the observation window: the sliding-window CUSUM of docs/semantics.md §5

Tables (moves, labels, P2's trap choices, log-likelihood ratios) are formulas written as
balanced decision trees over the state variables, so Storm evaluates each in logarithmic time.
"""

from __future__ import annotations

import functools
import importlib.resources
from dataclasses import dataclass
from pathlib import Path

import jinja2
import numpy as np

from hg2prism import __version__
from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import ACTION_LABELS, ACTIONS, TransitionSystem
from hg2prism.opponent.inference import TOLERANCE, InferenceModel
from hg2prism.opponent.perceptual_games import PerceptualGame
from hg2prism.model.world import World

PROPERTY = 'Pmax=? [F "goal"]'


@dataclass(frozen=True)
class Layout:
    """How hypergame states are encoded in PRISM variables (for decoding Storm's states)."""

    slots: int                      # observation slots o1 (oldest) .. o{slots}
    delay: int

    def slot_variables(self, i: int) -> tuple[str, str]:
        return f"o{i}_state", f"o{i}_act"


@dataclass(frozen=True)
class PrismModel:
    text: str
    properties: str
    layout: Layout
    commands: dict[str, int]        # module name -> number of commands


def region_label(letter: str) -> str:
    """The PRISM label of a region letter: "reg_A" for A. PRISM rejects a keyword as a label
    name even inside quotes, and A, C, E, F, G, I, P, R, S, U, W and X are keywords."""
    return f"reg_{letter}"


def region_labels(ts: TransitionSystem) -> list[tuple[str, int]]:
    """(PRISM label, label class) of each region letter (classes 0 and 1 are none and obs)."""
    return [(region_label(name), k) for k, name in enumerate(ts.label_names) if k >= 2]


def prism_number(value: float | int) -> str:
    """A number as PRISM reads it: integers plain, floats in their shortest exact decimal."""
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    text = np.format_float_positional(float(value), unique=True, trim="0")
    return text if "." in text else text + ".0"


def lookup(table: np.ndarray, keys: list[tuple[str, int]]) -> str:
    """An expression for table[k0 - lo0][k1 - lo1]...: a balanced tree of comparisons.

    keys: (expression, lowest value) per table dimension. Equal sub-blocks collapse to a constant.
    """
    def node(block: np.ndarray, dim: int, start: int) -> str:
        first = block.flat[0]
        if (block == first).all():
            return prism_number(first.item())
        if block.shape[0] == 1:
            return node(block[0], dim + 1, 0)
        expr, low = keys[dim]
        mid = block.shape[0] // 2
        left = node(block[:mid], dim, start)
        right = node(block[mid:], dim, start + mid)
        return f"({expr}<{low + start + mid} ? {left} : {right})"

    return node(np.asarray(table), 0, 0)


def _template_source(name: str) -> str:
    """Templates ship as the package `hg2prism.templates` (the repository's templates/ folder);
    running from a checkout without installing reads that folder directly."""
    try:
        folder = importlib.resources.files("hg2prism.templates")
    except ModuleNotFoundError:
        folder = Path(__file__).resolve().parents[2] / "templates"
    return folder.joinpath(name).read_text()


def upper(count: int) -> int:
    """The upper bound of a variable [0..upper] taking `count` values (0 .. count-1). PRISM
    rejects a range of one value ("Invalid range (0-0)"), so a variable that only ever holds 0
    (one trap set, one hypothesis, a one-state DFA) is declared [0..1]; 1 is never reached."""
    return max(count - 1, 1)


@functools.cache   # one environment, so each template is compiled once per process
def _environment() -> jinja2.Environment:
    environment = jinja2.Environment(
        loader=jinja2.FunctionLoader(_template_source),
        undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True,
        keep_trailing_newline=True)
    environment.globals["upper"] = upper
    return environment


def render_template(name: str, **context: object) -> str:
    return _environment().get_template(name).render(**context)


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
                inference: InferenceModel) -> PrismModel:
    n_cells, n_sets = ts.n_cells, ts.n_sets
    trapped = n_cells
    cell_key = [("cell", 0)]

    # Robot dynamics tables.
    moves = {a: lookup(np.append(ts.move[:, d], trapped), cell_key) for d, a in enumerate(ACTIONS)}
    label_expr = lookup(np.append(ts.cell_label, 0), cell_key)
    q_now = lookup(task.delta, [("q", 0), ("label_class", 0)])
    accepting = sorted(task.accepting)
    sink = sorted(task.sink)

    # The TS state as one number (for observations), and P2's trap choice per hypothesis.
    if ts.delay:
        # (with one trap set, traps is always 0 but declared [0..1]: see upper())
        ts_state = (f"(cell*{n_sets}+traps)*{ts.phases}+countdown" if n_sets > 1
                    else f"cell*{ts.phases}+countdown")
        trap_keys = [("cell", 0), ("traps", 0), ("countdown", 0)]
        shape = (n_cells, n_sets, ts.phases)
    else:
        ts_state = "cell"
        trap_keys = [("cell", 0)]
        shape = (n_cells,)
    trap_tables = [lookup(g.trap_choice[:-1].reshape(shape), trap_keys) for g in games]

    # P2's inference: ratio tables and CUSUM formulas.
    n_x, w = inference.n_hypotheses, inference.window
    slots = w - 1
    n_obs_states = ts.n_states - 1
    ratio_formulas = []      # (name, comment, expression)
    inference_rules = []     # per (hypothesis, action): switch and best formulas
    for h in range(n_x):
        others = [x for x in range(n_x) if x != h]
        for x in others:
            ratios = inference.ratios[h, x, :n_obs_states]              # [states, 4]
            for i in range(1, slots + 1):
                padded = np.vstack([np.zeros((1, 4)), ratios])           # state -1 = empty slot
                padded = np.hstack([np.zeros((padded.shape[0], 1)), padded])  # act -1
                ratio_formulas.append((
                    f"r_h{h}_x{x}_o{i}",
                    f"r(x{x} | x{h}) of the move in slot o{i}",
                    lookup(padded, [(f"o{i}_state", -1), (f"o{i}_act", -1)])))
            for d, a in enumerate(ACTIONS):
                ratio_formulas.append((
                    f"r_h{h}_x{x}_{a}",
                    f"r(x{x} | x{h}) of moving {a} now",
                    lookup(ratios[:, d], [("ts_state", 0)])))
        for a in ACTIONS:
            scores = {}
            for x in others:
                z = "0.0"
                for term in [f"r_h{h}_x{x}_o{i}" for i in range(1, slots + 1)] + [f"r_h{h}_x{x}_{a}"]:
                    z = f"max(0.0, {z}+{term})" if z != "0.0" else f"max(0.0, {term})"
                scores[x] = z
            inference_rules.append({"h": h, "action": a, "others": others, "scores": scores})

    model_text = render_template(
        "hypergame.prism.j2",
        version=__version__, world=world, ts=ts, task=task, games=games, inference=inference,
        actions=ACTIONS, labels=ACTION_LABELS, cell_map=cell_map(world, ts), trapped=trapped,
        moves=moves, label_expr=label_expr, q_now=q_now, accepting=accepting, sink=sink,
        ts_state=ts_state, trap_tables=trap_tables, slots=slots,
        n_obs_states=n_obs_states, ratio_formulas=ratio_formulas, inference_rules=inference_rules,
        switch_threshold=prism_number(inference.threshold - TOLERANCE), tolerance=prism_number(TOLERANCE),
        robot_outcomes=_robot_outcomes(ts), trap_cell_tables=_trap_cell_tables(ts),
        n_trap_cells=world.traps, start_cell=ts.decode(ts.start_state)[0],
        start_traps=ts.decode(ts.start_state)[1], slip=prism_number(world.slip),
        region_labels=region_labels(ts),
        set_members=[", ".join(f"({x},{y})" for x, y in ts.trap_cells(t)) for t in range(n_sets)],
        fmt=prism_number,
    )
    properties = render_template("hypergame.props.j2", property=PROPERTY, world=world)
    commands = _count_commands(model_text)
    return PrismModel(text=model_text, properties=properties,
                      layout=Layout(slots=slots, delay=ts.delay),
                      commands=commands)


def _robot_outcomes(ts: TransitionSystem) -> list[dict]:
    """One robot command per action: its outcomes as (probability, direction moved)."""
    perpendicular = {"N": "EW", "E": "NS", "S": "EW", "W": "NS"}
    commands = []
    for a in ACTIONS:
        outcomes = [("1-2*slip", a)] + [("slip", p) for p in perpendicular[a]] if ts.slip > 0 \
            else [("1", a)]
        commands.append({"action": a, "outcomes": outcomes})
    return commands


def _trap_cell_tables(ts: TransitionSystem) -> list[str]:
    """trap_cell_j: the j-th cell of the trap set in force, as a table over `trap_set`. One
    robot command per move then serves every trap set, which halves Storm's build time against
    one command per (move, trap set)."""
    members = np.array([sorted(ts.candidates[c] for c in members) for members in ts.trap_sets],
                       dtype=np.int64).reshape(ts.n_sets, -1)
    return [lookup(members[:, j], [("trap_set", 0)]) for j in range(members.shape[1])]


def _count_commands(text: str) -> dict[str, int]:
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
