"""The Python API: a few verbs over the pipeline, for notebooks and scripts.

    world = hg2prism.load_world("models/world1.toml")        # or world_from_toml(text)
    world = hg2prism.world_from_graph(G, entries=[1], task="F asset9")   # a NetworkX attack graph
    solution = hg2prism.solve(world)                          # Storm, sound; writes nothing
    solution.deceptive_value, solution.strategy.move(...)     # numbers and P1's moves
    hg2prism.baselines(world).v_ne_bounds                     # the symmetric baselines
    hg2prism.simulate(solution, episodes=2000).rate           # online play against P2

Nothing is printed unless the application configures logging (the `hg2prism` logger reports
each stage at INFO), and nothing is written unless `out` is given. docs/api.md has the details
and docs/semantics.md the meaning of every number.
"""

from __future__ import annotations

import contextlib
import numbers
import os
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from hg2prism.model.validation import MAX_EPISODES, MAX_HORIZON, MAX_SEED, Checks
from hg2prism.model.world import PlayerType, World, plain

from hg2prism.errors import COMMAND_LINE, InputError, listing
from hg2prism.worldfile import load_world, world_from_toml
from hg2prism.results import CheckResult, CheckResults, RunResults
from hg2prism.strategy.records import Strategy

__all__ = ["load_world", "world_from_toml", "world_from_graph", "solve", "run", "baselines",
           "simulate", "deception_values", "robust", "sweep", "detection", "episode", "draw_world",
           "draw_belief", "draw_sweep", "Solution", "AdaptiveSolution", "Run", "Strategy", "Baselines", "Simulation",
           "DeceptionValues", "RobustValue", "SweepRow", "SweepTable", "Episode", "EpisodeStep",
           "PlayerType", "load_strategy"]


# ---------------------------------------------------------------------------------------------
# The verbs' arguments, checked before any work: InputError("<verb>()", argument, reason)
# ---------------------------------------------------------------------------------------------

def _integer(verb: str, value: object, key: str, minimum: int,
             maximum: int | None = None) -> int:
    """An integer argument (numpy's too) in [minimum, maximum], by model/validation.py's rule."""
    return Checks(f"{verb}()").integer(plain(value), key, minimum, maximum)


