"""V_NE (docs/semantics.md §7) against the independent reference tests/reference_nash.py:
its exact small matrix-game solver against linear programming, and the package's V_NE inside
the reference's sound bracket on the model worlds (tests/test_mazes.py does the same on the
mazes `run` runs; tests/test_baselines_run.py on world1's results.json)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hg2prism
import reference_nash
from conftest import MODELS, QUICK
from hg2prism import progress

TOL = 1e-6          # docs/semantics.md §10: results compare equal within 1e-6


@pytest.mark.parametrize("k1", [1, 2, 3, 4])
@pytest.mark.parametrize("k2", [1, 2, 3, 5])
def test_small_game_values_match_linprog(k1: int, k2: int) -> None:
    rng = np.random.default_rng(10 * k1 + k2)
    m = rng.random((60, k1, k2))
    m[:20] = np.round(m[:20] * 3) / 3          # ties, duplicate rows and columns
    m[20:25] = m[20:25, :1]                    # identical rows
    low, x = reference_nash.lower_value(m)
    high, y = reference_nash.upper_value(m)
    for s in range(len(m)):
        value = reference_nash.lp_value(m[s])
        assert low[s] == pytest.approx(value, abs=1e-9)
        assert high[s] == pytest.approx(value, abs=1e-9)
        # the strategies are probability vectors that certify the values
        assert x[s].min() >= 0 and x[s].sum() == pytest.approx(1.0)
        assert y[s].min() >= 0 and y[s].sum() == pytest.approx(1.0)
        assert (x[s] @ m[s]).min() == pytest.approx(low[s], abs=1e-12)
        assert (m[s] @ y[s]).max() == pytest.approx(high[s], abs=1e-12)


def test_matching_pennies() -> None:
    m = np.array([[[1.0, 0.0], [0.0, 1.0]], [[0.0, 1.0], [1.0, 0.0]], [[0.3, 0.3], [0.3, 0.3]]])
    low, high, x, y = reference_nash.game_values(m)
    np.testing.assert_allclose(low, [0.5, 0.5, 0.3], atol=1e-15)
    np.testing.assert_allclose(high, low, atol=1e-15)
    np.testing.assert_allclose(x[:2], 0.5, atol=1e-15)


def _world2_delay2(folder: Path) -> Path:
    text = (MODELS / "world2.toml").read_text()
    assert "delay = 0\n" in text
    path = folder / "world2_d2.toml"
    path.write_text(text.replace("delay = 0\n", "delay = 2\n"))
    return path


# world2 with delay 2 (20 s) under `make test-all` only; `make test`'s mazes with delay have
# their V_NE checked against the reference too (tests/test_mazes.py)
@pytest.mark.parametrize("name", ["world1", "world2", *([] if QUICK else ["world2_d2"]),
                                  "world3", "world3_bayes"])
def test_model_worlds_v_ne_in_reference_bracket(name: str, tmp_path: Path) -> None:
    path = _world2_delay2(tmp_path) if name == "world2_d2" else MODELS / f"{name}.toml"
    ref = reference_nash.v_ne(path)
    assert ref.upper - ref.lower <= TOL, ref
    with progress.quiet():
        found = hg2prism.baselines(hg2prism.load_world(path))
    assert ref.contains(found.v_ne, TOL), (found.v_ne, ref)
    low, high = found.v_ne_bounds
    assert low - TOL <= ref.upper and ref.lower <= high + TOL
