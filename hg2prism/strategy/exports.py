"""P1's strategy in standard forms (docs/semantics.md §6 "Exports"): the DTMC it induces on the
hypergame, written in PRISM's explicit format (induced.tra, induced.sta, induced.lab) and in
Storm's DRN format (induced.drn), and the expected numbers of steps read off that DTMC.

State numbering: for a stationary strategy, state 0 is the initial state, then come the other
records of strategy.json (the non-absorbing canonical states) in the file's order, then one
state `goal` and one state `fail`. The initial state comes first because PRISM's default
(symbolic) engine takes state 0 as the initial state of an imported model, whatever the
"init" label says. For the step-bounded objective the strategy depends on the number of steps taken,
so the DTMC's states are pairs (record, t) reachable from (initial state, 0), t < H, in
breadth-first order, then `goal`, `fail` and `horizon` (H steps taken without reaching either).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hg2prism import numeric
from hg2prism.prism.decoding import DecodedStates
from hg2prism.prism.rendering import probability_text
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.numeric import ExplicitModel, Steps
from hg2prism.strategy.canonical import CanonicalMDP
from hg2prism.strategy.columns import (Field, Lines, Vocabulary, integers, literal,
                                       grouped_chunks, tokens)

ABSENT = -1     # the value of a state variable that does not apply (an empty window slot)
# Every variable of the merged absorbing states takes one of these values, so that no two states
# share a valuation (PRISM's symbolic engine identifies states by their valuations).
GOAL_VALUE, FAIL_VALUE, HORIZON_VALUE = -1, -2, -3


@dataclass(frozen=True, eq=False)
class InducedDTMC:
    """A DTMC with integer state variables, labels and, per state, P1's move (-1: absorbing)."""

    variables: tuple[str, ...]
    valuations: np.ndarray        # [n, variables] int
    chain: ExplicitModel          # one choice per state, its successors sorted, merged
    initial: int
    labels: dict[str, np.ndarray]  # label name -> [n] bool ("goal", "fail", ...; not "init")
    action: np.ndarray            # [n] P1's action slot, -1 in absorbing states
    place: np.ndarray | None = None   # [n] the arena state of each state (-1 in absorbing ones)
    arena_actions: tuple[tuple[str, ...], ...] = ()   # P1's action names per arena state

    def action_names(self) -> tuple[list[str], np.ndarray]:
        """P1's action in each state by name: the names and each state's code into them
        ("absorbing" in absorbing states; "a<slot>" without the arena's names)."""
        width = int(self.action.max(initial=0)) + 1
        if self.arena_actions and self.place is not None:
            width = max(width, max(len(a) for a in self.arena_actions))
            names = [a[k] if k < len(a) else "" for a in self.arena_actions for k in range(width)]
            code = np.where(self.action >= 0, self.place * width + self.action, len(names))
        else:
            names = [f"a{k}" for k in range(width)]
            code = np.where(self.action >= 0, self.action, width)
        return names + ["absorbing"], code

    @property
    def n(self) -> int:
        return len(self.valuations)

    @functools.cached_property
    def source(self) -> np.ndarray:
        """The transitions' sources, sorted (then by target: `target`, `probability`)."""
        return np.repeat(np.arange(self.n, dtype=self.chain.matrix.indices.dtype),
                         np.diff(self.chain.matrix.indptr))

    @property
    def target(self) -> np.ndarray:
        return self.chain.matrix.indices

    @property
    def probability(self) -> np.ndarray:
        return self.chain.matrix.data

    @functools.cached_property
    def numbers(self) -> Field:
        """The state numbers 0..n-1 as a text column (the writers below share it)."""
        return integers(np.arange(self.n))

    @functools.cached_property
    def probabilities(self) -> Field:
        """The transitions' probabilities as a text column (their short decimals:
        prism/rendering.py:probability_text)."""
        return tokens(self.probability, probability_text)


