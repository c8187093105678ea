"""Detecting a wrong opponent model (docs/semantics.md §9, the paper's Fig. 5).

:func:`detection_experiment` runs P1's deceptive strategy against a P2 who departs from P1's
model and feeds P1's likelihood-ratio detector (:mod:`hg2prism.analyses.detection`):

(a) one seeded episode in which P2 follows the model for ``deviate_after`` steps, then plays
    uniformly at random (the G-per-step picture, ``OUT/detection.{png,svg}``);
(b) many such episodes: the distribution of detection steps and the share not detected;
(c) as many episodes in which P2 follows the model: the false-alarm rate;
(d) the paper's other mismatch: P2's real inference runs with another window or threshold
    than P1's model of it. P1 keeps playing its records (the leader-game fallback of
    :func:`hg2prism.analyses.simulation.leader_fallback` on states they do not cover, counted
    as ``off_record_steps``); the detector compares P2's traps with P1's prediction.

(e) with a fallback (``--fallback robust|leader``, docs/semantics.md §14): the deviation and the
    compliant batches again, same seed and episodes, with P1 switching to the fallback after
    its detector's first rejection: the completion rate with and without re-planning.

Writes ``OUT/detection.json`` and ``OUT/detection.{png,svg}``.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from hg2prism.errors import COMMAND_LINE, InputError
from hg2prism.frontends import arena_of
from hg2prism.model.world import World
from hg2prism import progress
from hg2prism.outputs import write_json
from hg2prism.results import provenance

if TYPE_CHECKING:   # annotations only: the pipeline and the simulation import much more
    from hg2prism.strategy.policy import Policy
    from hg2prism.analyses.simulation import P2Policy, Replanning, SimulationSummary, StepRecord
    from hg2prism.strategy.records import Strategy
    from hg2prism.opponent.observer import Observer, ReportsBelief
    from hg2prism.results import Analysis, CheckResult

__all__ = ["DetectionBatch", "detection_batch", "detection_experiment", "detect",
           "detection_summary_lines", "FALLBACKS", "DEFAULT_FALLBACK_DELTA", "parse_fallback"]

# The seeded episode of the detection picture lasts more than deviate_after + this many steps.
STEPS_AFTER_DEVIATION = 3
SEED_SEARCH = 1000
MAX_DETECTION_EPISODES = 2000

FALLBACKS = ("robust", "leader")
DEFAULT_FALLBACK_DELTA = 0.1


def parse_fallback(fallback: str | None, delta: object | None) -> tuple[str | None, float | None]:
    """The re-planning fallback and, for "robust", its deviation budget (default
    DEFAULT_FALLBACK_DELTA); InputError (key --fallback or --fallback-delta)."""
    if fallback is None:
        if delta is not None:
            raise InputError(COMMAND_LINE, "--fallback-delta", "needs --fallback robust")
        return None, None
    if fallback not in FALLBACKS:
        raise InputError(COMMAND_LINE, "--fallback",
                         f"{fallback!r} is not one of {', '.join(FALLBACKS)}")
    if fallback == "leader":
        if delta is not None:
            raise InputError(COMMAND_LINE, "--fallback-delta",
                             "only the robust fallback has a budget")
        return fallback, None
    if delta is None:
        return fallback, DEFAULT_FALLBACK_DELTA
    from dataclasses import replace

    from hg2prism.experiments.robust import DELTAS
    from hg2prism.experiments.values import parse_values

    (parsed,) = parse_values(replace(DELTAS, option="--fallback-delta", hint=False), [delta])
    return fallback, parsed


# ---------------------------------------------------------------------------------------------
# Detection
# ---------------------------------------------------------------------------------------------

class DetectionBatch:
    """An observer for simulate_deceptive that runs one fresh MismatchDetector per episode
    (fed ``(s~_n, pi2_xh(v), a2_n, |A2(v)|)``) and keeps what the experiments report.

    ``first_rejection[e]``: the first step n at which episode e's detector rejected H0 (absent:
    never). ``unpredicted``: episodes in which P2 played a trap set other than the predicted
    one at a step with several choices. ``diverged``: episodes in which P2's real hypothesis
    differed from P1's model of it at some step. With ``keep_steps`` every Step of every
    episode is kept (``steps[e]``); otherwise an episode's detector stops at its rejection.
    """

    def __init__(self, alpha: float, epsilon: float, keep_steps: bool = False,
                 scores_of: ReportsBelief | None = None, draws: bool = False) -> None:
        from hg2prism.analyses.detection import MismatchDetector, Mixture

        self._make = lambda: MismatchDetector(alpha, epsilon)
        self.keep_steps = keep_steps
        # with an observer that compares scores with a threshold (CUSUM): the largest score
        # max_x Z_x (x != xh) any step reached under P1's model memory (how close P2 came to
        # changing her mind)
        self._scores_of = scores_of
        self._score_cache: dict = {}
        self.max_score = 0.0
        self.first_rejection: dict[int, int] = {}
        self.unpredicted: set[int] = set()
        self.diverged: set[int] = set()
        self.steps: dict[int, list] = {}
        self.records: dict[int, list] = {}
        self._episode: int | None = None
        self._detector = None
        # a P2 who draws her hypothesis is predicted by the posterior mixture (§12)
        self._mixture = Mixture if draws else None

    def __call__(self, record: StepRecord) -> None:
        episode = record.episode
        if episode != self._episode:
            self._episode = episode
            self._detector = self._make()
        if record.n_a2 > 1 and record.a2 != record.predicted_a2:
            self.unpredicted.add(episode)
        if record.memory.hypothesis != record.p2_memory.hypothesis:
            self.diverged.add(episode)
        if self._scores_of is not None:
            key = (record.memory, record.ts_state, record.a1)
            score = self._score_cache.get(key)
            if score is None:
                z = self._scores_of.belief(record.memory, (record.ts_state, record.a1))
                score = self._score_cache[key] = float(max(z)) if len(z) else 0.0
            self.max_score = max(self.max_score, score)
        if episode in self.first_rejection and not self.keep_steps:
            return
        predicted = (self._mixture(record.prediction) if self._mixture is not None
                     else record.predicted_a2)
        step = self._detector.observe(record.augmented_state, predicted, record.a2,
                                      record.n_a2)
        if step.rejected and episode not in self.first_rejection:
            self.first_rejection[episode] = step.n
        if self.keep_steps:
            self.steps.setdefault(episode, []).append(step)
            self.records.setdefault(episode, []).append(record)

    def rejections(self, episodes: int) -> list[int | None]:
        return [self.first_rejection.get(e) for e in range(episodes)]


def detection_batch(analysis: Analysis, strategy: Policy, episodes: int, horizon: int,
                    seed: int, alpha: float, epsilon: float, p2_policy: P2Policy | None = None,
                    p2_inference: Observer | None = None, keep_steps: bool = False,
                    progress: bool = False, track_scores: bool = False,
                    replanning: Replanning | None = None
                    ) -> tuple[SimulationSummary, DetectionBatch]:
    """Simulate `episodes` deceptive episodes with P1's detector running in each.
    Returns (SimulationSummary, DetectionBatch). With `track_scores` the batch records the
    largest score of P1's model of P2's inference when she compares scores with a threshold
    (CUSUM: DetectionBatch.max_score)."""
    from hg2prism.analyses.simulation import simulate_deceptive
    from hg2prism.opponent.observer import ReportsBelief

    model = analysis.inference
    scored = isinstance(model, ReportsBelief) and model.belief_threshold is not None
    batch = DetectionBatch(alpha, epsilon, keep_steps,
                           scores_of=model if track_scores and scored else None,
                           draws=model.draws)
    summary = simulate_deceptive(analysis, strategy, episodes, horizon, seed, p2_policy=p2_policy,
                                 observer=batch, progress=progress, p2_inference=p2_inference,
                                 replanning=replanning)
    return summary, batch


def _completion(summary: SimulationSummary) -> dict:
    return {"rate": summary.rate, "ci95": list(summary.ci95), "episodes": summary.episodes,
            "completed": summary.completed, "failed": summary.failed,
            "truncated": summary.truncated, "off_record_steps": summary.off_record_steps,
            "mean_length": summary.mean_length}


def _distribution(rejections: list[int | None], deviate_after: int | None = None) -> dict:
    from hg2prism.analyses.detection import summarize_detection
    from hg2prism.analyses.simulation import wilson_interval

    s = summarize_detection(rejections, deviate_after)
    result = {
        "episodes": s.episodes,
        "detected": s.detected,
        "not_detected": s.not_detected,
        "share_detected": s.share_detected,
        "share_detected_ci95": list(wilson_interval(s.detected, s.episodes)),
        "share_not_detected": s.share_not_detected,
        "mean_detection_step": s.mean_detection_step,
        "median_detection_step": s.median_detection_step,
        "histogram": {str(n): c for n, c in s.histogram},
    }
    if deviate_after is not None:
        result["detected_before_deviation"] = s.before_deviation
        result["mean_delay_after_deviation"] = s.mean_delay
    return result


def _find_seeded_episode(analysis: Analysis, strategy: Policy, horizon: int, seed: int,
                         alpha: float, epsilon: float, deviate_after: int, p2_policy: P2Policy
                         ) -> tuple[int, SimulationSummary, DetectionBatch]:
    """The first seed from `seed` upward whose deviating episode lasts more than
    deviate_after + STEPS_AFTER_DEVIATION steps (else the longest of SEED_SEARCH seeds)."""
    best = None
    for s in range(seed, seed + SEED_SEARCH):
        summary, batch = detection_batch(analysis, strategy, 1, horizon, s, alpha, epsilon,
                                         p2_policy=p2_policy, keep_steps=True)
        length = int(summary.lengths[0])
        if length > deviate_after + STEPS_AFTER_DEVIATION:
            return s, summary, batch
        if best is None or length > int(best[1].lengths[0]):
            best = (s, summary, batch)
    return best


def _check_positive(value: int | None, key: str, minimum: int) -> None:
    """An option's integer (None: not given), by model/validation.py's rule."""
    from hg2prism.model.validation import Checks

    if value is not None:
        Checks(COMMAND_LINE).integer(value, key, minimum)


def _replanning_rates(summary: SimulationSummary) -> dict:
    return {**_completion(summary), "detected_episodes": summary.replanned}


def paired_change(without: SimulationSummary, with_: SimulationSummary) -> dict:
    """The two runs of re-planning compared episode by episode (the same episodes, each from
    its own random stream): how many completed only with re-planning and only without, the
    change of the completion rate, and the exact two-sided McNemar test of "re-planning changes
    nothing" (a binomial test of the discordant episodes at 1/2; 1.0 when there are none).
    Two overlapping intervals of the rates say less: the runs are paired."""
    from scipy.stats import binomtest

    from hg2prism.analyses.simulation import GOAL

    done_with, done_without = with_.outcomes == GOAL, without.outcomes == GOAL
    only_with = int((done_with & ~done_without).sum())
    only_without = int((done_without & ~done_with).sum())
    discordant = only_with + only_without
    return {"only_with": only_with, "only_without": only_without,
            "change": (only_with - only_without) / with_.episodes,
            "mcnemar_p": binomtest(only_with, discordant, 0.5).pvalue if discordant else 1.0}


def _fallback_strategy(world: World, check_result: CheckResult, fallback: str,
                       delta: float | None) -> Policy:
    """P1's strategy after a detected mismatch (docs/semantics.md §14)."""
    import json
    import tempfile

    from hg2prism.analyses.simulation import LeaderStrategy, leader_fallback
    from hg2prism.experiments.robust import robust_strategy_for
    from hg2prism.strategy.records import Strategy

    analysis = check_result.analysis
    if fallback == "leader":
        return LeaderStrategy(analysis)
    with tempfile.TemporaryDirectory(prefix="hg2prism-fallback-") as scratch:
        records = json.loads(robust_strategy_for(world, check_result, delta, Path(scratch)))
    return Strategy.from_records(records, analysis.ts, fallback=leader_fallback(analysis))


