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
from hg2prism.cli import main
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
    # what the engine hands on does not change after it is built
    assert set(default.checked.timings) == {"parse", "build", "check"}
    with pytest.raises(TypeError):
        default.checked.timings["check"] = 0.0


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
    fail labels; decoding reads the PRISM variables; a variable the model lacks is an error
    unless its (initial) value is given."""
    with progress.quiet():
        checked = pipeline.check(world, tmp_path / "check")
    model = checked.engine.explicit(checked.checked.model)
    moves = model.transitions
    assert model.n_states == checked.checked.size[0] and len(moves.source) == checked.checked.size[2]
    assert moves.target.max() < model.n_states and {"goal", "fail"} <= set(moves.labels)
    assert np.array_equal(model.variable("place"), checked.decoded.place)
    # choice labels a<i> read back as action slots, the absorbing self-loops as -1
    assert set(moves.action.tolist()) == {-1, 0, 1, 2, 3}
    with pytest.raises(KeyError, match="no_such_variable"):
        model.variable("no_such_variable")
    assert model.variable("no_such_variable", 7).tolist() == [7] * model.n_states
    assert checked.decoded.goal[model.initial] == False  # noqa: E712


def test_a_missing_variable_is_its_default_or_an_error() -> None:
    empty = Transitions(source=np.zeros(0, dtype=np.int64), action=np.zeros(0, dtype=np.int64),
                        row_start=np.zeros(1, dtype=np.int64), target=np.zeros(0, dtype=np.int64),
                        probability=np.zeros(0), labels={})
    model = BuiltModel(n_states=3, initial=0, transitions=empty,
                          read_variable=lambda name: np.arange(3) if name == "x" else None)
    assert model.variable("x").tolist() == [0, 1, 2]
    assert model.variable("x", 5).tolist() == [0, 1, 2]
    assert model.variable("y", 4).tolist() == [4, 4, 4]
    with pytest.raises(KeyError):
        model.variable("y")


# A maze where P2 can never revise her first guess x1: Storm leaves the constant `hyp` out of
# its states. Decoding used to read it as 0, so strategy.json had no record of the real start
# state and `run` stopped with a StrategyError traceback (found running all 200 mazes).
CONSTANT_HYPOTHESIS = """name = "maze3"
[grid]
map = \"\"\"
#######
#B@.tC#
###A#.#
###...#
#######
\"\"\"
[robot]
slip = 0.0
[task]
formula = "F A & F B"
[adversary]
traps = 1
delay = 1
initial_traps = [[4, 3]]
hypotheses = ["F B & F C", "!obs U A"]
initial_hypothesis = 1
[inference]
window = 2
rationality = 3.0
threshold = 0.75
"""


def test_a_variable_storm_leaves_out_keeps_its_initial_value(tmp_path: Path) -> None:
    path = tmp_path / "maze3.toml"
    path.write_text(CONSTANT_HYPOTHESIS)
    with progress.quiet():
        checked = pipeline.check(load_world(path), tmp_path / "check")
    model = checked.engine.explicit(checked.checked.model)
    assert model.read_variable("hyp") is None           # Storm dropped it: it never changes
    assert checked.prism.layout.initial_value("hyp") == 1
    assert set(checked.decoded.hypothesis.tolist()) == {1}
    starts = [r for r in checked.records if r["window"] == [] and r["state"] == "x2_y3"]
    assert starts and all(r["hypothesis"] == 1 for r in starts)
    assert checked.records[0].get("initial") is True and checked.records[0] in starts
    assert main(["run", str(path), "--out", str(tmp_path / "run"), "--episodes", "20"]) == 0


def test_the_robot_module_last_is_the_same_model(tmp_path: Path) -> None:
    """hypergame.prism writes P1's module after the one-outcome modules (task, P2's standing
    traps, her inference), which saves Storm a fifth of its build: the model Storm builds is the
    one it builds with the robot module first (as written before), state for state, choice for
    choice, the same bits, and every variable the same in every state."""
    import re

    from hg2prism.engines import storm

    path = tmp_path / "w.toml"
    path.write_text(dict(worldgen.world_family())["fam05_d2_l1_w2_x3"])     # delay 2, window 2
    with progress.quiet():
        pipeline.emit(load_world(path), tmp_path / "out")
    prism = tmp_path / "out" / "hypergame.prism"
    written = prism.read_text()
    modules = re.findall(r"^module (\w+)$", written, flags=re.MULTILINE)
    assert modules[-1] == "robot" and {"task", "p2_traps", "p2_inference"} <= set(modules)
    robot = re.search(r"^// -+ P1: the arena\nmodule robot\n.*?^endmodule\n", written,
                      flags=re.MULTILINE | re.DOTALL).group(0)
    first = tmp_path / "robot_first.prism"
    first.write_text(written.replace(robot, "").replace("module task", robot + "\nmodule task", 1))
    models = [storm.explicit(storm.build(p, 'Pmax=? [F "goal"]')[0]) for p in (prism, first)]
    last, before = (m.transitions for m in models)
    for field in ("source", "action", "row_start", "target", "probability"):
        assert np.array_equal(getattr(last, field), getattr(before, field)), field
    assert last.labels.keys() == before.labels.keys()
    assert all(np.array_equal(last.labels[k], before.labels[k]) for k in last.labels)
    for name in ("place", "q", "traps", "countdown", "hyp", "o1_state", "o1_act"):
        assert np.array_equal(models[0].variable(name), models[1].variable(name)), name
