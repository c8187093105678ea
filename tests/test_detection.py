"""Online mismatch detection (docs/semantics.md §9): likelihood-ratio test on hand-computed sequences.

Notation: eps = epsilon; with 3 actions p0(predicted) = 1 - eps, p0(other) = eps / 2;
with eps = 0.1:  ln 0.9 = -0.1053605,  ln 0.05 = -2.9957323.
chi2.ppf(0.95, df) = 3.8414588 (df 1), 5.9914645 (df 2), 7.8147279 (df 3).
"""

from __future__ import annotations

import math
import random

import pytest
from scipy.stats import chi2

from hg2prism.analyses.detection import (
    MismatchDetector,
    Step,
    compliant_rejection_count,
    first_rejection,
    summarize_detection,
)

LN09 = math.log(0.9)
LN005 = math.log(0.05)
LN2 = math.log(2.0)
LN3 = math.log(3.0)
PPF95 = {1: 3.8414588206941, 2: 5.991464547107979, 3: 7.814727903251178}


def run_detector(observations, alpha: float, epsilon: float) -> list[Step]:
    """The Steps of a fresh detector fed (state, predicted, observed, n_actions)."""
    detector = MismatchDetector(alpha, epsilon)
    return [detector.observe(*obs) for obs in observations]


def detection_summary(steps_per_episode, deviate_after: int | None = None):
    """summarize_detection over the Step lists of episodes."""
    return summarize_detection([first_rejection(s) for s in steps_per_episode], deviate_after)


def false_alarm_rate(first_rejections) -> float:
    """Share of episodes (in which P2 never deviates) rejected at some step."""
    if len(first_rejections) == 0:
        raise ValueError("no episodes")
    return sum(1 for n in first_rejections if n is not None) / len(first_rejections)


def test_single_step_following_prediction():
    # observed == predicted, 3 actions, eps = 0.1:
    # ln L1 = 1 * ln(1/1) = 0, ln L0 = ln 0.9, G = -2 ln 0.9 = 0.2107210, df = 1
    d = MismatchDetector(alpha=0.05, epsilon=0.1)
    step = d.observe("s", "a", "a", 3)
    assert step == Step(n=1, counted=True, statistic=pytest.approx(-2 * LN09), df=1,
                        threshold=pytest.approx(PPF95[1]), rejected=False)
    assert step.statistic == pytest.approx(0.21072103131565256, abs=1e-12)
    assert d.first_rejection is None
    assert d.log_l0 == pytest.approx(LN09)
    assert d._log_l1 == 0.0


def test_single_action_steps_are_skipped():
    d = MismatchDetector(alpha=0.05, epsilon=0.1)
    # two single-action steps: n advances, nothing counted, df = 0 -> no test
    for n in (1, 2):
        step = d.observe("u", "x", "x", 1)
        assert step == Step(n=n, counted=False, statistic=0.0, df=0, threshold=None,
                            rejected=False)
    # a counted step: G = -2 ln 0.9, df = 1
    step = d.observe("s", "a", "a", 3)
    assert (step.n, step.counted, step.df) == (3, True, 1)
    assert step.statistic == pytest.approx(-2 * LN09)
    # another single-action step (even for a state seen before): df and G unchanged
    step = d.observe("s", "a", "a", 1)
    assert (step.n, step.counted, step.df) == (4, False, 1)
    assert step.statistic == pytest.approx(-2 * LN09)
    assert step.threshold == pytest.approx(PPF95[1])
    assert d.n == 4 and d.n_counted == 1
    # a skipped step does not enter the counts: the next visit of "s" with a different
    # action gives counts a:1, b:1 -> ln L1 = 2 ln(1/2), ln L0 = ln 0.9 + ln 0.05,
    # G = 2(-2 ln 2 - ln 0.9 - ln 0.05) = 3.4295969, df = 2
    step = d.observe("s", "a", "b", 3)
    assert (step.n, step.df) == (5, 2)
    assert step.statistic == pytest.approx(2 * (-2 * LN2 - LN09 - LN005))


def test_no_test_while_df_is_zero():
    # only single-action steps: df stays 0, threshold None, never rejected,
    # even if the "observed" action differs from the prediction (carries no information)
    d = MismatchDetector(alpha=0.5, epsilon=0.9)
    steps = [d.observe(("v", i % 3), "x", "y" if i % 2 else "x", 1) for i in range(1000)]
    assert all(s.df == 0 and s.threshold is None and not s.rejected and not s.counted
               and s.statistic == 0.0 for s in steps)
    assert [s.n for s in steps] == list(range(1, 1001))
    assert d.first_rejection is None
    assert first_rejection(steps) is None


