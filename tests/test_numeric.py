"""The numeric core (hg2prism/numeric) against closed forms and the independent reference.

* closed forms: gambler's ruin, an unreachable target (0) and a sure one (1), bounded
  reachability of a two-state chain, expected steps of a geometric chain, a hand-made MDP's
  attractor ranks and optimal values (maximiser and minimiser), and a chain left with
  probability 1e-9 whose error bound must cover the solve's actual error;
* the 50 generated worlds of tests/worldgen.py: the models come from the reference
  (tests/reference_deception.py: the MDP of V_static, the chain of the naive strategy, built
  from the semantics without hg2prism); the numeric core's attractor equals the states of
  positive value of the reference's solver and a naive level-by-level fixed point, its
  optimal values equal `reference.solve_reach_game`'s, its chain values `reference.dtmc_reach`'s,
  its bounded reachability a step-by-step iteration over dictionaries, and its expected steps a
  dense solve;
* bounded reachability (`numeric.bounded_reach`, its one implementation) on random small chains
  against its definition in plain Python (the distribution after each step), exact at its
  0s and 1s (bound 0, a start in the goal, no path within the bound, a goal reached surely);
* the lexicographic objective (strategy/objectives.py, built on the attractor) on random MDPs
  against its definition in plain Python: finite states, expected steps and moves;
* OpenBLAS's kernels and numpy's SIMD loops (hg2prism/reproducible.py): importing hg2prism
  first pins them to their AVX2 code, so that SciPy's sparse LU and numpy's exp and log give
  the same last bits on every x86-64 machine with AVX2.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import reference
import reference_deception
import worldgen
from hg2prism import numeric
from hg2prism.numeric import ExplicitModel
from conftest import share

FAMILY = worldgen.world_family()
TOL = 1e-10


def model_of(rows_of: list[list[dict]]) -> tuple[ExplicitModel, np.ndarray, np.ndarray]:
    """An ExplicitModel from successor dictionaries {state index, "goal" or "fail": p}, per
    state and choice; states n and n + 1 are goal and fail (no choices). Also the goal and
    fail masks."""
    n = len(rows_of)
    where = {"goal": n, "fail": n + 1}
    rows, cols, probs = [], [], []
    all_choices = [succ for choices in rows_of for succ in choices]
    for r, succ in enumerate(all_choices):
        rows += [r] * len(succ)
        cols += [where.get(t, t) for t in succ]
        probs += list(succ.values())
    counts = [len(choices) for choices in rows_of] + [0, 0]
    n_choices = len(all_choices)
    matrix = sp.csr_matrix((probs, (rows, cols)), shape=(n_choices, n + 2))
    model = ExplicitModel(matrix=matrix, group_start=np.r_[0, np.cumsum(counts)])
    goal, fail = np.zeros(n + 2, dtype=bool), np.zeros(n + 2, dtype=bool)
    goal[n], fail[n + 1] = True, True
    return model, goal, fail


def chain_of(succs: list[list[tuple]]) -> tuple[ExplicitModel, np.ndarray, np.ndarray]:
    """model_of for a chain: one choice per state."""
    return model_of([[dict(_merge(s))] for s in succs])


def _merge(succ):
    merged: dict = {}
    for t, p in succ:
        merged[t] = merged.get(t, 0.0) + p
    return merged.items()


# ---------------------------------------------------------------------------------------------
# Closed forms
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("p", [0.3, 0.5, 0.7])
def test_gamblers_ruin(p: float) -> None:
    """From i of 0..N, up with p, down with 1 - p: P(reach N) = (1 - r^i) / (1 - r^N), r =
    (1 - p) / p (i / N when p = 1/2); 0 is the ruin."""
    n = 20
    succs = [[("fail", 1.0)]] + [[(i + 1 if i + 1 < n else "goal", p), (i - 1 if i > 1 else 0,
                                                                        1 - p)]
                                 for i in range(1, n)]
    succs[0] = [("fail", 1.0)]
    model, goal, fail = chain_of(succs)
    got = numeric.chain_reach(model.chain(model.group_start[:-1]), goal, fail)
    i = np.arange(1, n)
    r = (1 - p) / p
    exact = i / n if p == 0.5 else (1 - r ** i) / (1 - r ** n)
    assert np.abs(got.values[1:n] - exact).max() <= got.error + 1e-15
    assert got.values[0] == 0.0 and got.error < 1e-13


def test_unreachable_target_is_zero_and_sure_target_is_one() -> None:
    """0 exactly where the chain cannot reach the target; 1 exactly where it cannot avoid it
    (a cycle left only towards the goal): graph analysis, not a solve."""
    succs = [[(1, 0.5), (0, 0.5)], [(0, 0.9), ("goal", 0.1)], [(3, 1.0)], [(2, 0.4), ("fail", 0.6)]]
    model, goal, fail = chain_of(succs)
    got = numeric.chain_reach(model.chain(model.group_start[:-1]), goal, fail)
    assert got.values.tolist() == [1.0, 1.0, 0.0, 0.0, 1.0, 0.0]
    assert got.error == 0.0


@pytest.mark.parametrize("horizon", [0, 1, 2, 7, 1000])
def test_bounded_reach_of_two_states(horizon: int) -> None:
    """State 0 enters the goal with probability p each step, else stays: 1 - (1 - p)^k."""
    p = 0.3
    model, goal, fail = chain_of([[("goal", p), (0, 1 - p)]])
    got = numeric.bounded_reach(model.chain(model.group_start[:-1]), goal, goal | fail, 0,
                                horizon)
    assert got == pytest.approx(1 - (1 - p) ** horizon, abs=1e-12)


def plain_bounded(rows: list[list[tuple[int, float]]], goal: list[bool], stop: list[bool],
                  start: int, horizon: int) -> float:
    """P(goal within `horizon` steps) by its definition, forwards: the distribution over the
    states after each step (the `stop` states keep their mass), its mass on the goal at the
    end."""
    mass = {start: 1.0}
    for _ in range(horizon):
        after: dict[int, float] = {}
        for s, m in mass.items():
            for t, p in ([(s, 1.0)] if stop[s] else rows[s]):
                after[t] = after.get(t, 0.0) + m * p
        mass = after
    return sum(m for s, m in mass.items() if goal[s])


def random_chain(rng: np.random.Generator, n: int) -> tuple[list[list[tuple[int, float]]],
                                                            list[bool], list[bool]]:
    """A random chain on n states as successor lists (some probabilities exactly 0, some
    states without a way to the goal), a goal and the absorbing states (goal among them)."""
    rows = []
    for _ in range(n):
        targets = rng.choice(n, size=int(rng.integers(1, min(n, 4) + 1)), replace=False)
        weights = rng.random(len(targets)) * (rng.random(len(targets)) < 0.8)
        weights[0] += 0.05
        rows.append(list(zip(targets.tolist(), (weights / weights.sum()).tolist())))
    goal = (rng.random(n) < 0.2).tolist()
    stop = [g or rng.random() < 0.15 for g in goal]
    return rows, goal, stop


def csr_of(rows: list[list[tuple[int, float]]]) -> sp.csr_matrix:
    """The chain's matrix, its zero entries kept (bounded_reach must not count them as edges)."""
    n = len(rows)
    entries = [(s, t, p) for s, row in enumerate(rows) for t, p in row]
    s, t, p = zip(*entries)
    return sp.csr_matrix((p, (s, t)), shape=(n, n))


