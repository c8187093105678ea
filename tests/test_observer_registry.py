"""The observer registry (opponent/registry.py): a third kind of observer, defined in this file
alone and registered from the test, runs through emit, check and run (the simulations) with
no edit to the package.

The observer is P2 who never changes her mind: her hypothesis stays the initial one whatever
P1 does. The hypergame then reduces to P1's best response to pi2 of that first guess, whose
value the package computes independently of the hypergame as V_static
(analyses/deception_value.static_value, docs/semantics.md §11): the deceptive value must be it.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from conftest import MODELS
from hg2prism import pipeline, progress
from hg2prism.analyses.deception_value import static_value
from hg2prism.errors import InputError
from hg2prism.model import sizeguard
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.frontends.grid import ACTIONS
from hg2prism.model.world import World
from hg2prism.worldfile import world_from_toml
from hg2prism.opponent import registry
from hg2prism.opponent.observer import Memory, MemoryBound, Observation, ObserverKind
from hg2prism.prism.observers import ObserverPrism
from hg2prism.prism.rendering import upper

TOL = 1e-6


# -- the observer: everything a new kind is, in one place -------------------------------------

@dataclass(frozen=True)
class NeverRevises:
    """P2 acts on her initial hypothesis forever; her memory is that hypothesis alone."""

    window: int
    initial_hypothesis: int
    n_hypotheses: int

    kind = "never"
    draws = False

    def initial_memory(self) -> Memory:
        return Memory(self.initial_hypothesis, ())

    def update(self, memory: Memory, observation: Observation) -> Memory:
        return memory

    def hypothesis(self, memory: Memory) -> int:
        return memory.hypothesis

    def hypothesis_distribution(self, memory: Memory) -> tuple[tuple[int, float], ...]:
        return ((memory.hypothesis, 1.0),)


def render_never(observer: NeverRevises, ts: TransitionSystem, labels: dict[int, str],
                 observed: np.ndarray | None = None, played: str | None = None) -> ObserverPrism:
    """`hyp` set once and kept: per move and hypothesis a command that keeps it (Storm drops
    a variable no update writes, and its states would then lose P2's hypothesis)."""
    commands = "\n".join(f"  [{label}] hyp={h} -> (hyp'={h});" for label in labels.values()
                          for h in range(observer.n_hypotheses))
    module = (f"module p2_inference\n  hyp : [0..{upper(observer.n_hypotheses)}] init "
              f"{observer.initial_hypothesis};   // never revised\n{commands}\nendmodule")
    return ObserverPrism(formulas="// P2 never revises her hypothesis: no tables", module=module,
                         slots=0, commands=len(labels) * observer.n_hypotheses,
                         header="// inference    never revises her first guess")


NEVER = ObserverKind(
    name="never", title="never-revising", settings=(),
    build=lambda world, games: NeverRevises(world.window, world.initial_hypothesis, len(games)),
    render=render_never,
    memory=lambda world: MemoryBound(hypotheses=1, observations=0),
    mismatches=lambda world, max_score, vary: [],
    report=lambda world: {"inference": "never", "window": world.window})


@pytest.fixture
def never(monkeypatch: pytest.MonkeyPatch) -> ObserverKind:
    """The kind registered for one test (monkeypatch removes it afterwards)."""
    monkeypatch.setitem(registry.KINDS, NEVER.name, NEVER)
    return NEVER


# -- the tests --------------------------------------------------------------------------------

def _never_world(name: str, initial_hypothesis: int) -> World:
    text = (MODELS / f"{name}.toml").read_text()
    text = text.replace("[inference]\n", '[inference]\nkind = "never"\n')
    text = "\n".join(line for line in text.splitlines() if not line.startswith("threshold"))
    text = "\n".join(line if not line.startswith("initial_hypothesis") else
                     f"initial_hypothesis = {initial_hypothesis}" for line in text.splitlines())
    return world_from_toml(text, f"{name}_never.toml")


def test_an_unregistered_kind_is_refused() -> None:
    with pytest.raises(InputError, match="unknown inference kind"):
        _never_world("world3", 0)


def test_the_registered_kind_is_loaded_and_its_foreign_keys_refused(never) -> None:
    world = _never_world("world3", 1)
    assert (world.inference, world.settings, world.initial_hypothesis) == ("never", (), 1)
    text = (MODELS / "world3.toml").read_text().replace("[inference]\n",
                                                        '[inference]\nkind = "never"\n')
    with pytest.raises(InputError, match="never-revising observer has no threshold"):
        world_from_toml(text)


@pytest.mark.parametrize("name, first", [("world3", 0), ("world3", 1), ("world2", 0)])
def test_never_revising_p2_runs_and_her_value_is_v_static(never, name: str, first: int,
                                                          tmp_path: Path) -> None:
    world = _never_world(name, first)
    with progress.quiet():
        model = pipeline.emit(world, tmp_path / "emit")
        result = pipeline.run(world, tmp_path / "run", episodes=200)
    assert model.commands["p2_inference"] == len(ACTIONS) * len(world.hypotheses)
    assert "never revises her first guess" in (tmp_path / "emit" / "hypergame.prism").read_text()
    analysis = result.check.analysis
    assert set(result.check.decoded.hypothesis.tolist()) <= {first}
    v_static = static_value(analysis.ts, analysis.task, analysis.games, first).value
    assert result.check.results.deceptive_value == pytest.approx(v_static, abs=TOL)
    assert result.results.v_static == pytest.approx(v_static, abs=TOL)
    assert (tmp_path / "run" / "strategy.json").exists()
    # results.json echoes her kind and its own settings (none), not another kind's
    parameters = json.loads((tmp_path / "run" / "results.json").read_text())["parameters"]
    assert parameters["inference"] == "never" and parameters["window"] == world.window
    assert not {"threshold", "prior", "decision"} & set(parameters)
    # the size guard bounds her hypergame through her kind's MemoryBound
    assert result.check.results.states <= sizeguard.estimate_states(world)


def test_detection_speaks_of_a_registered_kind_in_its_own_terms(never) -> None:
    """`detect` on an observer that is neither CUSUM nor Bayesian: its report showed
    "(window 2, decision None)" and "the largest CUSUM score P2 reaches ... is 0"."""
    import hg2prism
    from hg2prism.experiments.detect import detection_summary_lines

    world = _never_world("world3", 0)
    with progress.quiet():
        result = hg2prism.detection(hg2prism.solve(world), episodes=20, horizon=30)
    assert result["p1_model"] == {"inference": "never", "window": world.window}
    text = "\n".join(detection_summary_lines(result))
    assert f"P1's model (window {world.window}); P1 keeps" in text
    assert f"| as modelled (window {world.window}) |" in text
    assert "CUSUM" not in text and "None" not in text and "decision" not in text


def test_an_observer_whose_python_is_not_its_prism_is_named(never, monkeypatch,
                                                              tmp_path: Path) -> None:
    """An observer whose Python update goes where its PRISM part does not (here it moves to
    the other hypothesis, which its model never does): `run` stopped on "the strategy has no
    record for the hypergame state ..." alone; the line now says where to look."""
    from hg2prism.strategy.records import StrategyError

    world = _never_world("world3", 0)
    monkeypatch.setattr(NeverRevises, "update",
                        lambda self, memory, observation: Memory(1, ()))
    with progress.quiet(), pytest.raises(StrategyError) as caught:
        pipeline.run(world, tmp_path / "run", episodes=20)
    text = str(caught.value)
    assert "the strategy has no record for the hypergame state" in text
    assert text.endswith("does P2's observer update her memory in Python as its PRISM part "
                         'does? docs/architecture.md, "An observer")'), text


def test_configure_refuses_what_the_observer_does_not_have() -> None:
    """registry.configure (the sweeps' and the API's way to change P2's observer): a setting
    her kind does not have, or a kind nobody registered, is one InputError naming it (both
    were accepted silently, the setting ignored)."""
    from hg2prism.opponent.registry import configure

    world = world_from_toml((MODELS / "world3.toml").read_text(), "world3.toml")
    assert world.inference == "cusum"
    for settings, key in (({"prior": [1, 2, 3]}, "inference.prior"),
                          ({"bogus": 3}, "inference.bogus")):
        with pytest.raises(InputError) as refused:
            configure(world, **settings)
        assert refused.value.key == key and "threshold" in refused.value.reason
    with pytest.raises(InputError, match="no observer of kind 'psychic'"):
        configure(world, "psychic")
    # back from "bayes" to "cusum", whose threshold has no default: it was ValueError('threshold')
    # (an API review)
    with pytest.raises(InputError) as missing:
        configure(configure(world, "bayes"), "cusum")
    assert missing.value.key == "inference.threshold" and missing.value.reason == (
        "the cusum observer needs a threshold, which has no default: give it "
        "(configure(world, 'cusum', threshold=...))")
    # an InputError crosses processes (a Dask worker's) as it was: Exception's pickling called
    # the class with the message alone, a TypeError on unpickling
    import pickle

    for error in (missing.value, refused.value):
        back = pickle.loads(pickle.dumps(error))
        assert (type(back), str(back), back.file, back.key, back.reason) == (
            type(error), str(error), error.file, error.key, error.reason)
    assert isinstance(back, InputError) and pickle.loads(pickle.dumps(missing.value)).setting \
        == "threshold"
    assert dict(configure(configure(world, "bayes"), "cusum", threshold=0.5).settings) \
        == {"threshold": 0.5}
    assert dict(configure(world, threshold=2.0).settings)["threshold"] == 2.0


def test_a_kinds_swept_setting_is_a_sweep_parameter(monkeypatch: pytest.MonkeyPatch) -> None:
    """An observer's setting with `swept` is a parameter of `hg2prism sweep` without an edit of
    the sweep: its parameters are read off the registry (threshold, prior and decision too, as
    the table `sweep_parameters()` holds them), parsed as `swept` says and applied through
    registry.configure, a value the observer refuses for the world being a --values error. The
    table follows the registry: a kind registered after experiments.sweep was imported, as
    here, has its setting in it (it was left out when the table was built at import)."""
    from hg2prism.experiments import sweep

    monkeypatch.setitem(registry.KINDS, "patient", _patient(NEVER))
    found = {p.name: p for p in sweep._observer_parameters()}
    assert list(found) == ["threshold", "prior", "decision", "patience"]
    assert [name for name in sweep.sweep_parameters() if name in found] == [
        "threshold", "prior", "decision", "patience"]
    assert sweep.parse_sweep_values("prior", ["1,3"]) == [(0.25, 0.75)]
    assert sweep.parse_sweep_values("patience", ["3"]) == [3]
    # values joined by a comma are one value: the message says to separate them (not for
    # the prior, whose weights take commas)
    with pytest.raises(InputError, match=r"separate the values with spaces \(--values 1 4\)"):
        sweep.parse_sweep_values("rationality", ["1,4"])
    with pytest.raises(InputError) as caught:
        sweep.parse_sweep_values("rationality", ["x"])
    assert "separate" not in caught.value.reason
    assert re.fullmatch(sweep.owned_pattern(), "patience_3")    # its point folders are owned
    assert found["patience"].parse("3") == 3 and found["patience"].expected == "an integer >= 1"
    for bad in ("0", "x", "1.5"):
        with pytest.raises(ValueError):
            found["patience"].parse(bad)
    world = _world_of_kind("patient")
    assert world.setting("patience") == 1
    assert found["patience"].apply(world, 4).setting("patience") == 4
    with pytest.raises(InputError) as err:
        found["patience"].apply(world, 11)
    assert (err.value.file, err.value.key) == ("command line", "--values")
    assert "patience 11" in err.value.reason and "<= 10" in err.value.reason
    cusum = world_from_toml((MODELS / "world3.toml").read_text(), "cusum.toml")
    with pytest.raises(InputError, match="observer has no patience"):
        found["patience"].apply(cusum, 2)


def test_a_kinds_setting_named_as_a_world_parameter_is_one_line(monkeypatch, capsys) -> None:
    """An observer's swept setting named `rationality` (every world's): one line naming the
    kind and "every world" (it named "an observer kind's settings" twice), exit 2."""
    from dataclasses import replace

    from hg2prism.cli import main
    from hg2prism.experiments import sweep

    kind = _patient(NEVER)
    clash = replace(kind, settings=(replace(kind.settings[0], key="rationality"),))
    monkeypatch.setitem(registry.KINDS, "patient", clash)
    monkeypatch.setattr(sweep, "_TABLES", {})
    assert main(["validate", str(MODELS / "world3.toml")]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("hg2prism: error: sweep parameters: rationality: defined by both "
                           "observer kind 'patient' (its settings) and every world"), line


def _patient(never_kind: ObserverKind) -> ObserverKind:
    """The never-revising observer with a setting a sweep may vary (patience, which changes
    nothing she does)."""
    from dataclasses import replace

    from hg2prism.opponent.observer import Setting, Swept

    patience = Setting("patience", "an integer >= 1",
                       lambda checks, value, n: checks.integer(value, "inference.patience", 1,
                                                               10),
                       default=lambda n: 1, swept=Swept("number", "an integer >= 1", int, 1,
                                                        exclusive=False))
    return replace(never_kind, name="patient", title="patient", settings=(patience,))


def _world_of_kind(kind: str) -> World:
    """world3 with P2's observer of `kind` (registered, with no required setting)."""
    text = (MODELS / "world3.toml").read_text().replace("[inference]\n",
                                                        f'[inference]\nkind = "{kind}"\n')
    return world_from_toml("\n".join(line for line in text.splitlines()
                                     if not line.startswith("threshold")), f"{kind}.toml")


def _locked(never_kind: ObserverKind) -> ObserverKind:
    """A kind no process can be sent: its report holds a lock."""
    import threading
    from dataclasses import replace

    lock = threading.Lock()
    return replace(never_kind, name="locked", title="locked",
                   report=lambda world: {"inference": "locked", "lock": lock})


def test_a_parallel_sweep_carries_the_kind_to_its_workers(never, monkeypatch) -> None:
    """A kind registered at run time reaches a parallel sweep's worker processes, which have
    only the built-in kinds: a world of that kind, and a sweep of that kind's own setting, solve
    on workers=2 as they do serially (every point failed with "unknown inference kind"). A
    kind that cannot be sent and that no point uses stays behind without a word."""
    import hg2prism

    monkeypatch.setitem(registry.KINDS, "locked", _locked(NEVER))
    world = _never_world("world3", 1)
    serial = hg2prism.sweep(world, "window", [1, 2])
    parallel = hg2prism.sweep(world, "window", [1, 2], workers=2)
    assert not serial.failed and not parallel.failed
    assert [row.deceptive_value for row in parallel] == [row.deceptive_value for row in serial]
    monkeypatch.setitem(registry.KINDS, "patient", _patient(NEVER))
    patient = _world_of_kind("patient")
    swept = hg2prism.sweep(patient, "patience", [1, 3], workers=2)
    assert not swept.failed and swept.column("patience") == [1, 3]
    # patience changes nothing she does: both points are the never-revising P2's value
    assert swept.column("deceptive_value") == pytest.approx([
        hg2prism.solve(patient).deceptive_value] * 2, abs=TOL)


def test_a_kind_that_cannot_be_sent_is_one_line(never, monkeypatch) -> None:
    """A parallel sweep of a world whose kind cannot be sent to the workers (a lock in a
    closure) is refused before anything runs, in one line naming the kind (each point failed
    on its worker); serially it solves."""
    import hg2prism

    monkeypatch.setitem(registry.KINDS, "locked", _locked(NEVER))
    world = _world_of_kind("locked")
    with pytest.raises(InputError) as refused:
        hg2prism.sweep(world, "window", [1, 2], workers=2)
    assert (refused.value.file, refused.value.key) == ("sweep()", "workers")
    assert refused.value.reason.startswith("the locked observer (kind 'locked', registered at "
                                           "run time) cannot be sent to worker processes")
    assert "sweep it with one worker" in refused.value.reason
    assert "\n" not in str(refused.value)
    assert not hg2prism.sweep(world, "window", [1]).failed


def test_a_parallel_weight_sweep_carries_a_types_kind(never, tmp_path) -> None:
    """A world with P2's types whose type is of a kind registered at run time: the weight
    sweep (on the sweeps' driver) sends the kind to its workers too, and solves on workers=2
    as serially (every point failed with 'type[1].inference.kind: unknown inference kind').
    No weight is one line."""
    from hg2prism.experiments.adaptive import sweep_weights

    text = (MODELS / "world4.toml").read_text()
    stubborn = text.index('name = "stubborn"')
    text = text[:stubborn] + text[stubborn:].replace(
        "[type.inference]\nwindow = 3\nthreshold = 5.0\n",
        '[type.inference]\nkind = "never"\nwindow = 3\n', 1)
    world = world_from_toml(text, "world4_never.toml")
    assert [t.inference for t in world.types] == ["cusum", "never"]
    rows = {}
    for workers in (1, 2):
        with progress.quiet():
            _, failed = sweep_weights(world, [0.25, 0.75], tmp_path / str(workers),
                                      show_progress=False, workers=workers)
        assert failed == ()
        rows[workers] = json.loads((tmp_path / str(workers) / "sweep.json").read_text())["rows"]
    assert [r["v_adapt"] for r in rows[2]] == [r["v_adapt"] for r in rows[1]]
    with pytest.raises(InputError, match="no weight given"):
        sweep_weights(world, [], tmp_path / "none", show_progress=False)