def _valuations(mdp: CanonicalMDP, decoded: DecodedStates, ts: TransitionSystem,
                states: np.ndarray) -> tuple[tuple[str, ...], np.ndarray]:
    """State variables of canonical states: the arena state s (its number in the arena's
    order), P2's standing action and the countdown (delay > 0), the DFA state q, P2's
    hypothesis and her window slots o1 (oldest).., each slot's TS state as s[, standing,
    countdown] and P1's action there (its slot: the arena's order of the state's actions), and
    for the Bayesian observer P2's action in force there (`played`: two states may differ in it
    alone, and no two states may share a valuation)."""
    storm = mdp.representative[states]
    delayed = ts.delay > 0

    def ts_columns(ts_state: np.ndarray, prefix: str) -> tuple[list[str], list[np.ndarray]]:
        present = ts_state >= 0
        safe = np.where(present, ts_state, 0)
        if delayed:
            place, rest = np.divmod(safe, ts.n_sets * ts.phases)
            standing, countdown = np.divmod(rest, ts.phases)
        else:
            place = safe
        names = [f"{prefix}s"] + ([f"{prefix}standing", f"{prefix}countdown"]
                                  if delayed else [])
        cols = [place] + ([standing, countdown] if delayed else [])
        return names, [np.where(present, c, ABSENT) for c in cols]

    place = decoded.place[storm]
    here = np.where(place < ts.n_places,
                    ts.state(np.minimum(place, ts.n_places - 1), decoded.traps[storm],
                             decoded.countdown[storm]), -1)
    names, columns = ts_columns(here, "")
    names += ["q", "hyp"]
    columns += [decoded.q[storm], decoded.hypothesis[storm]]
    played = decoded.window.shape[2] > 2
    for i in range(decoded.window.shape[1]):
        slot = decoded.window[storm, i]
        slot_names, slot_columns = ts_columns(slot[:, 0], f"o{i + 1}_")
        names += slot_names + [f"o{i + 1}_act"] + ([f"o{i + 1}_played"] if played else [])
        columns += slot_columns + [np.where(slot[:, 0] >= 0, slot[:, 1], ABSENT)]
        if played:
            columns.append(np.where(slot[:, 0] >= 0, slot[:, 2], ABSENT))
    return tuple(names), np.column_stack(columns).astype(np.int64)


def _places(mdp: CanonicalMDP, decoded: DecodedStates, states: np.ndarray) -> np.ndarray:
    """The arena state of canonical states (none is absorbing)."""
    return decoded.place[mdp.representative[states]].astype(np.int64)


def _chain(source: np.ndarray, target: np.ndarray, probability: np.ndarray, n: int
           ) -> ExplicitModel:
    """The DTMC's transitions as a chain, each state's successors sorted and equal pairs'
    probabilities summed."""
    matrix = sp.coo_matrix((probability, (source, target)), shape=(n, n)).tocsr()
    matrix.sum_duplicates()
    matrix.sort_indices()
    return ExplicitModel(matrix=matrix, group_start=np.arange(n + 1))


def stationary_dtmc(mdp: CanonicalMDP, action: np.ndarray, decoded: DecodedStates,
                    ts: TransitionSystem, initial: int) -> InducedDTMC:
    """The DTMC a memoryless strategy (`action[s]`: a move for every non-absorbing canonical
    state s) induces: the initial state, the other records in strategy.json's order, then goal
    and fail."""
    live = np.flatnonzero(~mdp.absorbing)                 # strategy.json's order ...
    live = np.r_[live[live == initial], live[live != initial]]   # ... the initial state first
    n_live = len(live)
    goal_id, fail_id = n_live, n_live + 1
    index = np.full(mdp.n, -1, dtype=np.int32 if n_live + 2 < 2 ** 31 else np.int64)
    index[live] = np.arange(n_live)
    index[mdp.goal] = goal_id
    index[mdp.fail] = fail_id
    chosen = mdp.choice_action == action[mdp.choice_state]
    taken = np.flatnonzero(chosen[mdp.entry_choice])
    del chosen
    loops = np.array([goal_id, fail_id], dtype=index.dtype)
    source = np.concatenate([index[mdp.choice_state[mdp.entry_choice[taken]]], loops])
    target = np.concatenate([index[mdp.entry_target[taken]], loops])
    probability = np.r_[mdp.entry_prob[taken], 1.0, 1.0]
    del taken
    names, values = _valuations(mdp, decoded, ts, live)
    values = np.vstack([values, np.full((1, len(names)), GOAL_VALUE, dtype=np.int64),
                        np.full((1, len(names)), FAIL_VALUE, dtype=np.int64)])
    labels = {"goal": np.arange(n_live + 2) == goal_id, "fail": np.arange(n_live + 2) == fail_id}
    return InducedDTMC(variables=names, valuations=values,
                       chain=_chain(source, target, probability, n_live + 2),
                       initial=int(index[initial]),
                       labels=labels, action=np.r_[action[live], -1, -1],
                       place=np.r_[_places(mdp, decoded, live), -1, -1],
                       arena_actions=ts.arena.actions)


