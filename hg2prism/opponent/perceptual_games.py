"""P2's perceptual games G(x) (docs/semantics.md §4), solved in numpy.

G(x) is played on TS x DFA(x): at every step P2 commits to a trap set a2, then P1 answers with a1.
Values are solved to within 1e-10 (docs/semantics.md §10), one part of the game at a time, a part
per strongly connected set of DFA states (downstream first, each with the values of what it can
enter fixed: on delay worlds a part is a third to a fifth of the game, and its linear solves
several times cheaper; a part the world's games have in common is solved once, `SharedParts`):
a few sweeps of value iteration from below seed the strategies; the pair
greedy for the values is evaluated exactly (a sparse linear solve) and re-greedied for a few
rounds; where that cycles (on delay worlds P2 changed about a third of her trap sets every
round), Hoffman-Karp strategy iteration — P1 improves his answers, P2 best-responds exactly —
finds the values. Both players' strategy iterations look ahead (modified strategy iteration:
the strategy greedy for a few sweeps of value iteration from the exact values, kept only when
its exact values improve on them), which halves their rounds on delay worlds. (The games stage
of the benchmark's delay worlds fell from 9-151 s to 3-30 s with strategy iteration, and by a
further 1.2-2.8x of CPU with the parts and the look-ahead, docs/performance.md.) The result is certified:
  * the pair's value x is a fixed point of the game operator, so P1's best answer to P2's
    greedy strategy is at most x (the least fixed point lies below every fixed point), and
  * x is 0 wherever P2 can keep P1 away from the target forever against P1's strategy; then
    x is the unique solution of P2's best-response equations, so P1 guarantees at least x.
"""

from __future__ import annotations

import hashlib
import threading
from concurrent.futures import Future
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hg2prism.model.automata import DFA
from hg2prism.model.product import product, product_state
from hg2prism.numeric import (alternating_attractor, backward_reach, downstream_first,
                              first_index, keep_or_first, move_predecessors, near_best,
                              solve_plain)
from hg2prism.numeric.fastest import DISCOUNT, EXACT_SCORE_STOP, EXACT_SLACK, fastest_first
from hg2prism.numeric.tables import fold, outcome_sum
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.errors import SolverError

TIE = 1e-6              # P2's tie tolerance between trap sets (docs/semantics.md §4)
# Value iteration only seeds the strategies: strategy iteration then evaluates them exactly and
# improves them until they are certified, so a few sweeps do (measured: the same values and
# strategies on every test and benchmark world as with 1e-4, in a third of the time). Should
# certification fail, value iteration resumes with a tolerance 100 times smaller.
VI_TOLERANCE = 0.3
MAX_SWEEPS = 1_000_000
POLISH_ROUNDS = 12
# Strategy iteration switches a strategy only where the exact values improve by more than this:
# float noise in the linear solves (about 1e-15) must not make a player switch back and forth.
IMPROVEMENT = 1e-12
DROP = 1e-9             # a fall of P1's values by more than this is not float noise of a solve
MAX_ROUNDS = 10_000
# Sweeps of value iteration each look-ahead of P2's best response (of her operator against P1's
# answers) and of P1's improvement (of the game operator) takes before its greedy strategy is
# evaluated exactly; 0 turns the look-ahead off. 30 was fastest of 3, 10, 30, 100 and 300 on the
# benchmark's one-trap delay worlds (the solves fell from 98-114 to 56-62 on their leader game).
LOOKAHEAD = 30
P1_LOOKAHEAD = 30
# A part of at most this many moves (times outcomes) is known again by its tables, kept and
# compared in full (SharedParts), a larger one by a digest of them: the tables of a world's
# small parts take a few MB.
SHARED_TABLES = 250_000
# The restricted attractors a game keeps (`TurnBasedGame.positive_attractor`), the last ones
# asked for (besides the unrestricted one).
ATTRACTORS_KEPT = 2


@dataclass(frozen=True, eq=False)
class GameSolution:
    """Values of a turn-based reachability game on TS x DFA, with P2 moving first each step."""

    values: np.ndarray        # [n_ts, n_q]
    # (both None where only the values were asked for: `_solve`'s `strategies`)
    p2_strategy: np.ndarray   # [n_ts * n_q] P2's action at each game state (docs/semantics.md §4's rule)
    p1_strategy: np.ndarray   # [n_ts * n_q, n_sets] P1's optimal answer to each trap set
    sweeps: int


@dataclass(frozen=True, eq=False)
class PerceptualGame:
    """G(x) for one hypothesis x: what P2 plays and how she models P1 (docs/semantics.md §4)."""

    formula: str
    dfa: DFA
    values: np.ndarray        # [n_ts, n_q] V_x
    fresh_q: np.ndarray       # [n_ts] q_x0(v) = delta(iota, L(v))
    trap_choice: np.ndarray   # [n_ts] pi2_x(v): index of P2's action (a trap set in trap mode)
    log_policy: np.ndarray    # [n_ts, n_a2, A1max] ln pi1_x(a1 | v, a2), softmax at q_x0(v) over
                              # the actions enabled at v (-inf at the slots that are not)
    # [n_ts] every action P2 may take at v ties under the rule of §4 (her choice there is the
    # standing one or the first, and decides nothing); None when not computed
    all_tied: np.ndarray | None = None