def _budget(verb: str, value: object, key: str) -> None:
    """InputError unless a deviation budget is a number (numpy's too): the verbs take numbers,
    the command line's text is parsed by the command line."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(f"{verb}()", key, f"{value!r} is not a deviation budget in [0, 1): "
                         "expected a number")


def _flag(verb: str, value: object, key: str) -> bool:
    """A True/False argument (numpy's bool too)."""
    import numpy as np

    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{verb}()", key, f"expected True or False, got {value!r}")
    return bool(value)


def _option(verb: str, value: object, key: str, what: str, options) -> str:
    return Checks(f"{verb}()").choice(value, key, what, tuple(options))


def _storm_method(verb: str, method: object) -> str:
    from hg2prism.engines import default as default_engine

    return _option(verb, method, "storm_method", "Storm method", default_engine().methods)


def _sequence(verb: str, value: object, key: str, expected: str, call: bool = True) -> list:
    """A list of the values of a sequence argument (not a string); its error names the call
    `verb()`, or with `call` False the world `verb`."""
    from collections.abc import Iterable

    if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
        raise InputError(f"{verb}()" if call else verb, key,
                         f"expected {expected}, got {type(value).__name__}")
    return list(value)


def _world(verb: str, world: object) -> World:
    """The World of a `world` argument: a World, or the path of a world file (loaded)."""
    if isinstance(world, World):
        return world
    if isinstance(world, (str, os.PathLike)):
        return load_world(world)
    raise InputError(f"{verb}()", "world", "expected a World or the path of a world file, got "
                     f"{type(world).__name__}")


@contextlib.contextmanager
def _as_arguments(verb: str, renamed: dict[str, str] | None = None):
    """The stages' InputErrors about the command line's options (file "command line", key
    "--deltas") as errors in the verb's arguments (file "<verb>()", key "deltas"): the option's
    name without dashes, or as `renamed` says."""
    try:
        yield
    except InputError as err:
        if err.file != COMMAND_LINE:
            raise
        option, _, rest = err.key.partition(" ")
        key = (renamed or {}).get(option, option.lstrip("-").replace("-", "_"))
        raise InputError(f"{verb}()", f"{key} {rest}".strip(), err.reason) from None


def _node_name(node: object, file: str) -> str:
    """An attack-graph node's state name: n<v> for an integer, an identifier as it is."""
    import numbers
    import re

    if isinstance(node, numbers.Integral) and not isinstance(node, bool) and node >= 0:
        return f"n{int(node)}"
    if isinstance(node, str) and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", node):
        return node
    raise InputError(file, f"node {node!r}", "has no state name: nodes are integers >= 0 "
                     "(state n<v>) or ASCII identifiers, [A-Za-z_][A-Za-z0-9_]* (the state "
                     "of that name; networkx.relabel_nodes renames the others)")


def _asset(node: object, name: str) -> str:
    return f"asset{name[1:]}" if name != node else f"asset_{name}"


def _finite_real(p: object) -> bool:
    """Whether an edge's number is a finite real (not a bool, a str, NaN or inf)."""
    import math
    import numbers

    return not isinstance(p, bool) and isinstance(p, numbers.Real) and math.isfinite(p)


def _number(p: object) -> float:
    """An edge's probability as a float: a numpy float of lower precision (a float32 column)
    by its shortest decimal, the number that was written (np.float32(0.8) is 0.800000011920929
    as a float, so 0.8, 0.1 and 0.1 would not add up to 1)."""
    import numpy as np

    if isinstance(p, np.floating) and np.finfo(p.dtype).bits < 64:
        return float(str(p))
    return float(p)


def _edge_probability(graph, u: object, v: object, key: str, file: str,
                      outcomes: str = "outcomes") -> float:
    where = f"edge ({u!r}, {v!r})"
    data = graph.edges[u, v]
    if key not in data:
        raise InputError(file, where, f"has no {key!r} attribute (its success probability) "
                         f"and no {outcomes!r} (where the step leads)")
    p = data[key]
    if not _finite_real(p):
        text = (" (text: a CSV reader gives strings, convert them with float)"
                if isinstance(p, str) else "")
        raise InputError(file, where, f"{key} = {p!r} is not a probability{text}")
    if not 0 <= p <= 1:
        raise InputError(file, where, f"{key} = {p!r} is outside [0, 1]")
    if u == v:
        raise InputError(file, where, "is a self-loop; an attack step leads to another node")
    return _number(p)


def _edge_outcomes(graph, u: object, v: object, probability: str, outcomes: str,
                   order: dict, names: dict, file: str) -> dict[str, float]:
    """Where the attack step along edge (u, v) leads, by state name: the edge's `outcomes`
    attribute (node -> probability, each a node of the graph, adding up to 1) when it has one,
    else v with its success probability and u (staying) otherwise."""
    import math
    from collections.abc import Mapping

    data = graph.edges[u, v]
    if outcomes not in data:
        p = _edge_probability(graph, u, v, probability, file, outcomes)
        return {names[v]: p, names[u]: 1.0 - p} if 0 < p < 1 else {names[v if p else u]: 1.0}
    where, given = f"edge ({u!r}, {v!r})", data[outcomes]
    if probability in data:
        raise InputError(file, where, f"has both {probability!r} and {outcomes!r}: give the "
                         "step's success probability or its outcomes, not both")
    if u == v:
        raise InputError(file, where, "is a self-loop; an attack step leads to another node")
    if not isinstance(given, Mapping) or not given:
        raise InputError(file, where, f"{outcomes} = {given!r}: expected a dict node -> "
                         "probability (where the step leads, adding up to 1)")
    for node, p in given.items():
        if node not in order:
            raise InputError(file, where, f"{outcomes}: {node!r} is not a node of the graph "
                             f"(add it: graph.add_node({node!r}))")
        if not _finite_real(p) or not 0 <= p <= 1:
            raise InputError(file, where, f"{outcomes}: {node!r}: {p!r} is not a probability")
    given = {node: _number(p) for node, p in given.items()}
    total = math.fsum(given.values())
    if abs(total - 1.0) > 1e-9:
        raise InputError(file, where, f"{outcomes}: the probabilities add up to {total!r}, "
                         "not 1")
    return {names[node]: given[node] for node in sorted(given, key=order.__getitem__)
            if given[node] > 0}


def _success(graph, u: object, v: object, probability: str, outcomes: str, file: str) -> float:
    """The chance that the attack step along (u, v) reaches v (the arena has checked it)."""
    data = graph.edges[u, v]
    if outcomes in data:
        return _number(data[outcomes].get(v, 0.0))
    return _edge_probability(graph, u, v, probability, file, outcomes)


def _targets(graph, nodes: list, entries) -> list:
    """The targets of an attack graph: the nodes without outgoing edges that an edge leads to
    or that are entries (a node only edges' `outcomes` reach, where the attacker is caught
    say, is none)."""
    entered = set(entries)
    return [v for v in nodes
            if graph.out_degree(v) == 0 and (graph.in_degree(v) > 0 or v in entered)]


def _graph_nodes(graph, file: str, given: dict[str, object]) -> tuple[list, dict]:
    """The nodes in state order (sorted when they sort, else the graph's order) and their
    state names; every node given as an argument checked."""
    if not all(hasattr(graph, name) for name in ("is_directed", "is_multigraph", "edges")):
        raise InputError(file, "graph", "expected a directed graph without parallel edges "
                         f"(networkx.DiGraph), got {type(graph).__name__}")
    if not graph.is_directed() or graph.is_multigraph():
        raise InputError(file, "graph", "expected a directed graph without parallel edges "
                         "(networkx.DiGraph)")
    try:
        nodes = sorted(graph.nodes)
    except TypeError:
        nodes = list(graph.nodes)
    names = {node: _node_name(node, file) for node in nodes}
    if "outside" in names.values():
        raise InputError(file, "node 'outside'", "is the name of the attacker's initial "
                         "state; rename the node (networkx.relabel_nodes)")
    seen: dict[str, object] = {}
    for node, state in names.items():
        if state in seen:
            raise InputError(file, f"nodes {seen[state]!r} and {node!r}", "would both be the "
                             f"state {state!r}; rename one (networkx.relabel_nodes)")
        seen[state] = node
    for what, items in given.items():
        for node in items:
            if node not in names:
                raise InputError(file, what, f"{node!r} is not a node of the graph")
    return nodes, names


def _graph_positions(graph, entries, positions, file: str) -> dict:
    """The [arena.positions] table of an attack graph drawn where `positions` (node -> [x, y],
    every node) says, `outside` one unit left of its entries, at their mean height."""
    import math
    import numbers

    nodes, names = _graph_nodes(graph, file, {"positions": list(positions)})
    missing = [node for node in nodes if node not in positions]
    if missing:
        raise InputError(file, "positions", f"no position for {len(missing)} node(s), e.g. "
                         f"{missing[0]!r}: the figures need every node's [x, y] or none")
    table = {}
    for node in nodes:
        point = positions[node]
        if (isinstance(point, (str, bytes)) or not hasattr(point, "__len__") or len(point) != 2
                or not all(isinstance(c, numbers.Real) and not isinstance(c, bool)
                           and math.isfinite(c) for c in point)):
            raise InputError(file, "positions", f"node {node!r}: expected [x, y] (two numbers), got {point!r}")
        table[names[node]] = [float(point[0]), float(point[1])]
    firsts = [table[names[e]] for e in entries]
    table["outside"] = [min(x for x, _ in firsts) - 1.0,
                        sum(y for _, y in firsts) / len(firsts)]
    return table


def _graph_arena(graph, entries, labels, probability: str, outcomes: str, file: str) -> dict:
    """The [arena] table of an attack graph (world_from_graph)."""
    for key, value in (("probability", probability), ("outcomes", outcomes)):
        if not isinstance(value, str):
            raise InputError(file, key, f"expected an edge attribute's name (a str), got "
                             f"{value!r}")
    if probability == outcomes:
        raise InputError(file, "outcomes", f"names the same edge attribute as probability "
                         f"({outcomes!r}); expected another")
    nodes, names = _graph_nodes(graph, file, {"entries": entries, "labels": labels or {}})
    if not entries:
        raise InputError(file, "entries", "no entry node; expected the nodes the attacker "
                         "can enter from outside")
    order = {node: i for i, node in enumerate(nodes)}
    transitions = [{"state": "outside", "action": f"to_{names[e]}", "to": {names[e]: 1.0}}
                   for e in sorted(set(entries), key=order.__getitem__)]
    for u in nodes:
        for v in sorted(graph.successors(u), key=order.__getitem__):
            to = _edge_outcomes(graph, u, v, probability, outcomes, order, names, file)
            transitions.append({"state": names[u], "action": f"to_{names[v]}", "to": to})
    if labels is None:          # the targets; not a node only outcomes reach (caught, say)
        labels = {v: _asset(v, names[v]) for v in _targets(graph, nodes, entries)}
    label_table = {names[v]: [ps] if isinstance(ps, str) else list(ps)
                   for v, ps in labels.items()}
    label_table = {name: label_table[name] for name in map(names.get, nodes)
                   if label_table.get(name)}
    return {"states": ["outside", *(names[v] for v in nodes)], "initial": "outside",
            "labels": label_table, "transition": transitions}


def world_from_graph(graph, *, entries, task: str, hypotheses=None, labels=None,
                     traps: int = 1, trap_candidates=None, delay: int = 0, initial_traps=None,
                     initial_hypothesis: int | None = None, inference: dict | None = None,
                     simulation: dict | None = None, detection: dict | None = None,
                     probability: str = "p", name: str = "attack_graph",
                     description: str = "", positions=None, tie_break: str = "first",
                     outcomes: str = "outcomes") -> World:
    """The arena world (docs/semantics.md §15) of an attack graph: a networkx.DiGraph whose
    edges carry the attack step's success probability (attribute `probability`).

    States: `outside` (the initial state), then the nodes (sorted when they sort, else in the
    graph's order) named n<v> for an integer node v, their own name for an identifier. At
    `outside` P1 (the attacker) has one action per entry node, `to_<node>`, reaching it with
    probability 1; at node u one action per outgoing edge (u, v), `to_<v>`, reaching v with the
    edge's probability and staying at u otherwise (or the nodes of the edge's `outcomes`, node
    -> probability: a third outcome, caught, say). A node without outgoing edges (a target)
    is terminal: the episode ends there. Labels: `labels` maps nodes to propositions (a name
    or a list); by default each target v carries `asset<v>` (`asset_<name>` for a named node).
    P2 (the defender) sets `traps` traps (honeypots) among `trap_candidates` (default: every
    node with outgoing edges); `initial_traps` (nodes) stand at the start when delay > 0 (with
    delay 0, what a sweep over delay starts from); `tie_break` which of her tied sets P2 takes
    (docs/semantics.md §4: "first", the rule, or "last").
    `hypotheses` default to `F <p>` for each proposition; `inference` is the [inference] table
    (keys not given: CUSUM, window 2, rationality 1 and, for CUSUM, threshold 0.6); `simulation` and `detection` the
    optional tables; `positions` (node -> [x, y], every node) where the figures draw the nodes,
    `outside` then one unit left of the entries (default: a layered layout). Every problem is
    an InputError naming `name`, the key and the reason; what is likely a mistake but has a
    meaning (an edge with probability 0, a target among the trap candidates or entries, a
    target `labels` leaves unlabelled) a warning line (progress.warn)."""
    from collections.abc import Mapping

    from hg2prism.worldfile import world_from_data

    if not isinstance(name, str):
        raise InputError("world_from_graph()", "name",
                         f"expected a str, got {type(name).__name__}")
    # every other problem names the world, as its file would be named (docs/api.md)
    entries = _sequence(name, entries, "entries", "a list of nodes", call=False)
    if hypotheses is not None:
        hypotheses = _sequence(name, hypotheses, "hypotheses", "a list of formulas", call=False)
    # a generator is read once, here
    if trap_candidates is not None:
        trap_candidates = _sequence(name, trap_candidates, "trap_candidates", "a list of nodes",
                                    call=False)
    if initial_traps is not None:
        initial_traps = _sequence(name, initial_traps, "initial_traps", "a list of nodes",
                                  call=False)
    for key, table in (("labels", labels), ("inference", inference),
                       ("simulation", simulation), ("detection", detection),
                       ("positions", positions)):
        if table is not None and not isinstance(table, Mapping):
            raise InputError(name, key, f"expected a dict, got {type(table).__name__}")
    arena = _graph_arena(graph, entries, labels, probability, outcomes, name)
    if positions is not None:
        arena["positions"] = _graph_positions(graph, entries, positions, name)
    nodes, names = _graph_nodes(graph, name, {"trap_candidates": trap_candidates or (),
                                              "initial_traps": initial_traps or ()})
    if trap_candidates is None:
        trap_candidates = [v for v in nodes if graph.out_degree(v) > 0]
    propositions = list(dict.fromkeys(p for ps in arena["labels"].values() for p in ps))
    adversary = {"traps": traps, "trap_candidates": [names[v] for v in trap_candidates],
                 "delay": delay,
                 "hypotheses": list(hypotheses) if hypotheses is not None
                 else [f"F {p}" for p in propositions]}
    if initial_traps is not None:
        adversary["initial_traps"] = [names[v] for v in initial_traps]
    if initial_hypothesis is not None:
        adversary["initial_hypothesis"] = initial_hypothesis
    if tie_break != "first":
        adversary["tie_break"] = tie_break
    data = {"name": name, "description": description, "arena": arena,
            "task": {"formula": task}, "adversary": adversary,
            "inference": _inference_table(inference)}
    for key, table in (("simulation", simulation), ("detection", detection)):
        if table is not None:
            data[key] = dict(table)
    # as a world file gives them: numpy's numbers as Python's (traps=np.int64(1) was refused)
    world = world_from_data(plain(data, list), name=name)
    _graph_warnings(graph, entries, labels, trap_candidates, probability, outcomes, name)
    return world


def _graph_warnings(graph, entries, labels, trap_candidates, probability: str,
                    outcomes: str, file: str) -> None:
    """What world_from_graph accepts that has a meaning (docs/semantics.md §15) but is likely
    a mistake, one warning line each: edges with probability 0, targets (nodes without an
    outgoing edge) among the trap candidates or the entries, and, with `labels` given, targets
    without a label."""
    from hg2prism import progress

    nodes, names = _graph_nodes(graph, file, {})
    targets = set(_targets(graph, nodes, entries))
    never = [(u, v) for u in nodes for v in graph.successors(u)
             if _success(graph, u, v, probability, outcomes, file) == 0]
    if never:
        one = len(never) == 1
        where = ("he stays where he is, or goes where its outcomes say" if any(
            outcomes in graph.edges[e] for e in never) else "he stays where he is")
        progress.warn(f"{file}: edge{'' if one else 's'} "
                      f"{listing([f'({u!r}, {v!r})' for u, v in never], 3, count=True)}: "
                      f"probability 0, so the attacker's action along {'it' if one else 'each'} "
                      f"never succeeds ({where}); remove {'the edge' if one else 'them'} if the "
                      "step is impossible")
    for key, given, meaning in (
            ("trap_candidates", trap_candidates or (), "a honeypot there catches the attacker "
             "on reaching the target itself; leave it out unless the defender can guard a "
             "target (the default candidates: the nodes with an outgoing edge)"),
            ("entries", entries, "the attacker reaches that target from outside in one "
             "step with probability 1 (unless trapped there); leave it out of entries unless "
             "it is exposed so")):
        odd = [names[v] for v in dict.fromkeys(given) if v in targets]
        if odd:
            progress.warn(f"{file}: {key}: {listing(odd, 3, count=True)} "
                          f"{'has' if len(odd) == 1 else 'have'} no outgoing edge (a target): "
                          f"{meaning}")
    if labels is not None:
        bare = [names[v] for v in nodes if v in targets and v not in labels]
        if bare:
            progress.warn(f"{file}: labels: {listing(bare, 3, count=True)} "
                          f"{'has' if len(bare) == 1 else 'have'} no outgoing edge and no "
                          "label: reaching one ends the episode with "
                          "nothing gained (won only if the task is already done); label "
                          f"{'it' if len(bare) == 1 else 'them'} in labels= (by default every "
                          "such node is labelled asset<v>; labels={node: []} leaves one "
                          "unlabelled without this warning) or give them outgoing edges")


def _inference_table(given) -> dict:
    """world_from_graph's [inference]: the keys given over the defaults (CUSUM, window 2,
    rationality 1 and, for CUSUM, threshold 0.6)."""
    given = dict(given or {})
    table = {"kind": "cusum", "window": 2, "rationality": 1.0}
    if given.get("kind", "cusum") == "cusum":
        table["threshold"] = 0.6
    return {**table, **given}


def _reported(name: str, doc: str) -> property:
    """A Solution attribute read from its CheckResults (not a copy)."""
    return property(lambda self: getattr(self.results, name), doc=doc)


@dataclass(frozen=True, eq=False)
class Solution:
    """The deceptive value and strategy of a world (what `hg2prism check` computes): a view of
    the pipeline's CheckResult (hg2prism.results), with P1's strategy read from its records."""

    world: World
    strategy: Strategy              # P1's move in every reachable hypergame state
    check: CheckResult = field(repr=False)   # everything `check` computed (hg2prism.results)

    deceptive_value = _reported("deceptive_value", "Pmax of reaching the goal in the hypergame MDP")
    v_lead = _reported("v_lead", "the leader baseline (docs/semantics.md §7)")
    states = _reported("states", "canonical hypergame states")
    transitions = _reported("transitions", "canonical hypergame transitions")
    storm_method = _reported("storm_method", "how Pmax was solved")
    sound = _reported("sound", 'False for the "fast" method: the value is not certified')
    objective = _reported("objective", "what the strategy optimises: name, bound, value, steps")

    @property
    def results(self) -> CheckResults:
        """Everything `check` reports: results.json's fields as typed attributes."""
        return self.check.results

    def to_json(self) -> dict:
        """The content of results.json."""
        return self.results.to_json()

    def __repr__(self) -> str:
        shown = ("world", "deceptive_value", "v_lead", "states", "transitions", "storm_method",
                 "sound", "strategy", "objective")
        return "Solution(" + ", ".join(f"{name}={getattr(self, name)!r}" for name in shown) + ")"


def solve(world: World | str | Path, *, out: str | Path | None = None,
          storm_method: str = "sound", objective: str = "pmax",
          bound: int | None = None) -> Solution | AdaptiveSolution:
    """Build the hypergame of `world` (a World or the path of a world file), check it with
    Storm and extract P1's deceptive strategy. With `out`, what `hg2prism check` writes (the
    model, strategy.json, results.json, the automata and the induced DTMC) goes there
    (atomically); without, nothing is written (the model passes through a temporary folder
    Storm reads, removed before returning). `objective` is what the strategy optimises among
    the moves that keep Pmax (docs/semantics.md §6): "pmax" (the default), "lexicographic"
    (then the fewest expected steps) or "bounded" (the probability of the goal within `bound`
    steps, by default the world's simulation horizon; the moves then depend on the step).
    A world with P2's types ([[type]]) gives an `AdaptiveSolution` (docs/api.md)."""
    from hg2prism import pipeline
    from hg2prism.model import sizeguard

    from hg2prism.strategy.objectives import OBJECTIVES

    _option("solve", objective, "objective", "objective", OBJECTIVES)
    storm_method = _storm_method("solve", storm_method)
    if bound is not None:
        bound = _integer("solve", bound, "bound", 1, MAX_HORIZON)
        if objective != "bounded":
            raise InputError("solve()", "bound", "a number of steps for objective='bounded', "
                             f"got objective={objective!r}")
    if out is not None:
        out = _out_folder("solve", out)
    world = _world("solve", world)
    sizeguard.check_size(world)
    if world.types:           # P2's type unknown: adaptive deception (docs/semantics.md §16)
        with _as_arguments("solve"):
            return _solve_adaptive(world, out, storm_method, objective)[0]
    with _as_arguments("solve"), contextlib.ExitStack() as stack:
        folder = (stack.enter_context(command_stage("check", out, world)) if out is not None else
                  Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="hg2prism-"))))
        checked = pipeline.check(world, folder, storm_method, objective, bound)
        records = tuple(checked.records)
    return Solution(world=world, strategy=Strategy.from_records(records, checked.analysis.ts),
                    check=checked)


