"""explorer.html: one self-contained page (data and script inline, no server, no network) in
which a reader steps through the drawn episode, and through any of the candidate episodes the
drawn one was chosen from (analyses/episodes.py), and sees at every state what strategy.json
and P2's observer say there (docs/semantics.md §8 "The episode drawn"):

- the world, drawn by its drawer's positions (report/plots.py:world_drawer: a grid as cells, any
  other arena as a graph), the robot, the path so far and the traps P2 sets;
- each of P1's moves with its value (the record's ``values``, and ``bounded_values`` for the
  step-bounded objective), the move the strategy chooses and the move realised;
- P2's belief (the numbers her observer reports, observer.ReportsBelief: CUSUM scores with
  their threshold, or the posterior) and what it would become after each of P1's moves.

Everything shown is computed here in Python, by the strategy's records and the observer's own
`update` and `belief`; the page's script only draws it. Step numbering (shared with the figures):
step n is P1's n-th move (from 1); state n is the state after step n (state 0 the start); P2's
belief at step n is the one she holds after observing step n, so a change of mind caused by
step n's observation is shown at step n.
"""

from __future__ import annotations

import json
from collections.abc import Hashable
from pathlib import Path

from matplotlib.colors import to_hex

from hg2prism.analyses.episodes import (EPISODE_SEEDS, ChosenEpisode, candidate_episodes,
                                        belief_trace, episode_steps, outcome_text)
from hg2prism.model.world import World
from hg2prism.opponent.observer import ReportsBelief
from hg2prism.outputs import write_text
from hg2prism.prism.rendering import render_template
from hg2prism.report.style import TRAP_COLOUR, TRAPPED_COLOUR, hypothesis_colour
from hg2prism.strategy.records import Strategy
from hg2prism.strategy.stepped import SteppedStrategy, TimedMemory

__all__ = ["explorer_data", "explorer_html", "write_explorer"]

TEMPLATE = "explorer.html.j2"


class _Tables:
    """What states share, stored once: strategy records and P2's answers to each move."""

    def __init__(self) -> None:
        self.records: list[dict] = []
        self.options: list[list[dict]] = []
        self._records: dict[int, int] = {}
        self._options: dict[Hashable, int] = {}

    def record(self, record) -> int | None:
        if record is None:
            return None
        if id(record) not in self._records:
            self._records[id(record)] = len(self.records)
            self.records.append({k: v for k, v in record.items() if k != "initial"})
        return self._records[id(record)]

    def option(self, key: Hashable, make) -> int:
        if key not in self._options:
            self._options[key] = len(self.options)
            self.options.append(make())
        return self._options[key]


def _numbers(values) -> list[float]:
    return [float(b) for b in values]


class _Builder:
    """The page's data for one world: episodes as lists of states and steps."""

    def __init__(self, world: World, analysis, strategy, drawer) -> None:
        self.world, self.ts, self.observer = world, analysis.ts, analysis.inference
        self.strategy = strategy.base if isinstance(strategy, SteppedStrategy) else strategy
        self.drawer = drawer
        self.reports = isinstance(self.observer, ReportsBelief)
        self.tables = _Tables()

    def _record(self, step) -> int | None:
        if not isinstance(self.strategy, Strategy):
            return None
        memory = step.memory.memory if isinstance(step.memory, TimedMemory) else step.memory
        return self.tables.record(self.strategy.record(step.ts_state, step.q, memory))

    def _answers(self, step) -> int:
        """P2's belief and hypothesis after each move P1 could play in the step's state (the
        trap set in force the one she played)."""
        observer, v, rest = self.observer, step.ts_state, tuple(step.observation[2:])

        def make() -> list[dict]:
            answers = []
            for a, name in enumerate(self.ts.action_names(v)):
                observation = (v, a) + rest
                after = observer.update(step.p2_memory, observation)
                answers.append({"move": name, "hypothesis": observer.hypothesis(after),
                                "belief": _numbers(observer.belief(step.p2_memory, observation))
                                if self.reports else None})
            return answers

        return self.tables.option((step.p2_memory, v, rest), make)

    def episode(self, records: list, code: int, seed: int, drawn: bool) -> dict:
        """One episode: states 0..N (state n after step n) and steps 1..N."""
        steps = episode_steps(self.ts, records)
        initial = self.observer.initial_memory()
        states = [{"place": steps[0].start if steps else self.ts.arena.initial,
                   "belief": {"hypothesis": self.observer.hypothesis(initial), "acted": None,
                              "held": None, "changed": False, "belief": None}}]
        trace = belief_trace(self.observer, records)       # her belief after each step
        for i, (record, step) in enumerate(zip(records, steps)):
            states[-1]["record"] = self._record(record)
            states[-1]["answers"] = self._answers(record)
            states.append({"place": step.landing, "belief": {
                "hypothesis": trace.after[i], "acted": trace.acted[i], "held": trace.held[i],
                "changed": trace.after[i] != trace.held[i],
                "belief": list(trace.values[i]) if trace.values is not None else None}})
        return {"seed": seed, "outcome": outcome_text(code), "drawn": drawn,
                "states": states,
                "steps": [{"n": s.n, "start": s.start, "landing": s.landing,
                           "action": s.action_name, "realised": self.drawer.caption(s),
                           "p2_action": s.p2_action_name, "traps": list(s.traps),
                           "trapped": s.trapped, "hypothesis": s.hypothesis}
                          for s in steps]}


