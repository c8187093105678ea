"""The transition system TS of docs/semantics.md §§2 and 15: an arena unfolded with P2's
actions, as numpy tables.

TS states are numbered: with delay 0, state i is arena state i; with delay k > 0, state
(arena state * |A2| + standing action) * (k + 1) + countdown. The last state is `trapped`
(reached only when P2 sets traps). Terminal arena states (no P1 action) and `trapped` end an
episode: every action slot is a self-loop there. At a state with fewer P1 actions than the
largest number, the missing slots repeat its first action and `enabled` is False for them, so a
maximum over slots is right even unmasked; a softmax or a choice over actions reads `enabled`.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from hg2prism.model.arena import Arena, class_name


@dataclass(frozen=True, eq=False)
class TransitionSystem:
    arena: Arena
    label_names: tuple[str, ...]      # label class names: "" (none), then propositions joined by &
    place_label: np.ndarray           # [n_places] label class of each arena state
    a2_names: tuple[str, ...]         # P2's actions: general names, or the trap sets' members
    trap_sets: tuple[tuple[int, ...], ...]   # trap mode: candidate numbers of each P2 action
    set_places: np.ndarray | None     # trap mode: [n_a2, n_places] bool, does set j cover the state
    delay: int
    start_state: int
    succ: np.ndarray                  # [n_states, A1max, n_a2, K] successor state of each outcome
    prob: np.ndarray                  # [n_states, A1max, n_a2, K] its probability
    allowed: np.ndarray               # [n_states, n_a2] bool: A2(v)
    enabled: np.ndarray               # [n_states, A1max] bool: P1's action slot i exists at v
    terminal: np.ndarray              # [n_states] bool: the episode ends here (trapped included)

    @property
    def n_places(self) -> int:
        return self.arena.n_states

    @property
    def n_actions(self) -> int:
        return self.succ.shape[1]

    @property
    def letters(self) -> tuple[int, ...]:
        """The label classes the world's states produce: its arena states' and none (trapped)."""
        return tuple(sorted(set(self.place_label.tolist()) | {0}))

    @property
    def n_sets(self) -> int:
        """|A2|: P2's actions (trap sets in trap mode)."""
        return len(self.a2_names)

    @property
    def n_states(self) -> int:
        return self.succ.shape[0]

    @property
    def trapped(self) -> int:
        return self.n_states - 1

    @property
    def phases(self) -> int:
        """Countdown values 0..delay."""
        return self.delay + 1

    @property
    def traps_mode(self) -> bool:
        return self.set_places is not None

    def state(self, place: int, standing: int = 0, countdown: int = 0) -> int:
        if self.delay == 0:
            return place
        return (place * self.n_sets + standing) * self.phases + countdown

    def decode(self, state: int) -> tuple[int, int, int]:
        """(arena state, standing action, countdown) of a non-trapped state (standing =
        countdown = 0 when delay is 0)."""
        if self.delay == 0:
            return state, 0, 0
        place, rest = divmod(state, self.n_sets * self.phases)
        standing, countdown = divmod(rest, self.phases)
        return place, standing, countdown

    def places_of(self) -> np.ndarray:
        """[n_states - 1] the arena state of every TS state but `trapped`."""
        if self.delay == 0:
            return np.arange(self.n_states - 1)
        return np.arange(self.n_states - 1) // (self.n_sets * self.phases)

    def state_label(self) -> np.ndarray:
        """[n_states] label class of every TS state (`trapped` has the empty label)."""
        return np.append(self.place_label[self.places_of()], 0)

    def action_names(self, state: int) -> tuple[str, ...]:
        """P1's actions at TS state `state` (none at `trapped` and terminal states)."""
        if state == self.trapped:
            return ()
        return self.arena.actions[self.decode(state)[0]]

    def reachable(self, p2_sets: np.ndarray | None = None) -> np.ndarray:
        """[n_states] bool: the TS states reachable from the start, P1 playing every action
        (and every outcome), P2 playing at each state v one of p2_sets[:, v] ([k, n_states]
        actions: her choice under each hypothesis, say), or any action A2(v) allows when
        p2_sets is None. The hypergame's tables are only ever read at these states."""
        plays = self.allowed.copy()
        if p2_sets is not None:
            plays[:] = False
            for sets in np.asarray(p2_sets).reshape(-1, self.n_states):
                plays[np.arange(self.n_states), sets] = True
            plays &= self.allowed
        seen = np.zeros(self.n_states, dtype=bool)
        seen[self.start_state] = True
        frontier = np.array([self.start_state])
        while frontier.size:
            taken = plays[frontier][:, None, :, None] & (self.prob[frontier] > 0)
            successors = np.unique(self.succ[frontier][taken])
            frontier = successors[~seen[successors]]
            seen[frontier] = True
        return seen

    def trap_places(self, a2: int) -> tuple[int, ...]:
        """The arena states trap set `a2` covers (none for a general P2 action)."""
        if not self.traps_mode:
            return ()
        return tuple(self.arena.trap_candidates[c] for c in self.trap_sets[a2])

    def describe_state(self, state: int) -> dict:
        """A TS state as JSON-ready fields, a strategy record's first keys: ``state``, its
        arena state's name; ``standing``, P2's standing action by name (a trap set's states
        joined by '+'); ``countdown`` (both null when delay is 0); ``trapped`` and nulls for
        `trapped`."""
        if state == self.trapped:
            return {"state": "trapped", "standing": None, "countdown": None}
        place, standing, countdown = self.decode(state)
        name = self.arena.states[place]
        if self.delay == 0:
            return {"state": name, "standing": None, "countdown": None}
        return {"state": name, "standing": self.a2_names[standing], "countdown": countdown}