@dataclass(frozen=True, eq=False)
class Run:
    """What `hg2prism run` computes for a world, all of it written into `out`: the solution,
    results.json's content and the table of table.md."""

    solution: Solution | AdaptiveSolution
    results: RunResults | dict      # results.json: typed; a world with P2's types: its content
    table: str                      # table.md's text (the completion table, or adaptivity's)
    out: Path                       # where the files are

    def to_json(self) -> dict:
        """The content of results.json."""
        return self.results if isinstance(self.results, dict) else self.results.to_json()

    def __repr__(self) -> str:
        return f"Run(solution={self.solution!r}, out={str(self.out)!r})"


def run(world: World | str | Path, out: str | Path, *, episodes: int | None = None,
        horizon: int | None = None, seed: int | None = None, episode: str = "median",
        storm_method: str = "sound", objective: str = "pmax") -> Run:
    """Everything `hg2prism run` computes for `world` (a World or the path of a world file),
    written into the folder `out` as the command writes it (atomically, stale outputs
    removed): the check, the baselines, the PRISM-games models, the value of deception, the
    simulations (`episodes` episodes cut after `horizon` steps from `seed`, by default the
    world's [simulation]), table.md, the figures and the replay of the episode `episode` names
    ("median", "shortest" or "seed=N"). With objective "bounded" the bound is the horizon. A
    world with P2's types ([[type]]) is solved and its adaptive strategy simulated, as the
    command does (`episode` must then be left at "median")."""
    from hg2prism import pipeline
    from hg2prism.analyses.episodes import parse_episode_rule
    from hg2prism.model import sizeguard
    from hg2prism.strategy.objectives import OBJECTIVES

    _option("run", objective, "objective", "objective", OBJECTIVES)
    storm_method = _storm_method("run", storm_method)
    episodes, horizon, seed = _simulation_arguments("run", episodes, horizon, seed)
    with _as_arguments("run"):
        parse_episode_rule(episode)
    out = _out_folder("run", out)
    world = _world("run", world)
    sizeguard.check_size(world)
    if world.types:           # P2's type unknown: adaptive deception (docs/semantics.md §16)
        if str(episode).strip() != "median":
            raise InputError("run()", "episode", "a world with P2's types draws the episode of "
                             "adaptive_belief.png with `seed` (its type too, from the prior); "
                             "`episode` picks the figures' episode of a world with one "
                             "[inference]")
        settings = world.simulation
        simulation = (episodes or settings.episodes, horizon or settings.horizon,
                      settings.seed if seed is None else seed)
        with _as_arguments("run"):
            solution, table = _solve_adaptive(world, out, storm_method, objective, simulation,
                                              command="run")
        return Run(solution=solution, results=solution.results, table=table, out=out)
    with _as_arguments("run"), command_stage("run", out, world) as stage:
        ran = pipeline.run(world, stage, episodes, horizon, seed, show_progress=False,
                           storm_method=storm_method, episode=episode, objective=objective)
        records = tuple(ran.check.records)
    solution = Solution(world=world, strategy=Strategy.from_records(records, ran.check.analysis.ts),
                        check=ran.check)
    return Run(solution=solution, results=ran.results, table=ran.table, out=out)


