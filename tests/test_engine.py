"""The model-checker interface (hg2prism/engines/engine.py): the pipeline, the robust experiment
and the API reach Storm through it only, and the explicit model Storm hands back decodes to the
hypergame states the layout describes (hg2prism/prism/decoding.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import worldgen
from hg2prism import engines, pipeline, progress
from hg2prism.engines.engine import BuiltModel, Transitions
from hg2prism.experiments import robust
from hg2prism.worldfile import load_world

WORLD = dict(worldgen.world_family())["fam00_d0_l1_w1_x2"]


class Recording:
    """An engine that hands every call to Storm and remembers which methods were called."""

    def __init__(self) -> None:
        self.storm = engines.default()
        self.methods, self.sound_methods = self.storm.methods, self.storm.sound_methods
        self.calls: list[str] = []

    def __getattr__(self, name: str):
        method = getattr(self.storm, name)

        def recorded(*args, **kwargs):
            self.calls.append(name)
            return method(*args, **kwargs)
        return recorded


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory):
    path = tmp_path_factory.mktemp("engine") / "fam00.toml"
    path.write_text(WORLD)
    return load_world(path)


def test_the_pipeline_checks_through_the_engine_it_is_given(world, tmp_path: Path) -> None:
    """check() builds and solves with the engine passed in, keeps it on its result, and gives
    what Storm by default gives: the same value, sizes and strategy file."""
    engine = Recording()
    with progress.quiet():
        given = pipeline.check(world, tmp_path / "given", engine=engine)
        default = pipeline.check(world, tmp_path / "default")
    assert engine.calls[0] == "check" and given.engine is engine
    assert given.results.deceptive_value == default.results.deceptive_value
    assert given.results.storm_states == default.checked.size[0] > 0
    assert ((tmp_path / "given" / "strategy.json").read_bytes()
            == (tmp_path / "default" / "strategy.json").read_bytes())
    # the records are read off the explicit model the engine hands back
    assert given.records == default.records
    assert "explicit" in engine.calls
    # the chain the strategy induces, checked by the engine
    within = given.engine.induced_within(given.checked, given.strategy.choice, 10**6)
    assert within == pytest.approx(given.results.deceptive_value, abs=1e-9)


def test_the_robust_experiment_builds_interval_models_through_the_engine(world, tmp_path: Path
                                                                          ) -> None:
    engine = Recording()
    with progress.quiet():
        checked = pipeline.check(world, tmp_path / "check", engine=engine)
    engine.calls.clear()
    ((solved, _),) = robust.solve_budgets(world, checked, [0.0], tmp_path / "robust")
    built = engine.calls.index("build_interval")
    assert "explicit" in engine.calls[built:] and "check_robust" in engine.calls
    # at delta 0 the robust value is the deceptive value (docs/semantics.md §13)
    assert solved.robust_value == pytest.approx(checked.results.deceptive_value, abs=1e-9)
    assert json.loads(solved.records_json)


def test_the_explicit_model_decodes_to_the_layout(world, tmp_path: Path) -> None:
    """Storm's explicit model: one source per choice, successors inside the model, goal and
    fail labels; decoding reads the PRISM variables (0 for a variable the model lacks)."""
    with progress.quiet():
        checked = pipeline.check(world, tmp_path / "check")
    model = checked.engine.explicit(checked.checked.model)
    moves = model.transitions
    assert model.n_states == checked.checked.size[0] and len(moves.source) == checked.checked.size[2]
    assert moves.target.max() < model.n_states and {"goal", "fail"} <= set(moves.labels)
    assert np.array_equal(model.variable("cell"), checked.decoded.cell)
    assert not model.variable("no_such_variable").any()
    assert model.variable("no_such_variable").shape == (model.n_states,)
    assert checked.decoded.goal[model.initial] == False  # noqa: E712


def test_a_missing_variable_reads_as_zeros() -> None:
    empty = Transitions(source=np.zeros(0, dtype=np.int64), action=np.zeros(0, dtype=np.int64),
                        row_start=np.zeros(1, dtype=np.int64), target=np.zeros(0, dtype=np.int64),
                        probability=np.zeros(0), labels={})
    model = BuiltModel(n_states=3, initial=0, transitions=empty,
                          read_variable=lambda name: np.arange(3) if name == "x" else None)
    assert model.variable("x").tolist() == [0, 1, 2]
    assert model.variable("y").tolist() == [0, 0, 0]