def _candidates(played, strategy, drawn: ChosenEpisode, horizon: int, seed: int) -> list:
    """The drawn episode's candidates, (steps, code, seed) by seed: those it was chosen from,
    or for seed=N the simulation's seed set with the drawn episode."""
    if drawn.seeds is not None:
        return list(drawn.candidates)
    candidates = candidate_episodes(played, strategy, horizon, seed)
    if not any(c[2] == drawn.seed for c in candidates):
        candidates += list(drawn.candidates)
    return sorted(candidates, key=lambda c: c[2])


def explorer_data(world: World, analysis, played, strategy, drawn: ChosenEpisode,
                  horizon: int, seed: int) -> dict:
    """The page's data: the world's map and positions, its hypotheses and observer, and every
    candidate episode. `analysis` is the run's results.Analysis (P2's observer as she runs
    it), `played` the analysis the episodes were simulated with, `strategy` P1's policy."""
    from hg2prism.report.plots import world_drawer

    ts = analysis.ts
    drawer = world_drawer(world, ts)
    builder = _Builder(world, analysis, strategy, drawer)
    episodes = [builder.episode(steps, code, s, s == drawn.seed)
                for steps, code, s in _candidates(played, strategy, drawn, horizon, seed)]
    observer = analysis.inference
    return {
        "world": world.name, "formula": world.formula, "horizon": horizon,
        "chosen_as": drawn.describe(), "seed_set": list(drawn.seeds or (seed, seed + EPISODE_SEEDS - 1)),
        "hypotheses": list(world.hypotheses),
        "colours": [to_hex(hypothesis_colour(x)) for x in range(len(world.hypotheses))],
        "trap_colour": to_hex(TRAP_COLOUR), "trapped_colour": to_hex(TRAPPED_COLOUR),
        "observer": {"kind": observer.kind,
                     "name": observer.belief_name if builder.reports else None,
                     "threshold": observer.belief_threshold if builder.reports else None},
        "states": list(ts.arena.states),
        "positions": [list(drawer.position(s)) for s in range(ts.arena.n_states)],
        "start": int(ts.arena.initial),
        "candidates": [int(c) for c in ts.arena.trap_candidates],
        "map": drawer.explorer_map(),
        "records": builder.tables.records, "answers": builder.tables.options,
        "episodes": episodes,
    }


def explorer_html(data: dict) -> str:
    """The page: the template with `data` inline (a JSON text that cannot close its script)."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    text = text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    return render_template(TEMPLATE, title=f"{data['world']}: strategy explorer", data=text)


def write_explorer(world: World, analysis, played, strategy, drawn: ChosenEpisode,
                   horizon: int, seed: int, path: Path) -> None:
    """explorer.html (module docstring), written atomically."""
    write_text(path, explorer_html(explorer_data(world, analysis, played, strategy, drawn,
                                                 horizon, seed)))
