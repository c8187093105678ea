"""The certified `sound` method (docs/semantics.md §10): a fast solver's strategy evaluated exactly
and checked to be a fixed point of the Bellman operator.

  * on the generated family (delays 0-2, one and two traps, windows 1-3) its values equal Storm's
    own sound solver's within 1e-10 at every state;
  * a strategy that is not optimal is flagged (certified False, with the reason), not returned,
    and the check then falls back to Storm's sound solver;
  * on hand-made MDPs the certificate agrees with values computed by hand, including an end
    component where a naive fixed point would be 1 instead of 0.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from hg2prism import pipeline
from hg2prism.engines import certify, storm
from hg2prism.worldfile import load_world
from hg2prism.prism.hypergame import PROPERTY

import worldgen
from conftest import share

FAMILY = worldgen.world_family()


@functools.cache
def _model(name: str, folder: str) -> tuple[object, object]:
    seed, params = next((s, p) for n, s, p in worldgen.FAMILY if n == name)
    path = Path(folder) / f"{name}.toml"
    path.write_text(worldgen.make_world(seed, name=name, **params))
    out = Path(folder) / name
    pipeline.generate(pipeline.analyse(load_world(path)), out)
    model, formula, _ = storm.build(out / "hypergame.prism", PROPERTY)
    return model, formula


@pytest.mark.parametrize("name", share(name for name, _ in FAMILY))    # every fourth under `make test`
def test_certified_values_equal_storms_sound_solver(name: str, world_dir: Path) -> None:
    model, formula = _model(name, str(world_dir))
    certified = storm.certificate(model, formula)
    assert certified.certified, certified.reason
    assert certified.bellman_residual <= certify.BELLMAN_RESIDUAL
    sound, _ = storm.solve(model, formula, "storm-sound")
    assert np.abs(certified.values - sound).max() <= 1e-10
    # the route `check` takes returns the certified values themselves
    values, _ = storm.solve(model, formula, "sound")
    assert np.array_equal(values, certified.values)


def _stall(choice: np.ndarray, group_start: np.ndarray) -> np.ndarray:
    """Every state takes its last choice instead: not optimal on a world with a positive value."""
    return group_start[1:] - 1


def test_a_value_that_is_not_a_fixed_point_is_flagged(world_dir: Path, monkeypatch) -> None:
    model, formula = _model("fam00_d0_l1_w1_x2", str(world_dir))
    sound, _ = storm.solve(model, formula, "storm-sound")
    assert 0 < sound[model.initial_states[0]] < 1
    flagged = storm.certificate(model, formula, max_rounds=1, perturb=_stall)
    assert not flagged.certified
    assert "fixed point" in flagged.reason and flagged.bellman_residual > 1e-3
    # given rounds, strategy improvement repairs the same strategy
    repaired = storm.certificate(model, formula, perturb=_stall)
    assert repaired.certified and np.abs(repaired.values - sound).max() <= 1e-10

    # `solve` does not return a value it could not certify: it warns and asks Storm's sound solver
    warnings = []
    monkeypatch.setattr("hg2prism.progress.warn", lambda text: warnings.append(text))
    monkeypatch.setattr(storm, "certificate",
                        lambda m, f: flagged)
    values, _ = storm.solve(model, formula, "sound")
    assert warnings and "could not certify" in warnings[0]
    assert np.array_equal(values, sound)


def _mdp(rows: list[list[tuple[int, float]]], groups: list[int]) -> tuple[sp.csr_matrix, np.ndarray]:
    """A [choices x states] matrix from rows of (target, probability), choices grouped by state."""
    data, indices, indptr = [], [], [0]
    for row in rows:
        for target, p in row:
            indices.append(target)
            data.append(p)
        indptr.append(len(data))
    n = len(groups)
    matrix = sp.csr_matrix((data, indices, indptr), shape=(len(rows), n))
    return matrix, np.r_[0, np.cumsum(groups)]


def test_hand_made_mdp_with_an_end_component() -> None:
    # states: 0 start, 1 loop (an end component with 0), 2 goal, 3 fail
    # 0: a -> goal 0.5 / fail 0.5; b -> 1
    # 1: stay -> 1; back -> 0; exit -> goal 0.9 / fail 0.1
    rows = [[(2, 0.5), (3, 0.5)], [(1, 1.0)],
            [(1, 1.0)], [(0, 1.0)], [(2, 0.9), (3, 0.1)],
            [(2, 1.0)], [(3, 1.0)]]
    matrix, group_start = _mdp(rows, [2, 3, 1, 1])
    goal = np.array([False, False, True, False])
    # 0 takes b, 1 stays: the end component {1} would be a fixed point at 1 of the equations,
    # but the strategy's value there is 0 (graph analysis), so it is improved, not accepted
    staying = np.array([1, 2, 5, 6])
    once = certify.certify_reachability(matrix, group_start, goal, staying, max_rounds=1)
    assert not once.certified and once.values[1] == 0 and once.bellman_residual == pytest.approx(0.9)
    done = certify.certify_reachability(matrix, group_start, goal, staying)
    assert done.certified
    np.testing.assert_allclose(done.values, [0.9, 0.9, 1.0, 0.0], atol=1e-15)
    assert list(done.choice[:2]) == [1, 4]


def test_an_ill_conditioned_chain_is_certified_in_extended_precision() -> None:
    """A ring of 50 states left only from state 0, with probability 1e-6 to the goal and to
    failure each (value 1/2 everywhere): the double solve's error bound (8e-9) is above
    LINEAR_ERROR, so the certificate re-solves the strategy with its residuals in extended
    precision (bound 4e-12) rather than failing (world1 with a drawing Bayesian observer fell
    back to Storm's sound solver so, its bound 8.8e-10)."""
    from hg2prism.numeric import chain_reach

    n, leak = 50, 1e-6
    rows = [[(1, 1 - 2 * leak), (n, leak), (n + 1, leak)]]
    rows += [[((s + 1) % n, 0.5), (s, 0.5)] for s in range(1, n)]
    rows += [[(n, 1.0)], [(n + 1, 1.0)]]
    matrix, group_start = _mdp(rows, [1] * (n + 2))
    goal = np.zeros(n + 2, dtype=bool)
    goal[n] = True
    assert chain_reach(matrix, goal).error > certify.LINEAR_ERROR
    done = certify.certify_reachability(matrix, group_start, goal, np.arange(n + 2))
    assert done.certified, done.reason
    assert done.linear_error <= certify.LINEAR_ERROR
    np.testing.assert_allclose(done.values[:n], 0.5, atol=1e-11)
