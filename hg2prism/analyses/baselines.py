"""Symmetric-information Nash baseline (docs/semantics.md §7): the concurrent game on TS x DFA(phi).

Both players know the task phi and move at the same time with mixed strategies. The value is
the least fixed point of

    V(g) = val(M_g),   M_g[a1][a2] = sum_k prob[g, a1, a2, k] * V(next[g, a1, a2, k])

where `val` is the value of the zero-sum matrix game (P1 maximises over rows, P2 minimises over
her allowed columns). Value iteration from 0 converges to it from below (docs/semantics.md §10: stop when the
largest change is below 1e-10, fail past 10^6 sweeps).

Every sweep needs one matrix-game value per state, and on world1 value iteration needs about two
thousand sweeps, so one LP per state and sweep would be far too slow. Each sweep therefore
  1. finds, for all states at once, the matrices with a pure saddle point
     (max of row minima == min of column maxima): most states;
  2. for the others, re-uses the kernel (the square sub-matrix on the supports of both optimal
     strategies, Shapley-Snow) that solved the state last sweep: the two small linear systems
     are solved for all such states in one batch and the answer is accepted only if it is
     certified optimal (see below). Supports rarely change between sweeps;
  3. only where that fails, solves the LP with HiGHS, then reads the kernel off the LP's
     supports and polishes the LP solution with it.

Certificate: for mixed strategies x (P1) and y (P2), every value lies in
[min_j (x^T M)_j, max_i (M y)_i]. A solution is accepted when this gap is at most 1e-12, and the
lower end is used as the value, so every iterate stays below the least fixed point. HiGHS
(through scipy) rejects feasibility tolerances below 1e-10, so the kernel polish is what makes
values exact to 1e-12 rather than the LP tolerance.

Strategies are read off the final matrices. Where a state's game has a pure saddle point, P1
mixes uniformly over all moves that are optimal on their own instead of taking one saddle row:
still locally optimal, but it does not stall (e.g. against a wall where the value is 1) when
another optimal move makes progress. `guaranteed_value` then computes, exactly, what that
stationary strategy guarantees against a minimising P2 (docs/semantics.md §7 asks to report it beside V_NE).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from hg2prism import numeric
from hg2prism.model.automata import DFA
from hg2prism.model.product import product, product_state
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.errors import SolverError, probability
from hg2prism.numeric import ExplicitModel, near_best
from hg2prism.numeric.tables import fold, outcome_sum, ranges

VI_TOLERANCE = 1e-10        # docs/semantics.md §10: concurrent game, largest change per sweep
MAX_SWEEPS = 1_000_000
CHECK_SWEEPS = 100_000      # unconverged after this many: go on only while the bracket is wide
GAP = 1e-12                 # accepted width of a matrix game's certified value interval
LP_GAP = 1e-9               # an unpolished LP solution must still be this tight, or we fail
LP_OPTIONS = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}
SHORTFALL_WARNING = 1e-6    # docs/semantics.md §7: warn when P1's extracted strategy guarantees less
REFINED_TOLERANCE = 1e-14    # a bracket wider than SHORTFALL_WARNING: iterate on to this
REFINING_SWEEPS = 2          # ... within this many times the first iteration's sweeps in all
REFINING_LPS = 2000          # ... and this many LPs per tolerance (about 1 ms each; on a delay-2
                             # world one LP per state at every sweep near 1e-12)
SUPPORT = 1e-9              # a probability above this is in a strategy's support
TIE = 1e-9                  # a pure move this close to the value counts as optimal for P1


@dataclass(frozen=True, eq=False)
class ConcurrentGame:
    """A concurrent reachability game. goal states have value 1, zero states value 0; both are
    absorbing (their rows in next/prob are ignored). The others are `free`."""

    next: np.ndarray          # [G, A1, A2, K] successor of each outcome
    prob: np.ndarray          # [G, A1, A2, K] its probability
    allowed: np.ndarray       # [G, A2] bool: P2's available actions
    goal: np.ndarray          # [G] bool
    zero: np.ndarray          # [G] bool

    def __post_init__(self) -> None:
        g, a1, a2, k = self.next.shape
        if self.prob.shape != (g, a1, a2, k) or self.allowed.shape != (g, a2):
            raise ValueError("next, prob and allowed have inconsistent shapes")
        if self.goal.shape != (g,) or self.zero.shape != (g,):
            raise ValueError("goal and zero must have one entry per state")
        if (self.goal & self.zero).any():
            raise ValueError("a state cannot be both goal and zero")
        if not self.allowed.any(axis=1).all():
            raise ValueError("every state needs an allowed P2 action")
        if (self.next < 0).any() or (self.next >= g).any() or (self.prob < 0).any():
            raise ValueError("successors out of range or negative probabilities")
        total = self.prob.sum(axis=-1)[self.free]                       # [free, A1, A2]
        used = np.broadcast_to(self.allowed[self.free][:, None, :], total.shape)
        if not np.allclose(total[used], 1.0, atol=1e-9):
            raise ValueError("outcome probabilities of a free state do not sum to 1")

    @property
    def size(self) -> int:
        return self.next.shape[0]

    @property
    def free(self) -> np.ndarray:
        return ~(self.goal | self.zero)


@dataclass(frozen=True, eq=False)
class NashSolution:
    values: np.ndarray        # [G] V_NE
    p1: np.ndarray            # [G, A1] P1's stationary mixed strategy
    p2: np.ndarray            # [G, A2] P2's, 0 on disallowed actions
    sweeps: int
    lp_calls: int             # LPs solved (the rest was saddle points and cached kernels)
    converged: bool = True    # the last sweep changed no value by `tolerance` or more


@dataclass(frozen=True, eq=False)
class NashBaseline:
    """The Nash baseline on TS x DFA(phi), arrays indexed [TS state, DFA state, ...]."""

    game: ConcurrentGame
    solution: NashSolution
    values: np.ndarray        # [n_ts, n_q] value iteration's last iterate: V_NE where it converged
                              # (a lower bound where it stopped at a point bracket, §7)
    guaranteed: np.ndarray    # [n_ts, n_q] what P1's extracted strategy guarantees
    p1: np.ndarray            # [n_ts, n_q, A1max] (0 on slots not enabled at the state)
    p2: np.ndarray            # [n_ts, n_q, n_a2]
    initial: tuple[int, int]  # (start_state, delta(iota, L(start state)))
    v_ne: float
    v_ne_p1_guaranteed: float
    # The sound bracket around V_NE at the start (docs/semantics.md §7): what P1's extracted strategy
    # guarantees, and what P1's best response to P2's extracted strategy achieves.
    v_ne_bounds: tuple[float, float]
    # v_ne - v_ne_p1_guaranteed. It can be slightly negative (about -1e-8 on world1): value
    # iteration stops below the least fixed point, while the guarantee is computed exactly.
    shortfall: float

    @property
    def warn(self) -> bool:
        """docs/semantics.md §7: P1's stationary strategy guarantees noticeably less than V_NE."""
        return self.shortfall > SHORTFALL_WARNING

    @property
    def bracket_warn(self) -> bool:
        """docs/semantics.md §7: the sound bracket around V_NE is wider than 1e-6."""
        return self.v_ne_bounds[1] - self.v_ne_bounds[0] > SHORTFALL_WARNING