def test_repeated_visits_use_counts():
    # one state, 3 actions, predicted "a", eps = 0.1, observed a, b, a, c.
    # step 1: counts a1        ln L1 = 0                         ln L0 = ln .9
    #         G = -2 ln .9 = 0.2107210                         df 1
    # step 2: counts a1 b1     ln L1 = 2 ln(1/2) = -2 ln 2       ln L0 = ln .9 + ln .05
    #         G = 2(-2 ln 2 - ln .9 - ln .05) = 3.4295969      df 2 (< 5.9915)
    # step 3: counts a2 b1     ln L1 = 2 ln(2/3) + ln(1/3) = 2 ln 2 - 3 ln 3
    #         ln L0 = 2 ln .9 + ln .05
    #         G = 2(2 ln 2 - 3 ln 3 - 2 ln .9 - ln .05) = 2.5938216  df 2
    #         (G drops: L1 is re-evaluated with the current estimate phat = (2/3, 1/3))
    # step 4: counts a2 b1 c1  ln L1 = 2 ln(1/2) + 2 ln(1/4) = -6 ln 2
    #         ln L0 = 2 ln .9 + 2 ln .05
    #         G = 2(-6 ln 2 - 2 ln .9 - 2 ln .05) = 4.0866050  df 3 (< 7.8147)
    steps = run_detector([("s", "a", o, 3) for o in "abac"], alpha=0.05, epsilon=0.1)
    expected = [
        (-2 * LN09, 1),
        (2 * (-2 * LN2 - LN09 - LN005), 2),
        (2 * (2 * LN2 - 3 * LN3 - 2 * LN09 - LN005), 2),
        (2 * (-6 * LN2 - 2 * LN09 - 2 * LN005), 3),
    ]
    numbers = [0.21072103131565256, 3.4295968561838532, 2.5938215999704095, 4.086604990127926]
    for step, (g, df), num in zip(steps, expected, numbers):
        assert step.statistic == pytest.approx(g, abs=1e-12)
        assert step.statistic == pytest.approx(num, abs=1e-12)
        assert step.df == df
        assert step.threshold == pytest.approx(PPF95[df])
        assert not step.rejected


def test_two_states_and_two_action_smoothing():
    # s1: 3 actions, predicted a (p0 other = 0.05); s2: 2 actions, predicted x (p0 other = 0.1)
    # step 1 (s1, b): ln L1 = 0, ln L0 = ln .05, G = -2 ln .05 = 5.9914645 > 3.8415 (df 1)
    #   -> a single deviation at a fresh state already rejects (p0 = 0.05 < e^{-3.84/2} = 0.147)
    # step 2 (s2, y): ln L1 = 0, ln L0 = ln .05 + ln .1, G = 10.6966 df 2
    # step 3 (s1, b): s1 counts b2 -> still ln L1 = 0; ln L0 = 2 ln .05 + ln .1, G = 16.6880
    # step 4 (s2, x): s2 counts y1 x1 -> ln L1 = -2 ln 2; ln L0 = 2 ln .05 + ln .1 + ln .9
    #   G = 2(-2 ln 2 - 2 ln .05 - ln .1 - ln .9) = 2 * 7.0131158 = 14.0262316, df 3
    obs = [("s1", "a", "b", 3), ("s2", "x", "y", 2), ("s1", "a", "b", 3), ("s2", "x", "x", 2)]
    d = MismatchDetector(alpha=0.05, epsilon=0.1)
    steps = [d.observe(*o) for o in obs]
    ln01 = math.log(0.1)
    assert [s.statistic for s in steps] == pytest.approx([
        -2 * LN005,
        -2 * (LN005 + ln01),
        -2 * (2 * LN005 + ln01),
        2 * (-2 * LN2 - 2 * LN005 - ln01 - LN09),
    ], abs=1e-12)
    assert steps[3].statistic == pytest.approx(14.0262315893, abs=1e-9)
    assert [s.df for s in steps] == [1, 2, 2, 3]
    assert all(s.rejected for s in steps)
    assert d.first_rejection == 1


