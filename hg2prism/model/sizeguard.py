"""The size guard: an upper bound of the hypergame's canonical size, read off the world file.

Before anything is built, `estimate_states(world)` bounds the number of canonical hypergame
states (docs/semantics.md §6: the reachable states (v, q, M), goal states merged into one, failure states
into another) from the world alone — its arena (a grid world's compiled by its front end), the
task's DFA and the parameters — without solving any game, and `check_size` refuses a world
whose bound exceeds a limit.

The bound (rigorous; every factor over-approximates one component of a canonical state):

    estimate = X * P * sum_{L=0}^{w-1} sum_c Q(c) * N_L(c)  +  2

  c        an arena state (a grid's free cell): the arena state of a non-absorbing state;
  Q(c)     the DFA states q a non-absorbing canonical state can hold at c: q is
           delta(q', label(c)) with q' the DFA's initial state or a non-absorbing state, and
           q itself is neither accepting nor a sink (those states are the merged goal / fail);
           0 at a terminal arena state (the episode ends there);
  X        the number of hypotheses (P2's current one);
  P        (delay k > 0) P2's part of a TS state, |A2| * (k+1) pairs (standing action,
           countdown); 1 when delay is 0 (the TS state is the arena state);
  L        the length of P2's window: she remembers the last min(steps since her last change,
           w-1) observations (TS state, P1's action);
  N_L(c)   the number of state/action sequences (c_1,a_1),...,(c_L,a_L) that are walks ending
           next to c: c_{i+1} is an outcome of a_i from c_i, and c an outcome of a_L from c_L
           (outcomes: the successors of positive probability for some P2 action).
           N_0 = 1, N_L = A N_{L-1} with A[c', c] = #{a : c' is an outcome of a from c};
  2        the merged goal and failure states.

That is the CUSUM observer's memory (§5); each kind of observer says how its memory enters the
bound (`ObserverKind.memory`, opponent/registry.py): the Bayesian one (§12) remembers no
hypothesis beside its window (X is 1), w observations (L = 0 .. w), each with the action P2
played (at most as many as the hypotheses per observation step: pi2_x(v) of the observation's
state v for the hypothesis x she acted on, or with delay the standing action v holds).

From the world alone the Bayesian bound is about 30 times the canonical size on the benchmark's
Bayesian worlds. `check_size` then solves P2's perceptual games (`solved_games`) and bounds
again with the observer's `solved_memory`: an observation at state v records pi2_x(v) for one
of the hypotheses x, so each walk step counts the distinct sets of the hypotheses at its state
(`MemoryBound.sets_at`), one wherever they agree (1.37e6 against 1.06e6 canonical states there).

Why P appears once, not once per observation: P2's window is emptied whenever she changes her
hypothesis, so every observation in it was made under the current hypothesis x, and the trap
set in force at each of those steps is a function of the TS state and x (the standing set while
the countdown runs, pi2_x otherwise, docs/semantics.md §4). Given x, the trap part of the oldest observation
and the walk of cells and actions, the trap parts of the later observations and of the current
TS state are therefore determined. Consecutive observations are consecutive moves of one run,
hence walks. The bound only over-counts what the hypergame never reaches (hypothesis/window
pairs P2's inference never produces, walks cut short by traps and absorbing states, trap parts
and DFA states that do not occur at a cell).

Measured (estimate / canonical size): 1.0-4.6 on the benchmark family (1.2 at 1e6 states);
1.2-52 on the 46 generated test worlds, above 10 only on tiny worlds with delay > 0 where traps
end most runs within a few steps; 1.76 on world1. tests/test_scale.py checks
`real <= estimate <= 5 real` on a sample of them.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from hg2prism.errors import InputError
from hg2prism.frontends import arena_of
from hg2prism.model.arena import Arena, class_name
from hg2prism.model.world import World
from hg2prism.opponent.observer import p2_action_count
from hg2prism.opponent.registry import observer_kind

if TYPE_CHECKING:
    from hg2prism.opponent.perceptual_games import PerceptualGame

# Memory of a whole `hg2prism check`, measured as the peak resident memory of its process on
# the benchmark family (`make bench`'s `peak_mb`, docs/data/bench/results.json): 1.4-1.6 KB per
# canonical state from 5e5 states on (Storm's model with state valuations and choice labels, the
# arrays read back from Storm, the strategy export; 1,440 bytes at 4.2e6 states, 1,427 at 1.0e7
# in `make bench-huge`). It was 2.3-2.5 KB when this limit was set: the default keeps a model
# within 24 GiB at 4 KiB per *estimated* state, now a margin of 2.5x over the most measured per
# canonical state, on top of the estimate's own (1.0-4.6x on that family; about 30x on the
# Bayesian benchmark worlds from the world alone, 1.3x once P2's games are solved, which
# check_size does for a world the first bound refuses).
MEMORY_BUDGET = 24 * 2 ** 30
BYTES_PER_STATE = 4 * 1024
DEFAULT_LIMIT = MEMORY_BUDGET // BYTES_PER_STATE        # 6,291,456 estimated states
BEYOND = 10 ** 18     # the estimate stops counting here ("more than 10^18 states")
# P2's perceptual games hold tables over TS state x P1's action x P2's action x outcome, a
# successor and a probability (16 bytes) per entry, once for the TS and once per DFA state in
# each game, several games' worth at a time (two threads, their parts, the leader game).
# Measured: a peak of 1.3 GB (the process's, imports included) on a 41-state attack graph with
# 120 trap sets, delay 1 and 2-state DFAs (4.7e6 TS entries: 275 bytes each), 4.0 GB with 220
# sets (1.6e7 entries); this bound gives 288 bytes per entry there, 16 * (2 + 8 * 2).
GAME_COPIES = 8


def game_table_bytes(world: World) -> int:
    """The memory P2's perceptual games would take (GAME_COPIES), from the world alone: TS
    states (arena states, times |A2| * (k+1) with delay k) x P1's actions x |A2| x outcomes,
    16 bytes each, times 2 + GAME_COPIES * the largest DFA (task and hypotheses). The games
    come before the hypergame and are not bounded by its estimate: with many trap sets and
    delay their tables dwarf a small hypergame (41 arena states, 2,300 trap sets, delay 1:
    about 9e11 bytes, for a hypergame of a few dozen states)."""
    from hg2prism.model.automata import translate

    arena = arena_of(world)
    n_a2 = p2_action_count(world)
    ts_states = arena.n_states * (n_a2 * (world.delay + 1) if world.delay else 1) + 1
    classes, _ = arena.label_classes()
    label_names = tuple(class_name(c, arena.propositions) for c in classes)
    largest = max(translate(f, label_names).n_states
                  for f in (world.formula, *world.hypotheses))
    entries = float(ts_states) * arena.dest.shape[1] * n_a2 * arena.dest.shape[-1]
    return _bounded(entries * 16 * (2 + GAME_COPIES * largest))


def check_games_size(world: World, limit: int | None = None) -> int:
    """`game_table_bytes`, or InputError (key ``size``) when it exceeds the memory of `limit`
    estimated states (limit * BYTES_PER_STATE), and at least MEMORY_BUDGET (24 GiB): a
    --max-states above the default raises this bound with the hypergame's, a smaller one
    lowers only the hypergame's."""
    limit = DEFAULT_LIMIT if limit is None else limit
    need = game_table_bytes(world)
    budget = max(limit, DEFAULT_LIMIT) * BYTES_PER_STATE
    if need > budget:
        flag = f"--max-states {-(-need // BYTES_PER_STATE)}"
        hint = ((_beyond_machine(need, flag, "fewer trap candidates or traps, or a smaller "
                                 "delay", per_state=False) or f"To solve them anyway, pass {flag}")
                if need < BEYOND else "Reduce the trap candidates, traps or delay")
        refused = InputError(
            str(world.path), "size",
            f"P2's perceptual games would need about {gib(need)} (their tables "
            f"over TS state x P1's action x {p2_action_count(world):,} P2 actions x outcome, "
            f"with delay {world.delay}), more than the {gib(budget)} of the "
            f"limit; nothing was written. {hint}")
        refused.estimate = -(-need // BYTES_PER_STATE)      # the --max-states it asks for
        raise refused
    return need

def _adjacency(arena: Arena) -> sp.csr_matrix:
    """A[s', s] = the number of P1's actions a at s such that s' is a successor of a from s
    with positive probability for some P2 action (distinct successors; none from a terminal
    state, where the episode ends)."""
    n, n_a1 = arena.n_states, arena.n_actions
    reached = (arena.prob > 0) & arena.enabled[:, :, None, None]          # [S, A1, A2, K]
    src = np.broadcast_to(np.arange(n)[:, None, None, None], reached.shape)[reached]
    act = np.broadcast_to(np.arange(n_a1)[None, :, None, None], reached.shape)[reached]
    # distinct (s, a, s') triples
    triples = np.unique(np.stack([src, act, arena.dest[reached]]), axis=1)
    return sp.csr_matrix((np.ones(triples.shape[1]), (triples[2], triples[0])), shape=(n, n))


def _dfa_states_per_label(world: World, label_names: tuple[str, ...]) -> np.ndarray:
    """Q per label class: the non-absorbing DFA states delta(q', label), q' initial or
    non-absorbing."""
    from hg2prism.model.automata import translate

    dfa = translate(world.formula, label_names)
    absorbing = set(dfa.accepting) | set(dfa.sink)
    before = sorted({dfa.initial} | (set(range(dfa.n_states)) - absorbing))
    counts = np.zeros(len(label_names), dtype=np.int64)
    for k in range(len(label_names)):
        reached = {int(dfa.delta[q, k]) for q in before}
        counts[k] = len(reached - absorbing)
    return counts


def trap_parts(world: World) -> int:
    """P: the (standing action of P2, countdown) pairs of a TS state; 1 when delay is 0."""
    if world.delay == 0:
        return 1
    return p2_action_count(world) * (world.delay + 1)


def _arena_walks(world: World) -> tuple[Arena, np.ndarray, sp.csr_matrix]:
    """The arena, Q(c) per arena state and the adjacency A of the walks."""
    arena = arena_of(world)
    classes, label = arena.label_classes()
    label_names = tuple(class_name(c, arena.propositions) for c in classes)
    q_count = _dfa_states_per_label(world, label_names)[label]           # Q(s)
    q_count[arena.terminal] = 0            # the episode ends there: goal or failure
    return arena, q_count, _adjacency(arena)


def _memories(world: World, adjacency: sp.csr_matrix, n: int,
              games: list[PerceptualGame] | None = None, deviations: bool = False
              ) -> np.ndarray | None:
    """Per arena state c, X * sum_L N_L(c): the memories P2's observer (the world's own) can
    hold next to c (None: more than BEYOND). With P2's solved `games`, the observer's bound
    given them (`ObserverKind.solved_memory`), where it has one: each observation step of a
    walk then counts the sets an observation at its state may record. With `deviations` (P2
    may play any set, as in robust deception's interval model), an observer that records the
    set played counts every set per observation step."""
    kind = observer_kind(world.inference)
    memory = (kind.solved_memory(world, games) if games is not None and kind.solved_memory
              else kind.memory(world))                  # CUSUM: X hypotheses, w-1 walks
    if deviations and memory.records:
        sets = float(p2_action_count(world))
    else:
        sets = (memory.sets_per_observation if memory.sets_at is None
                else memory.sets_at[:n].astype(float))  # per arena state
    walks = np.ones(n)                                                    # N_0
    total = np.zeros(n)
    for length in range(memory.observations + 1):                        # L = 0 .. w-1 (CUSUM)
        if length:
            walks = adjacency @ (walks * sets)
        total += walks
        if total.max(initial=0.0) * memory.hypotheses >= BEYOND:   # huge: stop before overflow
            return None
    return total * memory.hypotheses


def _bounded(total: float) -> int:
    """An estimate as an integer: exact below 2^52, rounded up above, at most BEYOND."""
    if total >= BEYOND:
        return BEYOND
    if total < 2 ** 52:
        return int(total) + 2
    return min(math.ceil(total * (1 + 1e-9)) + 2, BEYOND)


def estimate_states(world: World, games: list[PerceptualGame] | None = None,
                    deviations: bool = False) -> int:
    """An upper bound of the hypergame's canonical size (see the module docstring), of the
    world's own observer (a world with types: its first type's); tighter for some observers
    given P2's solved perceptual `games` (`solved_games`). `deviations`: of the memories
    where P2 may also play sets her hypotheses do not choose (robust deception's interval
    model), which an observer that records the set played then holds."""
    arena, q_count, adjacency = _arena_walks(world)
    memories = _memories(world, adjacency, arena.n_states, games, deviations)
    if memories is None:
        return BEYOND
    return _bounded(float(np.dot(q_count, memories)) * trap_parts(world))


def estimate_adaptive(world: World) -> int:
    """An upper bound of the adaptive hypergame's canonical size (docs/semantics.md §16:
    states (v, q, C, memories of the types of C)), for a world with types: the least of two
    bounds (their totals), each rigorous. `_shared_run` counts the run of observations the types share once
    (tight where several types watch short windows: 245,602 against the other's 13.8e6 on a
    6 x 5 grid with three types and 2,331 canonical states); `_independent_types` counts each
    type's memory on its own (tighter where one type's long window dominates: 10,690 against
    34,522 on world4)."""
    return min(_shared_run(world), _independent_types(world))


def _independent_types(world: World) -> int:
    """`estimate_adaptive`'s second bound. At an arena state c the memory M_k of a consistent
    type k, with the trap part of the oldest observation of its window, is one of P * m_k(c)
    (m_k(c) = X_k sum_L N_L^k(c), as for one type: every action P2 played in its window is
    the type's own choice, or it would not be consistent); the current TS state's trap part is
    one of P. Summing over the non-empty sets C of types,
    sum_C prod_{k in C} P m_k(c) = prod_k (1 + P m_k(c)) - 1, so

        estimate = P * sum_c Q(c) * (prod_k (1 + P m_k(c)) - 1)  +  2.
    """
    from hg2prism.worldfile.types import world_of_type

    arena, q_count, adjacency = _arena_walks(world)
    parts = trap_parts(world)
    product = np.ones(arena.n_states)
    for k in range(len(world.types)):
        memories = _memories(world_of_type(world, k), adjacency, arena.n_states)
        if memories is None:
            return BEYOND
        product = np.minimum(product * (1.0 + parts * memories), float(BEYOND))
    return _bounded(min(float(np.dot(q_count, product - 1.0)) * parts, float(BEYOND)))


def _shared_run(world: World) -> int:
    """`estimate_adaptive`'s first bound.

    Every type watches the same run, so the types' windows are suffixes of one sequence of
    observations: the last L of them, L at most the longest window (L_k = the observations of
    type k's memory, `ObserverKind.memory`). Given that sequence, type k's memory is its
    hypothesis (one of X_k: X for CUSUM, 1 for the Bayesian observer) and how many of the L
    observations its window keeps (0 .. min(L, L_k)). The sequence is a walk of L steps
    ending next to c (N_L(c), as for one type) with the trap parts of its states: the oldest's
    one of P, each later one (and the current state's) fixed by the one before and P2's set at
    the state before, the choice pi2_x(v) of the hypothesis x she acted on: one of
    f = min(|A2|, X) (f = 1 without delay when no type records sets; with delay 0 the Bayesian
    observer's recorded set is that choice, also one of f). Summing over the non-empty sets C
    of types, sum_C prod_{k in C} X_k (min(L, L_k) + 1) = prod_k (1 + X_k (min(L, L_k) + 1)) - 1:

        estimate = P * sum_c Q(c) * sum_{L=0}^{max L_k} N_L(c) f^L
                     * (prod_k (1 + X_k (min(L, L_k) + 1)) - 1)  +  2."""
    from hg2prism.worldfile.types import world_of_type

    arena, q_count, adjacency = _arena_walks(world)
    bounds = []
    for k in range(len(world.types)):
        typed = world_of_type(world, k)
        bounds.append(observer_kind(typed.inference).memory(typed))
    records = world.delay > 0 or any(b.records for b in bounds)
    step = float(max([min(p2_action_count(world), len(world.hypotheses)) if records else 1]
                     + [b.sets_per_observation for b in bounds]))
    parts = trap_parts(world)
    walks = np.ones(arena.n_states)                                       # N_L f^L
    total = np.zeros(arena.n_states)
    for length in range(max(b.observations for b in bounds) + 1):
        if length:
            walks = (adjacency @ walks) * step
        memories = math.prod(1 + b.hypotheses * (min(length, b.observations) + 1)
                             for b in bounds) - 1
        total += walks * memories
        if total.max(initial=0.0) * parts >= BEYOND:           # huge: stop before overflow
            return BEYOND
    return _bounded(min(float(np.dot(q_count, total)) * parts, float(BEYOND)))


def check_size(world: World, limit: int | None = None) -> int:
    """The estimate, or InputError when it exceeds `limit` (default DEFAULT_LIMIT). A world
    with P2's types: every type's hypergame (key ``type[<k>]``) and the adaptive hypergame
    (key ``type``) are bounded; the adaptive estimate is returned."""
    limit = DEFAULT_LIMIT if limit is None else limit
    check_games_size(world, limit)
    if not world.types:
        estimate = estimate_states(world)
        if estimate > limit and observer_kind(world.inference).solved_memory:
            from hg2prism import progress

            progress.say(f"size guard: {estimate:,} states at most from the world alone, above "
                         f"the limit of {limit:,}; solving P2's games for a tighter bound")
            estimate = estimate_states(world, solved_games(world))
        return _refuse(world, "size", "hypergame", estimate, limit,
                       f"{len(world.hypotheses)} hypotheses and window {world.window}")
    from hg2prism.worldfile.types import world_of_type

    parts = [(f"type[{k}]", f"hypergame of type {t.name!r}",
              estimate_states(world_of_type(world, k)),
              f"{len(world.hypotheses)} hypotheses and the type's window {t.window}")
             for k, t in enumerate(world.types)]
    adaptive = estimate_adaptive(world)
    parts.append(("type", "adaptive hypergame (P2's type unknown)", adaptive,
                  f"{len(world.hypotheses)} hypotheses and the {len(world.types)} types' "
                  "windows " + ", ".join(str(t.window) for t in world.types)))
    # The first part above the limit is refused, naming it (a type's window is what to
    # reduce), with the --max-states that lets every part through (the adaptive hypergame's
    # is usually the largest), so that following its advice does not meet the next refusal.
    needed = max(part[2] for part in parts)
    for key, what, estimate, made in parts:
        _refuse(world, key, what, estimate, limit, made, needed)
    return adaptive


def check_robust_size(world: World, limit: int | None = None) -> int:
    """`check_size`, then the same for robust deception's interval model (docs/semantics.md
    §13), whose states are the hypergame's and, for each, one per P1 action and P2 action
    played: the hypergame's estimate times 1 + |A1| |A2| (33 on an 8-set grid; the interval
    model of a 12,318-state hypergame had 416,881 states). An estimate rather than a bound:
    Storm keeps each goal and failure state apart, which the hypergame's estimate merges (0.22
    to 1.05 times the interval model's states on test_robust's worlds). In the interval model
    P2 also plays sets her hypotheses do not choose, and an observer that records the set
    played (the Bayesian one) then holds them: its hypergame is counted with every set per
    observation step (`estimate_states(deviations=True)`; a Bayesian world with delay: 24.7e6
    against an interval model of 4.46e6 Storm states). Returns it."""
    limit = DEFAULT_LIMIT if limit is None else limit
    estimate = check_size(world, limit)
    factor = 1 + arena_of(world).n_actions * p2_action_count(world)
    if not world.types and observer_kind(world.inference).memory(world).records:
        estimate = max(estimate, estimate_states(world, deviations=True))
    return _refuse(world, "size", "interval model of robust deception",
                   _bounded(float(estimate) * factor), limit,
                   f"{len(world.hypotheses)} hypotheses and window {world.window}, times 1 + "
                   f"P1's actions x P2's actions played ({factor})")


def solved_games(world: World) -> list[PerceptualGame]:
    """P2's perceptual games of the world (the first stage of every command), for a bound an
    observer tightens with them: solved only where the bound from the world alone exceeds the
    limit (well under a second without delay, seconds with; a minute and a few GB on a
    delayed attack graph of 400 nodes with two traps)."""
    from hg2prism.frontends import transition_system
    from hg2prism.model.automata import translate
    from hg2prism.opponent.perceptual_games import perceptual_game

    ts = transition_system(world)
    return [perceptual_game(ts, translate(h, ts.label_names, ts.letters), world.rationality,
                            tie_break=world.tie_break)
            for h in world.hypotheses]


def machine_bytes() -> int | None:
    """This machine's physical memory in bytes (None where the system does not say)."""
    import os

    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def gib(size: float) -> str:
    """`size` bytes in GiB for a message: "1.5 GiB", "3,460,300,800 GiB" (no decimal above
    100 GiB)."""
    gib = size / 2 ** 30
    return f"{gib:,.1f} GiB" if round(gib, 1) < 100 else f"{gib:,.0f} GiB"


def _beyond_machine(need: int, flag: str, smaller: str, per_state: bool = True) -> str | None:
    """The hint when `need` bytes exceed this machine's memory: what makes the model smaller,
    then the override (which would exhaust the memory: a stress test's robust model, refused
    at 11.9e9 states, ran out of 24 GiB when forced)."""
    memory = machine_bytes()
    if memory is None or need <= memory:
        return None
    what = (f"That is about {gib(need)} at {BYTES_PER_STATE // 1024} KiB a "
            "state, more" if per_state else "That is more")
    return (f"{what} than this machine's {gib(memory)}: {smaller} make it "
            f"smaller ({flag} would try anyway)")


def _refuse(world: World, key: str, what: str, estimate: int, limit: int, made: str,
            needed: int | None = None) -> int:
    """`estimate`, or InputError(world, key) when it exceeds `limit`. `needed` (at least
    `estimate`): the --max-states to advise, when other parts of the world need more."""
    if estimate > limit:
        needed = max(estimate, needed or 0)
        size = "more than 10^18" if estimate >= BEYOND else f"up to {estimate:,}"
        window = f"{key}.inference.window" if key.startswith("type[") else (
            "the types' windows" if key == "type" else "inference.window")
        other = "" if needed == estimate else " and every other part of the world"
        hint = (_beyond_machine(needed * BYTES_PER_STATE, f"--max-states {needed}",
                                f"fewer traps, trap candidates or hypotheses, a smaller {window} "
                                "or delay")
                or f"To build it{other} anyway, pass --max-states {needed}") if needed < BEYOND \
            else f"Reduce {window} or the world"
        refused = InputError(
            str(world.path), key,
            f"the {what} may have {size} states (estimated from the arena, the "
            f"task's DFA, {made}), more than "
            + (f"the limit of {limit:,} that fits in memory" if limit == DEFAULT_LIMIT
               else f"the limit of {limit:,} (--max-states)")
            + f"; nothing was written. {hint}")
        refused.estimate = needed       # a sweep's refusal gives the largest of its points'
                                        # (sweep.guard_points)
        raise refused
    return estimate