def concurrent_game(ts: TransitionSystem, dfa: DFA) -> ConcurrentGame:
    """TS x DFA(phi) as a concurrent game (the product's arrays; g = s * n_q + q)."""
    arena = product(ts, dfa)
    return ConcurrentGame(next=arena.next, prob=arena.prob, allowed=arena.allowed,
                          goal=arena.goal, zero=arena.fail)


# ---------------------------------------------------------------------------------------------
# Matrix games


@dataclass
class _Kernels:
    """Per state, the kernel (rows, columns) that solved its matrix game last time: its size
    (0: none) and its rows and columns, the first `size` entries of each state's row."""

    size: np.ndarray          # [G]
    rows: np.ndarray          # [G, min(A1, A2)]
    cols: np.ndarray          # [G, min(A1, A2)]
    lp_calls: int = 0

    @classmethod
    def none(cls, states: int, n1: int, n2: int) -> "_Kernels":
        k = min(n1, n2)
        return cls(size=np.zeros(states, dtype=np.int64),
                   rows=np.zeros((states, k), dtype=np.int64),
                   cols=np.zeros((states, k), dtype=np.int64))


@dataclass
class _Solved:
    """Certified solutions of a batch of matrix games."""

    value: np.ndarray         # [n] lower end of the certified interval
    x: np.ndarray             # [n, A1]
    y: np.ndarray             # [n, A2]
    ok: np.ndarray            # [n] bool: certified