def unfolded_dtmc(mdp: CanonicalMDP, action_at: Callable[[int], np.ndarray],
                  decoded: DecodedStates, ts: TransitionSystem, initial: int,
                  horizon: int, max_states: int) -> InducedDTMC:
    """The DTMC a step-dependent strategy induces over H = `horizon` steps: states (s, t) with
    t the steps taken, reachable from (initial, 0), then goal, fail and `horizon` (t = H).
    `action_at(t)` is the [n] move of every canonical state after t steps (t < H). Raises
    ValueError past `max_states` states."""
    matrix = mdp.matrix()
    choice_of = np.full((mdp.n, mdp.n_actions), -1, dtype=np.int64)
    choice_of[mdp.choice_state, mdp.choice_action] = np.arange(len(mdp.choice_state))
    layers: list[np.ndarray] = []          # canonical states alive after t steps
    blocks: list[sp.csr_matrix] = []       # [layer t, n] transitions out of layer t
    frontier = np.array([initial], dtype=np.int64)
    total = 0
    for t in range(horizon):
        frontier = frontier[~mdp.absorbing[frontier]]
        if len(frontier) == 0:
            break
        total += len(frontier)
        if total > max_states:
            raise ValueError(f"the strategy's DTMC over {horizon} steps has more than "
                             f"{max_states:,} states")
        chosen = choice_of[frontier, action_at(t)[frontier]]
        block = matrix[chosen]
        layers.append(frontier)
        blocks.append(block)
        frontier = np.unique(block.indices)
    offsets = np.cumsum([0] + [len(layer) for layer in layers])
    n_live = int(offsets[-1])
    goal_id, fail_id, cut_id = n_live, n_live + 1, n_live + 2
    sources, targets, probs = [], [], []
    for t, (layer, block) in enumerate(zip(layers, blocks)):
        coo = block.tocoo()
        succ = coo.col
        if t + 1 < len(layers):
            position = np.full(mdp.n, -1, dtype=np.int64)
            position[layers[t + 1]] = offsets[t + 1] + np.arange(len(layers[t + 1]))
            live_index = position[succ]
        else:
            live_index = np.full(len(succ), cut_id, dtype=np.int64)
        index = np.where(mdp.goal[succ], goal_id, np.where(mdp.fail[succ], fail_id, live_index))
        sources.append(offsets[t] + coo.row)
        targets.append(index)
        probs.append(coo.data)
    source = np.concatenate(sources + [[goal_id, fail_id, cut_id]]).astype(np.int64)
    target = np.concatenate(targets + [[goal_id, fail_id, cut_id]]).astype(np.int64)
    probability = np.concatenate(probs + [[1.0, 1.0, 1.0]])
    states = np.concatenate(layers) if layers else np.zeros(0, dtype=np.int64)
    steps = np.repeat(np.arange(len(layers)), [len(layer) for layer in layers])
    names, values = _valuations(mdp, decoded, ts, states)
    values = np.column_stack([values, steps]) if len(states) else np.zeros((0, len(names) + 1),
                                                                           dtype=np.int64)
    names = names + ("t",)
    values = np.vstack([values] + [np.full((1, len(names)), v, dtype=np.int64)
                                   for v in (GOAL_VALUE, FAIL_VALUE, HORIZON_VALUE)])
    n = n_live + 3
    labels = {"goal": np.arange(n) == goal_id, "fail": np.arange(n) == fail_id,
              "horizon": np.arange(n) == cut_id}
    moves = (np.concatenate([action_at(t)[layer] for t, layer in enumerate(layers)])
             if layers else np.zeros(0, dtype=np.int64))
    start = 0 if n_live else (goal_id if mdp.goal[initial] else fail_id)
    return InducedDTMC(variables=names, valuations=values,
                       chain=_chain(source, target, probability, n), initial=start,
                       labels=labels, action=np.r_[moves, -1, -1, -1],
                       place=np.r_[_places(mdp, decoded, states), -1, -1, -1],
                       arena_actions=ts.arena.actions)


# ---------------------------------------------------------------------------------------------
# Writers
# ---------------------------------------------------------------------------------------------

def _valuation_fields(dtmc: InducedDTMC, before: str, between: str, after: str,
                      named: bool) -> list[Field]:
    """A state's valuation as fields: `before`, the values (each after `name=` if `named`)
    separated by `between`, then `after`."""
    fields = [literal(before)]
    for k, name in enumerate(dtmc.variables):
        prefix = (between if k else "") + (f"{name}=" if named else "")
        if prefix:
            fields.append(literal(prefix))
        fields.append(integers(dtmc.valuations[:, k]))
    return fields + [literal(after)]