@dataclass(frozen=True)
class _Batches:
    """What every batch of the experiment shares: the same strategy, episodes, horizon, seed
    and detector, so that the batches differ only in what P2 does."""

    analysis: Analysis
    strategy: Strategy              # the deceptive strategy (a Policy)
    episodes: int
    horizon: int
    seed: int
    alpha: float
    epsilon: float
    show_progress: bool

    def run(self, **options) -> tuple[SimulationSummary, DetectionBatch]:
        """detection_batch with these settings and `options` (p2_policy, p2_inference, ...)."""
        return detection_batch(self.analysis, self.strategy, self.episodes, self.horizon,
                               self.seed, self.alpha, self.epsilon,
                               progress=self.show_progress, **options)

    def replay(self, p2_policy: P2Policy | None, plan: Replanning) -> SimulationSummary:
        """The episodes again, P1 re-planning with `plan` (one random stream per episode)."""
        from hg2prism.analyses.simulation import simulate_deceptive

        return simulate_deceptive(self.analysis, self.strategy, self.episodes, self.horizon,
                                  self.seed, p2_policy=p2_policy, progress=self.show_progress,
                                  replanning=plan, episode_streams=True)


def detection_experiment(world: World, check_result: CheckResult, out: Path, episodes: int | None = None,
                         seed: int | None = None, show_progress: bool = True,
                         horizon: int | None = None, fallback: str | None = None,
                         fallback_delta: float | None = None) -> dict:
    """docs/semantics.md §9's experiment and the other mismatch (see the module docstring).

    `check_result` is pipeline.check(world, ...). `episodes` defaults to
    min(world.simulation.episodes, 2000) per batch, `seed` and `horizon` to the world's.
    With `fallback` ("robust", with budget `fallback_delta`, or "leader") the deviation and
    compliant batches are run again with re-planning (docs/semantics.md §14).
    Writes out/detection.json and out/detection.{png,svg} and returns the JSON's content.
    """
    from hg2prism.report import plots
    from hg2prism.analyses.simulation import deviating_policy, leader_fallback
    from hg2prism.strategy.records import Strategy

    _check_positive(episodes, "--episodes", 1)
    _check_positive(seed, "--seed", 0)
    _check_positive(horizon, "--horizon", 1)
    _check_deviation_fits(world, horizon)
    fallback, fallback_delta = parse_fallback(fallback, fallback_delta)
    out = Path(out)
    start_time = time.perf_counter()
    settings = world.detection
    deviate_after = settings.deviate_after
    episodes = episodes or min(world.simulation.episodes, MAX_DETECTION_EPISODES)
    horizon = horizon or world.simulation.horizon
    seed = world.simulation.seed if seed is None else seed
    analysis = check_result.analysis
    strategy = Strategy.from_records(check_result.records, analysis.ts,
                                     fallback=leader_fallback(analysis))
    deviating = deviating_policy(analysis.ts, deviate_after)
    batches = _Batches(analysis, strategy, episodes, horizon, seed, settings.alpha,
                       settings.epsilon, show_progress)

    # the batches' reports go to the logger either way (the API shows them where logging is
    # configured); `show_progress` draws the simulations' bars
    say = progress.say
    seeded, steps = _seeded_episode(batches, deviate_after, deviating, say)
    say(f"detection: {episodes} episodes, P2 follows the model for {deviate_after} step(s), "
        "then plays at random")
    deviation = _deviation_batch(batches, deviating, deviate_after)
    say(f"detection: {episodes} episodes, P2 follows the model (false alarms)")
    compliant, summary_c, batch_c = _compliant_batch(batches)
    mismatch = _mismatch_batches(world, batches, batch_c.max_score, summary_c.rate, say)
    replanning = None
    if fallback is not None:
        shown = f"{fallback} (delta {fallback_delta:g})" if fallback == "robust" else fallback
        say(f"detection: re-planning with the {shown} fallback")
        replanning = _replanning_batches(world, check_result, batches, fallback, fallback_delta,
                                         deviating)
    plots.detection_figure([s.statistic for s in steps], [s.threshold for s in steps],
                           deviate_after, seeded["detected_at"], out / "detection.png",
                           world_name=world.name, seed=seeded["seed"], replanning=replanning)

    result = _result(world, check_result, batches, deviate_after, seeded, deviation, compliant,
                     mismatch)
    result["seconds"] = round(time.perf_counter() - start_time, 3)
    if replanning is not None:
        result["replanning"] = replanning
    write_json(out / "detection.json", result)
    return result