class TurnBasedGame:
    """The product TS x DFA as a turn-based game (P2 picks the trap set, then P1 moves): game
    state g = s * n_q + q, its successors, probabilities, P2's allowed sets, goal and absorbing
    states. The solver here, the leader fallback of the simulation and the tests use it."""

    def __init__(self, ts: TransitionSystem, dfa: DFA) -> None:
        self.ts, self.dfa = ts, dfa
        arena = product(ts, dfa)
        n_q = dfa.n_states
        self.next, self.prob, self.allowed = arena.next, arena.prob, arena.allowed
        self.goal, self.zero_fixed = arena.goal, arena.fail
        self.free = arena.free
        self.terminal = arena.goal.astype(float)      # the value of each absorbing state
        self.size = arena.size
        self._reverse: tuple[np.ndarray, ...] | None = None
        standing = _standing_sets(ts)
        self.standing = None if standing is None else np.repeat(standing, n_q)
        self._pairs: tuple[np.ndarray, ...] | None = None
        self._attractors: list[tuple[np.ndarray, np.ndarray]] = []
        self._unrestricted: np.ndarray | None = None

    def restricted(self, states: np.ndarray, values: np.ndarray) -> TurnBasedGame:
        """The game on `states` (free states, increasing) alone, in local numbers: those
        states first, then one absorbing state per distinct value in `values` of the states
        they can enter outside them (the exits; each of positive value is a goal). Its values
        on `states` are the game's when `values` are exact on the exits. The exits' own
        numbers never matter to those values, so exits of equal value are one state: games
        that differ only in which outside states hold a value solve the same part."""
        sub = object.__new__(TurnBasedGame)
        sub.ts, sub.dfa = self.ts, self.dfa
        inside = np.zeros(self.size, dtype=bool)
        inside[states] = True
        entered = np.zeros(self.size, dtype=bool)
        entered[self.next[states].reshape(-1)] = True
        exits = np.flatnonzero(entered & ~inside)
        exit_values, exit_of = np.unique(values[exits], return_inverse=True)
        m = exit_values.size
        local = np.full(self.size, -1, dtype=self.next.dtype)
        local[states] = np.arange(states.size)
        local[exits] = states.size + exit_of
        n, shape = states.size + m, self.next.shape[1:]
        sub.next = np.empty((n,) + shape, dtype=self.next.dtype)
        sub.next[:states.size] = local[self.next[states]]
        sub.next[states.size:] = (states.size + np.arange(m))[:, None, None, None]
        sub.prob = np.zeros((n,) + shape)
        sub.prob[:states.size] = self.prob[states]
        sub.prob[states.size:, ..., 0] = 1.0
        # An exit is absorbing, with one allowed set (the first; any would do: an exit's moves
        # are never searched, `_predecessors` leaving out every state that is not free).
        sub.allowed = np.zeros((n, self.allowed.shape[1]), dtype=bool)
        sub.allowed[:states.size] = self.allowed[states]
        sub.allowed[states.size:, 0] = True
        sub.terminal = np.r_[np.zeros(states.size), exit_values]
        sub.goal = sub.terminal > 0
        sub.free = np.r_[np.ones(states.size, dtype=bool), np.zeros(m, dtype=bool)]
        sub.zero_fixed = ~sub.free & ~sub.goal
        sub.size = n
        sub.standing = (None if self.standing is None
                        else np.r_[self.standing[states], np.full(m, -1)])
        sub._reverse, sub._pairs, sub._attractors, sub._unrestricted = None, None, [], None
        return sub

    def signature(self) -> bytes:
        """A digest of what a `restricted` game's values on its free states (numbered first)
        depend on: their moves, P2's sets there and the exits' values. Two games of equal
        signature have the same values there, computed the same way."""
        digest = hashlib.blake2b(digest_size=32)
        k = int(self.free.sum())
        for table in (self.next[:k], self.prob[:k], self.allowed[:k], self.terminal[k:]):
            digest.update(repr((table.dtype.str, table.shape)).encode())
            digest.update(np.ascontiguousarray(table).data)
        return digest.digest()

    def share_key(self) -> tuple[bytes, tuple[np.ndarray, ...] | None]:
        """(key, tables): how `SharedParts` knows a `restricted` game again. A small one's key
        says what `signature` hashes but its tables (its free states' moves, probabilities and
        P2's sets), which are kept and compared in full: hashing them took longer than solving
        the part on small worlds. A large one's key is its `signature`, tables None."""
        k = int(self.free.sum())
        if self.next[:k].size > SHARED_TABLES:
            return b"digest " + self.signature(), None
        tables = (self.next[:k], self.prob[:k], self.allowed[:k])
        key = repr([(table.dtype.str, table.shape) for table in tables + (self.terminal[k:],)])
        return b"tables " + key.encode() + self.terminal[k:].tobytes(), tables

    def parts(self) -> list[np.ndarray]:
        """The free states by strongly connected set C of DFA states (those of TS x C), in
        numeric.downstream_first's order of the sets: a part's moves enter only itself, the
        parts before it and absorbing states, so each part can be solved once the values of
        the parts before it are known."""
        n_q = self.dfa.n_states
        order = downstream_first(self.dfa.delta)
        q_of = np.arange(self.size) % n_q
        parts = [np.flatnonzero(self.free & np.isin(q_of, part)) for part in order]
        return [part for part in parts if part.size]

    def moves(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The successors and probabilities [..., K] of the moves (g, a1, a2) numbered
        flat = (g * A1 + a1) * A2 + a2 (np.take on the flat tables: several times faster than
        indexing next[g, a1, a2] with three index arrays)."""
        outcomes = self.next.shape[-1]
        return (np.take(self.next.reshape(-1, outcomes), flat, axis=0),
                np.take(self.prob.reshape(-1, outcomes), flat, axis=0))

    def q_values(self, v: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Q[g, a1, a2] (at the game states `rows` only, if given); for absorbing g every
        entry is V(g)."""
        if rows is None:
            q = outcome_sum(self.prob, v, self.next)
            q[~self.free] = v[~self.free, None, None]
            return q
        q = outcome_sum(self.prob[rows], v, self.next[rows])
        absorbing = ~self.free[rows]
        q[absorbing] = v[rows[absorbing], None, None]
        return q

    def allowed_q(self, v: np.ndarray) -> np.ndarray:
        """q_values(v) at the trap sets P2 may play (`allowed`), 0 at the others, which the
        solver never reads: with delay P2 has one set in most states (the standing one while
        it counts down), so this skips most of the work. Bit-identical to q_values there."""
        if self.allowed.all():
            return self.q_values(v)
        flat, nxt, prob, _, _ = self.allowed_pairs()
        q = np.zeros(self.next.shape[:3])
        q.reshape(-1)[flat] = outcome_sum(prob, v, nxt)
        q[~self.free] = v[~self.free, None, None]
        return q

    def bellman(self, v: np.ndarray) -> np.ndarray:
        """operator(allowed_q(v)), the same numbers, without the [G, A1, A2] table: P1's best
        answer to each allowed (g, a2), then P2's least of them per state (inf where she has
        no set; v on the absorbing states that have one). Value iteration's sweep."""
        if self.allowed.all():
            return self.operator(self.q_values(v))
        _, nxt, prob, states, starts = self.allowed_pairs()
        answers = outcome_sum(prob, v, nxt)                           # [pairs, A1]
        best = answers[:, 0].copy()
        for a1 in range(1, answers.shape[1]):
            np.maximum(best, answers[:, a1], out=best)
        out = np.full(self.size, np.inf)
        out[states] = np.minimum.reduceat(best, starts)
        absorbing = states[~self.free[states]]
        out[absorbing] = v[absorbing]
        return out

    def allowed_pairs(self) -> tuple[np.ndarray, ...]:
        """The moves of P2's allowed sets, once: flat [..., A1] the move (g, a1, a2) of every
        allowed pair (g, a2) (in order of g, then a2) and answer a1, their successors and
        probabilities [..., A1, K], the states with an allowed set and where their pairs
        start. The leading dimension is the pairs' [pairs]; where every set is allowed (no
        delay), [G, A2] and views of the tables (no copy of them)."""
        if self._pairs is None:
            size, n_a1, n_a2, _ = self.next.shape
            if self.allowed.all():
                flat = np.arange(self.next[..., 0].size).reshape(size, n_a1, n_a2)
                self._pairs = (flat.transpose(0, 2, 1), self.next.transpose(0, 2, 1, 3),
                               self.prob.transpose(0, 2, 1, 3), np.arange(size),
                               np.arange(size) * n_a2)
                return self._pairs
            g, a2 = np.divmod(np.flatnonzero(self.allowed), n_a2)
            flat = (g[:, None] * n_a1 + np.arange(n_a1)) * n_a2 + a2[:, None]
            first = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
            self._pairs = (flat, *self.moves(flat), g[first], first)
        return self._pairs

    def operator(self, q: np.ndarray) -> np.ndarray:
        """min over allowed a2 of max over a1."""
        return np.where(self.allowed, best_answer(q), np.inf).min(axis=1)

    def _predecessors(self) -> tuple[np.ndarray, ...]:
        """The moves (g, a1, a2) entering each game state (numeric.move_predecessors), once."""
        if self._reverse is None:
            # The attractor enters only free states and reads only P2's allowed sets there
            # (where she has one in every state), so the moves of the others are left out:
            # most of them on delay worlds, and the absorbing states' on every game.
            only = self.free[:, None]
            if self.allowed.any(axis=1).all():
                only = only & self.allowed
            self._reverse = move_predecessors(
                self.next, self.prob, np.broadcast_to(only[:, None, :], self.next.shape[:3]))
        return self._reverse

    def positive_attractor(self, actions: np.ndarray | None = None) -> np.ndarray:
        """Rank of each state in P1's attractor for reaching the goal with positive probability
        (P2 picks a2 first); -1 outside. `actions` [G, A1, A2] restricts P1's moves
        (numeric.alternating_attractor). The ranks of the last few masks are kept (read-only):
        the solver asks again for one it just had (P1's greedy answers of a polishing round
        and of the certificate after it, every move near-optimal and no restriction at all)."""
        if actions is not None and actions.all():
            actions = None              # every move allowed: the unrestricted ranks
        if actions is None and self._unrestricted is not None:
            return self._unrestricted
        if actions is not None:
            for known, rank in self._attractors:
                if np.array_equal(known, actions):
                    return rank
        rank = alternating_attractor(self._predecessors(), self.next.shape[:3], self.goal,
                                     self.free, self.allowed, actions)
        rank.flags.writeable = False
        if actions is None:
            self._unrestricted = rank
        else:
            # a copy of the mask: a caller may change its own afterwards
            self._attractors = self._attractors[1 - ATTRACTORS_KEPT:] + [(actions.copy(), rank)]
        return rank


def best_answer(q: np.ndarray) -> np.ndarray:
    """q.max(axis=1): P1's best one-step value against each trap set, [G, A1, A2] -> [G, A2],
    as the maximum of the A1 slices (numeric.fold), about 2.5x faster than numpy's reduction."""
    return fold(np.maximum, q, 1)


def _standing_sets(ts: TransitionSystem) -> np.ndarray | None:
    """The trap set standing in each TS state (-1 when trapped); None when delay is 0."""
    if not ts.delay:
        return None
    return np.r_[np.arange(ts.n_states - 1) // ts.phases % ts.n_sets, -1]   # `trapped` last


class SharedParts:
    """The parts of games already solved for one world, by `TurnBasedGame.share_key`, for the
    games of that world to share: the task's DFA and the hypotheses' often have a part that is
    the same game (on the benchmark's worlds, "!obs U A" is a hypothesis and what is left of
    the task once C is reached). Thread-safe: a game that needs a part another thread is
    solving waits for it."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        # by `TurnBasedGame.share_key`: the parts of that key, their tables (None: the key is
        # the digest) and their values
        self._parts: dict[bytes, list[tuple[tuple[np.ndarray, ...] | None, Future]]] = {}

    def solved(self, part: TurnBasedGame) -> tuple[np.ndarray, int]:
        """(values, sweeps) of `_solve_whole(part)`, solved once (the sweeps 0 where the part
        was solved for another game)."""
        key, tables = part.share_key()
        with self._lock:
            known = self._parts.setdefault(key, [])
            future = next((done for kept, done in known
                           if kept is None or all(map(np.array_equal, kept, tables))), None)
            mine = future is None
            if mine:
                future = Future()
                known.append((tables, future))
        if mine:
            try:
                values, _, _, sweeps = _solve_whole(part)
            except BaseException as error:
                future.set_exception(error)
                raise
            future.set_result((values, sweeps))
            return values, sweeps
        return future.result()[0], 0


def solve_game(ts: TransitionSystem, dfa: DFA, shared: SharedParts | None = None,
               tie_break: str = "first") -> GameSolution:
    return _solve(TurnBasedGame(ts, dfa), shared, tie_break)


def _solve(game: TurnBasedGame, shared: SharedParts | None = None,
           tie_break: str = "first", strategies: bool = True) -> GameSolution:
    """The game's values and strategies. The free states are solved one part at a time
    (`TurnBasedGame.parts`: one per strongly connected set of DFA states), downstream first,
    each on its own with the values of what it can enter fixed (on delay worlds a part is a
    third to a fifth of the game, and its linear solves several times cheaper; a game of one
    part leaves out its absorbing states, two thirds of its tables), and each once per world
    when `shared` is given; the composed values are then certified on the whole game (module
    docstring), which falls back to solving it whole should that fail.

    Without `strategies` (P2's perceptual games keep the values alone; the strategies None) a
    game of one part takes its part's values as they are: the part was certified, and on the
    whole game the same certificate would pass, on the same numbers (its free states are the
    part's, with the same moves, one-step values, residuals and attractor ranks; the absorbing
    states they enter are the part's exits, of the same values)."""
    parts = game.parts()
    certified = None
    if parts:
        x, sweeps = game.terminal.copy(), 0
        for states in parts:
            part = game.restricted(states, x)
            if shared is None:
                values, _, _, used = _solve_whole(part)
            else:
                values, used = shared.solved(part)
            x[states] = values[:states.size]
            sweeps += used
        if not strategies and len(parts) == 1:
            return GameSolution(values=x.reshape(game.ts.n_states, game.dfa.n_states),
                                p2_strategy=None, p1_strategy=None, sweeps=sweeps)
        certified = _finish(game, x, game.allowed_q(x), tie_break)
    if certified is None:
        certified = _solve_whole(game, tie_break)
        sweeps = certified[3]
    values, p1, p2 = certified[:3]
    return GameSolution(values=values.reshape(game.ts.n_states, game.dfa.n_states),
                        p2_strategy=p2, p1_strategy=p1, sweeps=sweeps)


def _solve_whole(game: TurnBasedGame, tie_break: str = "first"
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Values (certified), P1's answers, P2's trap sets and the sweeps of value iteration used:
    value iteration seeds strategy iteration (`_certify`), with a tolerance 100 times smaller
    each time certification fails."""
    rank = game.positive_attractor()
    zero = ~game.goal & (rank < 0)
    fixed = ~game.free | zero
    lower = game.terminal.copy()
    tolerance, sweeps = VI_TOLERANCE, 0
    while True:
        lower, used = _value_iteration(game, lower, fixed, tolerance)
        sweeps += used
        certified = _certify(game, lower, zero, optimal_slack=max(100 * tolerance, 1e-11),
                             tie_break=tie_break)
        if certified is not None:
            return (*certified, sweeps)
        if tolerance < 1e-15:
            raise SolverError("could not certify the game values to 1e-10 (docs/semantics.md §10)")
        tolerance /= 100


def _value_iteration(game: TurnBasedGame, v: np.ndarray, fixed: np.ndarray,
                     tolerance: float) -> tuple[np.ndarray, int]:
    """Value iteration from below: every iterate is a lower bound of the least fixed point."""
    for sweep in range(1, MAX_SWEEPS + 1):
        new = game.bellman(v)
        new[fixed] = v[fixed]
        change = np.abs(new - v).max()
        v = new
        if change < tolerance:
            return v, sweep
    raise SolverError(f"value iteration did not converge in {MAX_SWEEPS} sweeps")


def _certify(game: TurnBasedGame, v: np.ndarray, zero: np.ndarray, optimal_slack: float,
             tie_break: str = "first") -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Greedy strategies for both players from v, evaluated exactly and, if that pair is not
    optimal yet, improved by strategy iteration (`_strategy_iteration`); if certified (see the
    module docstring), the exact values x, P1's answers greedy for x (which guarantee x) and
    P2's trap sets chosen from x by docs/semantics.md §4's rule (`trap_rule`), else None."""
    # First the pair greedy for the values, re-evaluated (usually certified within a few
    # rounds; kept first because it finds the same values to the last bit as before); where it
    # cycles (delay worlds), Hoffman-Karp strategy iteration from the last pair.
    q = game.allowed_q(v)
    for _ in range(POLISH_ROUNDS):
        p1, p2 = _greedy(game, q, optimal_slack)
        x = _evaluate_pair(game, p1, p2, zero)
        q = game.allowed_q(x)
        if _residual(game, x, q) <= 1e-11:
            break
        optimal_slack = 1e-12
    else:
        x = _strategy_iteration(game, p1, p2, zero)
        q = game.allowed_q(x)
    return _finish(game, x, q, tie_break)


def _finish(game: TurnBasedGame, x: np.ndarray, q: np.ndarray, tie_break: str = "first"
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(x, P1's answers greedy for x, P2's trap sets by `trap_rule`) if the values x of a pair
    of strategies (q = allowed_q(x)) are certified (module docstring), else None."""
    if _residual(game, x, q) > 1e-11:
        return None
    # From exact values of a pair, only float noise separates truly optimal moves.
    p1_x, _, rank = _greedy_ranked(game, q, 1e-12)
    # is_certified(game, p1_x, x), from the attractor of the same states when there is one
    if not (is_certified(game, p1_x, x) if rank is None else _zero_outside(rank, x)):
        return None
    worst = np.where(game.allowed, best_answer(q), np.inf)
    return x, p1_x, trap_rule(worst, game.standing, tie_break)


def _residual(game: TurnBasedGame, x: np.ndarray, q: np.ndarray) -> float:
    """How far x is from a fixed point of the game operator (q = Q of x), over the free states."""
    return float(np.abs(game.operator(q) - x)[game.free].max(initial=0.0))


def _strategy_iteration(game: TurnBasedGame, p1: np.ndarray, p2: np.ndarray, zero: np.ndarray
                        ) -> np.ndarray:
    """The game's values by Hoffman-Karp strategy iteration from the pair (p1, p2): P2
    best-responds exactly to P1's answers (`_trap_response`), then P1 switches an answer
    p1[g, a2] only where another move is better by more than IMPROVEMENT; until he cannot.

    P1 guarantees each round's values (P2's best response is exact), and a strict switch
    cannot let P2 keep P1 from the goal where he had a positive value (on such a trap the state
    of largest value could not have improved), so the values rise, strictly where P1 switched,
    no strategy of P1 comes back and the iteration ends, at a fixed point of the game operator
    (up to IMPROVEMENT) that P1 guarantees: the least one, the game's value. (The other way
    round, P2 improving against P1's best responses, can end at a larger fixed point.) Where P1
    waits a long time (delay worlds) float noise in the values can exceed IMPROVEMENT, and a
    switch that only looks better can let P2 trap him: the values then drop, and the switches
    at the states that dropped are undone (all of them, ending the iteration, if values still
    drop). Each round first tries a look-ahead (P1_LOOKAHEAD): the answers greedy for that
    many sweeps of the game operator from x, kept when P2's best response to them leaves the
    values nowhere below x and above it somewhere by more than IMPROVEMENT, a rise too. The
    caller certifies the result."""
    solve = game.free & ~zero
    p1 = p1.copy()
    p2, x = _trap_response(game, p1, p2, zero)
    for _ in range(MAX_ROUNDS):
        q = game.allowed_q(x)                                         # [G, A1, A2]
        current = np.take_along_axis(q, p1[:, None, :], axis=1)[:, 0, :]
        better = (solve[:, None] & game.allowed) & (best_answer(q) > current + IMPROVEMENT)
        if not better.any():
            return x
        switched = np.where(better, q.argmax(axis=1), p1)
        if P1_LOOKAHEAD:
            w = x.copy()
            keep = ~solve
            for _ in range(P1_LOOKAHEAD):
                w = np.where(keep, w, game.bellman(w))
            qw = game.allowed_q(w)
            now = np.take_along_axis(qw, switched[:, None, :], axis=1)[:, 0, :]
            ahead = (solve[:, None] & game.allowed) & (best_answer(qw) > now + IMPROVEMENT)
            if ahead.any():
                jump = np.where(ahead, qw.argmax(axis=1), switched)
                p2_jump, new = _trap_response(game, jump, p2, zero)
                if (new >= x - IMPROVEMENT).all() and (new > x + IMPROVEMENT).any():
                    p1, p2, x = jump, p2_jump, new
                    continue
        p2_new, new = _trap_response(game, switched, p2, zero)
        dropped = new < x - DROP
        if dropped.any():
            switched = np.where(dropped[:, None], p1, switched)
            if (switched == p1).all():
                return x
            p2_new, new = _trap_response(game, switched, p2, zero)
            if (new < x - DROP).any():
                return x
        p1, p2, x = switched, p2_new, new
    raise SolverError(f"strategy iteration did not end in {MAX_ROUNDS} rounds")


def _trap_response(game: TurnBasedGame, p1: np.ndarray, p2: np.ndarray, zero: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """P2's best trap sets against P1's answers p1[g, a2] (an MDP in which she minimises the
    chance of the goal) and their exact values, by strategy iteration from p2.

    Where P2 can keep P1 from the goal forever against p1 the value is 0, fixed; from every
    other state each of her strategies reaches the goal or those states for sure, so her
    operator has a single fixed point, and switching where a trap set is better by more than
    IMPROVEMENT lowers the values until it is reached."""
    answers = p1[:, None, :] == np.arange(game.next.shape[1])[None, :, None]   # [G, A1, A2]
    pinned = zero | (game.positive_attractor(answers) < 0)
    solve = game.free & ~pinned
    # Her choices, by state: the allowed sets at the states to solve, and the successors and
    # probabilities of P1's answer to each (only these: with delay most states allow one set).
    n_a1, n_a2 = game.next.shape[1:3]
    pair_g, pair_a2 = np.nonzero(solve[:, None] & game.allowed)
    pair_next, pair_prob = game.moves((pair_g * n_a1 + p1[pair_g, pair_a2]) * n_a2 + pair_a2)
    starts = np.flatnonzero(np.r_[True, pair_g[1:] != pair_g[:-1]])
    states = pair_g[starts]
    first = _SegmentArgmin(pair_g, pair_a2, starts, game.size, n_a2)
    x = _evaluate_pair(game, p1, p2, pinned)
    for _ in range(MAX_ROUNDS):
        best, step = first(outcome_sum(pair_prob, x, pair_next), p2)
        if best is None:
            return p2, x
        # Look ahead (modified strategy iteration): the sets greedy for LOOKAHEAD sweeps of
        # her operator from x, kept only if their exact values are nowhere above x and below
        # it somewhere by more than IMPROVEMENT (else the plain step): every round lowers the
        # values, so no strategy comes back.
        w = x.copy()
        for _ in range(LOOKAHEAD):
            w[states] = np.minimum.reduceat(outcome_sum(pair_prob, w, pair_next), starts)
        _, jump = first(outcome_sum(pair_prob, w, pair_next), step)
        if (jump != step).any():
            new = _evaluate_pair(game, p1, jump, pinned)
            if (new <= x + IMPROVEMENT).all() and (new < x - IMPROVEMENT).any():
                p2, x = jump, new
                continue
        p2, x = step, _evaluate_pair(game, p1, step, pinned)
    raise SolverError(f"P2's strategy iteration did not end in {MAX_ROUNDS} rounds")


class _SegmentArgmin:
    """P2's switches over her choices listed pair by pair (state pair_g, set pair_a2, grouped
    by state from `starts`): called with each pair's value and her sets `p2` [G], it returns
    (True, p2 switched to the first set of least value wherever that is below the value of
    p2's set by more than IMPROVEMENT) or (None, p2) where she switches nowhere. The same
    choices as the argmin over a [G, A2] table with inf at the sets not listed, without one."""

    def __init__(self, pair_g: np.ndarray, pair_a2: np.ndarray, starts: np.ndarray,
                 size: int, n_a2: int) -> None:
        self.pair_g, self.pair_a2, self.starts, self.size = pair_g, pair_a2, starts, size
        self.states = pair_g[starts]
        self.lengths = np.diff(np.r_[starts, pair_g.size])
        self.index = np.full((size, n_a2), -1)
        self.index[pair_g, pair_a2] = np.arange(pair_g.size)

    def __call__(self, values: np.ndarray, p2: np.ndarray) -> tuple[bool | None, np.ndarray]:
        if not self.states.size:
            return None, p2
        least = np.minimum.reduceat(values, self.starts)
        at = self.index[self.states, p2[self.states]]
        current = np.where(at >= 0, values[at], np.inf)    # (p2 unlisted: any listed set is better)
        better = least < current - IMPROVEMENT
        if not better.any():
            return None, p2
        at_least = near_best(values, lowest=True, best=np.repeat(least, self.lengths))
        first = first_index(self.pair_g, self.size, at_least)[self.states[better]]
        switched = p2.copy()
        switched[self.states[better]] = self.pair_a2[first]
        return True, switched


def _greedy(game: TurnBasedGame, q: np.ndarray, optimal_slack: float) -> tuple[np.ndarray, np.ndarray]:
    """P1's answer to every trap set and P2's trap set (exactly greedy: strategy iteration
    needs it), greedy for values v whose one-step values are q = game.q_values(v) [G, A1, A2]."""
    return _greedy_ranked(game, q, optimal_slack)[:2]


def _greedy_ranked(game: TurnBasedGame, q: np.ndarray, optimal_slack: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """`_greedy`'s (p1, p2) and the ranks of the attractor of P1's near-optimal moves it used,
    when P1's answers are all among those moves (else None): then that attractor holds the
    same states as the attractor of P1's answers alone (`is_certified`'s). It holds no fewer
    (his answers are among the moves) and no more: at each of its states, of rank r > 0, and
    each of P2's sets, some near-optimal move enters rank < r with positive probability, so
    the near-optimal move he answers with, the one most likely to, does too."""
    best_a1 = best_answer(q)                                          # [G, A2]
    p2 = np.where(game.allowed, best_a1, np.inf).argmin(axis=1)
    # P1: among (near-)optimal answers, one that makes progress toward the goal, so that P1
    # never stalls (a wall bump can look exactly as good as a real move).
    optimal = near_best(q, optimal_slack, axis=1, best=best_a1[:, None, :])
    rank = game.positive_attractor(optimal)
    lower = np.where(rank >= 0, rank, np.iinfo(np.int64).max)
    # The chance of moving strictly closer: maximising it (not merely asking for a chance > 0)
    # keeps hitting times short and the linear systems well conditioned. Only at P2's allowed
    # sets (-1 at P1's other answers; the rest are never read: answer 0).
    flat, nxt, prob, _, _ = game.allowed_pairs()                    # [..., A1(, K)]
    from_state = np.take(lower, flat[..., :1] // optimal[0].size)
    gain = np.where(lower[nxt[..., 0]] < from_state, prob[..., 0], 0.0)
    for k in range(1, nxt.shape[-1]):       # outcome by outcome, as outcome_sum adds them
        gain = gain + np.where(lower[nxt[..., k]] < from_state, prob[..., k], 0.0)
    closer = np.where(optimal.reshape(-1)[flat], gain, -1.0)
    p1 = np.zeros(p2.shape + (game.next.shape[2],), dtype=np.intp)
    p1.reshape(-1)[np.flatnonzero(game.allowed)] = closer.argmax(axis=-1).reshape(-1)
    # closer is -1 exactly at the moves that are not near-optimal (a gain is >= 0)
    return p1, p2, (rank if (closer >= 0).any(axis=-1).all() else None)


def trap_rule(worst: np.ndarray, standing: np.ndarray | None, tie_break: str = "first"
              ) -> np.ndarray:
    """P2's choice of trap set (docs/semantics.md §4): worst[i, a2] is the value of P1's best answer to a2
    (inf where a2 is not allowed); the sets within TIE of the lowest are tied, and among them
    P2 keeps the standing set (standing[i], -1 for none) when it is tied, else takes the
    first (`tie_break` "first", the rule) or the last ("last")."""
    return keep_or_first(near_best(worst, TIE, axis=1, lowest=True), standing,
                         last=tie_break == "last")


def _evaluate_pair(game: TurnBasedGame, p1: np.ndarray, p2: np.ndarray, zero: np.ndarray) -> np.ndarray:
    """Exact reach probabilities when P2 plays p2[g] and P1 answers p1[g, a2]."""
    return _evaluate_moves(game, p1[np.arange(game.size), p2], p2, zero)


def _evaluate_moves(game: TurnBasedGame, a1: np.ndarray, p2: np.ndarray, zero: np.ndarray) -> np.ndarray:
    """Exact reach probabilities when P2 plays p2[g] and P1 moves a1[g] (0 on `zero`)."""
    n = game.size
    rows = np.arange(n)
    nxt, prob = game.moves((rows * game.next.shape[1] + a1) * game.next.shape[2] + p2)  # [G, K]
    solve = game.free & ~zero
    # States that can reach the goal in this chain (the rest have value 0): a breadth-first
    # search from the goal along reversed edges, entering only states to solve.
    edge = solve[:, None] & (prob > 0)
    solve &= backward_reach(np.broadcast_to(rows[:, None], nxt.shape)[edge], nxt[edge],
                            np.flatnonzero(game.goal), n)
    x = game.terminal.copy()
    idx = np.flatnonzero(solve)
    if idx.size:
        pos = np.full(n, -1)
        pos[idx] = np.arange(idx.size)
        sub_next, sub_prob = nxt[idx], prob[idx]
        inner = solve[sub_next] & (sub_prob > 0)
        r = np.broadcast_to(np.arange(idx.size)[:, None], sub_next.shape)[inner]
        c = pos[sub_next[inner]]
        matrix = sp.identity(idx.size, format="csr") - sp.csr_matrix(
            (sub_prob[inner], (r, c)), shape=(idx.size, idx.size))
        rhs = (sub_prob * game.terminal[sub_next]).sum(axis=1)
        x[idx] = solve_plain(matrix, rhs)
    return x


def is_certified(game: TurnBasedGame, p1: np.ndarray, x: np.ndarray) -> bool:
    """x is 0 wherever P2, against P1's answers p1, can avoid the goal forever: outside the
    positive attractor of the goal when P1 answers each a2 with p1[g, a2]."""
    answers = p1[:, None, :] == np.arange(game.next.shape[1])[None, :, None]   # [G, A1, A2]
    return _zero_outside(game.positive_attractor(answers), x)


def _zero_outside(rank: np.ndarray, x: np.ndarray) -> bool:
    """x is 0 (to 1e-12) outside the attractor of ranks `rank`."""
    return bool((x[rank < 0] <= 1e-12).all())


def fastest_answers(ts: TransitionSystem, dfa: DFA, solution: GameSolution,
                    discount: float = DISCOUNT) -> np.ndarray:
    """P1's answer at every game state to P2's strategy (docs/semantics.md §4's rule on the exact values,
    optimal up to its 1e-6 ties): among P1's value-optimal moves,
    the one maximising the discounted probability of reaching the goal, so that P1 never
    stalls (any optimal answer keeps the value, but some dither for a long time)."""
    return fastest_moves(ts, dfa, solution.values.reshape(-1), solution.p2_strategy,
                         discount).answers


@dataclass(frozen=True, eq=False)
class FastestMoves:
    """P1's fastest value-optimal moves against a fixed trap policy of P2, and the discounted
    reach scores they are ranked by (docs/semantics.md §§6-7: value first, then speed)."""

    answers: np.ndarray       # [G] P1's move: among the optimal ones, the largest score
    scores: np.ndarray        # [G] W(g): discounted probability of reaching the goal


def fastest_moves(ts: TransitionSystem, dfa: DFA, values: np.ndarray, p2: np.ndarray,
                  discount: float = DISCOUNT) -> FastestMoves:
    """P1's fastest optimal moves on TS x DFA when P2 plays the trap set p2[g] at every game
    state g and `values` [G] are P1's optimal values there (the leader pair of
    docs/semantics.md §7 when p2 is P2's leader strategy and `values` V_lead).

    A move is optimal when its one-step value is within 1e-9 of values[g]. The scores are
    W(g) = max over optimal a1 of sum_k P(k) * (1 if the outcome is a goal else discount *
    W(next_k)), iterated from 0 until the change is below 1e-12 (0 on absorbing states); P1
    plays the optimal move with the largest score, scores within a relative 1e-12 tied and
    ties to the first action slot (a padded slot repeats the state's first action, so it never
    wins a tie), by the rule every strategy is read with (numeric.fastest.fastest_first)."""
    game = TurnBasedGame(ts, dfa)
    v = np.asarray(values, dtype=float)
    rows = np.arange(game.size)
    nxt = game.next[rows, :, p2]                                      # [G, A1, K]
    prob = game.prob[rows, :, p2]
    optimal = (prob * v[nxt]).sum(-1) >= v[:, None] - EXACT_SLACK
    optimal &= game.free[:, None]                       # absorbing states: no move, score 0
    n_a1, n_k = nxt.shape[1:]
    choices = np.arange(game.size * n_a1)
    fastest = fastest_first(choices // n_a1, np.repeat(choices, n_k), nxt.reshape(-1),
                            prob.reshape(-1), game.goal, optimal.reshape(-1), EXACT_SCORE_STOP,
                            discount=discount)
    answers = np.where(fastest.choice >= 0, fastest.choice - rows * n_a1, 0)
    return FastestMoves(answers=answers, scores=fastest.scores)


def perceptual_game(ts: TransitionSystem, dfa: DFA, rationality: float,
                    shared: SharedParts | None = None, tie_break: str = "first"
                    ) -> PerceptualGame:
    """Solve G(x) and derive P2's strategy and her softmax model of P1 (docs/semantics.md
    §§4, 15): the softmax and the max over a1 range over the actions enabled at v. `shared`:
    the parts solved for the world's other games (`SharedParts`); `tie_break`: which of the
    tied sets P2 takes (`trap_rule`: [adversary] tie_break)."""
    game = TurnBasedGame(ts, dfa)
    solution = _solve(game, shared, tie_break, strategies=False)
    label = ts.state_label()
    fresh_q = dfa.delta[dfa.initial, label]                           # [S]
    flat = solution.values.reshape(-1)
    g = product_state(np.arange(ts.n_states), fresh_q, dfa.n_states)
    q = game.q_values(flat, g)                                        # [S, A1, A2]
    worst = np.where(ts.allowed, q.max(axis=1), np.inf)              # [S, A2] m(a2)
    choice = trap_rule(worst, _standing_sets(ts), tie_break)
    all_tied = (~ts.allowed | near_best(worst, TIE, axis=1, lowest=True)).all(axis=1)
    # A padded slot repeats action 0, so the max above is right unmasked; the softmax is not.
    scaled = np.where(ts.enabled[:, None, :], rationality * q.transpose(0, 2, 1), -np.inf)
    top = scaled.max(axis=2, keepdims=True)                           # [S, A2, A1max]
    log_policy = scaled - (top + np.log(np.exp(scaled - top).sum(axis=2, keepdims=True)))
    return PerceptualGame(formula=dfa.formula, dfa=dfa, values=solution.values,
                          fresh_q=fresh_q, trap_choice=choice, log_policy=log_policy,
                          all_tied=all_tied)