def _certify(m: np.ndarray, allowed: np.ndarray, x: np.ndarray, y: np.ndarray,
             ok: np.ndarray) -> _Solved:
    """Clean up candidate strategies and keep those whose value interval is within GAP."""
    ok = ok & (x >= -GAP).all(axis=1) & (y >= -GAP).all(axis=1)
    x = np.clip(x, 0.0, None)
    y = np.where(allowed, np.clip(y, 0.0, None), 0.0)
    sx, sy = x.sum(axis=1, keepdims=True), y.sum(axis=1, keepdims=True)
    ok &= (sx[:, 0] > 0.5) & (sy[:, 0] > 0.5)
    x, y = x / np.where(sx > 0, sx, 1.0), y / np.where(sy > 0, sy, 1.0)
    lower = np.where(allowed, np.einsum("na,nab->nb", x, m), np.inf).min(axis=1)
    upper = np.einsum("nab,nb->na", m, y).max(axis=1)
    ok &= upper - lower <= GAP
    return _Solved(value=lower, x=x, y=y, ok=ok)


def _kernel_solve(m: np.ndarray, allowed: np.ndarray, rows: np.ndarray,
                  cols: np.ndarray) -> _Solved:
    """Solve every game m[i] on its k x k kernel (rows[i], cols[i]) and certify the result.

    On the kernel both players make the other indifferent:
        x^T B = v 1, sum x = 1      and      B y = w 1, sum y = 1.
    """
    n, k = rows.shape
    batch = np.arange(n)[:, None, None]
    b = m[batch, rows[:, :, None], cols[:, None, :]]                   # [n, k, k]
    # Both players' systems in one stack, P1's first (numpy solves and factors each matrix
    # of a stack on its own: the same numbers as two stacks, in half the calls).
    systems = np.zeros((2 * n, k + 1, k + 1))
    systems[:n, :k, :k] = b.transpose(0, 2, 1)
    systems[n:, :k, :k] = b
    systems[:, :k, k] = -1.0
    systems[:, k, :k] = 1.0
    rhs = np.zeros((2 * n, k + 1, 1))
    rhs[:, k] = 1.0
    # A singular system cannot be this kernel; swap in the identity so the batch solve works.
    # (Near-singular ones are solved: the certificate below rejects inaccurate answers.)
    nonsingular = np.linalg.det(systems) != 0
    regular = (nonsingular[:n] & nonsingular[n:]
               & allowed[np.arange(n)[:, None], cols].all(axis=1))
    systems[~np.concatenate((regular, regular))] = np.eye(k + 1)
    solved = np.linalg.solve(systems, rhs)[..., 0]
    xk, yk = solved[:n], solved[n:]
    x = np.zeros(m.shape[:2])
    y = np.zeros((n, m.shape[2]))
    x[np.arange(n)[:, None], rows] = xk[:, :k]
    y[np.arange(n)[:, None], cols] = yk[:, :k]
    return _certify(m, allowed, x, y, regular)