def _result(world: World, check_result: CheckResult, batches: _Batches, deviate_after: int,
            seeded: dict, deviation: dict, compliant: dict, mismatch: list[dict]) -> dict:
    """detection.json's content, but the time taken and the re-planning batches."""
    from hg2prism.opponent.registry import observer_kind

    return {
        **provenance(world, check_result.engine),
        "alpha": batches.alpha,
        "epsilon": batches.epsilon,
        "deviate_after": deviate_after,
        "horizon": batches.horizon,
        "seed": batches.seed,
        "episodes": batches.episodes,
        "p2_plays": "trap sets" if arena_of(world).traps_mode else "actions",
        "deceptive_value": check_result.results.deceptive_value,
        "storm_method": check_result.results.storm_method,
        "sound": check_result.results.sound,
        "p1_model": observer_kind(world.inference).report(world),
        "notes": ("df counts distinct (augmented state, P2 action) pairs, as in the paper. The "
                  "test is made at every step: the false-alarm rate (episodes rejected at some "
                  "step) is not bounded by alpha (docs/semantics.md §9). P1 plays its "
                  "exported records and, on states they do not cover (reachable only when P2 "
                  "departs from the model), the leader-game fallback; such steps are counted in "
                  "off_record_steps. Every batch uses the same seed."),
        "seeded_episode": seeded,
        "deviation": deviation,
        "compliant": compliant,
        "model_mismatch": {
            "shown_setting": _shown_setting(world),
            "reference": {"p2_inference": "as modelled", "p2_window": world.window,
                          **({f"p2_{name}": world.setting(name)}
                             if (name := _shown_setting(world)) else {}),
                          "detection_rate": compliant["false_alarm_rate"],
                          "completion": compliant["completion"]},
            "variants": mismatch,
        },
    }