def a2_actions(arena: Arena, traps: int) -> tuple[tuple[str, ...], tuple[tuple[int, ...], ...]]:
    """P2's actions: (names, trap sets). General actions are named by the arena; a trap set
    (the `traps`-subsets of the candidates, in combinations order) by its states joined by '+'."""
    if not arena.traps_mode:
        return arena.p2_actions, ()
    sets = tuple(itertools.combinations(range(len(arena.trap_candidates)), traps))
    names = tuple("+".join(arena.states[arena.trap_candidates[c]] for c in members)
                  for members in sets)
    return names, sets


def trap_set_index(n: int, members) -> int:
    """The index of the set `members` (distinct candidate numbers below n) among the
    len(members)-subsets of range(n) in combinations order (a2_actions), without listing them."""
    chosen, k = sorted(members), len(members)
    index, previous = 0, -1
    for i, c in enumerate(chosen):
        index += sum(math.comb(n - 1 - j, k - 1 - i) for j in range(previous + 1, c))
        previous = c
    return index


def trap_set_at(n: int, k: int, index: int) -> tuple[int, ...]:
    """The `index`-th k-subset of range(n) in combinations order (trap_set_index's inverse)."""
    members, c = [], 0
    for i in range(k):
        while index >= (before := math.comb(n - 1 - c, k - 1 - i)):
            index -= before
            c += 1
        members.append(c)
        c += 1
    return tuple(members)


def carried_standing(n: int, standing, traps: int) -> int:
    """The standing set of `traps` traps that keeps one of another size (`standing`: candidate
    numbers among n): the first `traps` of them in candidate order and, when they are fewer, the
    first other candidates; its index (trap_set_index). A sweep over traps and World.replace
    use it (docs/semantics.md §7, Sweeps)."""
    chosen = sorted(standing)[:traps]
    chosen += [c for c in range(n) if c not in chosen][:traps - len(chosen)]
    return trap_set_index(n, chosen)


