"""strategy.json: P1's deceptive strategy as records, one per reachable hypergame state that is
neither goal nor failure (docs/semantics.md §6), and `Strategy`, the one type that holds it:
read from the records (or the file), asked for P1's move in a hypergame state.

Writers: `strategy_records` (the records as dicts) and `strategy_json` (the file's text, built
column-wise by strategy/columns.py: the same text as json.dumps of each record, for millions
of records).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from hg2prism.engines.engine import Transitions
from hg2prism.prism.decoding import DecodedStates
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.frontends.grid import ACTIONS
from hg2prism.opponent.observer import Memory
from hg2prism.strategy.columns import Field, Lines, Texts, Vocabulary, integers, literal, tokens
from hg2prism.strategy.deceptive import StormChoices


class StrategyError(LookupError):
    """The strategy has no (or an unreadable) record for a hypergame state."""


def strategy_records(decoded: DecodedStates, choices: StormChoices, moves: Transitions,
                     ts: TransitionSystem, extras: RecordExtras | None = None) -> list[dict]:
    """P1's deceptive strategy: one record per reachable non-absorbing canonical state.

    `extras` (RecordExtras) adds keys after ``action``."""
    records = []
    described: dict[int, dict] = {}     # a few hundred TS states describe millions of records

    def describe(state: int) -> dict:
        if state not in described:
            described[state] = ts.describe_state(state)
        return dict(described[state])

    cells, traps, countdowns = decoded.cell.tolist(), decoded.traps.tolist(), decoded.countdown.tolist()
    qs, hypotheses = decoded.q.tolist(), decoded.hypothesis.tolist()
    windows = decoded.window.tolist()
    chosen = moves.action[choices.choice].tolist()
    absorbing = (decoded.goal | decoded.fail).tolist()
    canonical = decoded.canonical.tolist()
    for s in choices.representative.tolist():
        if absorbing[s]:
            continue
        record = describe(ts.state(cells[s], traps[s], countdowns[s]))
        record["q"] = qs[s]
        record["hypothesis"] = hypotheses[s]
        record["window"] = [window_entry(ts, entry, describe(entry[0]))
                            for entry in windows[s] if entry[0] >= 0]
        record["action"] = ACTIONS[chosen[s]]
        if extras is not None:
            record.update(extras.fields(canonical[s]))
        records.append(record)
    return records


def _json_number(x: float) -> float | None:
    return None if x != x else x          # NaN (a move without a choice) is written null


class RecordExtras:
    """The keys strategy.json's records gain after ``action`` (docs/semantics.md §6): ``values``,
    the value of every move ``{"N": ..., "E": ..., "S": ..., "W": ...}`` (from `move_values`
    [canonical states, 4], clamped into [0, 1], §10); for the step-bounded objective also
    ``schedule`` (per canonical state, runs ``[first step, last step, move]``) and
    ``bounded_values`` (each move's probability of the goal within the bound)."""

    def __init__(self, move_values: np.ndarray, schedules: Sequence[list] | None = None,
                 bounded_values: np.ndarray | None = None) -> None:
        self.values = np.clip(move_values, 0.0, 1.0)
        self.schedules = schedules
        self.bounded = None if bounded_values is None else np.clip(bounded_values, 0.0, 1.0)

    def fields(self, state: int) -> dict:
        """The added keys of canonical state `state`'s record."""
        row = self.values[state].tolist()
        fields = {"values": {m: _json_number(x) for m, x in zip(ACTIONS, row)}}
        if self.schedules is not None:
            fields["schedule"] = self.schedules[state]
            fields["bounded_values"] = {m: _json_number(x)
                                        for m, x in zip(ACTIONS, self.bounded[state].tolist())}
        return fields

    def json_tail(self, states: np.ndarray) -> list[Field | Texts]:
        """The added keys of each state's record as compact JSON fields, ending the record:
        the text json.dumps gives, without dumping a dict per record (millions of records)."""
        if self.schedules is not None:
            compact = {"separators": (",", ":")}
            return [Texts([json.dumps(self.fields(c), **compact)[1:] for c in states.tolist()])]
        values = self.values[states]
        fields = []
        for k, move in enumerate(ACTIONS):
            fields += [literal(("\"values\":{" if k == 0 else ",") + f'"{move}":'),
                       tokens(values[:, k], _json_float)]
        return fields + [literal("}}")]


def _json_float(x: float) -> str:
    return json.dumps(_json_number(x))


def window_entry(ts: TransitionSystem, entry: list[int], described: dict) -> dict:
    """A window entry of a record: the observation's TS state, P1's move and, for the Bayesian
    observer (entries of three), `played`, the cells of the trap set in force."""
    record = dict(described, action=ACTIONS[entry[1]])
    if len(entry) > 2:
        record["played"] = [list(c) for c in ts.trap_cells(entry[2])]
    return record


def strategy_json(decoded: DecodedStates, choices: StormChoices, moves: Transitions,
                  ts: TransitionSystem, extras: RecordExtras | None = None) -> bytes:
    """strategy.json: the records of `strategy_records`, one compact JSON object per line.

    Built column-wise from JSON fragments per TS state (and per observed move), because a few
    hundred TS states describe millions of records: the same text as json.dumps of each record,
    without creating the records."""
    states = choices.representative
    states = states[~(decoded.goal | decoded.fail)[states]]
    compact = {"separators": (",", ":")}
    ts_state = ts.state(decoded.cell[states], decoded.traps[states], decoded.countdown[states])
    fields = [tokens(ts_state, lambda v: json.dumps(ts.describe_state(v), **compact)[:-1]
                     + ',"q":'),
              integers(decoded.q[states]), literal(',"hypothesis":'),
              integers(decoded.hypothesis[states]), literal(',"window":[')]
    window = decoded.window[states]                           # [n, slots, 2 or 3]
    with_sets = window.shape[-1] > 2
    n_sets = ts.n_sets if with_sets else 1
    code = window[..., 0] * 4 + window[..., 1]
    if with_sets:
        code = code * n_sets + window[..., 2]
    present = window[..., 0] >= 0
    used = np.unique(code[present])
    entries = [json.dumps(window_entry(ts, [c // n_sets // 4, c // n_sets % 4]
                                       + ([c % n_sets] if with_sets else []),
                                       ts.describe_state(c // n_sets // 4)), **compact)
               for c in used.tolist()]
    # A slot's entry, after a comma when an earlier slot has one.
    entry = Vocabulary.of(entries + ["," + e for e in entries])
    earlier = np.zeros(len(states), dtype=bool)
    for k in range(window.shape[1]):
        rank = np.searchsorted(used, code[:, k])
        fields.append(Field(entry, np.where(present[:, k], rank + len(used) * earlier, -1)))
        earlier |= present[:, k]
    chosen = moves.action[choices.choice[states]]
    if extras is None:
        fields.append(Field(Vocabulary.of([f'],"action":"{a}"}}' for a in ACTIONS]), chosen))
    else:
        fields.append(Field(Vocabulary.of([f'],"action":"{a}",' for a in ACTIONS]), chosen))
        fields += extras.json_tail(decoded.canonical[states])
    fields.append(literal(",\n").where(np.arange(len(states)) < len(states) - 1))
    return Lines(fields, len(states)).render(b"[\n", b"\n]\n")


def _record_key(ts: TransitionSystem, record: Mapping, where: str) -> tuple[int, int, Memory]:
    """The hypergame state ``(ts_state, q, Memory)`` a strategy record is for."""
    v = _record_ts_state(ts, record, where)
    try:
        q, hypothesis = int(record["q"]), int(record["hypothesis"])
        entries = list(record["window"])
    except (KeyError, TypeError, ValueError) as err:
        raise StrategyError(f"{where}: bad or missing field ({err})") from None
    window = tuple(_window_observation(ts, entry, f"{where}, window entry {j}")
                   for j, entry in enumerate(entries))
    return v, q, Memory(hypothesis, window)


def _record_ts_state(ts: TransitionSystem, record: Mapping, where: str) -> int:
    """The TS state of a record's (or window entry's) cell, traps and countdown."""
    try:
        cell = tuple(int(c) for c in record["cell"])
    except (KeyError, TypeError, ValueError) as err:
        raise StrategyError(f"{where}: bad or missing 'cell' ({err})") from None
    if cell not in ts.cell_index:
        raise StrategyError(f"{where}: cell {list(cell)} is not a free cell of the world")
    index = ts.cell_index[cell]
    if ts.delay == 0:
        return ts.state(index)
    traps = record.get("traps")
    countdown = record.get("countdown")
    if traps is None or countdown is None:
        raise StrategyError(f"{where}: 'traps' and 'countdown' are required when delay > 0")
    trap_set = _trap_set_index(ts, traps, where)
    countdown = int(countdown)
    if not 0 <= countdown <= ts.delay:
        raise StrategyError(f"{where}: countdown {countdown} outside 0..{ts.delay}")
    return ts.state(index, trap_set, countdown)


def _trap_set_index(ts: TransitionSystem, cells: object, where: str) -> int:
    candidate_of = {c: k for k, c in enumerate(ts.candidates)}
    try:
        members = tuple(sorted(candidate_of[ts.cell_index[tuple(int(c) for c in t)]]
                               for t in cells))
        return ts.trap_sets.index(members)
    except (KeyError, ValueError, TypeError):
        raise StrategyError(f"{where}: traps {cells} are not a P2 action of the world") from None


def _window_observation(ts: TransitionSystem, entry: Mapping, where: str) -> tuple[int, ...]:
    """A window entry as an observation: (TS state, action), and the trap set in force when
    the entry has `played` (Bayesian observer)."""
    if not isinstance(entry, Mapping):
        raise StrategyError(f"{where}: expected an object, got {entry!r}")
    observation = (_record_ts_state(ts, entry, where), _action_index(entry.get("action"), where))
    if "played" in entry:
        observation += (_trap_set_index(ts, entry["played"], where),)
    return observation


def _action_index(name: object, where: str) -> int:
    if name not in ACTIONS:
        raise StrategyError(f"{where}: action {name!r} is not one of {', '.join(ACTIONS)}")
    return ACTIONS.index(name)


Fallback = Callable[[int, int, Memory], int]


class Strategy:
    """P1's memoryless deterministic strategy on hypergame states ``(ts_state, q, Memory)``.

    The exported records cover the states reachable when P2 behaves as modelled. An experiment
    in which P2 deviates can lead P1 elsewhere (for instance onto a trap candidate the model
    would have trapped it on); there `action` raises StrategyError unless a `fallback`
    ``(ts_state, q, memory) -> action index`` is given (see `leader_fallback`).
    """

    def __init__(self, table: Mapping[tuple[int, int, Memory], int],
                 ts: TransitionSystem | None = None, fallback: Fallback | None = None,
                 records: tuple[dict, ...] = ()) -> None:
        self.table = dict(table)
        self.ts = ts
        self.fallback = fallback
        self.records = records          # the records read (strategy.json's content), if any
        self._rows: dict | None = None  # table key -> record, for the schedules

    @classmethod
    def from_records(cls, records: Iterable[Mapping], ts: TransitionSystem,
                     fallback: Fallback | None = None) -> "Strategy":
        """Read the exported records ``{cell, traps, countdown, q, hypothesis, window, action}``."""
        table: dict[tuple[int, int, Memory], int] = {}
        records = tuple(records)
        for i, record in enumerate(records):
            where = f"strategy record {i}"
            key = _record_key(ts, record, where)
            action = _action_index(record.get("action"), where)
            if table.setdefault(key, action) != action:
                raise StrategyError(f"{where}: conflicting actions {ACTIONS[table[key]]} and "
                                    f"{ACTIONS[action]} for the same state")
        return cls(table, ts, fallback, records=tuple(records))

    @classmethod
    def load(cls, path: str | Path, ts: TransitionSystem,
             fallback: Fallback | None = None) -> "Strategy":
        """Read a strategy.json file."""
        with open(path, encoding="utf-8") as handle:
            return cls.from_records(json.load(handle), ts, fallback)

    def __len__(self) -> int:
        return len(self.table)

    def __contains__(self, key: object) -> bool:
        return key in self.table

    def action(self, ts_state: int, q: int, memory: Memory) -> int:
        """P1's action index (into dynamics.ACTIONS); for a state without a record the
        fallback's action, or StrategyError when there is no fallback."""
        try:
            return self.table[(ts_state, q, memory)]
        except KeyError:
            if self.fallback is not None:
                return int(self.fallback(ts_state, q, memory))
            raise StrategyError(
                f"the strategy has no record for the hypergame state "
                f"{self.describe(ts_state, q, memory)}") from None

    def move(self, cell: tuple[int, int], q: int, hypothesis: int,
             window: Iterable[tuple] = (), traps: Iterable[tuple[int, int]] | None = None,
             countdown: int | None = None, step: int = 0) -> str:
        """P1's move ("N", "E", "S" or "W") when the robot is at `cell` (x, y), the task DFA is
        in `q` (after reading the cell's label), P2 holds `hypothesis` and remembers `window`:
        (cell, move) pairs, oldest first. With delay > 0, `traps` (cells) and `countdown` give
        the standing traps, and each window entry is (cell, move, traps, countdown). For the
        Bayesian observer each entry is (cell, move, traps, countdown, played), `played` the
        cells of the trap set in force (traps and countdown None when delay is 0), and
        `hypothesis` the window's MAP hypothesis. `step` is the number of steps taken so far:
        the move of a step-bounded strategy (records with a ``schedule``) depends on it, from
        the bound on it stays the last step's; the other strategies ignore it.
        Raises KeyError for a state the strategy has no record of (the fallback is not used)."""
        if self.ts is None:
            raise ValueError("move() needs the strategy's transition system")
        where = "move()"

        def state(cell, traps, countdown) -> int:
            return _record_ts_state(self.ts, {"cell": cell, "traps": traps,
                                              "countdown": countdown}, where)

        try:
            v = state(cell, traps, countdown)
            observed = tuple(
                (state(entry[0], *(entry[2:4] if len(entry) > 2 else (None, None))),
                 _action_index(entry[1], where))
                + ((_trap_set_index(self.ts, entry[4], where),) if len(entry) > 4 else ())
                for entry in window)
        except StrategyError as err:
            raise KeyError(str(err)) from None
        key = (v, int(q), Memory(int(hypothesis), observed))
        if key not in self.table:
            raise KeyError(f"no record for {self.describe(*key)}")
        if step < 0:
            raise ValueError(f"step must be at least 0, got {step}")
        schedule = self._schedule(key)
        if schedule:
            last = max(int(run[1]) for run in schedule)
            for first, end, move in schedule:
                if int(first) <= min(step, last) <= int(end):
                    return str(move)
        return ACTIONS[self.table[key]]

    def _schedule(self, key: tuple[int, int, Memory]) -> list | None:
        """The ``schedule`` of the record of `key` (step-bounded strategies), else None."""
        if not self.records or "schedule" not in self.records[0]:
            return None
        if self._rows is None:      # built when first asked: bounded strategies only
            rows: dict[tuple[int, int, Memory], int] = {}
            for i, record in enumerate(self.records):
                where = f"strategy record {i}"
                first = rows.setdefault(_record_key(self.ts, record, where), i)
                if self.records[first].get("schedule") != record.get("schedule"):
                    raise StrategyError(f"{where}: another schedule for the state of "
                                        f"strategy record {first}")
            self._rows = rows
        return self.records[self._rows[key]]["schedule"]

    def describe(self, ts_state: int, q: int, memory: Memory) -> str:
        if self.ts is None:
            return f"(ts_state={ts_state}, q={q}, {memory})"

        def where(state: int) -> str:
            d = self.ts.describe_state(state)
            text = f"cell {d['cell']}"
            if d["traps"] is not None:
                text += f" traps {d['traps']} countdown {d['countdown']}"
            return text

        window = ", ".join(f"{where(o[0])} {ACTIONS[o[1]]}"
                           + (f" played {list(self.ts.trap_cells(o[2]))}" if len(o) > 2 else "")
                           for o in memory.window)
        return f"{where(ts_state)}, q={q}, hypothesis={memory.hypothesis}, window=[{window}]"