def command_stage(command: str, out: Path, world: World):
    """outputs.staged for what the command `command` ("check", "run", "sweep", ...) writes into
    `out`, as the command line stages it: its stale outputs are removed, and where `out` held
    another world's outputs (or another version of this world's), every output is."""
    from hg2prism.experiments.sweep import owned_pattern
    from hg2prism.outputs import OWNED, staged

    owns = owned_pattern() if command == "sweep" else OWNED[command]
    every = "|".join(f"(?:{pattern})" for pattern in (*OWNED.values(), owned_pattern()))
    return staged(Path(out), owns=owns, world=world.name, every=every, digest=world.digest())


def _out_folder(verb: str, out: object) -> Path:
    """`out` as a folder this process can write (or create), checked before any work as the
    command line checks --out (outputs.check_writable)."""
    from hg2prism.outputs import check_writable

    if not isinstance(out, (str, os.PathLike)):
        raise InputError(f"{verb}()", "out", "expected the path of a folder (a str or a "
                         f"pathlib.Path), got {type(out).__name__}")
    if os.fspath(out) == "":        # not the current folder by accident (None writes nothing)
        raise InputError(f"{verb}()", "out", "an empty path; expected a folder (\".\" for the "
                         "current one), or None to write nothing")
    with _as_arguments(verb):
        check_writable(Path(out), "out")
    return Path(out)


def _out_file(verb: str, path: object) -> Path:
    """`path` as a file this process can write, checked as the command line checks a file's
    --out."""
    from hg2prism.outputs import check_writable

    if not isinstance(path, (str, os.PathLike)):
        raise InputError(f"{verb}()", "path", "expected the path of a file (a str or a "
                         f"pathlib.Path), got {type(path).__name__}")
    if os.fspath(path) == "":
        raise InputError(f"{verb}()", "path", "an empty path; expected a file name")
    if Path(path).is_dir():
        raise InputError(f"{verb}()", "path", f"{path} is a folder; expected a file name")
    with _as_arguments(verb, {"out": "path"}):
        check_writable(Path(path).parent, "out", staged=False)
    return Path(path)


@dataclass(frozen=True, eq=False)
class AdaptiveSolution:
    """What `hg2prism check` computes for a world with P2's types (docs/semantics.md §16):
    V_adapt and P1's adaptive strategy, what adaptivity is worth, and each type's own
    Solution."""

    world: World
    v_adapt: float                      # Pmax of the adaptive hypergame
    v_oracle: float                     # sum_k w_k V_k: P1 told the type
    v_k: dict[str, float]               # per type, its deceptive value V_k
    v_commit: dict[str, float]          # per type j, V_commit(j) against the prior
    value_of_adaptivity: float          # V_adapt - max_j V_commit(j)
    cost_of_not_knowing: float          # V_oracle - V_adapt
    strategy: tuple[dict, ...] = field(repr=False)   # strategy.json's records (the adaptive strategy)
    types: tuple[Solution, ...] = field(repr=False)  # each type's own Solution (V_k, its strategy)
    results: dict = field(repr=False)   # results.json's content

    def to_json(self) -> dict:
        """The content of results.json."""
        return self.results


