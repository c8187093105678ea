"""The adaptive hypergame of docs/semantics.md §16 as a structured PRISM model
(templates/adaptive.prism.j2): P2's type is unknown to P1, who keeps the set of types still
consistent with the actions P2 played and every consistent type's memory.

Components, so that the commands grow with the types, the hypotheses and the outcomes, never
with the product:

  robot            place, alive_t<k> (type k still consistent) and, with delay, P2's standing
                   action and countdown: per action slot one command whose outcomes are (the
                   hypothesis x whose action P2 plays, the arena's outcome under it). The group of
                   consistent types playing act_x has probability mass_x / mass_all (carried by
                   the first hypothesis with that action: pr_x), and the types that play another
                   action stop being consistent.
  task             q, as in the hypergame (prism/hypergame.py)
  p2_inference_t<k> type k's memory: its observer's module (prism/observers.py, the renderer its
                   kind registers) with every name it defines suffixed _t<k>; it records the
                   action type k plays (a2_t<k>), which is the action played whenever type k is
                   still consistent.

The POMDP form (`hidden`): the type is a variable `type` drawn at the first step (the label
`draw`), P2 plays a2_t<type>, the robot records it in `played`, and every variable but `type`
is observable.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.model.world import World
from hg2prism.opponent.observer import Observer
from hg2prism.opponent.perceptual_games import PerceptualGame
from hg2prism.opponent.registry import observer_kind
from hg2prism.prism.arena_tables import InForce, p2_choices
from hg2prism.engines.engine import BuiltModel
from hg2prism.prism.hypergame import PROPERTY, Layout, count_commands, template_context
from hg2prism.prism.observers import ts_state_expression
from hg2prism.prism.rendering import cases, prism_number, render_template

# PRISM's POMDP engine (its fixed-resolution grid approximation, `-gridresolution`): on world4
# resolution 2 gives the same lower bound as PRISM's default 10 and a tighter upper one, in
# 10 s instead of 49 s (docs/adaptive.md); a coarser grid (1) is far looser. The POMDP's header
# gives the command with it; experiments/adaptive.py runs it so.
PRISM_RESOLUTION = 2

__all__ = ["AdaptiveModel", "TypeModel", "build_adaptive_model", "rename", "type_view"]

_DEFINED = re.compile(r"^\s*formula\s+(\w+)\s*=", re.MULTILINE)
_VARIABLE = re.compile(r"^\s*(\w+)\s*:\s*(?:\[|bool)", re.MULTILINE)


@dataclass(frozen=True)
class TypeModel:
    """One type of P2 as the model needs it: its name, weight and first guess, its observer
    (built on its own perceptual games: its rationality) and their games."""

    name: str
    weight: float
    rationality: float
    observer: Observer
    games: tuple[PerceptualGame, ...]


@dataclass(frozen=True)
class AdaptiveModel:
    text: str
    properties: str
    commands: dict[str, int]
    memory_variables: tuple[tuple[str, ...], ...]   # per type, its memory's variables (suffixed)
    # per type, how its memory is encoded, in its observer's own names (prism/hypergame.py);
    # `type_view` reads the model's state variables in those names
    layouts: tuple[Layout, ...] = ()


def type_view(model: BuiltModel, k: int, layout: Layout) -> BuiltModel:
    """The built adaptive model seen as type k's hypergame: its memory variables under their
    observer's names (hyp, o<i>_...), the shared ones (place, q, traps, countdown) as they are."""
    own = {name for i in range(1, layout.slots + 1) for name in layout.slot_variables(i)}
    own.add("hyp")

    def read(name: str):
        return model.read_variable(f"{name}_t{k}" if name in own else name)

    return BuiltModel(model.n_states, model.initial, model.transitions, read)


def rename(text: str, names: set[str], suffix: str, extra: dict[str, str]) -> str:
    """`text` with every identifier in `names` suffixed and those in `extra` replaced."""
    table = {name: name + suffix for name in names}
    table.update(extra)
    if not table:
        return text
    pattern = re.compile(r"\b(" + "|".join(sorted(map(re.escape, table), key=len,
                                                      reverse=True)) + r")\b")
    return pattern.sub(lambda m: table[m.group(1)], text)


def _type_parts(k: int, t: TypeModel, ts: TransitionSystem, labels: dict[int, str],
                observed: np.ndarray) -> dict:
    """Type k's observer part, its names suffixed _t<k> (ts_state shared, written once)."""
    part = observer_kind(t.observer.kind).render(t.observer, ts, labels, observed, None)
    if part.robot:
        raise ValueError(f"type {t.name}: its observer draws its hypothesis (decision "
                         "\"sample\"), which a type may not (docs/semantics.md §16)")
    formulas = re.sub(r"^formula ts_state = .*;\n?", "", part.formulas, flags=re.MULTILINE)
    defined = set(_DEFINED.findall(formulas)) | set(_VARIABLE.findall(part.module))
    extra = {"p2_inference": f"p2_inference_t{k}", "trap_set": f"a2_t{k}"}
    suffix = f"_t{k}"
    header = part.header.replace("// inference", "//").strip()
    return dict(name=t.name, weight=t.weight, rationality=t.rationality,
                initial_hypothesis=t.observer.initial_hypothesis,
                header="// " + header.lstrip("/ "),
                formulas=rename(formulas, defined, suffix, extra),
                module=rename(part.module, defined, suffix, extra),
                variables=tuple(sorted(name + suffix for name in _VARIABLE.findall(part.module))),
                hypothesis=("hyp" + suffix) if part.hypothesis_variable else None,
                slots=part.slots, slot_sets=part.slot_sets)


