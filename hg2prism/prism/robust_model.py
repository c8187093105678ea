"""The robust hypergame of docs/semantics.md §13 as an interval MDP in the PRISM language.

The hypergame MDP of docs/semantics.md §6 with P2's choice made uncertain: each step takes
two transitions. P1's action leads to an intermediate state that records the slot and P2's
action played, with probability intervals [1-delta, 1] for the predicted action and [eps, delta]
for every other action P2 may play (none where she has a single one); P1's action then takes
effect under the action played, and the task DFA, P2's standing action and her inference
advance as in the hypergame.
P1 maximises, the resolution of the intervals minimises: PRISM's `Pmaxmin=? [F "goal"]`.

The model of §13 has eps = 0. PRISM and Storm read it (Storm's interval builder, PRISM as an
IMDP) but check interval models only when every lower bound is positive, so `eps` is a
constant the file leaves undefined: hg2prism builds it with eps = 0 (`EXACT_CONSTANTS`), the
cross-checks, and PRISM or Storm on the command line, with eps = 1e-9 (`CHECK_CONSTANTS`; `prism
robust.prism robust.props -const eps=1e-9 -ex -epsilon 1e-12`): a slightly weaker adversary, a value at least
R_delta.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hg2prism.errors import InputError
from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.model.world import World
from hg2prism.opponent.observer import Observer
from hg2prism.opponent.perceptual_games import PerceptualGame
from hg2prism.prism.hypergame import (Layout, PrismModel, count_commands, slot_labels,
                                      template_context)
from hg2prism.prism.rendering import prism_number, render_template

# PRISM's property: P1 maximises, the interval resolution (P2's deviation) minimises.
PRISM_PROPERTY = 'Pmaxmin=? [F "goal"]'
# Storm's: the same formula, checked with uncertainty resolution ROBUST (the adversary opposes P1).
STORM_PROPERTY = 'Pmax=? [F "goal"]'
# Labels of the second transition of a step (P1's action taking effect under P2's action
# played) are step_a<i>; P1's choices keep the hypergame's labels a<i>, so that decoding Storm's
# choices reads the same slots (and step_a<i> reads as no slot).
STEP_PREFIX = "step_"
# Smallest lower bound PRISM and Storm accept for a deviation (docs/semantics.md §13), and the
# definitions of the model's constant eps for the exact model and for the cross-checks.
CHECK_EPS = 1e-9
EXACT_CONSTANTS = "eps=0"
CHECK_CONSTANTS = f"eps={CHECK_EPS!r}"
# Names of the variables that tell an intermediate state (move >= 0) from one where P1 chooses.
MOVE_VARIABLE, PLAYED_VARIABLE = "move", "played"


@dataclass(frozen=True)
class RobustModel:
    """The interval model of one deviation budget."""

    prism: PrismModel
    delta: float


def delta_text(delta: float) -> str:
    """How a budget is written in file and folder names: 0, 0.02, 0.1 (shortest decimal), or
    1e-30 where that decimal would be long (a name must stay short enough for the system)."""
    text = prism_number(float(delta))
    text = text[:-2] if text.endswith(".0") else text
    return text if len(text) <= 12 else repr(float(delta))


def checkable_constants(delta: float, ts: TransitionSystem) -> str:
    """The definition of eps a checker can be given for budget `delta`: CHECK_CONSTANTS, or,
    for a budget below CHECK_EPS for each of P2's other actions, eps = delta / |A2|, so that
    the lower bounds of a step (1 - delta, and eps for each other action) sum to less than 1
    whatever the rounding (with CHECK_EPS they would exceed 1)."""
    if 0 < delta < CHECK_EPS * (ts.n_sets - 1):
        return f"eps={delta / ts.n_sets!r}"
    return CHECK_CONSTANTS


def refuse_drawing(world: World, inference: Observer) -> None:
    """InputError when P2 draws her hypothesis: the interval model is defined for an observer
    that plays one (docs/semantics.md §13)."""
    if inference.draws:
        raise InputError(str(world.path), "inference.decision",
                         'robust deception (docs/semantics.md §13) is defined here for a '
                         'Bayesian observer that plays her MAP hypothesis ("map"), not one that '
                         'draws it ("sample")')


def build_robust_model(world: World, ts: TransitionSystem, task: DFA,
                       games: list[PerceptualGame], inference: Observer, delta: float
                       ) -> RobustModel:
    """The interval model of docs/semantics.md §13 for budget `delta` (0 <= delta < 1), its
    constant eps undefined: every off-prediction set where P2 may deviate gets at least
    min(eps, delta) (0 for the model itself, `EXACT_CONSTANTS`; positive for PRISM and Storm's
    checks, which need positive lower bounds, `CHECK_CONSTANTS`)."""
    if not 0.0 <= delta < 1.0:
        raise ValueError(f"delta must lie in [0, 1), got {delta}")
    refuse_drawing(world, inference)
    context = template_context(world, ts, task, games, inference, played=PLAYED_VARIABLE,
                               observer_prefix=STEP_PREFIX)
    if ts.n_sets == 1:
        deviation = "0"              # nothing to deviate to
    elif ts.delay:
        deviation = "countdown>0 ? 0 : delta"
    else:
        deviation = "delta"
    text = render_template(
        "robust.prism.j2", **context, step_labels=slot_labels(context["tables"], STEP_PREFIX),
        deviation=deviation,
        delta_text=prism_number(float(delta)), check_constants=checkable_constants(delta, ts),
        property=PRISM_PROPERTY)
    prism = PrismModel(text=text, properties=PRISM_PROPERTY + "\n",
                       layout=Layout(slots=context["observer"].slots, delay=ts.delay,
                                     slot_sets=context["observer"].slot_sets,
                                     hypothesis_variable=context["observer"].hypothesis_variable,
                                     initial=Layout.initial_values(text)),
                       commands=count_commands(text))
    return RobustModel(prism=prism, delta=float(delta))


def write_robust_model(model: RobustModel, folder: Path) -> tuple[Path, Path]:
    """folder/robust.prism and folder/robust.props."""
    from hg2prism.outputs import write_text

    prism, props = folder / "robust.prism", folder / "robust.props"
    write_text(prism, model.prism.text)
    write_text(props, model.prism.properties)
    return prism, props