def test_decision_flips_exactly_at_chi2_quantile_alpha():
    # sequence a, b at one state (eps = 0.1, 3 actions): at step 2
    # G = 2 ln(L1/L0) = 2 ln((1/4) / (0.9 * 0.05)) = 3.4295969, df = 2.
    # For df = 2, chi2.ppf(1 - alpha, 2) = -2 ln alpha, so G > threshold <=> alpha > L0/L1 = 0.18.
    obs = [("s", "a", "a", 3), ("s", "a", "b", 3)]
    g = 2 * math.log(0.25 / (0.9 * 0.05))
    assert chi2.sf(g, 2) == pytest.approx(0.18, abs=1e-12)
    # alpha = 0.181: threshold -2 ln 0.181 = 3.4185 < G -> reject at step 2
    # (step 1: G = 0.2107 < chi2.ppf(0.819, 1) = 1.789, no rejection)
    steps = run_detector(obs, alpha=0.181, epsilon=0.1)
    assert steps[1].threshold == pytest.approx(-2 * math.log(0.181))
    assert [s.rejected for s in steps] == [False, True]
    assert first_rejection(steps) == 2
    # alpha = 0.179: threshold -2 ln 0.179 = 3.4407 > G -> no rejection
    steps = run_detector(obs, alpha=0.179, epsilon=0.1)
    assert steps[1].threshold == pytest.approx(-2 * math.log(0.179))
    assert [s.rejected for s in steps] == [False, False]
    assert first_rejection(steps) is None


def test_following_the_prediction_at_one_repeated_state_eventually_rejects():
    # Always playing the prediction at ONE state: phat = 1 so ln L1 = 0 and
    # G_N = -2 N ln(1 - eps) = 0.2107210 N (eps = 0.1), while df stays 1.
    # G_18 = 3.7929786 < 3.8414588 < G_19 = 4.0036996: the decision flips at N = 19 -- a false
    # alarm although P2 behaves exactly as modelled.
    d = MismatchDetector(alpha=0.05, epsilon=0.1)
    steps = [d.observe("s", "a", "a", 3) for _ in range(30)]
    assert all(s.df == 1 for s in steps)
    assert steps[17].statistic == pytest.approx(18 * -2 * LN09)
    assert steps[17].statistic < PPF95[1] < steps[18].statistic
    assert [s.rejected for s in steps] == [False] * 18 + [True] * 12
    assert d.first_rejection == 19
    assert compliant_rejection_count(0.05, 0.1) == 19
    # single-action steps in between do not count: the 19th COUNTED visit rejects
    d = MismatchDetector(alpha=0.05, epsilon=0.1)
    for _ in range(19):
        d.observe("u", "x", "x", 1)
        d.observe("s", "a", "a", 3)
    assert d.first_rejection == 38
    # the defaults of docs/semantics.md §1 (alpha 0.05, eps 0.01): 3.8414588 / (-2 ln 0.99) = 191.11 -> 192
    d = MismatchDetector(alpha=0.05, epsilon=0.01)
    steps = [d.observe("s", "a", "a", 4) for _ in range(200)]
    assert d.first_rejection == 192 == compliant_rejection_count(0.05, 0.01)
    assert not steps[190].rejected and steps[191].rejected


def test_following_the_prediction_two_alternating_states():
    # two states, always the prediction: G_N = 0.2107210 N, df = 2 from N = 2 on;
    # 5.9914645 / 0.2107210 = 28.43 -> first rejection at N = 29
    obs = [(i % 2, "a", "a", 3) for i in range(40)]
    steps = run_detector(obs, alpha=0.05, epsilon=0.1)
    assert first_rejection(steps) == 29 == compliant_rejection_count(0.05, 0.1, 2)
    assert steps[27].statistic < PPF95[2] < steps[28].statistic


def test_following_the_prediction_at_fresh_states_never_rejects():
    # every step a new state: G_N = 0.2107 N, df = N, and chi2.ppf(0.95, N) > N > G_N
    d = MismatchDetector(alpha=0.05, epsilon=0.1)
    steps = [d.observe(("v", i), i % 4, i % 4, 4) for i in range(2000)]
    assert d.first_rejection is None
    assert all(s.df == s.n and s.statistic < s.n < s.threshold for s in steps)
    # the argument needs chi2.ppf(1 - alpha, N) > N (true for alpha < 0.317): with alpha = 0.5
    # and eps = 0.5, -2 ln(1 - 0.5) = 1.386 > chi2.ppf(0.5, 1) = 0.455, so a compliant P2 is
    # rejected at the very first step even at a fresh state.
    steps = run_detector([(("v", i), 0, 0, 2) for i in range(5)], alpha=0.5, epsilon=0.5)
    assert steps[0].statistic == pytest.approx(-2 * math.log(0.5))
    assert steps[0].threshold == pytest.approx(chi2.ppf(0.5, 1))
    assert first_rejection(steps) == 1