def _seeded_episode(batches: _Batches, deviate_after: int, deviating: P2Policy,
                    say: Callable[[str], None]) -> tuple[dict, list]:
    """(a) One seeded episode, for the picture: its record and its detector steps."""
    from hg2prism.analyses.episodes import outcome_text

    ts = batches.analysis.ts
    chosen, summary, batch = _find_seeded_episode(
        batches.analysis, batches.strategy, batches.horizon, batches.seed, batches.alpha,
        batches.epsilon, deviate_after, deviating)
    steps = batch.steps.get(0, [])
    records = batch.records.get(0, [])
    detected_at = batch.first_rejection.get(0)
    per_step = []
    for step, record in zip(steps, records):
        per_step.append({
            "n": step.n,
            "state": ts.arena.states[ts.decode(record.ts_state)[0]],
            "hypothesis_modelled": record.memory.hypothesis,
            "hypothesis_real": record.p2_memory.hypothesis,
            "predicted": ts.a2_names[record.predicted_a2],
            "played": ts.a2_names[record.a2],
            "choices": record.n_a2,
            "counted": step.counted,
            "G": step.statistic,
            "df": step.df,
            "threshold": step.threshold,
            "rejected": step.rejected,
        })
    seeded = {
        "seed": chosen,
        "searched_from_seed": batches.seed,
        "rule": (f"the first seed from {batches.seed} upward whose episode lasts more than "
                 f"deviate_after + {STEPS_AFTER_DEVIATION} steps"),
        "steps": int(summary.lengths[0]),
        "outcome": outcome_text(int(summary.outcomes[0])),
        "detected_at": detected_at,
        "per_step": per_step,
    }
    say(f"detection: seeded episode (seed {chosen}, {seeded['steps']} steps): "
        + (f"mismatch detected at step {detected_at}" if detected_at is not None
           else "mismatch not detected"))
    return seeded, steps