def test_bounded_reach_against_its_definition() -> None:
    """numeric.bounded_reach, the one implementation of bounded reachability, equals the
    forward distribution of plain_bounded on random small chains from every state and bound
    (to CONVERGED: it stops once that close to the unbounded value), and exactly where the
    answer is 0 or 1: bound 0, a start in the goal or stopped outside it, no path to the goal
    within the bound (the goal unreachable, or reachable only in more steps), the goal
    reached surely."""
    rng = np.random.default_rng(11)
    for _ in range(40):
        n = int(rng.integers(1, 9))
        rows, goal, stop = random_chain(rng, n)
        chain = csr_of(rows)
        for start in range(n):
            assert numeric.bounded_reach(chain, np.array(goal), np.array(stop), start,
                                         0) == float(goal[start])
            for horizon in (1, 2, 5, 30, 1000):
                got = numeric.bounded_reach(chain, np.array(goal), np.array(stop), start,
                                            horizon)
                want = plain_bounded(rows, goal, stop, start, horizon)
                assert got == pytest.approx(want, abs=numeric.chains.CONVERGED + 1e-14)
                if stop[start]:         # a goal at the start, or stopped outside the goal
                    assert got == want == float(goal[start])
                if want == 0.0:         # no path to the goal in at most `horizon` steps
                    assert got == 0.0
    # paths of two and three steps from state 0 to the goal (state 3), a zero entry towards a
    # stop state (5) that is no goal, and a state (4) that cannot reach the goal: exactly 0
    # before step 2 and from states 4 and 5, 0.75 at step 2, exactly 1 from step 3 on
    rows = [[(1, 0.25), (2, 0.75)], [(5, 0.0), (2, 1.0)], [(3, 1.0)], [], [(4, 1.0)], [(5, 1.0)]]
    goal, stop = [False, False, False, True, False, False], [False, False, False, True, False,
                                                             True]
    chain = csr_of(rows)
    for horizon in range(6):
        for start, want in ((0, (0.0, 0.0, 0.75, 1.0, 1.0, 1.0)[horizon]),
                            (1, float(horizon >= 2)), (4, 0.0), (5, 0.0), (3, 1.0)):
            assert plain_bounded(rows, goal, stop, start, horizon) == want
            assert numeric.bounded_reach(chain, np.array(goal), np.array(stop), start,
                                         horizon) == want


def test_expected_steps_of_a_geometric_chain() -> None:
    """Goal with a, fail with b, stay with 1 - a - b: P(goal) = a / (a + b), and the time to
    either end, with or without conditioning on the goal, is geometric with mean 1 / (a + b)."""
    a, b = 0.1, 0.15
    model, goal, fail = chain_of([[("goal", a), ("fail", b), (0, 1 - a - b)]])
    steps = numeric.expected_steps(model.chain(model.group_start[:-1]), 0, goal, goal | fail)
    assert steps.goal_probability == pytest.approx(a / (a + b), rel=1e-14)
    assert steps.to_end == pytest.approx(1 / (a + b), rel=1e-14)
    assert steps.to_goal == pytest.approx(1 / (a + b), rel=1e-14)
    never = numeric.expected_steps(model.chain(model.group_start[:-1]), 0, fail & ~fail,
                                   goal | fail)
    assert (never.goal_probability, never.to_goal) == (0.0, None)


def hand_mdp() -> tuple[ExplicitModel, np.ndarray, np.ndarray]:
    """0: stay, or a fair coin to 1 or fail; 1: goal w.p. 0.5 else back to 0, or stay;
    2: to 0 surely, or to fail; 3: only stays."""
    return model_of([[{0: 1.0}, {1: 0.5, "fail": 0.5}],
                     [{"goal": 0.5, 0: 0.5}, {1: 1.0}],
                     [{0: 1.0}, {"fail": 1.0}],
                     [{3: 1.0}]])


def test_attractor_ranks_and_choices() -> None:
    model, goal, fail = hand_mdp()
    rank = numeric.attractor(model, goal, stop=fail)
    assert rank.tolist() == [2, 1, 3, -1, 0, -1]
    assert numeric.progress_choices(model, rank).tolist() == [1, 2, 4, -1, -1, -1]
    every = numeric.attractor(model, goal, every=True, stop=fail)
    assert every.tolist() == [-1, -1, -1, -1, 0, -1]
    assert numeric.can_reach(model, goal, fail).tolist() == [True, True, True, False, True,
                                                             False]