def _solve_adaptive(world: World, out, storm_method: str, objective: str,
                    simulation: tuple[int, int, int] | None = None,
                    command: str = "check") -> tuple[AdaptiveSolution, str]:
    """The AdaptiveSolution of a world with P2's types and its table (table.md); with
    `simulation` (episodes, horizon, seed) its adaptive strategy simulated too, as `run` does."""
    from hg2prism.experiments.adaptive import check_adaptive

    if objective != "pmax":
        raise InputError(str(world.path), "type", "a world with P2's types ([[type]], adaptive "
                         "deception) is solved for the pmax objective only, got "
                         f"objective={objective!r}")
    def solved(folder: Path) -> tuple:
        found = check_adaptive(world, folder, storm_method, simulation=simulation)
        return found, tuple(Solution(world=c.analysis.world, strategy=Strategy.from_records(
            tuple(c.records), c.analysis.ts), check=c) for c in found.checks)

    if out is not None:
        with command_stage(command, out, world) as stage:
            found, types = solved(stage)
    else:
        with tempfile.TemporaryDirectory(prefix="hg2prism-") as scratch:
            found, types = solved(Path(scratch) / "adaptive")
    r = found.results
    return AdaptiveSolution(
        world=world, v_adapt=r["v_adapt"], v_oracle=r["v_oracle"],
        v_k={t["name"]: t["deceptive_value"] for t in r["types"]},
        v_commit={t["name"]: t["v_commit"] for t in r["types"]},
        value_of_adaptivity=r["value_of_adaptivity"],
        cost_of_not_knowing=r["cost_of_not_knowing"], strategy=tuple(found.strategy.records),
        types=types, results=r), found.table


def load_strategy(folder: str | Path, world: World | str | Path | None = None) -> Strategy:
    """P1's strategy that `hg2prism check` or `run` (or `solve`/`run` with `out`) wrote into
    `folder`, read back from its strategy.json to answer `move(...)` without solving again
    (one type's folder, `type<k>/`, of an adaptive run too). The world is the one results.json
    names (its `world_file`, from the current folder) unless `world` (a World or the path of
    its file) is given; either way it must be the world the folder was written for (the same
    `World.digest()`, results.json's `world_digest`)."""
    from hg2prism.errors import WHOLE_FILE
    from hg2prism.frontends import transition_system
    from hg2prism.strategy.records import StrategyError
    from hg2prism.worldfile.types import world_of_type

    if not isinstance(folder, (str, os.PathLike)):
        raise InputError("load_strategy()", "folder", "expected the path of a folder (a str or "
                         f"a pathlib.Path), got {type(folder).__name__}")
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("load_strategy()", "folder", f"{str(folder)!r} is "
                         f"{'a file' if folder.exists() else 'no folder'}: expected a folder "
                         "hg2prism check or run wrote")
    results, source = _results_of(folder)
    if "v_adapt" in results:
        raise InputError(str(folder), WHOLE_FILE, "holds an adaptive strategy (P2's types), "
                         "which has no move: read its strategy.json's records, or load one "
                         "type's strategy from its folder type<k>/")
    world = _world("load_strategy", world) if world is not None else _named_world(source, results)
    names = [t.name for t in world.types]
    if results.get("p2_type") in names:            # one type's folder of an adaptive run
        world = world_of_type(world, names.index(results["p2_type"]))
    if world.digest() != results["world_digest"]:
        shown = world.name if str(world.path) == world.name else f"{world.name} ({world.path})"
        raise InputError("load_strategy()", "world", f"{shown} is not the world {folder} was "
                         f"written for ({results.get('world')!r}, of another World.digest()); "
                         "give that world (a sweep point's is the swept world with the point's "
                         "parameters, World.replace)")
    records = _read_json(folder / "strategy.json", "strategy.json")
    if not isinstance(records, list) or not records:
        raise InputError(str(folder / "strategy.json"), WHOLE_FILE, "expected a list of "
                         f"strategy records, got {'none' if records == [] else repr(records)[:40]}")
    odd = next((k for k, record in enumerate(records) if not isinstance(record, dict)), None)
    if odd is not None:
        raise InputError(str(folder / "strategy.json"), WHOLE_FILE, f"record {odd} is not an "
                         f"object: {repr(records[odd])[:40]}")
    ts = transition_system(world)
    try:
        strategy = Strategy.from_records(records, ts)
        _in_range(strategy, world, ts)
    except StrategyError as error:
        raise InputError(str(folder / "strategy.json"), WHOLE_FILE, "is not a strategy of "
                         f"this world: {error}") from None
    return strategy


def _in_range(strategy: Strategy, world: World, ts) -> None:
    """StrategyError for a record (of a hand-edited strategy.json) whose task state q or
    hypothesis the world does not have: Strategy.from_records reads them as numbers."""
    from hg2prism.model.automata import translate
    from hg2prism.strategy.records import StrategyError

    n_states = translate(world.formula, ts.label_names, ts.letters).n_states
    for _, q, memory in strategy.table:
        for name, value, bound, what in (
                ("q", q, n_states, f"the task's DFA has {n_states} states"),
                ("hypothesis", memory.hypothesis, len(world.hypotheses),
                 f"the world has {len(world.hypotheses)} hypotheses")):
            if not 0 <= value < bound:
                record = next(k for k, r in enumerate(strategy.records)
                              if int(r[name]) == value)
                raise StrategyError(f"strategy record {record}: {name} = {value} is out of "
                                    f"range ({what}, numbered from 0)")


def _results_of(folder: Path) -> tuple[dict, Path]:
    """What load_strategy reads of the run that wrote `folder`, and the file it is in: its
    results.json, or for one deviation's folder of `hg2prism robust` (robust_<δ>/), the
    robust.json beside it."""
    from hg2prism.errors import WHOLE_FILE

    path = folder / "results.json"
    if not path.exists():
        if (folder / "sweep.json").exists():
            raise InputError(str(folder), WHOLE_FILE, "is a sweep's folder: load one point's "
                             "strategy from its folder (<parameter>_<value>/)")
        if (folder / "robust.json").exists():
            raise InputError(str(folder), WHOLE_FILE, "is the folder of hg2prism robust: load "
                             "one deviation's robust strategy from its folder (robust_<delta>/)")
        if folder.name.startswith("robust_") and (folder.parent / "robust.json").exists():
            path = folder.parent / "robust.json"
    results = _read_json(path, "results.json")
    if not isinstance(results, dict) or not isinstance(results.get("world_digest"), str):
        raise InputError(str(path), WHOLE_FILE, f"is not the {path.name} of hg2prism check, "
                         "run or robust (it has no world_digest)")
    return results, path


def _named_world(source: Path, results: dict) -> World:
    """The world whose file results.json (or robust.json: `source`) names (`world_file`), for
    load_strategy."""
    named = results.get("world_file")
    where = str(source)
    if not isinstance(named, str) or not named or named == results.get("world"):
        raise InputError(where, "world_file", f"names {named!r}, the name of a world made in "
                         "Python (no file): give it, load_strategy(folder, world=...)")
    if not Path(named).is_file():
        raise InputError(where, "world_file", f"names {named!r}, not a file from {Path.cwd()}: "
                         "give the world, load_strategy(folder, world=...)")
    try:
        return load_world(named)
    except InputError as error:
        raise InputError(where, "world_file", f"names {named!r}, not a world file here "
                         f"({error.reason}): give the world, load_strategy(folder, "
                         "world=...)") from None