def _deviation_batch(batches: _Batches, deviating: P2Policy, deviate_after: int) -> dict:
    """(b) Many episodes with the deviation: when it is detected, and how often not."""
    episodes = batches.episodes
    summary, batch = batches.run(p2_policy=deviating)
    deviation = _distribution(batch.rejections(episodes), deviate_after)
    reached = [e for e in range(episodes) if summary.lengths[e] > deviate_after]
    deviation["episodes_reaching_deviation"] = len(reached)
    deviation["episodes_with_unpredicted_traps"] = len(batch.unpredicted)
    deviation["share_not_detected_among_reaching_deviation"] = (
        sum(1 for e in reached if e not in batch.first_rejection) / len(reached)
        if reached else None)
    deviation["completion"] = _completion(summary)
    return deviation


def _compliant_batch(batches: _Batches) -> tuple[dict, SimulationSummary, DetectionBatch]:
    """(c) As many episodes in which P2 follows the model: the false alarms (the episodes
    rejected at some step, `_distribution`'s detected ones)."""
    episodes = batches.episodes
    summary, batch = batches.run(track_scores=True)
    alarms = _distribution(batch.rejections(episodes))
    compliant = {
        "episodes": episodes,
        "false_alarms": alarms["detected"],
        "false_alarm_rate": alarms["share_detected"],
        "false_alarm_rate_ci95": alarms["share_detected_ci95"],
        "false_alarm_steps": alarms["histogram"],
        "completion": _completion(summary),
        "max_cusum_score": batch.max_score,
    }
    return compliant, summary, batch