def _lp_solve(m: np.ndarray, allowed: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """One matrix game by LP: max v s.t. x^T M[:, j] >= v for allowed j, x a distribution.
    P2's optimal strategy is the dual of the column constraints."""
    n1 = m.shape[0]
    cols = np.flatnonzero(allowed)
    c = np.zeros(n1 + 1)
    c[-1] = -1.0
    a_ub = np.hstack([-m[:, cols].T, np.ones((cols.size, 1))])
    a_eq = np.append(np.ones(n1), 0.0)[None]
    res = linprog(c, A_ub=a_ub, b_ub=np.zeros(cols.size), A_eq=a_eq, b_eq=[1.0],
                  bounds=[(0, None)] * n1 + [(None, None)], method="highs", options=LP_OPTIONS)
    if res.status != 0:
        raise SolverError(f"matrix game LP failed: {res.message}")
    y = np.zeros(m.shape[1])
    y[cols] = -res.ineqlin.marginals
    return -res.fun, res.x[:n1], y


def _solve_matrix_games(m: np.ndarray, allowed: np.ndarray, states: np.ndarray,
                        kernels: _Kernels) -> _Solved:
    """Certified values and optimal strategies of the games m[i] (state states[i])."""
    n, n1, n2 = m.shape
    value = np.empty(n)
    x = np.zeros((n, n1))
    y = np.zeros((n, n2))

    # 1. Pure saddle points, all states at once.
    # (minima and maxima are exact in any order: folded slice by slice, as numpy's reduction
    # over an axis of 4 or 8 is several times slower)
    masked_min = fold(np.minimum, np.where(allowed[:, None, :], m, np.inf), 2)   # row minima
    col_max = np.where(allowed, fold(np.maximum, m, 1), np.inf)                  # column maxima
    row, col = masked_min.argmax(axis=1), col_max.argmin(axis=1)
    lower, upper = masked_min[np.arange(n), row], col_max[np.arange(n), col]
    done = upper - lower <= GAP
    value[done] = lower[done]
    # P1 mixes uniformly over every move that is optimal on its own. Any mixture of them is
    # optimal too, and unlike a single saddle row (often the first, N) it does not stall
    # against a wall while another optimal move makes progress.
    optimal = near_best(masked_min, TIE, axis=1, best=lower[:, None])
    x[done] = optimal[done] / optimal[done].sum(axis=1, keepdims=True)
    y[done, col[done]] = 1.0

    # 2. Last sweep's kernel, batched by kernel size.
    todo = np.flatnonzero(~done)
    sizes = kernels.size[states[todo]]
    for k in np.unique(sizes[sizes > 0]):
        idx = todo[sizes == k]
        rows, cols = kernels.rows[states[idx], :k], kernels.cols[states[idx], :k]
        got = _kernel_solve(m[idx], allowed[idx], rows, cols)
        hit = idx[got.ok]
        value[hit], x[hit], y[hit] = got.value[got.ok], got.x[got.ok], got.y[got.ok]
        done[hit] = True

    # 3. LP, then polish with the kernel on the LP's supports.
    for i in np.flatnonzero(~done):
        kernels.lp_calls += 1
        _, lp_x, lp_y = _lp_solve(m[i], allowed[i])
        rows, cols = np.flatnonzero(lp_x > SUPPORT), np.flatnonzero(lp_y > SUPPORT)
        if rows.size == cols.size:
            got = _kernel_solve(m[i:i + 1], allowed[i:i + 1], rows[None], cols[None])
            if got.ok[0]:
                value[i], x[i], y[i] = got.value[0], got.x[0], got.y[0]
                kernels.size[states[i]] = rows.size
                kernels.rows[states[i], :rows.size] = rows
                kernels.cols[states[i], :cols.size] = cols
                continue
        # Degenerate supports: keep the LP answer if it is tight enough, without a kernel.
        kernels.size[states[i]] = 0
        got = _certify(m[i:i + 1], allowed[i:i + 1], lp_x[None], lp_y[None], np.ones(1, bool))
        gap = np.einsum("ab,b->a", m[i], got.y[0]).max() - got.value[0]
        if gap > LP_GAP:
            raise SolverError(f"matrix game of state {states[i]}: LP value interval {gap:.2e} wide")
        value[i], x[i], y[i] = got.value[0], got.x[0], got.y[0]
    return _Solved(value=value, x=x, y=y, ok=np.ones(n, dtype=bool))


# ---------------------------------------------------------------------------------------------
# The concurrent game


def _entered(entering: sp.csr_matrix, states: np.ndarray) -> np.ndarray:
    """The sorted columns of `entering`'s rows `states`: the free states with a move that may
    enter one of them."""
    start, stop = entering.indptr[states], entering.indptr[states + 1]
    lengths = stop - start
    hit = np.zeros(entering.shape[1], dtype=bool)
    hit[entering.indices[ranges(start, lengths)]] = True
    return np.flatnonzero(hit)


def solve_nash(game: ConcurrentGame, tolerance: float = VI_TOLERANCE,
               start: NashSolution | None = None, budget: int | None = None,
               lp_budget: int | None = None) -> NashSolution:
    """V_NE by value iteration from 0 (or on from an earlier solution `start`, whose values are
    below the least fixed point too) until the largest change is below `tolerance`, and
    stationary locally optimal strategies read off the final matrix games.
    Raises SolverError past MAX_SWEEPS sweeps; with a `budget` (`lp_budget`), stops after that
    many sweeps (once that many LPs were solved) instead, at the iterate reached (still below
    the least fixed point)."""
    free = np.flatnonzero(game.free)
    kernels = _Kernels.none(game.size, game.next.shape[1], game.next.shape[2])
    v = game.goal.astype(float) if start is None else start.values.copy()
    n1 = game.next.shape[1]
    uniform = (np.full((game.size, n1), 1.0 / n1),
               game.allowed / game.allowed.sum(axis=1, keepdims=True))
    if not free.size:       # every state decided (a goal or a failure): nothing to iterate
        return NashSolution(values=v, p1=uniform[0], p2=uniform[1],
                            sweeps=0 if start is None else start.sweeps, lp_calls=0)
    # Only free states change: restrict the tables to them once.
    nxt, prob, allowed = game.next[free], game.prob[free], game.allowed[free]
    # A state's matrix game, hence its solution (saddle point, cached kernel or LP: each a
    # function of the matrix and the state's cached kernel, which only an LP sets), changes
    # only when a successor's value did: each sweep solves those states alone, with the same
    # numbers as a sweep over every state.
    entering = sp.csr_matrix(
        (np.ones(nxt[0].size * len(free), dtype=np.int8),
         (nxt.reshape(-1), np.repeat(np.arange(len(free)), nxt[0].size))),
        shape=(game.size, len(free)))
    entering.sum_duplicates()
    dirty = np.arange(len(free))
    for sweeps in range(1, MAX_SWEEPS + 1):
        block = outcome_sum(np.take(prob, dirty, axis=0), v, np.take(nxt, dirty, axis=0))
        solved = _solve_matrix_games(block, np.take(allowed, dirty, axis=0), free[dirty],
                                     kernels)
        # Certified lower ends are <= val(M), so the iterates stay below the fixed point;
        # the maximum keeps them monotone despite rounding.
        old = v[free[dirty]]
        new = np.maximum(old, solved.value)
        change = np.abs(new - old).max(initial=0.0)
        changed = free[dirty[new != old]]
        v[free[dirty]] = new
        if (change < tolerance or sweeps == budget
                or (lp_budget is not None and kernels.lp_calls >= lp_budget)):
            break
        dirty = _entered(entering, changed)
    else:
        raise SolverError(f"Nash value iteration did not converge in {MAX_SWEEPS} sweeps")

    # Strategies from the final matrices. Absorbing states: uniform (their moves do not matter).
    p1, p2 = uniform
    final = _solve_matrix_games(outcome_sum(prob, v, nxt), allowed, free, kernels)
    p1[free], p2[free] = final.x, final.y
    return NashSolution(values=v, p1=p1, p2=p2,
                        sweeps=sweeps + (0 if start is None else start.sweeps),
                        lp_calls=kernels.lp_calls, converged=bool(change < tolerance))


def _mixed_model(game: ConcurrentGame, mix: np.ndarray, player: int) -> ExplicitModel:
    """The MDP left to one player (1 or 2) when the other mixes with the stationary strategy
    `mix` [G, the other's actions]: its choices are the player's actions (P2's allowed ones
    only), their outcomes every (other action, successor) with its weight."""
    g, n1, n2, k = game.next.shape
    if player == 1:
        weight = mix[:, None, :, None] * game.prob                       # [G, A1, A2, K]
        return ExplicitModel.from_tables(game.next.reshape(g, n1, n2 * k),
                                         weight.reshape(g, n1, n2 * k))
    weight = (mix[:, :, None, None] * game.prob).transpose(0, 2, 1, 3)   # [G, A2, A1, K]
    return ExplicitModel.from_tables(game.next.transpose(0, 2, 1, 3).reshape(g, n2, n1 * k),
                                     weight.reshape(g, n2, n1 * k), game.allowed)


def guaranteed_value(game: ConcurrentGame, p1: np.ndarray) -> np.ndarray:
    """[G] reach probability P1 guarantees with the stationary mixed strategy p1: P2 minimises in
    the MDP where p1 is fixed. Solved exactly (hg2prism/numeric): the states where P2 can avoid
    the goal surely (outside the attractor where every P2 action risks the goal) get 0; on the
    rest every stationary P2 strategy reaches goal or those states with probability 1, so
    policy iteration with exact evaluation converges to the minimum (numeric/policy.py)."""
    model = _mixed_model(game, p1, player=2)
    rank = numeric.attractor(model, game.goal, every=True, stop=game.zero)
    first = model.first_best(model.matrix @ game.goal.astype(float), sense=-1.0)
    found = numeric.optimal_reach(model, game.goal, first, maximise=False, stop=rank < 0)
    if not found.converged:
        raise SolverError("policy iteration for P1's guaranteed value did not converge")
    return found.values


def best_response_value(game: ConcurrentGame, p2: np.ndarray,
                        improvement: float = numeric.policy.FLOOR) -> np.ndarray:
    """[G] P1's maximal reach probability against P2's stationary mixed strategy p2 (an MDP).
    Solved exactly (hg2prism/numeric): policy iteration starts from an attractor policy (each
    move gives a positive chance of getting closer to the goal, so the goal or a state of value
    0 is reached with probability 1) and switches a move only on a strict improvement: by more
    than `improvement` plus twice the bound on the evaluation's rounding error, so that a move
    that stalls never looks better by rounding where values are within rounding of 1
    (numeric/policy.py proves that it terminates). Where the last policy's chain is
    ill-conditioned (a walk left only by unlikely outcomes), it is solved again on the quotient
    of the end components (`collapse`, numeric/policy.py). V_static (docs/semantics.md §11)
    asks for an improvement of 1e-12."""
    model = _mixed_model(game, p2, player=1)
    rank = numeric.attractor(model, game.goal, stop=game.zero)
    progress = numeric.progress_choices(model, rank)
    first = np.where(progress >= 0, progress, model.group_start[:-1])
    found = numeric.optimal_reach(model, game.goal, first, stop=game.zero, floor=improvement,
                                  collapse=True)
    if not found.converged:
        raise SolverError("policy iteration for P1's best response did not converge")
    return found.values


def _enabled_only(ts: TransitionSystem, p1: np.ndarray, n_q: int) -> np.ndarray:
    """P1's mixed strategy [G, A1max] with the weight of padded action slots (not enabled: they
    repeat the state's first action, so the game cannot tell them apart) moved to slot 0."""
    disabled = np.repeat(~ts.enabled, n_q, axis=0)
    if not disabled.any():
        return p1
    p1 = p1.copy()
    p1[:, 0] += np.where(disabled, p1, 0.0).sum(axis=1)
    p1[disabled] = 0.0
    return p1


@dataclass(frozen=True, eq=False)
class _Bracket:
    """The ends of the Nash bracket at the start state g0 (docs/semantics.md §7) and the
    strategies that give them."""

    guaranteed: np.ndarray    # [G] what p1 guarantees
    lower: float              # guaranteed[g0]
    p1: np.ndarray
    upper: float              # P1's best response to p2 at g0
    p2: np.ndarray


def _bracket(game: ConcurrentGame, solution: NashSolution, g0: int,
             best: _Bracket | None = None) -> _Bracket:
    """The bracket of the strategies read off `solution`, each end kept from `best` where it
    was better there: each end is sound whichever iterate its strategy comes from."""
    guaranteed = guaranteed_value(game, solution.p1)
    upper = best_response_value(game, solution.p2)[g0]
    if best is not None and not guaranteed[g0] > best.lower:
        guaranteed, lower, p1 = best.guaranteed, best.lower, best.p1
    else:
        lower, p1 = probability(guaranteed[g0], "P1's guaranteed Nash value"), solution.p1
    if best is not None and not upper < best.upper:
        upper, p2 = best.upper, best.p2
    else:
        upper = probability(upper, "P1's best response to P2's Nash strategy")
        p2 = solution.p2
    return _Bracket(guaranteed=guaranteed, lower=lower, p1=p1, upper=upper, p2=p2)


def nash_baseline(ts: TransitionSystem, dfa: DFA) -> NashBaseline:
    """The Nash baseline of docs/semantics.md §7 for the task DFA, read at every (s, q) and at the start."""
    game = concurrent_game(ts, dfa)
    n_q = dfa.n_states
    q0 = int(dfa.delta[dfa.initial, ts.state_label()[ts.start_state]])
    g0 = product_state(ts.start_state, q0, n_q)
    # Where value iteration has not converged after CHECK_SWEEPS sweeps (an edge of probability
    # 1e-6 leaks that little per sweep), the strategies read off its iterate give a sound
    # bracket: it goes on, CHECK_SWEEPS sweeps at a time, only while that bracket is wider than
    # VI_TOLERANCE, and at most MAX_SWEEPS sweeps in all (then the bracket is the answer). A
    # 5-node attack graph ran 10^6 sweeps (43 s) for a bracket that was the point 1.
    solution = solve_nash(game, budget=CHECK_SWEEPS)
    ends = _bracket(game, solution, g0)
    while (not solution.converged and solution.sweeps < MAX_SWEEPS
           and ends.upper - ends.lower > VI_TOLERANCE):
        solution = solve_nash(game, start=solution,
                              budget=min(CHECK_SWEEPS, MAX_SWEEPS - solution.sweeps))
        ends = _bracket(game, solution, g0, ends)
    # A wide bracket: strategies read off values that have not converged enough (ties between
    # trap sets that the exact values would break). Value iteration goes on, 100 times
    # tighter each time down to 1e-14, and each end keeps the best strategy found.
    tolerance = VI_TOLERANCE
    sweeps = solution.sweeps
    while ends.upper - ends.lower > SHORTFALL_WARNING and tolerance > REFINED_TOLERANCE:
        tolerance /= 100.0
        left = REFINING_SWEEPS * sweeps - solution.sweeps
        if left <= 0:
            break
        solution = solve_nash(game, tolerance, start=solution, budget=left,
                              lp_budget=REFINING_LPS)
        ends = _bracket(game, solution, g0, ends)
    guaranteed, v_guaranteed, p1, upper, p2 = (ends.guaranteed, ends.lower, ends.p1,
                                                ends.upper, ends.p2)
    if v_guaranteed > upper + 1e-9:
        raise SolverError(f"the Nash bracket is empty: [{v_guaranteed!r}, {upper!r}]")
    # Each end is an exact solve within its rounding (about 1e-11 on ill-conditioned chains):
    # where the lower end computes above the upper one (by at most 1e-9), V_NE is both.
    upper = max(upper, v_guaranteed)
    # Value iteration approaches V_NE from below, and the lower end of the bracket is also
    # below V_NE: the larger of the two is the better estimate, kept inside the bracket.
    v_ne = min(max(probability(solution.values[g0], "V_NE"), v_guaranteed), upper)
    return NashBaseline(
        game=game, solution=solution,
        values=solution.values.reshape(ts.n_states, n_q),
        guaranteed=guaranteed.reshape(ts.n_states, n_q),
        p1=_enabled_only(ts, p1, n_q).reshape(ts.n_states, n_q, -1),
        p2=p2.reshape(ts.n_states, n_q, -1),
        initial=(ts.start_state, q0), v_ne=v_ne, v_ne_p1_guaranteed=v_guaranteed,
        v_ne_bounds=(v_guaranteed, upper), shortfall=v_ne - v_guaranteed,
    )