def build_transition_system(arena: Arena, traps: int = 0, delay: int = 0,
                            initial_standing: int = 0) -> TransitionSystem:
    """Unfold `arena` with P2's actions (`traps` per set in trap mode), the delay and the
    action standing at the start (an index into A2; used when delay > 0)."""
    classes, place_label = arena.label_classes()
    label_names = tuple(class_name(c, arena.propositions) for c in classes)
    a2_names, trap_sets = a2_actions(arena, traps)
    n_places, n_sets, phases = arena.n_states, len(a2_names), delay + 1
    set_places = None
    if arena.traps_mode:
        set_places = np.zeros((n_sets, n_places), dtype=bool)
        for t, members in enumerate(trap_sets):
            set_places[t, [arena.trap_candidates[c] for c in members]] = True

    n_states = (n_places * n_sets * phases if delay else n_places) + 1
    trapped = n_states - 1
    if delay:
        idx = np.arange(n_states - 1)
        state_place, rest = np.divmod(idx, n_sets * phases)
        state_standing, state_count = np.divmod(rest, phases)
    else:
        state_place = np.arange(n_places)
        state_standing = np.zeros(n_places, dtype=np.int64)
        state_count = np.zeros(n_places, dtype=np.int64)

    # Padding: a missing action slot repeats the state's first action; a terminal state loops.
    counts = np.array([len(a) for a in arena.actions], dtype=np.int64)
    first = np.zeros_like(arena.dest[:, :1])
    dest, prob = arena.dest.copy(), arena.prob.copy()
    pad = np.arange(arena.n_actions)[None, :] >= counts[:, None]
    dest = np.where(pad[:, :, None, None], dest[:, :1], dest)
    prob = np.where(pad[:, :, None, None], prob[:, :1], prob)
    ends = counts == 0
    loop = np.arange(n_places)[:, None, None, None] + first
    dest[ends] = loop[ends]
    prob[ends] = 0.0
    prob[ends, :, :, 0] = 1.0

    shape = (len(state_place), arena.n_actions, n_sets, arena.dest.shape[3])
    target = np.broadcast_to(dest[state_place], shape)          # [S, A1, n_a2, K] arena state
    tprob = np.broadcast_to(prob[state_place], shape)
    a2 = np.arange(n_sets)
    if set_places is not None:
        hit = set_places[a2[None, None, :, None], target]
    else:
        hit = np.zeros(shape, dtype=bool)
    if delay:
        changed = a2[None, :] != state_standing[:, None]              # [S, n_a2]
        next_count = np.where(changed, delay, np.maximum(state_count[:, None] - 1, 0))
        next_state = ((target * n_sets + a2[None, None, :, None]) * phases
                      + next_count[:, None, :, None])
    else:
        next_state = target
    ended = ends[state_place]
    here = np.arange(len(state_place))[:, None, None, None]
    succ = np.where(hit & ~ended[:, None, None, None], trapped, next_state)
    succ = np.where(ended[:, None, None, None], here, succ)
    succ = np.concatenate([succ, np.full((1,) + shape[1:], trapped)], axis=0)
    prob = np.concatenate([tprob, np.zeros((1,) + shape[1:])], axis=0)
    prob[trapped, :, :, 0] = 1.0

    allowed = np.ones((n_states, n_sets), dtype=bool)
    if delay:
        waiting = state_count > 0
        allowed[:-1][waiting] = False
        allowed[np.flatnonzero(waiting), state_standing[waiting]] = True
    enabled = np.ones((n_states, arena.n_actions), dtype=bool)
    enabled[:-1] = arena.enabled[state_place] | ended[:, None]
    terminal = np.append(ended, True)

    start_state = (arena.initial * n_sets + initial_standing) * phases if delay else arena.initial
    return TransitionSystem(
        arena=arena, label_names=label_names, place_label=place_label, a2_names=a2_names,
        trap_sets=trap_sets, set_places=set_places, delay=delay, start_state=int(start_state),
        succ=succ, prob=prob, allowed=allowed, enabled=enabled, terminal=terminal,
    )