def _read_json(path: Path, what: str) -> object:
    """The JSON content of `path`, an output of hg2prism (InputError naming it otherwise)."""
    import json

    from hg2prism.errors import WHOLE_FILE

    try:
        with open(path, encoding="utf-8") as handle:
            return json.load(handle)
    except FileNotFoundError:
        raise InputError(str(path), WHOLE_FILE, f"not found: expected a folder hg2prism check "
                         f"or run wrote (with its {what})") from None
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise InputError(str(path), WHOLE_FILE, f"cannot be read as JSON: {error}") from None


def _one_type(solution, verb: str) -> None:
    """InputError for a verb that plays one model of P2, given an AdaptiveSolution or anything
    but a Solution."""
    if isinstance(solution, AdaptiveSolution):
        raise InputError(str(solution.world.path), "type", f"{verb} plays P1's strategy against "
                         "one model of P2; this world lists P2's types ([[type]]): give it one "
                         "type's Solution, solution.types[k] (the adaptive strategy is simulated "
                         "by hg2prism run)")
    if not isinstance(solution, Solution):
        raise InputError(f"{verb}()", "solution", "expected a Solution (what hg2prism.solve "
                         f"returns), got {type(solution).__name__}")


def _typed_world(world: World, verb: str, instead: str) -> None:
    if world.types:
        raise InputError(str(world.path), "type", f"{verb} does not handle a world with P2's "
                         f"types ([[type]], adaptive deception); {instead}")


@dataclass(frozen=True)
class Baselines:
    """The symmetric-information baselines at the initial state (docs/semantics.md §7)."""

    v_ne: float
    v_ne_bounds: tuple[float, float]    # sound bracket around V_NE
    v_ne_p1_guaranteed: float           # what P1's extracted Nash strategy guarantees
    v_lead: float


def baselines(world: World | str | Path) -> Baselines:
    """V_NE (with its sound bracket) and V_lead of `world`."""
    from hg2prism.analyses import baselines as nash
    from hg2prism import pipeline

    world = _world("baselines", world)
    analysis = pipeline.analyse(world)
    solved = nash.nash_baseline(analysis.ts, analysis.task)
    return Baselines(v_ne=solved.v_ne, v_ne_bounds=solved.v_ne_bounds,
                     v_ne_p1_guaranteed=solved.v_ne_p1_guaranteed, v_lead=analysis.v_lead)


@dataclass(frozen=True)
class Simulation:
    """Episodes of P1's deceptive strategy against P2's inference (docs/semantics.md §8)."""

    episodes: int
    horizon: int
    seed: int
    completed: int
    failed: int
    truncated: int
    rate: float                     # completed / episodes
    ci95: tuple[float, float]       # Wilson score interval of the rate
    # P2's changes of hypothesis (docs/semantics.md §11): the share of episodes with one, the
    # mean number per episode, and the share with one after which the episode went on
    p2_switched: float
    p2_switches_mean: float
    p2_switched_in_play: float


def _played(solution: Solution, horizon: int | None):
    """What plays the solution's strategy: the analysis (P2's inference), P1's policy and the
    horizon (by default the world's, or a step-bounded solution's bound). A step-bounded
    strategy's move depends on the steps taken: P1 counts them beside P2's memory."""
    checked = solution.check
    if horizon is None:
        horizon = (checked.bounded.bound if checked.bounded is not None
                   else solution.world.simulation.horizon)
    analysis, strategy = checked.player(solution.strategy)
    return analysis, strategy, horizon


def _simulation_arguments(verb: str, episodes: object, horizon: object, seed: object) -> tuple:
    """episodes, horizon and seed as the world's [simulation] allows them (None: not given)."""
    return tuple(None if value is None else _integer(verb, value, key, minimum, most)
                 for key, value, minimum, most in (("episodes", episodes, 1, MAX_EPISODES),
                                                   ("horizon", horizon, 1, MAX_HORIZON),
                                                   ("seed", seed, 0, MAX_SEED)))


def simulate(solution: Solution, *, episodes: int | None = None, horizon: int | None = None,
             seed: int | None = None) -> Simulation:
    """Play `episodes` episodes of the solution's strategy, each cut after `horizon` steps.
    What is not given comes from the world's `[simulation]` settings, as on the command line
    (by default 10,000 episodes, horizon 200, seed 0); the horizon of a step-bounded solution
    is by default its bound, whose rate then estimates its bounded value."""
    _one_type(solution, "simulate")
    from hg2prism.analyses.simulation import simulate_deceptive

    episodes, horizon, seed = _simulation_arguments("simulate", episodes, horizon, seed)
    settings = solution.world.simulation
    episodes = settings.episodes if episodes is None else episodes
    seed = settings.seed if seed is None else seed
    analysis, strategy, horizon = _played(solution, horizon)
    summary = simulate_deceptive(analysis, strategy, episodes, horizon, seed, progress=False)
    return Simulation(episodes=summary.episodes, horizon=horizon, seed=seed,
                      completed=summary.completed, failed=summary.failed,
                      truncated=summary.truncated, rate=summary.rate, ci95=tuple(summary.ci95),
                      p2_switched=summary.p2_switched / summary.episodes,
                      p2_switches_mean=summary.p2_switches / summary.episodes,
                      p2_switched_in_play=summary.p2_switched_in_play / summary.episodes)


# ---------------------------------------------------------------------------------------------
# What `run`, `robust`, `sweep` and `detect` compute beside the value (thin verbs over
# analyses/ and experiments/)
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class DeceptionValues:
    """The value of deception at the initial state (docs/semantics.md §11), as results.json of
    `hg2prism run` reports it."""

    deceptive_value: float
    v_static: float                 # P1 plans against P2's first guess, which never changes
    v_naive: float                  # P1 ignores the deception: the leader's moves, P2 inferring
    value_of_deception: float       # deceptive_value - v_naive


def deception_values(solution: Solution) -> DeceptionValues:
    """V_static, V_naive and the value of deception of a solution (what `run` adds to
    results.json)."""
    _one_type(solution, "deception_values")
    from hg2prism.analyses import deception_value

    worth = deception_value.deception_values(solution.check.analysis, solution.deceptive_value)
    return DeceptionValues(deceptive_value=solution.deceptive_value, v_static=worth.v_static,
                           v_naive=worth.v_naive, value_of_deception=worth.value_of_deception)


@dataclass(frozen=True)
class RobustValue:
    """One budget of robust deception (docs/semantics.md §13), a row of `hg2prism robust`'s
    robust.json."""

    delta: float                            # how far P2 may stray from P1's model of her
    robust_value: float                     # R_delta: P1's best guarantee against such a P2
    nominal_worst_case: float               # the deceptive strategy's worst case
    robust_strategy_nominal_value: float    # the robust strategy against the modelled P2
    states: int


def robust(solution: Solution, deltas) -> list[RobustValue]:
    """The robust value of each budget in `deltas` (numbers in [0, 1)), as `hg2prism robust`
    computes it (without Storm's cross-check); writes nothing."""
    _one_type(solution, "robust")
    from hg2prism.experiments.robust import parse_deltas, solve_budgets

    deltas = _sequence("robust", deltas, "deltas", "a list of deviation budgets in [0, 1)")
    for delta in deltas:
        _budget("robust", delta, "deltas")
    with _as_arguments("robust"):
        budgets = parse_deltas(deltas)
    with tempfile.TemporaryDirectory(prefix="hg2prism-") as scratch:
        solved = solve_budgets(solution.world, solution.check, budgets, Path(scratch),
                               storm_check=False)
    return [RobustValue(delta=r.delta, robust_value=r.robust_value,
                        nominal_worst_case=r.nominal_worst_case,
                        robust_strategy_nominal_value=r.robust_strategy_nominal_value,
                        states=r.states) for r, _ in solved]


