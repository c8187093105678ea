"""The one deceptive episode the figures and the replay draw, chosen by a stated rule
(docs/semantics.md §8 "The episode drawn").

The candidates are the *seed set*: seeds ``seed, seed+1, ..., seed+EPISODE_SEEDS-1`` (``seed``
is the simulation's seed), each simulated as one episode with ``numpy.random.default_rng`` of
that seed. Rules:

- ``median`` (the default): among the completed candidates sorted by (length, seed), the one at
  position ``(k - 1) // 2`` of ``k`` (the lower median), so that the picture shows a typical
  completed episode rather than a lucky one;
- ``shortest``: the first of that order;
- ``seed=N``: the episode simulated with seed N, whatever its outcome.

When no candidate completes, ``median`` and ``shortest`` draw the first candidate (seed
``seed``) and say so.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

from hg2prism.errors import COMMAND_LINE, InputError
from hg2prism.model.validation import MAX_SEED
from hg2prism.strategy.policy import Policy

if TYPE_CHECKING:
    from hg2prism.results import Analysis

__all__ = ["EPISODE_SEEDS", "EpisodeRule", "ChosenEpisode", "parse_episode_rule", "candidate_episodes",
           "choose_episode",
           "outcome_text", "Step", "episode_steps", "BeliefTrace", "belief_trace"]

EPISODE_SEEDS = 50
RULES = ("median", "shortest")
_SEED_RULE = re.compile(r"seed=(\d+)")


@dataclass(frozen=True)
class EpisodeRule:
    """How the drawn episode is chosen: ``kind`` is "median", "shortest" or "seed"; ``seed`` is
    N for "seed=N"."""

    kind: str = "median"
    seed: int | None = None

    def __str__(self) -> str:
        return f"seed={self.seed}" if self.kind == "seed" else self.kind


def parse_episode_rule(text: str | EpisodeRule | None) -> EpisodeRule:
    """`--episode`'s value: "median", "shortest" or "seed=N" with N >= 0 (None: "median").
    Raises InputError (key --episode) otherwise."""
    if text is None:
        return EpisodeRule()
    if isinstance(text, EpisodeRule):
        return text
    value = str(text).strip()
    if value in RULES:
        return EpisodeRule(value)
    match = _SEED_RULE.fullmatch(value)
    if match and int(match.group(1)) <= MAX_SEED:
        return EpisodeRule("seed", int(match.group(1)))
    raise InputError(COMMAND_LINE, "--episode", "expected median, shortest or seed=N with N "
                     f"an integer in [0, {MAX_SEED:,}], got {value!r}")


@dataclass(frozen=True, eq=False)
class ChosenEpisode:
    """The episode drawn: its steps (simulation.StepRecord, in order) and how it was chosen."""

    steps: list
    seed: int                   # the seed it was simulated with (one episode)
    outcome: str                # "task completed", "failed" or "cut by the horizon"
    rule: EpisodeRule
    seeds: tuple[int, int] | None       # the seed set searched (first, last), None for seed=N
    completed_lengths: tuple[int, ...]  # lengths of the completed candidates, sorted
    fallback: bool = False              # no candidate completed: the first one is drawn
    # every candidate simulated, (steps, outcome code, seed) by seed (seed=N: the one drawn)
    candidates: tuple = ()

    @property
    def n_steps(self) -> int:
        return len(self.steps)

    def describe(self) -> str:
        """How the episode was chosen, in words (figure titles, results.json)."""
        if self.rule.kind == "seed":
            return f"the episode of seed {self.seed}"
        first, last = self.seeds
        if self.fallback:
            return f"no episode of seeds {first}..{last} completed: the first (seed {first})"
        which = "median-length" if self.rule.kind == "median" else "shortest"
        return f"the {which} completed episode of seeds {first}..{last}"


def outcome_text(code: int) -> str:
    from hg2prism.analyses import simulation

    return {simulation.GOAL: "task completed", simulation.FAIL: "failed"}.get(
        int(code), "cut by the horizon")


def _one_episode(analysis: Analysis, strategy: Policy, horizon: int, seed: int) -> tuple[list, int]:
    from hg2prism.analyses import simulation

    steps: list = []
    summary = simulation.simulate_deceptive(analysis, strategy, 1, horizon, seed,
                                            observer=steps.append, progress=False)
    return steps, int(summary.outcomes[0])


def candidate_episodes(analysis: Analysis, strategy: Policy, horizon: int, seed: int
                       ) -> list[tuple[list, int, int]]:
    """The seed set's episodes (module docstring): (steps, outcome code, seed) by seed."""
    return [(*_one_episode(analysis, strategy, horizon, candidate), candidate)
            for candidate in range(seed, seed + EPISODE_SEEDS)]


def choose_episode(analysis: Analysis, strategy: Policy, horizon: int, seed: int,
                   rule: EpisodeRule | str | None = None) -> ChosenEpisode:
    """The deceptive episode `rule` names (module docstring); `analysis` is a
    results.Analysis, `strategy` P1's Policy (a records.Strategy), `seed` the simulation's seed."""
    from hg2prism.analyses import simulation

    rule = parse_episode_rule(rule)
    if rule.kind == "seed":
        steps, code = _one_episode(analysis, strategy, horizon, rule.seed)
        return ChosenEpisode(steps, rule.seed, outcome_text(code), rule, None, (),
                             candidates=((steps, code, rule.seed),))
    candidates = tuple(candidate_episodes(analysis, strategy, horizon, seed))
    completed = sorted((c for c in candidates if c[1] == simulation.GOAL),
                       key=lambda c: (len(c[0]), c[2]))
    lengths = tuple(len(c[0]) for c in completed)
    seeds = (seed, seed + EPISODE_SEEDS - 1)
    if not completed:
        steps, code, first = candidates[0]
        return ChosenEpisode(steps, first, outcome_text(code), rule, seeds, lengths, True,
                             candidates)
    index = (len(completed) - 1) // 2 if rule.kind == "median" else 0
    steps, code, chosen = completed[index]
    return ChosenEpisode(steps, chosen, outcome_text(code), rule, seeds, lengths,
                         candidates=candidates)