def _mismatch_batches(world: World, batches: _Batches, max_score: float, reference_rate: float,
                      say: Callable[[str], None]) -> list[dict]:
    """(d) P2's real inference differs from P1's model of it: one batch per variant."""
    from hg2prism.opponent import registry

    games, episodes = batches.analysis.games, batches.episodes
    shown = _shown_setting(world)
    mismatch = []
    for variant in registry.mismatches(world, max_score):
        say(f"detection: {episodes} episodes, P2's inference uses {variant.label} "
            f"(P1 models window {world.window}"
            f"{_setting(shown, world.setting(shown))})")
        summary, batch = batches.run(p2_inference=registry.build_observer(variant.world, games))
        observable = len(batch.unpredicted)
        detected_observable = sum(1 for e in batch.unpredicted if e in batch.first_rejection)
        dist = _distribution(batch.rejections(episodes))
        mismatch.append({
            "p2_inference": variant.label,
            "chosen_as": variant.why,
            "p2_window": variant.world.window,
            **({f"p2_{shown}": variant.shown} if shown else {}),
            "episodes": episodes,
            "detected": dist["detected"],
            "detection_rate": dist["share_detected"],
            "detection_rate_ci95": dist["share_detected_ci95"],
            "mean_detection_step": dist["mean_detection_step"],
            "median_detection_step": dist["median_detection_step"],
            "histogram": dist["histogram"],
            "episodes_with_hypothesis_divergence": len(batch.diverged),
            "episodes_with_unpredicted_traps": observable,
            "detection_rate_given_unpredicted_traps": (detected_observable / observable
                                                       if observable else None),
            "completion": _completion(summary),
            "completion_change": summary.rate - reference_rate,
        })
    return mismatch


def _replanning_batches(world: World, check_result: CheckResult, batches: _Batches,
                        fallback: str, fallback_delta: float | None,
                        deviating: P2Policy) -> dict:
    """(e) The deviation and compliant batches again, P1 switching to the fallback at its
    detector's first rejection, and without re-planning for comparison."""
    from hg2prism.analyses.simulation import Replanning

    plan = Replanning(_fallback_strategy(world, check_result, fallback, fallback_delta),
                      batches.alpha, batches.epsilon)
    # "without": the deceptive strategy as its own fallback, so that the detections are
    # counted while P1's play is that of no re-planning
    same = Replanning(batches.strategy, batches.alpha, batches.epsilon)
    without_b, with_b = batches.replay(deviating, same), batches.replay(deviating, plan)
    without_c, with_c = batches.replay(None, same), batches.replay(None, plan)
    return {
        "fallback": fallback,
        "delta": fallback_delta,
        "random_numbers": ("each episode its own stream, numpy default_rng([seed, "
                           "episode]), in both runs: an episode is played identically with "
                           "and without re-planning up to P1's switch"),
        "deviation": {"without": _replanning_rates(without_b),
                      "with": _replanning_rates(with_b),
                      "paired": paired_change(without_b, with_b)},
        "compliant": {"without": _replanning_rates(without_c),
                      "with": _replanning_rates(with_c),
                      "paired": paired_change(without_c, with_c)},
    }