@dataclass(frozen=True)
class SweepRow:
    """One solved point of a sweep: the swept parameters' values and the values at the
    initial state (a row of sweep.csv)."""

    point: tuple[tuple[str, object], ...]   # (parameter, value) in the sweep's order
    deceptive_value: float
    v_lead: float
    v_ne: float
    v_ne_p1_guaranteed: float
    v_ne_bounds: tuple[float, float]
    states: int
    transitions: int
    row: dict = field(repr=False, compare=False)   # the row as sweep.json holds it

    def __getitem__(self, name: str) -> object:
        """A swept parameter's value, or a column (`row["rationality"]`, sweep.csv's
        `row["v_ne_lower"]` too)."""
        from hg2prism.experiments.sweep import csv_cell

        point = dict(self.point)
        if name in point:
            return point[name]
        return self.row[name] if name in self.row else _known(csv_cell(self.row, name), name)


def _known(value: object, name: str) -> object:
    if value is None:
        raise KeyError(name)
    return value


@dataclass(frozen=True)
class SweepTable:
    """The solved points of a sweep, in grid order (the first parameter varies slowest), and
    the points that failed with their one-line reason."""

    parameters: tuple[str, ...]
    rows: tuple[SweepRow, ...]
    failed: tuple[dict, ...]

    def __iter__(self):
        return iter(self.rows)

    def __len__(self) -> int:
        return len(self.rows)

    def column(self, name: str) -> list:
        """One column: a swept parameter or a value (`table.column("deceptive_value")`), or
        a column of sweep.csv (`v_ne_lower`, `v_ne_upper`: the ends of `v_ne_bounds`)."""
        return [row[name] for row in self.rows]

    def to_csv(self, path: str | Path | None = None) -> str:
        """The table as `hg2prism sweep` writes sweep.csv (also written to `path` if given)."""
        from hg2prism.experiments.sweep import sweep_csv
        from hg2prism.outputs import write_text

        if path is not None:
            path = _out_file("to_csv", path)
        text = sweep_csv(self.parameters, [row.row for row in self.rows])
        if path is not None:
            write_text(path, text)
        return text


def sweep(world: World | str | Path, parameter: str | None = None, values=None, *,
          grid=None, storm_method: str = "sound", workers: int = 1,
          deception: bool = False) -> SweepTable:
    """Solve the world at each value of `parameter` (or at every point of `grid`, a list of
    (parameter, values) pairs), as `hg2prism sweep` does; the parameters are those of
    `hg2prism sweep --param` (inference, delay, window, threshold, prior, decision,
    rationality, traps, initial_hypothesis, tie_break, and those the world's front end, such
    as a grid's robot settings, or an observer registers).
    With `deception` (`sweep --deception`) each row also has `row["v_static"]`,
    `row["v_naive"]` and `row["value_of_deception"]`. `workers` > 1 solves the points on as
    many processes (a local Dask cluster; a script that calls it needs `if __name__ ==
    "__main__":`, as multiprocessing does). Each point's line goes to the hg2prism logger at
    INFO as it is solved. Writes nothing; a bad parameter or value raises InputError."""
    from hg2prism.experiments.sweep import sweep_grid

    storm_method = _storm_method("sweep", storm_method)
    workers = _integer("sweep", workers, "workers", 1)
    script = _unguarded_script() if workers > 1 else None
    if script is not None:
        raise InputError("sweep()", "workers", f"{script} does its work outside `if __name__ == "
                         f"\"__main__\":`, and each of the {workers} worker processes would run "
                         f"it again: put the work under that test, or pass workers=1")
    deception = _flag("sweep", deception, "deception")
    world = _world("sweep", world)
    _typed_world(world, "sweep", "sweep its prior with hg2prism sweep WORLD --param weight")
    if (grid is None) == (parameter is None):
        raise InputError("sweep()", "grid" if grid is not None else "parameter", "give a "
                         "parameter and its values, or a grid of (parameter, values) pairs")
    if grid is None:
        grid = [(parameter, _sequence("sweep", values, "values", f"a list of {parameter} values"))]
        renamed = {"--param": "parameter", "--values": "values"}
    else:
        pairs = _sequence("sweep", grid, "grid", "a list of (parameter, values) pairs")
        if not all(isinstance(pair, (tuple, list)) and len(pair) == 2 for pair in pairs):
            raise InputError("sweep()", "grid", "expected a list of (parameter, values) pairs")
        grid = [(p, _sequence("sweep", v, "grid", f"a list of {p} values")) for p, v in pairs]
        renamed = {"--param": "grid", "--values": "grid"}
    with tempfile.TemporaryDirectory(prefix="hg2prism-") as scratch, \
            _as_arguments("sweep", renamed):
        run = sweep_grid(world, grid, Path(scratch), show_progress=False,
                         storm_method=storm_method, workers=workers, deception=deception)
    names = tuple(name for name, _ in run.parameters)
    rows = tuple(SweepRow(point=tuple((n, row[n]) for n in names),
                          deceptive_value=row["deceptive_value"], v_lead=row["v_lead"],
                          v_ne=row["v_ne"], v_ne_p1_guaranteed=row["v_ne_p1_guaranteed"],
                          v_ne_bounds=tuple(row["v_ne_bounds"]), states=row["states"],
                          transitions=row["transitions"], row=row) for row in run.rows)
    return SweepTable(parameters=names, rows=rows, failed=run.failed)


def _unguarded_script() -> str | None:
    """The script this process runs when the call comes from its top level outside `if
    __name__ == "__main__":`: a worker process multiprocessing starts (Dask's, by spawning)
    runs that script again before it takes any work, and so on. None when the call comes from
    inside such a guard (at any depth of the script's statements), and for the hg2prism
    program, a package's or a folder's __main__, python -c and notebooks, which
    multiprocessing does not run again."""
    import ast

    main = sys.modules.get("__main__")
    path, spec = getattr(main, "__file__", None), getattr(main, "__spec__", None)
    if not isinstance(path, str) or (spec is not None and (
            spec.name == "__main__" or spec.name.endswith(".__main__"))):
        return None
    script = os.path.abspath(path)
    frame, line = sys._getframe(1), None
    while frame is not None:            # the script's own top level, running this call
        if frame.f_code.co_name == "<module>" and os.path.abspath(frame.f_code.co_filename) == script:
            line = frame.f_lineno
        frame = frame.f_back
    if line is None:                    # called after the script ran (python -i): not run again
        return None
    try:
        tree = ast.parse(Path(path).read_bytes())
    except (OSError, SyntaxError, ValueError):
        return None
    for node in ast.walk(tree):
        if (isinstance(node, ast.If) and node.body
                and node.body[0].lineno <= line <= (node.body[-1].end_lineno or line)
                and {"__name__", "__main__"} <= {getattr(n, "id", getattr(n, "value", None))
                                                 for n in ast.walk(node.test)}):
            return None
    return path


def detection(solution: Solution, *, episodes: int | None = None, seed: int | None = None,
              horizon: int | None = None, fallback: str | None = None,
              fallback_delta: float | None = None) -> dict:
    """Whether P2 can tell that P1's model of her is wrong (docs/semantics.md §9, §14), as
    `hg2prism detect` computes it: the content of detection.json (its `deviation`,
    `compliant` and `model_mismatch` batches; its progress, batch by batch, on the hg2prism
    logger at INFO). `episodes` default to min(the world's, 2000), seed and
    horizon to the world's; `fallback` ("robust" with `fallback_delta`, or "leader") re-plans
    on detection. Writes nothing."""
    _one_type(solution, "detection")
    from hg2prism.experiments.detect import detection_experiment, parse_fallback

    episodes, horizon, seed = _simulation_arguments("detection", episodes, horizon, seed)
    if fallback_delta is not None:
        _budget("detection", fallback_delta, "fallback_delta")
    with _as_arguments("detection"):
        parse_fallback(fallback, fallback_delta)
    # its stage reports (each batch, each re-check) go to the hg2prism logger, as `detect`
    # shows them: a run of thousands of episodes takes a while
    with tempfile.TemporaryDirectory(prefix="hg2prism-") as scratch, \
            _as_arguments("detection"):
        return detection_experiment(solution.world, solution.check, Path(scratch), episodes,
                                    seed, False, horizon, fallback, fallback_delta)