@pytest.mark.parametrize("seed", range(40))
def test_downstream_first_orders_the_strongly_connected_sets(seed: int) -> None:
    """numeric.downstream_first on random small graphs (self-loops, cycles, isolated nodes)
    against the definition, with reachability found by a depth-first search here: the sets
    partition the nodes, two nodes share a set exactly when each reaches the other, and a set
    comes after every other set it reaches."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 9))
    successor = rng.integers(0, n, size=(n, int(rng.integers(1, 4))))
    sinks = rng.random(n) < 0.3                         # nodes with a self-loop only
    successor[sinks] = np.arange(n)[sinks][:, None]
    reaches = []
    for i in range(n):
        seen, stack = {i}, [i]
        while stack:
            for j in successor[stack.pop()]:
                if int(j) not in seen:
                    seen.add(int(j))
                    stack.append(int(j))
        reaches.append(seen)
    order = numeric.downstream_first(successor)
    assert sorted(i for part in order for i in part) == list(range(n))
    position = {i: k for k, part in enumerate(order) for i in part}
    for i in range(n):
        for j in range(n):
            mutual = j in reaches[i] and i in reaches[j]
            assert (position[i] == position[j]) == mutual, (i, j)
            if j in reaches[i] and not mutual:
                assert position[j] < position[i], (i, j)


def test_optimal_values_of_a_hand_mdp() -> None:
    """Maximiser: 0 -> 1 and 1 -> goal: x1 = 0.5 + 0.5 x0, x0 = 0.5 x1 give x0 = 1/3, x1 = 2/3;
    2 takes 0. Minimiser: everyone stays (or fails) and nothing reaches the goal."""
    model, goal, fail = hand_mdp()
    progress = numeric.progress_choices(model, numeric.attractor(model, goal, stop=fail))
    first = np.where(progress >= 0, progress, model.group_start[:-1])
    best = numeric.optimal_reach(model, goal, first, stop=fail)
    assert best.converged
    np.testing.assert_allclose(best.values, [1 / 3, 2 / 3, 1 / 3, 0, 1, 0], atol=1e-15)
    rank = numeric.attractor(model, goal, every=True, stop=fail)
    worst = numeric.optimal_reach(model, goal, model.group_start[:-1], maximise=False,
                                  stop=rank < 0)
    assert worst.values.tolist() == [0, 0, 0, 0, 1, 0]


def test_a_chain_left_with_probability_1e9() -> None:
    """A class of two states swapping, left with probability 1e-9 towards the goal (0.7) or
    failure (0.3): the value 0.7 is exact while the system is ill-conditioned; the error
    bound must cover the solve's actual error (the cause of issue 22's item 9 on maze 113)."""
    eps = 1e-9
    model, goal, fail = chain_of([[(1, 1 - eps), ("goal", 0.7 * eps), ("fail", 0.3 * eps)],
                                  [(0, 1 - eps), ("goal", 0.7 * eps), ("fail", 0.3 * eps)]])
    got = numeric.chain_reach(model.chain(model.group_start[:-1]), goal, fail)
    assert np.abs(got.values[:2] - 0.7).max() <= got.error
    assert got.error < 1e-5


def naive_end_components(rows_of: list[list[dict]], inside: set[int]
                         ) -> tuple[set[frozenset], set[tuple[int, int]]]:
    """The maximal end components by their definition, with sets: keep the choices that stay
    inside (a choice whose weights are all 0 goes nowhere: it leaves), group the states that
    reach each other along them, drop the choices that leave their group, until nothing
    changes. Returns (the components, their (state, choice) pairs)."""
    kept = {(s, c) for s in inside for c, succ in enumerate(rows_of[s])
            if all(t in inside for t, p in succ.items() if p > 0)
            and any(p > 0 for p in succ.values())}
    while True:
        reach = {s: {s} for s in inside}
        changed = True
        while changed:
            changed = False
            for s, c in kept:
                for t, p in rows_of[s][c].items():
                    if p > 0 and not reach[t] <= reach[s]:
                        reach[s] |= reach[t]
                        changed = True
        group = {s: frozenset(t for t in reach[s] if s in reach[t]) for s in inside}
        narrower = {(s, c) for s, c in kept
                    if all(t in group[s] for t, p in rows_of[s][c].items() if p > 0)}
        if narrower == kept:
            return {group[s] for s, _ in kept}, kept
        kept = narrower


@pytest.mark.parametrize("seed", range(40))
def test_end_components_against_their_definition(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 14))
    targets = list(range(n)) + ["goal", "fail"]
    rows_of = []
    for _ in range(n):
        choices = []
        for _ in range(int(rng.integers(1, 4))):
            picked = rng.choice(len(targets), size=int(rng.integers(1, 3)), replace=False)
            weight = rng.random(len(picked)) * (rng.random() > 0.1)  # now and then all 0
            choices.append({targets[i]: float(w) for i, w in zip(picked, weight)})
        rows_of.append(choices)
    model, goal, fail = model_of(rows_of)
    inside = ~(goal | fail) & (rng.random(n + 2) > 0.15)
    component, internal = numeric.end_components(model, inside)
    expected, pairs = naive_end_components(rows_of, set(np.flatnonzero(inside).tolist()))
    got = {frozenset(np.flatnonzero(component == label).tolist())
           for label in set(component.tolist()) - {-1}}
    assert got == expected
    assert set(np.flatnonzero(internal).tolist()) == {
        int(model.group_start[s]) + c for s, c in pairs}


def test_a_walk_that_leaves_slowly() -> None:
    """A ring of 6 states, each moving on (or on, except with probability 1e-9 to state 6),
    and state 6, which exits (goal 0.8, fail 0.2) or goes back to the ring: one end component
    whose only exit is 6's, worth 0.8 everywhere. From the leaking walk, plain policy iteration
    never switches (every gain is within its error bound) and ends with the walk's
    ill-conditioned chain; the quotient's node has one choice and its value is exact."""
    eps = 1e-9
    ring = [[{(i + 1) % 6: 1 - eps, 6: eps}, {(i + 1) % 6: 1.0}] for i in range(6)]
    model, goal, fail = model_of(ring + [[{0: 1.0}, {"goal": 0.8, "fail": 0.2}]])
    start = np.r_[model.group_start[:6], model.group_start[6] + 1, 0, 0]
    plain = numeric.optimal_reach(model, goal, start, stop=fail, floor=1e-12)
    assert plain.converged and plain.error > numeric.policy.ILL_CONDITIONED
    found = numeric.optimal_reach(model, goal, start, stop=fail, floor=1e-12, collapse=True)
    assert found.converged and found.error < 1e-14 and found.residual < 1e-14
    np.testing.assert_allclose(found.values[:7], 0.8, rtol=0, atol=1e-15)
    assert found.choice[6] == model.group_start[6] + 1            # state 6 exits
    # the others walk to 6 along the component's own choices: the first with a chance of
    # getting there is the leaking move, whose values the quotient's are
    assert found.choice[:6].tolist() == model.group_start[:6].tolist()