def detect(world: World, out: Path, episodes: int | None = None, seed: int | None = None,
           horizon: int | None = None, show_progress: bool = True,
           storm_method: str = "sound", fallback: str | None = None,
           fallback_delta: float | None = None) -> dict:
    """pipeline.check in a temporary folder (so that OUT/results.json of `hg2prism run` is not
    overwritten), then :func:`detection_experiment` into `out`."""
    import tempfile

    from hg2prism import pipeline

    _check_positive(episodes, "--episodes", 1)
    _check_positive(seed, "--seed", 0)
    _check_positive(horizon, "--horizon", 1)
    _check_deviation_fits(world, horizon)
    parse_fallback(fallback, fallback_delta)
    with tempfile.TemporaryDirectory(prefix="hg2prism-detect-") as scratch:
        quiet = contextlib.nullcontext() if show_progress else progress.quiet()
        with quiet:
            checked = pipeline.check(world, Path(scratch), storm_method)
        return detection_experiment(world, checked, out, episodes, seed, show_progress, horizon,
                                    fallback, fallback_delta)


def _check_deviation_fits(world: World, horizon: int | None) -> None:
    """InputError when no episode can last past the steps P2 follows the model: with a horizon
    of at most deviate_after P2 never deviates, and every batch is the compliant one."""
    given = horizon is not None
    horizon = horizon or world.simulation.horizon
    after = world.detection.deviate_after
    if horizon <= after:
        raise InputError(COMMAND_LINE, "--horizon", f"a horizon of {horizon}"
                         + ("" if given else " (the world's [simulation] horizon)")
                         + f" ends every episode before P2 deviates: she follows the model "
                         f"for {after} steps ([detection] deviate_after); expected a horizon "
                         f"above {after}")


def _setting(name: str | None, value: object) -> str:
    """P2's setting shown after her window in reports (ObserverKind.shown_setting):
    ", threshold 1.5" (CUSUM), ", decision map" (Bayesian), nothing for a kind without one."""
    if name is None or value is None:
        return ""
    return f", {name} {value:g}" if isinstance(value, float) else f", {name} {value}"


def _shown_setting(world: World) -> str | None:
    from hg2prism.opponent.registry import observer_kind

    return observer_kind(world.inference).shown_setting


def _recorded_setting(result: dict) -> tuple[str | None, object]:
    """The setting a detection.json shows beside P2's window and P1's model's value of it
    (records written before it was named: CUSUM's threshold, else the Bayesian decision, each
    from `p1_model`)."""
    mismatch, model = result["model_mismatch"], result["p1_model"]
    if "shown_setting" in mismatch:
        name = mismatch["shown_setting"]
        return name, mismatch["reference"].get(f"p2_{name}")
    name = ("threshold" if model.get("threshold") is not None
            else "decision" if model.get("decision") is not None else None)
    return name, model.get(name)


def _rate(c: dict) -> str:
    low, high = c["ci95"]
    return f"{c['rate']:.4f} [{low:.4f}, {high:.4f}]"


def _step(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f}"