@dataclass(frozen=True)
class EpisodeStep:
    """One step of an episode (docs/semantics.md §8), everything by name."""

    n: int                                # the step, from 1
    state: str                            # the arena state P1 moved from (a cell: "x2_y4")
    move: str                             # the action P1 chose, by name
    realised: str                         # what happened, as the world's front end names the
    #                                       outcome (a grid: the direction he went), else "outcome k"
    landing: str                          # the state reached ("trapped" when trapped)
    traps: tuple[str, ...]                # the states P2's trap set covered
    p2_action: str                        # P2's action by name
    hypothesis: int                       # the hypothesis P2 acted on during the step (drawn,
    #                                       with the Bayesian "sample" decision)
    belief: tuple[float, ...] | None      # her observer's numbers per hypothesis (CUSUM
    #                                       scores, Bayesian posteriors) after observing the
    #                                       step, None if unreported
    trapped: bool
    hypothesis_after: int                 # hers after observing the step (the figures'
    #                                       "hypothesis at step n"); another: she changed her mind


@dataclass(frozen=True)
class Episode:
    """One episode of the solution's strategy against P2's inference."""

    seed: int
    outcome: str                          # "task completed", "failed" or "cut by the horizon"
    steps: tuple[EpisodeStep, ...]
    belief_name: str | None               # what EpisodeStep.belief is ("CUSUM score Z_x")
    threshold: float | None               # where P2 changes her mind, if her rule has one
    drawn: object = field(repr=False, compare=False)   # analyses.episodes.ChosenEpisode
    made_for: tuple = field(default=(), repr=False, compare=False)  # _episode_key of its Solution

    def __len__(self) -> int:
        return len(self.steps)

    def __iter__(self):
        return iter(self.steps)

    def __getitem__(self, index):
        return self.steps[index]


def _realised(world: World, step) -> str:
    from hg2prism.frontends import outcome_name

    return outcome_name(world, step.action_name, step.outcome)


def episode(solution: Solution, seed: int | None = None, *, horizon: int | None = None
            ) -> Episode:
    """The episode of seed `seed` (by default the world's simulation seed) of the solution's
    strategy, cut after `horizon` steps (by default as `simulate`): what `hg2prism run --episode
    seed=N` draws, step by step."""
    _one_type(solution, "episode")
    from hg2prism.analyses.episodes import belief_trace, choose_episode, episode_steps

    _, horizon, seed = _simulation_arguments("episode", None, horizon, seed)
    seed = solution.world.simulation.seed if seed is None else seed
    analysis, strategy, horizon = _played(solution, horizon)
    drawn = choose_episode(analysis, strategy, horizon, seed, f"seed={seed}")
    ts = solution.check.analysis.ts
    names = ts.arena.states
    trace = belief_trace(solution.check.analysis.inference, drawn.steps)
    steps = tuple(EpisodeStep(
        n=step.n, state=names[step.start], move=step.action_name,
        realised=_realised(solution.world, step),
        landing="trapped" if step.trapped else names[step.landing],
        traps=tuple(names[t] for t in step.traps), p2_action=step.p2_action_name,
        hypothesis=trace.acted[i], trapped=step.trapped, hypothesis_after=trace.after[i],
        belief=trace.values[i] if trace.values is not None else None)
        for i, step in enumerate(episode_steps(ts, drawn.steps)))
    return Episode(seed=drawn.seed, outcome=drawn.outcome, steps=steps,
                   made_for=_episode_key(solution),
                   belief_name=trace.name, threshold=trace.threshold, drawn=drawn)


# ---------------------------------------------------------------------------------------------
# Figures: each draws into the matplotlib Axes given (or a new figure's) and returns them
# ---------------------------------------------------------------------------------------------

def _episode_key(solution: Solution) -> tuple:
    """What an episode's states and hypotheses are numbered by: its world and hypergame."""
    analysis = solution.check.analysis
    return (analysis.world.name, analysis.ts.n_states, analysis.world.hypotheses,
            analysis.world.inference)


def _played_episode(solution: Solution, played: object, verb: str) -> Episode:
    """The episode a figure draws: `played`, or by default the world's seed's."""
    if played is None:
        return episode(solution)
    if not isinstance(played, Episode):
        raise InputError(f"{verb}()", "played", "expected an Episode (what hg2prism.episode "
                         f"returns), got {type(played).__name__}")
    if played.made_for != _episode_key(solution):
        raise InputError(f"{verb}()", "played", "is an episode of another world or hypergame "
                         f"({played.made_for[0]!r}); draw it with the Solution it came from")
    return played


def draw_world(solution: Solution, played: Episode | None = None, *, ax=None):
    """The world and one episode (by default the world's seed's), as `run`'s world figure."""
    from hg2prism.report import plots

    from hg2prism.analyses.episodes import belief_trace

    _one_type(solution, "draw_world")
    played = _played_episode(solution, played, "draw_world")
    ts = solution.check.analysis.ts
    ax = _axes(ax, "draw_world", lambda: plots.world_figure_inches(solution.world, ts))
    trace = belief_trace(solution.check.analysis.inference, played.drawn.steps)
    plots.world_figure(solution.world, ts, played.drawn, trace, None, ax=ax)
    return ax


def draw_belief(solution: Solution, played: Episode | None = None, *, ax=None):
    """P2's belief along an episode (by default the world's seed's), as `run`'s belief
    figure."""
    from hg2prism.analyses.episodes import belief_trace
    from hg2prism.report import plots

    _one_type(solution, "draw_belief")
    played = _played_episode(solution, played, "draw_belief")
    ax = _axes(ax, "draw_belief", lambda: plots.BELIEF_INCHES)
    trace = belief_trace(solution.check.analysis.inference, played.drawn.steps)
    plots.belief_figure(solution.world, trace, played.drawn, None, ax=ax)
    return ax


def draw_sweep(table: SweepTable, *, ax=None, world_name: str | None = None):
    """A sweep's values against its (first) parameter, as `hg2prism sweep`'s figure."""
    from hg2prism.report import plots

    if not isinstance(table, SweepTable):
        raise InputError("draw_sweep()", "table", "expected a SweepTable (what hg2prism.sweep "
                         f"returns), got {type(table).__name__}")
    ax = _axes(ax, "draw_sweep", lambda: plots.SWEEP_INCHES)
    rows = [row.row for row in table.rows]
    if len(table.parameters) == 1:
        plots.sweep_figure(table.parameters[0], rows, None, world_name, ax=ax)
    else:
        plots.sweep_grid_figure(list(table.parameters), rows, None, world_name, ax=ax)
    return ax


def _axes(ax: object, verb: str, inches):
    """The Axes a figure draws into: `ax`, which must be a matplotlib Axes, or a new figure's
    of the size `inches()`."""
    from matplotlib.axes import Axes
    import matplotlib.pyplot as plt

    if ax is None:
        return plt.figure(figsize=inches(), layout="constrained").add_subplot()
    if not isinstance(ax, Axes):
        raise InputError(f"{verb}()", "ax", "expected a matplotlib Axes (or None for a new "
                         f"figure), got {type(ax).__name__}")
    return ax
