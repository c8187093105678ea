"""P2's decision rules exactly at their boundaries (docs/semantics.md §5, §12), where `>=` and
`>` give different hypergames.

CUSUM switches when a score reaches the threshold (`max Z >= c`, within 1e-9): the worlds here
set the threshold to exactly the CUSUM score of one of P1's first moves, so that P2 changes her
mind on that move and on no other. The Bayesian observer acts on the first hypothesis within
1e-9 of the largest log-posterior: the worlds here give the prior that makes two hypotheses'
posteriors tie after one of P1's first moves. On each, the independent reference
(tests/reference.py, tests/reference_bayes.py) and the package must agree (values, canonical
sizes, Storm's transitions against the Python observer), and the reference itself must see a
different hypergame when the rule is moved off the boundary, so that these worlds do test it.
"""

from __future__ import annotations

import functools
import math
import re
from pathlib import Path

import pytest

import reference
import reference_bayes
import test_bayes
import test_core
import worldgen
from hg2prism import pipeline, progress
from hg2prism.worldfile import load_world, world_from_toml

FAMILY = dict(worldgen.world_family())
# (family world, P1's first move): its CUSUM score is the threshold. Windows 1 (P2's next
# hypothesis a table in the model) and 2 (CUSUM formulas), delay 0 and 1.
CUSUM_CASES = [("fam10_d1_l2_w1_x2", 1), ("fam13_d1_l2_w2_x2", 2), ("fam18_d0_l1_w1_x3", 0)]
# (two-hypothesis family world made Bayesian with "map", window, P1's first move): after that
# move the prior makes the posteriors tie. Windows 1 and 2, delay 1.
BAYES_CASES = [("fam04_d1_l1_w2_x2", 1, 2), ("fam04_d1_l1_w2_x2", 2, 2),
               ("fam10_d1_l2_w1_x2", 1, 1), ("fam19_d1_l1_w1_x2", 1, 1)]
OFF = 1e-8      # moves a rule off its boundary: ten times the tolerance


def _analysis(text: str) -> pipeline.Analysis:
    with progress.quiet():
        return pipeline.analyse(world_from_toml(text))


@functools.cache
def cusum_threshold(base: str, action: int) -> float:
    """The CUSUM score max_x Z_x of P1's move `action` from the start (P2's first observation):
    from then on the world's threshold."""
    observer = _analysis(FAMILY[base]).inference
    start = _analysis(FAMILY[base]).ts.start_state
    return float(observer.scores(observer.initial_memory(), (start, action)).max())


def cusum_text(base: str, threshold: float) -> str:
    return re.sub(r"^threshold = .*$", f"threshold = {threshold!r}", FAMILY[base], flags=re.M)


@functools.cache
def bayes_prior(base: str, window: int, action: int) -> tuple[float, float]:
    """A prior under which P2's two hypotheses tie after P1's move `action` from the start:
    ln p0 + ln pi1_0(a | v0, pi2_h(v0)) = ln p1 + ln pi1_1(a | v0, pi2_h(v0)), with h the
    prior's most probable hypothesis (h = 1 when p1 > p0)."""
    analysis = _analysis(test_bayes.bayes_text(FAMILY[base], None, "map", window))
    observer, start = analysis.inference, analysis.ts.start_state
    for h in (0, 1):
        ll = observer.log_likelihood[:, start, action, int(observer.trap_choice[h][start])]
        gap = float(ll[0] - ll[1])
        if gap != 0.0 and (gap > 0) == (h == 1):
            return 1.0, math.exp(gap)
    raise AssertionError(f"{base}: move {action} does not separate the two hypotheses")


def bayes_text(base: str, window: int, prior: tuple[float, float]) -> str:
    text = test_bayes.bayes_text(FAMILY[base], None, "map", window)
    return text.replace('decision = "map"\n',
                        f'decision = "map"\nprior = [{prior[0]!r}, {prior[1]!r}]\n')


def _write(folder: Path, name: str, text: str) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(text)
    return path


@functools.cache
def cusum_run(base: str, action: int, folder: str) -> tuple[pipeline.CheckResult,
                                                              reference.Reference]:
    path = _write(Path(folder), f"tie_{base}_{action}",
                  cusum_text(base, cusum_threshold(base, action)))
    with progress.quiet():
        result = pipeline.check(load_world(path), Path(folder) / path.stem)
    # the reference translates its DFAs right after the pipeline, as in tests/test_core.py
    return result, reference.solve(path)