def test_quotient_of_a_component_without_exit() -> None:
    """hand_mdp's state 3 only stays: an end component without exit, worth 0 in the quotient;
    0 and 1 each stay in their own component and exit by their other choice."""
    model, goal, fail = hand_mdp()
    start = model.group_start[:-1].copy()
    found = numeric.policy._on_quotient(model, goal, start, fail, 1e-14, 0.0, 100)
    assert found.converged
    np.testing.assert_allclose(found.values, [1 / 3, 2 / 3, 1 / 3, 0, 1, 0], atol=1e-15)


# ---------------------------------------------------------------------------------------------
# The generated worlds, against the reference
# ---------------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def reference_models(name: str, tmp: str):
    """(the static MDP's successor rows or None, the naive chain's successors)."""
    path = __import__("pathlib").Path(tmp) / f"{name}.toml"
    path.write_text(dict(FAMILY)[name])
    ref = reference_deception.Deception(path)
    mdp = ref.static_mdp()
    _, table = ref.naive_table()
    chain = reference_deception.chain_successors(ref.w, table) if table else None
    return (None if mdp is None else mdp[1]), chain


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(tmp_path_factory.mktemp("numeric"))


def naive_attractor(rows_of: list[list[dict]]) -> list[int]:
    """Level by level, with sets: the rank of each state for "some choice has a positive
    chance of entering a lower rank" (goal rank 0), -1 outside."""
    rank = {"goal": 0}
    level = 0
    while True:
        level += 1
        new = [i for i, choices in enumerate(rows_of) if i not in rank and any(
            any(p > 0 and t in rank for t, p in succ.items()) for succ in choices)]
        if not new:
            return [rank.get(i, -1) for i in range(len(rows_of))]
        rank.update((i, level) for i in new)


def dictionary_bounded(succs: list[list[tuple]], start: int, horizon: int) -> float:
    """P(goal within `horizon` steps), one step at a time over dictionaries."""
    reach = [0.0] * len(succs)
    for _ in range(horizon):
        reach = [sum(p * (1.0 if t == "goal" else 0.0 if t == "fail" else reach[t])
                     for t, p in succ) for succ in succs]
    return reach[start]


def dense_steps(succs: list[list[tuple]]) -> tuple[float, float]:
    """P(goal) and E[steps to the end] from state 0 by a dense solve (finite only when every
    state ends)."""
    n = len(succs)
    matrix, to_goal = np.zeros((n, n)), np.zeros(n)
    for i, succ in enumerate(succs):
        for t, p in succ:
            if t == "goal":
                to_goal[i] += p
            elif t != "fail":
                matrix[i, t] += p
    system = np.eye(n) - matrix
    return (float(np.linalg.solve(system, to_goal)[0]),
            float(np.linalg.solve(system, np.ones(n))[0]))


@pytest.mark.parametrize("name", share(name for name, _ in FAMILY))     # every fourth under `make test`
def test_family_against_reference(name: str, folder: str) -> None:
    rows_of, succs = reference_models(name, folder)
    if rows_of is not None:
        model, goal, fail = model_of(rows_of)
        rank = numeric.attractor(model, goal, stop=fail)
        progress = numeric.progress_choices(model, rank)
        assert rank[:-2].tolist() == naive_attractor(rows_of)
        state_pairs = [[i] for i in range(len(rows_of))]
        pair_rows = [list(range(4 * i, 4 * i + 4)) for i in range(len(rows_of))]
        row_succ = [list(succ.items()) for choices in rows_of for succ in choices]
        exact = reference.solve_reach_game(state_pairs, pair_rows, row_succ)
        np.testing.assert_array_equal(rank[:-2] >= 0, exact > 0)
        first = np.where(progress >= 0, progress, model.group_start[:-1])
        best = numeric.optimal_reach(model, goal, first, stop=fail)
        assert best.converged and best.error < 1e-10
        np.testing.assert_allclose(best.values[:-2], exact, atol=TOL)
        # the same maximum on the quotient of the end components (numeric/policy.py)
        quotient = numeric.policy._on_quotient(model, goal, first, fail, numeric.policy.FLOOR,
                                               0.0, 10_000)
        assert quotient.converged and quotient.error < 1e-10
        np.testing.assert_allclose(quotient.values[:-2], exact, atol=TOL)
    if succs is None:
        return
    model, goal, fail = chain_of(succs)
    chain = model.chain(model.group_start[:-1])
    got = numeric.chain_reach(chain, goal, fail)
    np.testing.assert_allclose(got.values[:-2], reference.dtmc_reach(succs), atol=TOL)
    for horizon in (1, 3, 10, 40):
        assert numeric.bounded_reach(chain, goal, goal | fail, 0, horizon) == pytest.approx(
            dictionary_bounded(succs, 0, horizon), abs=TOL)
    steps = numeric.expected_steps(chain, 0, goal, goal | fail)
    assert steps.goal_probability == pytest.approx(got.values[0], abs=TOL)
    ends = numeric.can_reach(model, goal | fail)[:-2].all()
    if ends:
        probability, to_end = dense_steps(succs)
        assert steps.goal_probability == pytest.approx(probability, abs=TOL)
        assert steps.to_end == pytest.approx(to_end, rel=1e-9)
    else:
        assert steps.to_end is None