def _deviation_episode(rng: random.Random, deviate_after: int, horizon: int,
                       alpha: float = 0.05, epsilon: float = 0.01) -> list[Step]:
    """A few states, 4 actions (some single-action steps); P2 follows the model for
    n <= deviate_after, then plays uniformly."""
    detector = MismatchDetector(alpha, epsilon)
    predicted_of = {s: rng.randrange(4) for s in range(6)}
    steps = []
    for n in range(1, horizon + 1):
        state = rng.randrange(7)
        if state == 6:                       # a forced step
            steps.append(detector.observe(state, 0, 0, 1))
            continue
        predicted = predicted_of[state]
        observed = predicted if n <= deviate_after else rng.randrange(4)
        steps.append(detector.observe(state, predicted, observed, 4))
    return steps


def test_random_deviations_are_detected():
    rng = random.Random(12345)
    episodes = [_deviation_episode(rng, deviate_after=4, horizon=100) for _ in range(200)]
    firsts = [first_rejection(s) for s in episodes]
    # with eps = 0.01 and 4 actions one deviation at a fresh state gives
    # -2 ln(0.01/3) = 11.4 -- far above any threshold reached here
    assert all(f is not None and f > 4 for f in firsts)
    summary = detection_summary(episodes, deviate_after=4)
    assert summary.episodes == 200 and summary.detected == 200
    assert summary.not_detected == 0 and summary.share_not_detected == 0.0
    assert summary.before_deviation == 0
    assert min(summary.delays) >= 1 and summary.mean_delay < 10
    # the statistic is never negative and only rises/falls on counted steps
    for steps in episodes:
        for prev, cur in zip(steps, steps[1:]):
            assert cur.statistic >= 0.0
            if not cur.counted:
                assert (cur.statistic, cur.df) == (prev.statistic, prev.df)


def test_compliant_episodes_have_no_false_alarm_under_defaults():
    # horizon 100 < 192 counted steps needed by any compliant sequence (alpha .05, eps .01)
    rng = random.Random(7)
    episodes = [_deviation_episode(rng, deviate_after=10**9, horizon=100) for _ in range(50)]
    firsts = [first_rejection(s) for s in episodes]
    assert false_alarm_rate(firsts) == 0.0


def test_summaries():
    firsts = [5, None, 7, 5, 3, None, 12, 6]
    s = summarize_detection(firsts, deviate_after=4)
    assert s.episodes == 8 and s.detected == 6 and s.not_detected == 2
    assert s.share_detected == pytest.approx(0.75)
    assert s.share_not_detected == pytest.approx(0.25)
    assert s.detection_steps == (3, 5, 5, 6, 7, 12)
    assert s.histogram == ((3, 1), (5, 2), (6, 1), (7, 1), (12, 1))
    assert s.before_deviation == 1                       # n = 3 <= 4
    assert s.delays == (1, 1, 2, 3, 8)
    assert s.mean_delay == pytest.approx(3.0)
    assert s.mean_detection_step == pytest.approx(38 / 6)
    assert s.median_detection_step == pytest.approx(5.5)
    assert false_alarm_rate(firsts) == pytest.approx(0.75)
    assert false_alarm_rate([None, None, None, 2]) == pytest.approx(0.25)
    none = summarize_detection([None, None])
    assert none.detected == 0 and none.share_not_detected == 1.0
    assert none.mean_detection_step is None and none.median_detection_step is None
    assert none.delays == () and none.mean_delay is None
    with pytest.raises(ValueError):
        summarize_detection([])
    with pytest.raises(ValueError):
        false_alarm_rate([])


def test_invalid_input():
    for bad in (0.0, 1.0, -0.1, 1.5):
        with pytest.raises(ValueError):
            MismatchDetector(alpha=bad, epsilon=0.1)
        with pytest.raises(ValueError):
            MismatchDetector(alpha=0.05, epsilon=bad)
    d = MismatchDetector(alpha=0.05, epsilon=0.1)
    with pytest.raises(ValueError):
        d.observe("s", "a", "a", 0)
    d.observe("s", "a", "a", 2)
    with pytest.raises(ValueError):                      # prediction is a function of the state
        d.observe("s", "b", "a", 2)
    with pytest.raises(ValueError):                      # so is the number of actions
        d.observe("s", "a", "a", 3)
    d.observe("s", "a", "b", 2)
    with pytest.raises(ValueError):                      # a third action among 2
        d.observe("s", "a", "c", 2)