def detection_summary_lines(result: dict) -> list[str]:
    """What `make world2` prints about the detection experiment."""
    seeded, dev, comp = result["seeded_episode"], result["deviation"], result["compliant"]
    k = result["deviate_after"]
    hist = ", ".join(f"{n}: {c}" for n, c in dev["histogram"].items())
    # what P2 plays, in the table's words (records before it was written: trap sets)
    moves = "action" if result.get("p2_plays") == "actions" else "traps"
    shown, modelled = _recorded_setting(result)
    lines = [
        f"Mismatch detection in {result['world']} (alpha {result['alpha']}, epsilon "
        f"{result['epsilon']}, P2 follows the model for {k} step(s), then plays at random)",
        "",
        f"  seeded episode (seed {seeded['seed']}, {seeded['steps']} steps, {seeded['outcome']}): "
        + (f"detected at step {seeded['detected_at']}" if seeded["detected_at"] is not None
           else "not detected"),
        f"  {dev['episodes']} episodes: detected {dev['detected']} "
        f"({dev['share_detected']:.1%}), not detected {dev['not_detected']} "
        f"({dev['share_not_detected']:.1%}; {dev['episodes'] - dev['episodes_reaching_deviation']}"
        f" ended by step {k}), mean detection step {_step(dev['mean_detection_step'])}, "
        f"median {_step(dev['median_detection_step'])}",
        f"  detection steps: {hist or 'none'}",
        f"  false alarms when P2 follows the model: {comp['false_alarms']}/{comp['episodes']} "
        f"({comp['false_alarm_rate']:.2%}, 95% CI [{comp['false_alarm_rate_ci95'][0]:.4f}, "
        f"{comp['false_alarm_rate_ci95'][1]:.4f}])",
        "",
        f"P2's real inference differs from P1's model (window {result['p1_model']['window']}"
        f"{_setting(shown, modelled)}); "
        "P1 keeps playing its strategy:",
        "",
        f"| P2's inference | episodes where her hypothesis differed from P1's model / where "
        f"her {moves} did | detected | detected where her {moves} differed | mean detection step "
        "| completion (95% CI) | change | off-record steps |",
        "|---|---|---|---|---|---|---|---|",
    ]
    ref = result["model_mismatch"]["reference"]
    lines.append(f"| as modelled (window {ref['p2_window']}"
                 f"{_setting(shown, modelled)}) "
                 f"| 0 / 0 | {ref['detection_rate']:.1%} (false alarms) | - | - "
                 f"| {_rate(ref['completion'])} | - | {ref['completion']['off_record_steps']} |")
    for v in result["model_mismatch"]["variants"]:
        given = v["detection_rate_given_unpredicted_traps"]
        given_text = f"{given:.1%}" if given is not None else "-"
        lines.append(f"| {v['p2_inference']} | {v['episodes_with_hypothesis_divergence']} / "
                     f"{v['episodes_with_unpredicted_traps']} | {v['detection_rate']:.1%} "
                     f"| {given_text} | {_step(v['mean_detection_step'])} "
                     f"| {_rate(v['completion'])} | {v['completion_change']:+.4f} "
                     f"| {v['completion']['off_record_steps']} |")
    if result.get("replanning") is not None:
        lines += _replanning_lines(result["replanning"], k)
    lines.append("")
    if result["p1_model"].get("threshold") is None:        # no CUSUM score to report
        lines.append(f"  ({result['episodes']} episodes per row, seed {result['seed']}, horizon "
                     f"{result['horizon']})")
    else:
        lines.append(f"  ({result['episodes']} episodes per row, seed {result['seed']}, horizon "
                     f"{result['horizon']}; the largest CUSUM score P2 reaches when she follows the "
                     f"model is {result['compliant']['max_cusum_score']:.4g})")
    return lines


def _replanning_lines(replanning: dict, k: object) -> list[str]:
    """The summary's re-planning table: both runs' rates and their paired comparison,
    for P2 deviating after step `k` and for P2 following the model."""
    shown = (f"the robust strategy (delta {replanning['delta']:g})"
             if replanning["fallback"] == "robust" else "the leader-game strategy")
    lines = [
        "",
        f"Re-planning: at the detector's first rejection P1 switches to {shown} "
        "(both columns play the same episodes, each from its own random stream, "
        "seeded from the seed and its number, until P1's moves differ; they are "
        "other episodes than the table above's, whose rates they match only up to "
        "sampling noise):",
        "",
        "| P2 | completion without re-planning (95% CI) | with re-planning (95% CI) "
        "| change | completed only with / only without (McNemar p) "
        "| episodes in which the detector fired |",
        "|---|---|---|---|---|---|",
    ]
    for batch, name in (("deviation", f"deviates after step {k}"), ("compliant", "follows the model")):
        without, with_ = replanning[batch]["without"], replanning[batch]["with"]
        paired = replanning[batch]["paired"]
        lines.append(f"| {name} | {_rate(without)} | {_rate(with_)} "
                     f"| {with_['rate'] - without['rate']:+.4f} "
                     f"| {paired['only_with']} / {paired['only_without']} "
                     f"(p = {paired['mcnemar_p']:.2g}) "
                     f"| {with_['detected_episodes']} / {with_['episodes']} |")
    return lines