@pytest.mark.parametrize("slots", [1, 2, 3, 7, 8, 11])
def test_outcome_sum_adds_left_to_right(slots: int) -> None:
    """numeric.tables.outcome_sum: left to right, slot by slot, hence numpy's own sum below 8
    slots bit for bit (pairwise beyond, where only the left fold is promised)."""
    from hg2prism.numeric.tables import outcome_sum

    rng = np.random.default_rng(slots)
    prob = rng.random((400, 4, 5, slots))
    v = rng.random(50)
    nxt = rng.integers(0, 50, size=prob.shape)
    got = outcome_sum(prob, v, nxt)
    left = prob[..., 0] * v[nxt[..., 0]]
    for k in range(1, slots):
        left = left + prob[..., k] * v[nxt[..., k]]
    assert np.array_equal(got, left)
    if slots < 8:
        assert np.array_equal(got, (prob * v[nxt]).sum(axis=-1))
    np.testing.assert_allclose(got, (prob * v[nxt]).sum(axis=-1), rtol=1e-14)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_fold_is_the_reduction(axis: int) -> None:
    from hg2prism.numeric.tables import fold

    table = np.random.default_rng(axis).random((30, 4, 8))
    table[3, 2, 5] = np.inf
    for ufunc in (np.minimum, np.maximum):
        assert np.array_equal(fold(ufunc, table, axis), ufunc.reduce(table, axis=axis))


def test_backward_distance_counts_edges_into_the_sources() -> None:
    """numeric.graph.backward_distance (the certification's first strategy ranks moves by it):
    0 -> 1 -> 2, 3 -> 1, 4 alone, 2 -> 0 (a cycle back): from the source 2 the fewest edges are
    2, 1, 0, 2, inf; with sources 2 and 4 the same but 0 at 4; no source: inf everywhere."""
    import math

    from hg2prism.numeric.graph import backward_distance

    rows, columns = np.array([0, 1, 3, 2]), np.array([1, 2, 1, 0])
    assert backward_distance(rows, columns, np.array([2]), 5).tolist() == [2, 1, 0, 2, math.inf]
    assert backward_distance(rows, columns, np.array([2, 4]), 5).tolist() == [2, 1, 0, 2, 0]
    assert np.isinf(backward_distance(rows, columns, np.array([], dtype=int), 5)).all()


def test_min_expected_steps_against_closed_forms() -> None:
    """numeric.min_expected_steps (the lexicographic objective's): state 0 ends with
    probability 1/2 per step by its first choice (2 steps expected) or moves to state 1, which
    ends with probability 1/4 per step (4, so 5 from 0); from the proper second choice it
    switches to the first: [2, 4, 0]. With the first choice not allowed, it keeps [5, 4, 0]."""
    import scipy.sparse as sp

    from hg2prism.numeric import ExplicitModel, min_expected_steps

    matrix = sp.csr_matrix(np.array([[0.5, 0.0, 0.5],      # state 0, choice 0
                                     [0.0, 1.0, 0.0],      # state 0, choice 1
                                     [0.0, 0.75, 0.25]]))  # state 1
    model = ExplicitModel(matrix=matrix, group_start=np.array([0, 2, 3, 3]))
    states, start = np.array([0, 1]), np.array([1, 2, -1])
    found = min_expected_steps(model, states, np.ones(3, dtype=bool), start)
    assert found.converged and found.values.tolist() == pytest.approx([2.0, 4.0, 0.0])
    assert found.choice[:2].tolist() == [0, 2] and found.rounds == 2
    kept = min_expected_steps(model, states, np.array([False, True, True]), start)
    assert kept.values.tolist() == pytest.approx([5.0, 4.0, 0.0]) and kept.rounds == 1


def _lexicographic_by_definition(n, choices, absorbing, values, slack=1e-8):
    """The lexicographic objective's finite states and expected steps in plain Python
    (docs/semantics.md §6): `choices` lists per state its choices (lists of (target,
    probability)); a choice is optimal when its value is within `slack` of its state's. Φ is
    the greatest set from which the absorbing states are reached by optimal choices whose
    successors stay in Φ or are absorbing; E by value iteration over those choices."""
    optimal = [[sum(p * values[t] for t, p in c) >= values[s] - slack for c in choices[s]]
               for s in range(n)]
    phi = {s for s in range(n) if not absorbing[s]}
    while True:
        def stays(s, k):
            return optimal[s][k] and all(t in phi or absorbing[t] for t, _ in choices[s][k])
        reached = {s for s in range(n) if absorbing[s]}
        grown = True
        while grown:
            grown = False
            for s in phi - reached:
                if any(stays(s, k) and any(t in reached for t, _ in c)
                       for k, c in enumerate(choices[s])):
                    reached.add(s)
                    grown = True
        now = reached - {s for s in range(n) if absorbing[s]}
        if now == phi:
            break
        phi = now
    e = [0.0] * n
    for _ in range(20_000):
        e = [min(1.0 + sum(p * e[t] for t, p in c) for k, c in enumerate(choices[s])
                 if stays(s, k)) if s in phi else 0.0 for s in range(n)]
    return phi, e, stays