def _type_action(n_x: int, hypothesis: str | None, delay: bool) -> str:
    """a2_t<k>: the action type k plays, act_x for its hypothesis."""
    if hypothesis is None:
        raise ValueError("a type's observer must keep its hypothesis in a variable")
    return cases([(f"{hypothesis}={x}", f"act_x{x}") for x in range(n_x - 1)], f"act_x{n_x - 1}")


def build_adaptive_model(world: World, ts: TransitionSystem, task: DFA,
                         types: list[TypeModel], hidden: bool = False) -> AdaptiveModel:
    """The adaptive hypergame's PRISM text (an `mdp`; with `hidden` the `pomdp` of §16)."""
    games = list(types[0].games)
    n_x = len(games)
    context = template_context(world, ts, task, games, types[0].observer)
    labels = context["labels"]
    observed = ts.reachable(np.array([g.trap_choice for g in games]))[:-1]
    force = InForce(ts, context["tables"], *p2_choices(
        ts, np.array([g.trap_choice for g in games]), observed), selector=False)
    parts = [_type_parts(k, t, ts, labels, observed) for k, t in enumerate(types)]
    n = len(types)
    weight = [prism_number(t.weight) for t in types]
    mass_all = "+".join(f"(alive_t{k}=1 ? {weight[k]} : 0)" for k in range(n))
    mass = ["+".join(f"(alive_t{k}=1 & a2_t{k}=act_x{x} ? {weight[k]} : 0)" for k in range(n))
            for x in range(n_x)]
    representative = []
    for x in range(n_x):
        earlier = [f"!(act_x{y}=act_x{x} & mass_x{y}>0)" for y in range(x)]
        representative.append("(" + " & ".join([f"mass_x{x}>0"] + earlier) + ")")
    if hidden:
        now = cases([(f"type={k}", f"a2_t{k}") for k in range(n - 1)], f"a2_t{n - 1}")
        chosen = [f"(({now})=act_x{x}" + "".join(f" & !(({now})=act_x{y})" for y in range(x))
                  + " ? 1 : 0)" for x in range(n_x)]
    commands = []
    for slot in context["tables"].slots:
        guard = "!stop" + (f" & {slot.guard}" if slot.guard else "")
        # (mass_all>0 holds wherever the robot can be; PRISM checks that the probabilities
        # sum to 1 in every state the guard allows, reachable or not)
        guard += " & type>=0" if hidden else " & mass_all>0"
        outcomes = []
        for x in range(n_x):
            update_p2 = [f"(played'=act_x{x})"] if hidden else [
                f"(alive_t{k}'=(alive_t{k}=1 & a2_t{k}=act_x{x}) ? 1 : 0)" for k in range(n)]
            if ts.delay:
                update_p2 += [f"(traps'=act_x{x})",
                              f"(countdown'=(act_x{x}!=traps) ? {ts.delay} : max(countdown-1, 0))"]
            drawn = chosen[x] if hidden else f"pr_x{x}"
            for o in slot.outcomes:
                outcomes.append((f"{drawn}*{force.prob(o, x)}",
                                 " & ".join([force.update(o, x)] + update_p2)))
        commands.append(dict(label=slot.label, guard=guard, outcomes=outcomes))
    observables = []
    if hidden:
        observables = (["drawn", "place", "played", "q"] + (["traps", "countdown"] if ts.delay else [])
                       + [v for part in parts for v in part["variables"]])
    text = render_template(
        "adaptive.prism.j2", **{**context, "force": force}, types=parts,
        ts_state=ts_state_expression(ts), robot_commands=commands,
        type_action=[_type_action(n_x, part["hypothesis"], bool(ts.delay)) for part in parts],
        mass_all=mass_all, mass=mass, representative=representative, hidden=hidden,
        model_type="pomdp" if hidden else "mdp", observables=observables,
        resolution=PRISM_RESOLUTION, property=PROPERTY,
        drawn=[k for k, t in enumerate(types) if t.weight > 0])
    properties = f"// adaptive hypergame (docs/semantics.md §16)\n{PROPERTY}\n"
    initial = Layout.initial_values(text)
    layouts = []
    for k, part in enumerate(parts):
        suffix = f"_t{k}"
        layouts.append(Layout(
            slots=part["slots"], delay=ts.delay, slot_sets=part["slot_sets"],
            hypothesis_variable=part["hypothesis"] is not None,
            initial=tuple((name.removesuffix(suffix), value) for name, value in initial
                          if name.endswith(suffix) or not re.search(r"_t\d+$", name))))
    return AdaptiveModel(text=text, properties=properties, commands=count_commands(text),
                         memory_variables=tuple(part["variables"] for part in parts),
                         layouts=tuple(layouts))