@dataclass(frozen=True)
class Step:
    """One step of an episode as drawn, in the arena's terms (docs/semantics.md §15): the arena
    state P1 was in, the action he chose (its slot and name), the outcome of that action that
    happened (an index into the arena's outcome axis) and the arena state it led to, P2's action
    (for trap sets, the states it covers) and hypothesis, and whether P1 was trapped. A trapped
    step lands on the trapped state; a step that stays lands where it started. When several
    outcomes lead to the same state, the first one with positive probability is reported."""

    n: int
    start: int                  # arena state before the step
    action: int                 # P1's action slot at `start`
    action_name: str
    outcome: int                # the outcome taken (index k of the arena's tables)
    landing: int                # arena state reached
    p2_action: int              # P2's action (index into ts.a2_names)
    p2_action_name: str
    traps: tuple[int, ...]      # arena states P2's trap set covers (none with general actions)
    trapped: bool
    hypothesis: int             # the hypothesis P2 acted on (drawn, when she draws it)
    terminal: bool = False      # `landing` is a terminal state (no action): the episode ends

    @property
    def stays(self) -> bool:
        return self.landing == self.start


def _outcome(ts, step) -> int:
    """The outcome of (state, a1, a2) that led to the step's successor: the first with positive
    probability (else the first at all; 0 when none does)."""
    import numpy as np

    reached = ts.succ[step.ts_state, step.a1, step.a2] == step.next_state
    positive = reached & (ts.prob[step.ts_state, step.a1, step.a2] > 0)
    hits = np.flatnonzero(positive if positive.any() else reached)
    return int(hits[0]) if hits.size else 0


def episode_steps(ts, steps) -> list[Step]:
    """The steps (simulation.StepRecord) of an episode on `ts` (a TransitionSystem) as Steps."""
    arena = ts.arena
    drawn = []
    for record in steps:
        place = ts.decode(record.ts_state)[0]
        outcome = _outcome(ts, record)
        trapped = record.next_state == ts.trapped
        if trapped:
            j = record.a2 if arena.p2_dependent else 0
            landing = int(arena.dest[place, record.a1, j, outcome])
        else:
            landing = int(ts.decode(record.next_state)[0])
        drawn.append(Step(
            n=record.n, start=int(place), action=int(record.a1),
            action_name=ts.action_names(record.ts_state)[record.a1], outcome=outcome,
            landing=landing, p2_action=int(record.a2), p2_action_name=ts.a2_names[record.a2],
            traps=tuple(int(p) for p in ts.trap_places(record.a2)), trapped=trapped,
            hypothesis=record.acted,
            terminal=bool(arena.terminal[landing]) and not trapped))
    return drawn


@dataclass(frozen=True, eq=False)
class BeliefTrace:
    """P2's side of an episode, step by step: the hypothesis she acted on, the one she
    holds after reading P1's move, and (when her observer reports them, observer.ReportsBelief)
    the per-hypothesis numbers her update rests on. The hypothesis she holds is her memory's
    (a Bayesian observer's most probable one); she acts on it unless she draws her hypothesis
    (decision "sample", docs/semantics.md §12), when she acts on the one drawn."""

    acted: tuple[int, ...]          # [n-1]: hypothesis P2 acted on at step n
    after: tuple[int, ...]          # [n-1]: her hypothesis after step n's update
    name: str | None                # what `values` are ("CUSUM score Z_x"), None if unreported
    threshold: float | None         # the level at which she changes her mind, if any
    values: tuple[tuple[float, ...], ...] | None    # [n-1][x]
    held: tuple[int, ...] = ()      # [n-1]: her hypothesis before step n (`acted` when empty)

    @property
    def before(self) -> tuple[int, ...]:
        """[n-1]: the hypothesis P2 held before step n."""
        return self.held or self.acted

    @property
    def changes(self) -> tuple[tuple[int, int], ...]:
        """P2's changes of mind as (n, x): observing step n made her switch to x (the
        figures' step-numbering rule, docs/semantics.md §15 "Figures": shown at step n)."""
        return tuple((n, after) for n, (held, after) in enumerate(zip(self.before, self.after),
                                                                  start=1) if after != held)


def belief_trace(observer, steps) -> BeliefTrace:
    """P2's belief along `steps` (simulation.StepRecord) under `observer` (her inference)."""
    from hg2prism.opponent.observer import ReportsBelief

    held = tuple(observer.hypothesis(s.p2_memory) for s in steps)
    acted = tuple(s.acted for s in steps)
    after = tuple(observer.hypothesis(observer.update(s.p2_memory, s.observation)) for s in steps)
    if not isinstance(observer, ReportsBelief):
        return BeliefTrace(acted, after, None, None, None, held)
    values = tuple(tuple(float(b) for b in observer.belief(s.p2_memory, s.observation))
                   for s in steps)
    return BeliefTrace(acted, after, observer.belief_name, observer.belief_threshold, values,
                       held)