@pytest.mark.parametrize("seed", [0, 1, 3, 4, 5, 6, 7, 8])    # seeds with both kinds of state
def test_lexicographic_objective_against_its_definition(seed: int) -> None:
    """strategy.objectives.lexicographic_actions on random MDPs (4 action slots, some missing,
    self-loops, states with no optimal way out) against _lexicographic_by_definition: the
    same finite states, expected steps within 1e-9, an allowed move of least expected steps
    at every finite state and the default's move elsewhere."""
    from hg2prism.strategy.canonical import CanonicalMDP
    from hg2prism.strategy.objectives import lexicographic_actions

    rng = np.random.default_rng(seed)
    n = 14
    absorbing = [s >= n - 2 for s in range(n)]          # n - 2 goal, n - 1 fail
    values = np.r_[rng.choice([0.0, 0.5, 1.0], size=n - 2), 1.0, 0.0]
    choices, state, action, entry_choice, entry_target, entry_prob = [], [], [], [], [], []
    for s in range(n):
        mine = []
        if not absorbing[s]:
            for a in range(4):
                if rng.random() < 0.3:
                    continue
                targets = rng.choice(n, size=int(rng.integers(1, 3)), replace=False)
                probs = rng.dirichlet(np.ones(len(targets)))
                mine.append(list(zip(targets.tolist(), probs.tolist())))
                for t, p in mine[-1]:
                    entry_choice.append(len(state))
                    entry_target.append(t)
                    entry_prob.append(p)
                state.append(s)
                action.append(a)
        choices.append(mine)
    goal, fail = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    goal[n - 2], fail[n - 1] = True, True
    mdp = CanonicalMDP(n=n, representative=np.arange(n), goal=goal, fail=fail,
                       choice_state=np.array(state), choice_action=np.array(action),
                       choice_storm=np.arange(len(state)), entry_choice=np.array(entry_choice),
                       entry_target=np.array(entry_target), entry_prob=np.array(entry_prob),
                       n_actions=4)
    default = np.full(n, -1)
    for s in range(n - 2):
        if choices[s]:
            default[s] = action[state.index(s)]
    found = lexicographic_actions(mdp, values, default)
    phi, e, stays = _lexicographic_by_definition(n, choices, absorbing, values)
    assert set(np.flatnonzero(found.finite).tolist()) == phi
    assert 0 < len(phi) < n - 2            # the seeds give both kinds of state
    for s in range(n):
        if s in phi:
            assert found.expected[s] == pytest.approx(e[s], rel=1e-9)
            slots = [a for a, st in zip(action, state) if st == s]
            k = slots.index(int(found.action[s]))
            assert stays(s, k)
            assert 1.0 + sum(p * e[t] for t, p in choices[s][k]) == pytest.approx(e[s], rel=1e-9)
        elif not absorbing[s]:
            assert np.isinf(found.expected[s]) and found.action[s] == default[s]


def _fastest_by_definition(states, choices, goal, optimal, stop, tie=1e-12):
    """The fastest-first rule in plain Python (docs/semantics.md §6): `choices` lists per
    state its choices, each a list of (target, probability); W iterated from 0 until it changes
    by less than `stop`; the first optimal choice within a relative `tie` of the best."""
    w = [0.0] * states

    def score(c):
        return sum(p if goal[t] else 0.9 * p * w[t] for t, p in c)

    numbered = [[(k, c) for k, c in enumerate(cs)] for cs in choices]
    index, flat = 0, []
    for s in range(states):
        flat.append([(index + k, c) for k, c in numbered[s] if optimal[index + k]])
        index += len(choices[s])
    for _ in range(1000):
        new = [max((score(c) for _, c in flat[s]), default=0.0) for s in range(states)]
        change = max(abs(a - b) for a, b in zip(new, w))
        w = new
        if change < stop:
            break
    chosen = []
    for s in range(states):
        scored = [(i, score(c)) for i, c in flat[s]]
        top = max((x for _, x in scored), default=None)
        chosen.append(-1 if top is None else next(i for i, x in scored if x >= top - tie * abs(top)))
    return chosen, w


@pytest.mark.parametrize("seed", range(6))
def test_fastest_first_against_its_definition(seed: int, monkeypatch) -> None:
    """numeric.fastest.fastest_first, which every strategy's fastest-first rule calls, against
    the rule in plain Python on random MDPs with repeated targets, exact ties (probabilities
    1/4 and 1/2, symmetric choices), states without an optimal choice and goal states; and its
    two-thread sweep (for large models) gives the same numbers bit for bit."""
    from hg2prism.numeric import fastest

    rng = np.random.default_rng(seed)
    states = 40
    goal = rng.random(states) < 0.1
    choices = []
    for s in range(states):
        own = []
        for _ in range(0 if goal[s] else int(rng.integers(0, 4))):
            shape = [0.5, 0.25, 0.25] if rng.random() < 0.7 else [1.0]
            own.append([(int(rng.integers(states)), p) for p in shape])
        if own and rng.random() < 0.3:
            own.append(list(own[0]))                        # the same choice again: a tie
        choices.append(own)
    optimal = np.array([rng.random() < 0.7 for cs in choices for _ in cs])
    choice_state = np.array([s for s, cs in enumerate(choices) for _ in cs], dtype=np.int64)
    entries = [(k, t, p) for k, c in enumerate(c for cs in choices for c in cs) for t, p in c]
    entry_choice, entry_target, entry_prob = (np.array(x) for x in zip(*entries))
    expected, w = _fastest_by_definition(states, choices, goal, optimal, 1e-12)
    got = fastest.fastest_first(choice_state, entry_choice.astype(np.int64),
                                entry_target.astype(np.int64), entry_prob.astype(float), goal,
                                optimal, 1e-12)
    assert got.choice.tolist() == expected
    assert got.scores == pytest.approx(w, abs=1e-11)
    assert (got.choice >= 0).sum() < states and (got.choice >= 0).any()   # both kinds present
    monkeypatch.setattr(fastest, "THREADED_GROUPS", 2)
    threaded = fastest.fastest_first(choice_state, entry_choice.astype(np.int64),
                                     entry_target.astype(np.int64), entry_prob.astype(float),
                                     goal, optimal, 1e-12)
    assert np.array_equal(threaded.choice, got.choice)
    assert np.array_equal(threaded.scores, got.scores)