@functools.cache
def bayes_run(base: str, window: int, action: int, folder: str
              ) -> tuple[str, pipeline.CheckResult, Path]:
    name = f"tie_bayes_{base}_{window}_{action}"
    path = _write(Path(folder), name, bayes_text(base, window, bayes_prior(base, window, action)))
    with progress.quiet():
        result = pipeline.check(load_world(path), Path(folder) / name)
    return name, result, path


@pytest.mark.parametrize("base, action", CUSUM_CASES)
def test_the_threshold_on_a_score_is_a_boundary(base: str, action: int,
                                                world_dir: Path) -> None:
    """The reference sees another hypergame when the threshold is just above the score, and
    the package's P2 changes her mind on the score exactly, not just above it."""
    threshold = cusum_threshold(base, action)
    solved = [reference.solve(_write(world_dir, f"off_{base}_{action}_{k}",
                                     cusum_text(base, threshold + k * OFF)))
              for k in (0, 1)]
    assert [(r.value, r.states, r.transitions) for r in solved[:1]] != \
        [(r.value, r.states, r.transitions) for r in solved[1:]]
    observer = _analysis(cusum_text(base, threshold)).inference
    start = _analysis(cusum_text(base, threshold)).ts.start_state
    first = observer.initial_memory()
    assert observer.update(first, (start, action)).hypothesis != first.hypothesis
    above = _analysis(cusum_text(base, threshold + OFF)).inference
    assert above.update(first, (start, action)).hypothesis == first.hypothesis


@pytest.mark.parametrize("base, action", CUSUM_CASES)
def test_cusum_on_the_threshold_agrees_with_the_reference(base: str, action: int,
                                                          world_dir: Path) -> None:
    case = cusum_run(base, action, str(world_dir))
    for check in (test_core.test_deceptive_value_matches_reference,
                  test_core.test_canonical_size_matches_reference,
                  test_core.test_storm_inference_transitions_are_those_of_section_5,
                  test_core.test_python_inference_matches_reference,
                  test_core.test_exported_strategy_is_optimal):
        check(case)


@pytest.mark.parametrize("base, window, action", BAYES_CASES)
def test_tied_posteriors_are_a_boundary(base: str, window: int, action: int,
                                        world_dir: Path) -> None:
    """Just off the tie (p1 larger by a factor 1 + 1e-8) the reference sees another hypergame,
    and the package's P2 acts on hypothesis 0 at the tie (the first of the tied) and on
    hypothesis 1 off it."""
    p0, p1 = bayes_prior(base, window, action)
    solved = [reference_bayes.solve(_write(world_dir, f"off_bayes_{base}_{window}_{k}",
                                           bayes_text(base, window, (p0, p1 * (1 + k * OFF)))))
              for k in (0, 1)]
    assert (solved[0].value, solved[0].states, solved[0].transitions) != \
        (solved[1].value, solved[1].states, solved[1].transitions)
    tied = _analysis(bayes_text(base, window, (p0, p1))).inference
    off = _analysis(bayes_text(base, window, (p0, p1 * (1 + OFF)))).inference
    start = _analysis(bayes_text(base, window, (p0, p1))).ts.start_state
    first = ((start, action, int(tied.trap_choice[tied.initial_hypothesis][start])),)
    assert abs(_gap(tied, first)) < 1e-12
    assert (tied.map_hypothesis(first), off.map_hypothesis(first)) == (0, 1)


def _gap(observer, window: tuple) -> float:
    scores = observer.log_scores(window)
    return scores[0] - scores[1]


@pytest.mark.parametrize("base, window, action", BAYES_CASES)
def test_tied_posteriors_agree_with_the_reference(base: str, window: int, action: int,
                                                  world_dir: Path) -> None:
    case = bayes_run(base, window, action, str(world_dir))
    for check in (test_bayes.test_value_and_size_match_the_reference,
                  test_bayes.test_storm_transitions_are_those_of_the_python_observer,
                  test_bayes.test_exported_strategy_is_optimal):
        check(case)