def prism_explicit(dtmc: InducedDTMC) -> dict[str, Iterable[bytes]]:
    """PRISM's explicit files: {"tra": ..., "sta": ..., "lab": ...}, each as pieces of text
    formatted as they are written (outputs.write_chunks). PRISM reads them with
    `prism -importtrans induced.tra -importstates induced.sta -importlabels induced.lab -dtmc`."""
    state = dtmc.numbers
    tra = Lines([Field(state.vocabulary, dtmc.source), literal(" "),
                 Field(state.vocabulary, dtmc.target), literal(" "),
                 dtmc.probabilities, literal("\n")], len(dtmc.source))
    sta = Lines([state] + _valuation_fields(dtmc, ":(", ",", ")\n", named=False), dtmc.n)
    names = ["init", "deadlock"] + list(dtmc.labels)
    lab = [" ".join(f'{k}="{name}"' for k, name in enumerate(names))]
    members: dict[int, list[int]] = {dtmc.initial: [0]}
    for k, name in enumerate(names[2:], start=2):
        for i in np.flatnonzero(dtmc.labels[name]).tolist():
            members.setdefault(i, []).append(k)
    lab += [f"{i}: " + " ".join(map(str, sorted(members[i]))) for i in sorted(members)]
    return {"tra": tra.chunks(f"{dtmc.n} {len(dtmc.source)}\n".encode()),
            "sta": sta.chunks(("(" + ",".join(dtmc.variables) + ")\n").encode()),
            "lab": [("\n".join(lab) + "\n").encode()]}


GOAL_PROPERTY = 'P=? [F "goal"]'


def goal_props() -> bytes:
    """goal.props, written beside the induced DTMC: the property that re-checks the strategy's
    value with PRISM or Storm alone (for the step-bounded objective the unfolded DTMC gives the
    bounded value with the same property)."""
    return ("// P(F \"goal\") in the DTMC P1's strategy induces (induced.tra/.sta/.lab, induced.drn):\n"
            "//   prism -importtrans induced.tra -importstates induced.sta -importlabels induced.lab "
            "-dtmc goal.props -epsilon 1e-12\n"
            "//   storm --explicit-drn induced.drn --prop goal.props\n"
            f"{GOAL_PROPERTY}\n").encode()


def drn(dtmc: InducedDTMC, comment: str = "") -> Iterable[bytes]:
    """Storm's DRN format (stormpy.build_model_from_drn): per state its labels, its valuation
    as a comment and one choice labelled with P1's action by name (`absorbing` in absorbing
    states); as pieces of text formatted as they are written (outputs.write_chunks)."""
    lines = [f"// {line}" for line in comment.splitlines()] + [
        "@type: DTMC", "@value_type: double", "@parameters", "", "@reward_models", "",
        "@nr_states", str(dtmc.n), "@nr_choices", str(dtmc.n), "@model"]
    named = ["" for _ in range(dtmc.n)]
    named[dtmc.initial] = " init"
    for name, mask in dtmc.labels.items():
        for i in np.flatnonzero(mask).tolist():
            named[i] += f" {name}"
    label_sets = sorted(set(named))
    label_code = {text: k for k, text in enumerate(label_sets)}
    moves, move_code = dtmc.action_names()
    state = dtmc.numbers
    heads = Lines([literal("state "), state,
                   Field(Vocabulary.of(label_sets),
                         np.fromiter(map(label_code.__getitem__, named), np.int64, dtmc.n))]
                  + _valuation_fields(dtmc, "\n//[", ", ", "]\n\taction ", named=True)
                  + [Field(Vocabulary.of(moves), move_code),
                     literal("\n")], dtmc.n)
    branches = Lines([literal("\t\t"), Field(state.vocabulary, dtmc.target), literal(" : "),
                      dtmc.probabilities, literal("\n")], len(dtmc.target))
    starts = np.searchsorted(dtmc.source, np.arange(dtmc.n + 1))
    return grouped_chunks(heads, branches, starts, ("\n".join(lines) + "\n").encode())


# ---------------------------------------------------------------------------------------------
# Numbers of the DTMC
# ---------------------------------------------------------------------------------------------

def expected_steps(dtmc: InducedDTMC) -> Steps:
    """P(F goal), the expected steps until an absorbing state, and the expected steps to the
    goal given that it is reached (docs/semantics.md §6 "Timing"): `numeric.expected_steps`
    on the DTMC, every labelled state absorbing."""
    absorbing = np.zeros(dtmc.n, dtype=bool)
    for mask in dtmc.labels.values():
        absorbing |= mask
    return numeric.expected_steps(dtmc.chain.matrix, dtmc.initial, dtmc.labels["goal"],
                                  absorbing)