def test_fastest_first_ties_scores_equal_but_for_rounding() -> None:
    """Two moves with the same chance of the goal, 0.1 + 0.2 + 0.3 and 0.3 + 0.2 + 0.1, whose
    sums differ in the last bit (the second larger): within the relative 1e-12 they tie and the
    first wins, as every strategy's rule says; with no tolerance the second would."""
    from hg2prism.numeric import fastest

    assert 0.1 + 0.2 + 0.3 > 0.3 + 0.2 + 0.1
    choice_state = np.array([0, 0])
    entry_choice = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    entry_target = np.array([1, 1, 1, 2, 1, 1, 1, 2])
    entry_prob = np.array([0.3, 0.2, 0.1, 0.4, 0.1, 0.2, 0.3, 0.4])
    goal = np.array([False, True, False])
    optimal = np.array([True, True])
    tied = fastest.fastest_first(choice_state, entry_choice, entry_target, entry_prob, goal,
                                 optimal, 1e-12)
    strict = fastest.fastest_first(choice_state, entry_choice, entry_target, entry_prob, goal,
                                   optimal, 1e-12, relative_tie=0.0)
    assert tied.choice.tolist() == [0, -1, -1] and strict.choice.tolist() == [1, -1, -1]
    assert tied.scores[0] == 0.1 + 0.2 + 0.3


def test_choices_taking_and_first_index_against_their_definitions() -> None:
    """numeric.choices_taking (a strategy by action laid on a model's choices: strategy/
    deceptive.storm_choices and robust deception both wrote it) and numeric.first_index (the
    first Storm state of each canonical state: the canonical MDP and robust deception), against
    plain loops on random models, with absent actions (-1), unwanted states and absent keys."""
    rng = np.random.default_rng(7)
    for _ in range(20):
        n = int(rng.integers(1, 30))
        counts = rng.integers(1, 5, n)
        choice_state = np.repeat(np.arange(n), counts)
        choice_action = rng.integers(-1, 4, len(choice_state))
        wanted = rng.integers(-1, 4, n)
        got = numeric.choices_taking(choice_state, choice_action, wanted, n)
        for s in range(n):
            mine = np.flatnonzero(choice_state == s)
            hits = [c for c in mine if choice_action[c] == wanted[s] and choice_action[c] >= 0]
            assert got[s] == (hits[0] if hits else mine[0])
        keys = rng.integers(0, 12, int(rng.integers(0, 40)))
        first = numeric.first_index(keys, 12)
        for k in range(12):
            where = np.flatnonzero(keys == k)
            assert first[k] == (where[0] if where.size else -1)


# Small dyadic values, so that differences and margins are exact: 0.75 is exactly within 0.25
# (absolute, or relative to a best of 1) of 1.0, and lies on the tolerance.
TIE_VALUES = np.array([-1.0, 0.0, 0.5, 0.75, 1.0, 1.0, 2.0])
TIE_CASES = [(tie, relative, lowest) for tie in (0.0, 0.25, 0.5) for relative in (False, True)
             for lowest in (False, True)]


def _loop_near_best(row: list[float], tie: float, relative: bool, lowest: bool,
                    best: float | None = None) -> list[bool]:
    """numeric.near_best of one row of options, by its definition in plain Python."""
    if best is None:
        best = min(row) if lowest else max(row)
    margin = tie * abs(best) if relative else tie
    return [v <= best + margin if lowest else v >= best - margin for v in row]


def _tie_tables(rng: np.random.Generator) -> list[np.ndarray]:
    """Random small tables [rows, options] of TIE_VALUES (exact ties), with absent options
    (inf, -inf), a single option, every option tied, and rows with every option absent."""
    tables = []
    for _ in range(30):
        rows, options = int(rng.integers(1, 6)), int(rng.integers(1, 5))
        table = rng.choice(TIE_VALUES, (rows, options))
        table[rng.random((rows, options)) < 0.15] = rng.choice([np.inf, -np.inf])
        tables.append(table)
    tables += [np.full((3, 4), 0.5), np.array([[1.0], [-np.inf], [np.inf]]),
               np.array([[np.inf, np.inf], [-np.inf, -np.inf], [0.75, 1.0]])]
    return tables


def test_the_dense_tie_rules_against_plain_loops() -> None:
    """numeric.near_best, first_near_best, first_near_best_of and keep_or_first (the tie
    rules of P2's trap sets, the objectives' moves, the naive answers, the Bayesian and
    CUSUM observers, the baselines' optimal moves: one implementation for all, a code review
    found them written about seven times) against their definitions in plain Python, on random
    small tables: exact ties, values exactly at the tolerance, absolute and relative
    tolerances, largest and smallest, all options tied, a single option, absent options."""
    rng = np.random.default_rng(11)
    for table in _tie_tables(rng):
        preferred = rng.integers(-1, table.shape[1], len(table))
        for tie, relative, lowest in TIE_CASES:
            with np.errstate(invalid="ignore"):     # 0 * inf and inf - inf: NaN, none tied
                tied = numeric.near_best(table, tie, axis=1, relative=relative, lowest=lowest)
                first = numeric.first_near_best(table, tie, axis=1, relative=relative,
                                                lowest=lowest)
                down = numeric.first_near_best(table.T, tie, axis=0, relative=relative,
                                               lowest=lowest)
            for i, row in enumerate(table.tolist()):
                want = _loop_near_best(row, tie, relative, lowest)
                assert tied[i].tolist() == want
                top = max((k for k in range(len(row)) if want[k]), default=len(row) - 1)
                assert first[i] == down[i] == (want.index(True) if any(want) else 0)
                kept = numeric.keep_or_first(tied[i:i + 1], preferred[i:i + 1])[0]
                last = numeric.keep_or_first(tied[i:i + 1], None, last=True)[0]
                assert kept == (preferred[i] if preferred[i] >= 0 and want[preferred[i]]
                                else first[i])
                assert last == top
                if not relative and not lowest:
                    assert numeric.first_near_best_of(row, tie) == first[i]
        given = table.max(axis=1, keepdims=True)
        assert np.array_equal(numeric.near_best(table, 0.5, axis=1, best=given),
                              numeric.near_best(table, 0.5, axis=1))


