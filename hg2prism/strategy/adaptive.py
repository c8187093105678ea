"""P1's adaptive strategy (docs/semantics.md §16) from the engine's adaptive model: its states
read as adaptive hypergame states (v, q, C, memories of C), the canonical MDP over them, the
deceptive strategy's rule (value first, then speed: strategy/deceptive.py), and its records.

Each type's memory is decoded by prism/decoding.py on the model seen as that type's hypergame
(prism/adaptive.type_view); a canonical state is (v, q, C) with the memories of the types of C
only (a type no longer consistent keeps updating its variables in the model, which does not
matter to anything).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from hg2prism.engines.engine import BuiltModel
from hg2prism.model.automata import DFA
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.prism.adaptive import AdaptiveModel, type_view
from hg2prism.prism.decoding import DecodedStates, canonical_size, decode_states, row_keys
from hg2prism.strategy.canonical import canonical_mdp, canonical_values
from hg2prism.strategy.deceptive import deceptive_actions, storm_choices
from hg2prism.strategy.records import RecordExtras, frozen, start_first, strategy_records

__all__ = ["AdaptiveStrategy", "AdaptiveStates", "adaptive_strategy", "decode_adaptive"]


@dataclass(frozen=True, eq=False)
class AdaptiveStrategy:
    records: list[dict]          # strategy.json's content
    size: tuple[int, int]        # canonical states and transitions
    states: AdaptiveStates | None = None   # the engine's states decoded


@dataclass(frozen=True, eq=False)
class AdaptiveStates:
    """The engine's states as adaptive hypergame states (docs/semantics.md §16): each type's
    decoded memory (`per_type`, prism/decoding.py on the model seen as that type's hypergame),
    which types are still consistent (`alive` [n, types]), and `joint`, the decoded states of
    the first type numbered canonically as (v, q, C, memories of C)."""

    per_type: tuple[DecodedStates, ...]
    alive: np.ndarray
    joint: DecodedStates

    def keys(self, ts: TransitionSystem) -> list:
        """Per engine state its key as analyses/adaptive.AdaptiveGame writes it: (v, q, C,
        memories of C) with each memory an observer's Memory, or "goal" / "fail"."""
        base, n = self.joint, len(self.alive)
        v = base.ts_states(ts).tolist()
        q = base.q.tolist()
        memories = [d.memories() for d in self.per_type]
        keys = []
        for s in range(n):
            if base.goal[s] or base.fail[s]:
                keys.append("goal" if base.goal[s] else "fail")
                continue
            types = tuple(np.flatnonzero(self.alive[s]).tolist())
            keys.append((v[s], q[s], types, tuple(memories[k][s] for k in types)))
        return keys


def decode_adaptive(model: BuiltModel, adaptive: AdaptiveModel, ts: TransitionSystem,
                    task: DFA, weights: Sequence[float],
                    window_hypotheses: Sequence[Callable | None]) -> AdaptiveStates:
    """The engine's states of the adaptive model read as adaptive hypergame states."""
    n_types = len(weights)
    decoded = [decode_states(type_view(model, k, adaptive.layouts[k]), adaptive.layouts[k], ts,
                             task, window_hypotheses[k]) for k in range(n_types)]
    alive = np.stack([model.variable(f"alive_t{k}", int(weights[k] > 0))
                      for k in range(n_types)], axis=1).astype(bool)
    base = decoded[0]
    columns = [base.place, base.traps, base.countdown, base.q, alive.astype(np.int64)]
    for k, d in enumerate(decoded):
        memory = np.column_stack([d.hypothesis, d.window.reshape(len(d.hypothesis), -1)])
        columns.append(np.where(alive[:, k:k + 1], memory, -1))
    key = np.column_stack(columns)
    key[base.goal] = -2
    key[base.fail] = -3
    canonical = row_keys(key)
    joint = dataclasses.replace(base, canonical=canonical,
                                n_canonical=int(canonical.max()) + 1 if canonical.size else 0)
    return AdaptiveStates(tuple(decoded), alive, joint)


def adaptive_strategy(model: BuiltModel, values: np.ndarray, adaptive: AdaptiveModel,
                      ts: TransitionSystem, task: DFA, names: Sequence[str],
                      weights: Sequence[float],
                      window_hypotheses: Sequence[Callable | None]) -> AdaptiveStrategy:
    """The adaptive strategy's records: per reachable non-absorbing canonical state, the
    state, q, `types` (the consistent types, each with its belief share, hypothesis and
    window) and the action (with `values`, each action's value)."""
    n_types = len(names)
    states_of = decode_adaptive(model, adaptive, ts, task, weights, window_hypotheses)
    decoded, alive, joint = states_of.per_type, states_of.alive, states_of.joint
    base, canonical = joint, joint.canonical
    moves = model.transitions
    mdp = canonical_mdp(joint, moves, ts.n_actions)
    state_values = canonical_values(joint, values)
    action = deceptive_actions(mdp, state_values)
    choices = storm_choices(joint, moves, mdp.representative, action)
    extras = RecordExtras(mdp.by_state(mdp.choice_values(state_values)))
    per_type = [strategy_records(_joint(d, joint), choices, moves, ts, None, model.initial)
                for d in decoded]
    states = _states_written(joint, choices, model.initial)
    records = []
    for i, record in enumerate(per_type[0]):
        s = states[i]
        consistent = [k for k in range(n_types) if alive[s, k]]
        total = sum(weights[k] for k in consistent)
        merged = {key: value for key, value in record.items()
                  if key not in ("hypothesis", "window", "action")}
        merged["types"] = {names[k]: {"belief": weights[k] / total,
                                      "hypothesis": per_type[k][i]["hypothesis"],
                                      "window": per_type[k][i]["window"]}
                           for k in consistent}
        merged["action"] = record["action"]
        v = ts.state(int(base.place[s]), int(base.traps[s]), int(base.countdown[s]))
        merged.update(extras.fields(int(canonical[s]), ts.action_names(v)))
        records.append(frozen(merged))
    return AdaptiveStrategy(records, canonical_size(joint, moves), states_of)


def _joint(decoded: DecodedStates, joint: DecodedStates) -> DecodedStates:
    """A type's decoded states numbered as the adaptive hypergame's canonical states."""
    return dataclasses.replace(decoded, canonical=joint.canonical, n_canonical=joint.n_canonical)


def _states_written(joint: DecodedStates, choices, initial: int) -> list[int]:
    """The engine states strategy_records writes, in its order."""
    states, _ = start_first(joint, choices, initial)
    return states.tolist()