def test_the_grouped_tie_rules_against_plain_loops() -> None:
    """numeric.first_index with `where`, first_best and ExplicitModel.first_best (the first of
    each state's choices that attains, or comes within a tolerance of, its best: certification's
    first strategy, the attractor's moves, policy iteration, P2's switches, the fastest-first
    rule) against plain loops on random groups: exact ties, values exactly at the relative
    tolerance, a single choice, every choice tied, states without choices or without a tied
    choice, group labels with gaps; and the grouped form against the dense one."""
    rng = np.random.default_rng(12)
    for _ in range(40):
        n = int(rng.integers(1, 12))
        counts = rng.integers(0, 4, n)
        counts[rng.integers(n)] = max(1, counts.max())
        state = np.repeat(np.arange(n), counts)
        score = rng.choice(TIE_VALUES[:-2], len(state))       # finite: no inf among choices
        where = rng.random(len(state)) < 0.6
        got = numeric.first_index(state, n, where)
        for s in range(n):
            mine = [c for c in np.flatnonzero(state == s) if where[c]]
            assert got[s] == (mine[0] if mine else -1)
        model = ExplicitModel(matrix=sp.csr_matrix((len(state), n)),
                              group_start=np.r_[0, np.cumsum(counts)])
        for sense in (1.0, -1.0):
            first = model.first_best(score, sense)
            for s in range(n):
                mine = np.flatnonzero(state == s).tolist()
                values = [sense * score[c] for c in mine]
                assert first[s] == (mine[values.index(max(values))] if mine else -1)
        labels = np.cumsum(rng.integers(1, 3, n))[state]            # runs, labels with gaps
        for tie in (0.0, 0.25, 0.5):
            best = numeric.first_best(score, labels, relative_tie=tie)
            runs = [np.flatnonzero(labels == label).tolist() for label in np.unique(labels)]
            assert best.tolist() == [run[_loop_near_best(score[run].tolist(), tie, True, False)
                                         .index(True)] for run in runs]
    table = rng.choice(TIE_VALUES, (50, 4))
    assert np.array_equal(numeric.argmax_by_group(table.reshape(-1), np.repeat(np.arange(50), 4),
                                                  50, relative_tie=0.25) - np.arange(50) * 4,
                          numeric.first_near_best(table, 0.25, axis=1, relative=True))


def test_the_lexicographic_objective_says_when_its_policy_iteration_stopped_early(
        monkeypatch, caplog) -> None:
    """lexicographic_actions promises the fewest expected steps among the Pmax-optimal moves,
    but took the moves of policy iteration stopped by its round limit in silence (a code
    review): stopped, it warns. On world1 one round is not enough; the default is."""
    import logging

    import hg2prism
    from hg2prism.strategy import objectives

    world = hg2prism.load_world(Path(__file__).resolve().parent.parent / "models" / "world1.toml")
    said = "the lexicographic objective's policy iteration stopped after 1 rounds"
    for rounds, warned in ((1, True), (objectives.MAX_POLICY_ITERATIONS, False)):
        monkeypatch.setattr(objectives, "MAX_POLICY_ITERATIONS", rounds)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="hg2prism"):
            hg2prism.solve(world, objective="lexicographic")
        assert any(said in r.getMessage() for r in caplog.records) == warned



# ---------------------------------------------------------------------------------------------
# The same last bits on every x86-64 machine with AVX2 (hg2prism/reproducible.py)
# ---------------------------------------------------------------------------------------------

_KERNELS = ("import {first}, scipy.sparse.linalg, os\n"
            "from hg2prism.reproducible import kernels\n"
            "print(repr((kernels(), os.environ.get('OPENBLAS_CORETYPE'), "
            "os.environ.get('NPY_DISABLE_CPU_FEATURES'))))")
_PINNED = ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES", "HG2PRISM_KERNELS")


def _kernels_in_a_new_process(first: str, **env: str) -> tuple:
    import ast
    import os
    import subprocess
    import sys

    environment = {k: v for k, v in os.environ.items() if k not in _PINNED} | env
    done = subprocess.run([sys.executable, "-c", _KERNELS.format(first=first)], env=environment,
                          capture_output=True, text=True, timeout=120, check=True)
    return ast.literal_eval(done.stdout.strip())


def test_importing_hg2prism_first_pins_openblas_and_numpy_to_their_avx2_code() -> None:
    """SciPy's sparse LU (the games' exact solves) calls OpenBLAS, whose AVX-512 kernels gave
    other last bits than an AVX2 machine's (other ties, other strategies: the snapshot test
    failed on a Xeon), and numpy's AVX-512 exp and log other log-likelihood ratios: importing
    hg2prism before numpy pins OpenBLAS to its Haswell kernels, as OpenBLAS itself then
    reports, and numpy to its AVX2 loops (X86_V3). A variable the user set is kept,
    HG2PRISM_KERNELS=native pins nothing, and numpy imported first keeps its own code (and
    does not pin the processes it starts either)."""
    import platform

    from hg2prism.reproducible import NEEDS, _cpu_flags

    if platform.machine() != "x86_64" or not NEEDS <= _cpu_flags():
        pytest.skip("not an x86-64 processor with AVX2 and FMA: nothing is pinned")
    avx512 = "avx512f" in _cpu_flags()
    pinned, blas, simd = _kernels_in_a_new_process("hg2prism")
    assert pinned == {"blas_kernels": "Haswell", "numpy_simd": "X86_V3"}
    assert blas == "Haswell" and (simd == "X86_V4 AVX512_ICL AVX512_SPR") == avx512
    chosen, blas, _ = _kernels_in_a_new_process("hg2prism", OPENBLAS_CORETYPE="Sandybridge")
    assert chosen["blas_kernels"] == blas == "Sandybridge" and chosen["numpy_simd"] == "X86_V3"
    for first, env in (("numpy, hg2prism", {}), ("hg2prism", {"HG2PRISM_KERNELS": "native"})):
        native, blas, simd = _kernels_in_a_new_process(first, **env)
        assert blas is None and simd is None, first
        assert native["blas_kernels"] != "unknown"
        assert ("X86_V4" in native["numpy_simd"]) == avx512, native
