"""strategy.json: P1's deceptive strategy as records, one per reachable hypergame state that is
neither goal nor failure (docs/semantics.md §6), and `Strategy`, the one type that holds it:
read from the records (or the file), asked for P1's move in a hypergame state.

Writers: `strategy_records` (the records as dicts) and `strategy_json` (the file's text, built
column-wise by strategy/columns.py: the same text as json.dumps of each record, for millions
of records).
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np

from hg2prism.engines.engine import Transitions
from hg2prism.errors import InputError, did_you_mean, listing
from hg2prism.prism.decoding import DecodedStates
from hg2prism.model.dynamics import TransitionSystem
from hg2prism.opponent.observer import Memory
from hg2prism.strategy.columns import Field, Lines, Texts, Vocabulary, integers, literal, tokens
from hg2prism.strategy.deceptive import StormChoices


class StrategyError(LookupError):
    """The strategy has no (or an unreadable) record for a hypergame state."""


_READ_ONLY = ("strategy records are read-only (a solution's strategy, its check and robust() "
              "share them): record.thawed() gives a copy to change")


def _refuse(self, *args, **kwargs):
    raise TypeError(_READ_ONLY)


class Record(dict):
    """A strategy.json record as hg2prism hands it out: a dict that cannot be changed, nor can
    its window entries, values or schedule (`frozen`). A solution's `Strategy`, its check's
    records and the experiments on it (robust deception, simulations) read the same records,
    so an edit of one would change them all. `thawed()` gives a plain copy to change; reading,
    comparing, `dict(record)`, json.dumps and pickling work as on a dict."""

    __slots__ = ()
    __setitem__ = __delitem__ = __ior__ = clear = pop = popitem = setdefault = update = _refuse

    def __new__(cls, *args, **kwargs):
        record = dict.__new__(cls)
        dict.__init__(record, *args, **kwargs)      # filled once, here
        return record

    def __init__(self, *args, **kwargs) -> None:    # record.__init__(...) changes nothing
        pass

    def __reduce__(self):
        return Record, (dict(self),)

    def thawed(self) -> dict:
        """A plain copy (dicts and lists all the way down) to change."""
        return _thawed(self)


class RecordList(list):
    """A list inside a `Record` (a window, a schedule): read-only, otherwise a list."""

    __slots__ = ()
    __setitem__ = __delitem__ = __iadd__ = __imul__ = _refuse
    append = extend = insert = remove = pop = clear = sort = reverse = _refuse

    def __new__(cls, *args):
        entries = list.__new__(cls)
        list.__init__(entries, *args)              # filled once, here
        return entries

    def __init__(self, *args) -> None:              # entries.__init__(...) changes nothing
        pass

    def __reduce__(self):
        return RecordList, (list(self),)


_PLAIN = (str, int, float, bool, type(None))


def frozen(value: object) -> object:
    """`value` with its dicts made `Record`s and its lists `RecordList`s, all the way down (a
    Record is returned as it is: it is frozen all the way down already). A record read from
    JSON holds str, numbers, None, dicts and lists: those are tried first, by exact type."""
    kind = type(value)
    if kind in _PLAIN or kind is Record:
        return value
    if kind is dict or (kind is not list and isinstance(value, Mapping)):
        return Record({key: frozen(item) for key, item in value.items()})
    if kind is list or isinstance(value, list | tuple):
        return RecordList([frozen(item) for item in value])
    return value


def _thawed(value: object) -> object:
    if isinstance(value, dict):
        return {key: _thawed(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_thawed(item) for item in value]
    return value


def start_first(decoded: DecodedStates, choices: StormChoices, initial: int | None
                 ) -> tuple[np.ndarray, int]:
    """The engine states whose records are written (the representatives of the non-absorbing
    canonical states), the initial state's first, and how many of them are marked initial
    (1, or 0 when the initial state is absorbing or unknown)."""
    states = choices.representative
    states = states[~(decoded.goal | decoded.fail)[states]]
    if initial is None:
        return states, 0
    first = np.flatnonzero(decoded.canonical[states] == decoded.canonical[initial])
    if not first.size:
        return states, 0
    return np.r_[states[first[0]], np.delete(states, first[0])], 1


def strategy_records(decoded: DecodedStates, choices: StormChoices, moves: Transitions,
                     ts: TransitionSystem, extras: RecordExtras | None = None,
                     initial: int | None = None) -> list[dict]:
    """P1's deceptive strategy: one record per reachable non-absorbing canonical state, that of
    the engine's `initial` state first, marked ``"initial": true``.

    `extras` (RecordExtras) adds keys after ``action``."""
    records = []
    described: dict[int, dict] = {}     # a few hundred TS states describe millions of records

    def describe(state: int) -> dict:
        if state not in described:
            described[state] = ts.describe_state(state)
        return dict(described[state])

    states, marked = start_first(decoded, choices, initial)
    cells, traps, countdowns = decoded.place.tolist(), decoded.traps.tolist(), decoded.countdown.tolist()
    qs, hypotheses = decoded.q.tolist(), decoded.hypothesis.tolist()
    windows = decoded.window.tolist()
    chosen = moves.action[choices.choice].tolist()
    canonical = decoded.canonical.tolist()
    for i, s in enumerate(states.tolist()):
        v = ts.state(cells[s], traps[s], countdowns[s])
        record = {"initial": True} if i < marked else {}
        record.update(describe(v))
        record["q"] = qs[s]
        record["hypothesis"] = hypotheses[s]
        record["window"] = RecordList([Record(window_entry(ts, entry, describe(entry[0])))
                                       for entry in windows[s] if entry[0] >= 0])
        names = ts.action_names(v)
        record["action"] = names[chosen[s]]
        if extras is not None:
            record.update(extras.fields(canonical[s], names))
        records.append(Record(record))      # read-only, all the way down (`Record`)
    return records


def _json_number(x: float) -> float | None:
    return None if x != x else x          # NaN (a move without a choice) is written null


class RecordExtras:
    """The keys strategy.json's records gain after ``action`` (docs/semantics.md §6): ``values``,
    the value of every action available in the record's state, by name (from `move_values`
    [canonical states, action slots], clamped into [0, 1], §10); for the step-bounded objective
    also ``schedule`` (per canonical state, runs ``[first step, last step, action slot]``,
    written with the action's name) and ``bounded_values`` (each action's probability of the
    goal within the bound)."""

    def __init__(self, move_values: np.ndarray, schedules: Sequence[list] | None = None,
                 bounded_values: np.ndarray | None = None) -> None:
        self.values = np.clip(move_values, 0.0, 1.0)
        self.schedules = schedules
        self.bounded = None if bounded_values is None else np.clip(bounded_values, 0.0, 1.0)

    def fields(self, state: int, names: Sequence[str]) -> dict:
        """The added keys of canonical state `state`'s record, read-only (`Record`); `names`:
        the actions available there (slot k is names[k])."""
        row = self.values[state].tolist()
        fields = {"values": Record(zip(names, map(_json_number, row)))}
        if self.schedules is not None:
            fields["schedule"] = RecordList([RecordList([first, last, names[a]])
                                             for first, last, a in self.schedules[state]])
            fields["bounded_values"] = Record(zip(names, map(_json_number,
                                                         self.bounded[state].tolist())))
        return fields

    def json_tail(self, states: np.ndarray, ts: TransitionSystem, ts_states: np.ndarray
                  ) -> list[Field | Texts]:
        """The added keys of each record (canonical state states[i] in TS state ts_states[i])
        as compact JSON fields, ending the record: the text json.dumps gives, without dumping a
        dict per record (millions of records)."""
        if self.schedules is not None:
            compact = {"separators": (",", ":")}
            return [Texts([json.dumps(self.fields(c, ts.action_names(v)), **compact)[1:]
                           for c, v in zip(states.tolist(), ts_states.tolist())])]
        values = self.values[states]
        names = _slot_names(ts)
        place = _places(ts, ts_states)
        fields = []
        for k in range(min(values.shape[1], ts.n_actions)):
            key = Vocabulary.of([("\"values\":{" if k == 0 else ",") + json.dumps(n) + ":"
                                 for n in names[:, k].tolist()])
            present = ts.enabled[ts_states, k]
            fields += [Field(key, np.where(present, place, -1)),
                       tokens(values[:, k], _json_float).where(present)]
        return fields + [literal("}}")]


def _places(ts: TransitionSystem, ts_states: np.ndarray) -> np.ndarray:
    """The arena state of each TS state (none is `trapped`)."""
    return ts.places_of()[ts_states]


def _slot_names(ts: TransitionSystem) -> np.ndarray:
    """[arena states, A1max] P1's action names by slot ("" where a slot is not enabled)."""
    names = np.full((ts.n_places, ts.n_actions), "", dtype=object)
    for place, actions in enumerate(ts.arena.actions):
        names[place, :len(actions)] = actions
    return names


def _json_float(x: float) -> str:
    return json.dumps(_json_number(x))


def window_entry(ts: TransitionSystem, entry: list[int], described: dict) -> dict:
    """A window entry of a record: the observation's TS state, P1's action by name and, for
    the Bayesian observer (entries of three), ``played``, the name of P2's action in force."""
    record = dict(described, action=ts.action_names(entry[0])[entry[1]])
    if len(entry) > 2:
        record["played"] = ts.a2_names[entry[2]]
    return record


def strategy_json(decoded: DecodedStates, choices: StormChoices, moves: Transitions,
                  ts: TransitionSystem, extras: RecordExtras | None = None,
                  initial: int | None = None) -> bytes:
    """strategy.json: the records of `strategy_records`, one compact JSON object per line."""
    return b"".join(strategy_json_chunks(decoded, choices, moves, ts, extras, initial))


def strategy_json_chunks(decoded: DecodedStates, choices: StormChoices, moves: Transitions,
                         ts: TransitionSystem, extras: RecordExtras | None = None,
                         initial: int | None = None) -> Iterator[bytes]:
    """The text of `strategy_json` in pieces, formatted as they are written
    (outputs.write_chunks).

    Built column-wise from JSON fragments per TS state (and per observed move), because a few
    hundred TS states describe millions of records: the same text as json.dumps of each record,
    without creating the records."""
    states, marked = start_first(decoded, choices, initial)
    compact = {"separators": (",", ":")}
    ts_state = ts.state(decoded.place[states], decoded.traps[states], decoded.countdown[states])
    first = Field(Vocabulary.of(['{"initial":true,', "{"]),
                  np.where(np.arange(len(states)) < marked, 0, 1))
    fields = [first,
              tokens(ts_state, lambda v: json.dumps(ts.describe_state(v), **compact)[1:-1]
                     + ',"q":'),
              integers(decoded.q[states]), literal(',"hypothesis":'),
              integers(decoded.hypothesis[states]), literal(',"window":[')]
    window = decoded.window[states]                           # [n, slots, 2 or 3]
    with_sets = window.shape[-1] > 2
    n_sets = ts.n_sets if with_sets else 1
    n_a1 = ts.n_actions
    code = window[..., 0].astype(np.int64) * n_a1 + window[..., 1]
    if with_sets:
        code = code * n_sets + window[..., 2]
    present = window[..., 0] >= 0
    used = np.unique(code[present])
    entries = [json.dumps(window_entry(ts, [c // n_sets // n_a1, c // n_sets % n_a1]
                                       + ([c % n_sets] if with_sets else []),
                                       ts.describe_state(c // n_sets // n_a1)), **compact)
               for c in used.tolist()]
    # A slot's entry, after a comma when an earlier slot has one.
    entry = Vocabulary.of(entries + ["," + e for e in entries])
    earlier = np.zeros(len(states), dtype=bool)
    for k in range(window.shape[1]):
        rank = np.searchsorted(used, code[:, k])
        fields.append(Field(entry, np.where(present[:, k], rank + len(used) * earlier, -1)))
        earlier |= present[:, k]
    chosen = _places(ts, ts_state) * n_a1 + moves.action[choices.choice[states]]
    names = _slot_names(ts).reshape(-1).tolist()
    if extras is None:
        fields.append(Field(Vocabulary.of([f'],"action":{json.dumps(a)}}}' for a in names]),
                            chosen))
    else:
        fields.append(Field(Vocabulary.of([f'],"action":{json.dumps(a)},' for a in names]),
                            chosen))
        fields += extras.json_tail(decoded.canonical[states], ts, ts_state)
    fields.append(literal(",\n").where(np.arange(len(states)) < len(states) - 1))
    return Lines(fields, len(states)).chunks(b"[\n", b"\n]\n")


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


@functools.lru_cache(maxsize=8)
def _numbering(ts: TransitionSystem) -> tuple[dict[str, int], dict[str, int]]:
    """Arena state names and P2's action names -> their numbers."""
    return ({n: i for i, n in enumerate(ts.arena.states)},
            {n: i for i, n in enumerate(ts.a2_names)})


def _record_ts_state(ts: TransitionSystem, record: Mapping, where: str) -> int:
    """The TS state of a record's (or window entry's) state, standing action and countdown."""
    states, _ = _numbering(ts)
    name = record.get("state") if isinstance(record, Mapping) else None
    if not isinstance(name, str):
        raise StrategyError(f"{where}: bad or missing 'state' ({name!r})")
    if name not in states:
        raise StrategyError(f"{where}: {name!r} is not a state of the world")
    index = states[name]
    if ts.delay == 0:
        return ts.state(index)
    standing = record.get("standing")
    countdown = record.get("countdown")
    if standing is None or countdown is None:
        raise StrategyError(f"{where}: 'standing' and 'countdown' are required when delay > 0")
    a2 = _p2_action_index(ts, standing, where)
    try:
        countdown = int(countdown)
    except (TypeError, ValueError):
        raise StrategyError(f"{where}: bad countdown {countdown!r}") from None
    if not 0 <= countdown <= ts.delay:
        raise StrategyError(f"{where}: countdown {countdown} outside 0..{ts.delay}")
    return ts.state(index, a2, countdown)


def _p2_action_index(ts: TransitionSystem, name: object, where: str) -> int:
    _, actions = _numbering(ts)
    if not isinstance(name, str) or name not in actions:
        raise StrategyError(f"{where}: {name!r} is not a P2 action of the world") from None
    return actions[name]


def _window_observation(ts: TransitionSystem, entry: Mapping, where: str) -> tuple[int, ...]:
    """A window entry as an observation: (TS state, action), and P2's action in force when
    the entry has `played` (Bayesian observer)."""
    if not isinstance(entry, Mapping):
        raise StrategyError(f"{where}: expected an object, got {entry!r}")
    v = _record_ts_state(ts, entry, where)
    observation = (v, _action_index(ts, v, entry.get("action"), where))
    if "played" in entry:
        observation += (_p2_action_index(ts, entry["played"], where),)
    return observation


def _action_index(ts: TransitionSystem, v: int, name: object, where: str) -> int:
    """The slot of P1's action `name` at TS state v."""
    names = ts.action_names(v)
    if name not in names:
        raise StrategyError(f"{where}: action {name!r} is not one of {', '.join(names)} "
                            f"(the actions at {ts.arena.states[ts.decode(v)[0]]})")
    return names.index(name)


def _order(key: tuple[int, int, Memory]) -> tuple:
    """Hypergame states in a stable order (for the example a message shows)."""
    return (key[0], key[1], key[2].hypothesis, len(key[2].window), key[2].window)


def _named_ts_state(ts: TransitionSystem, state: object, standing: object,
                    countdown: object) -> int:
    """`Strategy.move`'s state, standing action and countdown as a TS state (InputError naming
    the argument that names nothing)."""
    states, _ = _numbering(ts)
    if not isinstance(state, str) or state not in states:
        names = list(ts.arena.states)
        raise InputError("move()", "state", f"{state!r} is not a state of the world, whose "
                         f"{len(names)} states are {listing(names, 5)}"
                         + did_you_mean(state, names))
    if ts.delay == 0:
        for key, given in (("standing", standing), ("countdown", countdown)):
            if given is not None:     # it used to be ignored without a word
                raise InputError("move()", key, f"got {given!r}, but this world has delay 0: "
                                 "P2's action takes effect at once, so there is no standing "
                                 "action or countdown; leave it out")
    try:
        return _record_ts_state(ts, {"state": state, "standing": standing,
                                     "countdown": countdown}, "move()")
    except StrategyError as err:
        reason = str(err).removeprefix("move(): ")
        key = "countdown" if "countdown" in reason and "standing" not in reason else "standing"
        raise InputError("move()", key, reason) from None


def _window_observations(ts: TransitionSystem, window: Iterable) -> list[tuple[int, ...]]:
    """`Strategy.move`'s window entries as observations (InputError, key "window")."""
    shape = "(state, action)" if ts.delay == 0 else "(state, action, standing, countdown)"
    observed = []
    if isinstance(window, (str, bytes)) or not isinstance(window, Iterable):
        raise InputError("move()", "window", f"expected a list of {shape} entries, oldest "
                         f"first, got {type(window).__name__}")
    try:
        for entry in window:
            if isinstance(entry, Mapping):
                entry = _entry_tuple(entry)
            if isinstance(entry, (str, bytes)) or not isinstance(entry, Sequence):
                raise StrategyError(f"window entry {entry!r}: expected {shape}")
            if len(entry) < (2 if ts.delay == 0 else 4):
                raise StrategyError(f"window entry {tuple(entry)!r}: expected {shape} (and the "
                                    "action played, for a Bayesian observer)")
            u = _record_ts_state(ts, {"state": entry[0], "standing": entry[2] if len(entry) > 2
                                      else None, "countdown": entry[3] if len(entry) > 3
                                      else None}, "move()")
            observed.append((u, _action_index(ts, u, entry[1], "move()"))
                            + ((_p2_action_index(ts, entry[4], "move()"),)
                               if len(entry) > 4 else ()))
    except StrategyError as err:
        raise InputError("move()", "window", str(err).removeprefix("move(): ")) from None
    return observed


def read_record(ts: TransitionSystem, record: Mapping, where: str
                ) -> tuple[tuple[int, int, Memory], int]:
    """A strategy.json record read: the hypergame state ``(ts_state, q, Memory)`` it is for and
    P1's action slot there (StrategyError naming `where` for a bad record)."""
    key = _record_key(ts, record, where)
    return key, _action_index(ts, key[0], record.get("action"), where)


Fallback = Callable[[int, int, Memory], int]

# The keys of a strategy.json record that name its hypergame state: Strategy.move's arguments.
MOVE_KEYS = ("state", "q", "hypothesis", "window", "standing", "countdown")


def _entry_tuple(entry: Mapping) -> tuple:
    """A window entry as strategy.json writes it (a dict) as Strategy.move's tuple."""
    try:
        return ((entry["state"], entry["action"], entry.get("standing"), entry.get("countdown"))
                + ((entry["played"],) if "played" in entry else ()))
    except KeyError as missing:
        raise StrategyError(f"window entry {dict(entry)!r}: no {missing}") from None


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
        """Read the exported records ``{state, standing, countdown, q, hypothesis, window,
        action}`` (other keys, such as ``initial`` and ``values``, are not read here)."""
        table: dict[tuple[int, int, Memory], int] = {}
        records = tuple(records)
        for i, record in enumerate(records):
            where = f"strategy record {i}"
            key, action = read_record(ts, record, where)
            if table.setdefault(key, action) != action:
                names = ts.action_names(key[0])
                raise StrategyError(f"{where}: conflicting actions {names[table[key]]} and "
                                    f"{names[action]} for the same state")
        return cls(table, ts, fallback, records=tuple(
            frozen(record) if isinstance(record, Mapping) else record for record in records))

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
        """P1's action slot at `ts_state`; for a state without a record the
        fallback's action, or StrategyError when there is no fallback."""
        try:
            return self.table[(ts_state, q, memory)]
        except KeyError:
            if self.fallback is not None:
                return int(self.fallback(ts_state, q, memory))
            raise StrategyError(
                f"the strategy has no record for the hypergame state "
                f"{self.describe(ts_state, q, memory)}") from None

    def _check_indices(self, q: object, hypothesis: object, step: object) -> None:
        """`move`'s integer arguments: integers, and q and the hypothesis among those the
        strategy has records for (InputError naming the argument)."""
        import numbers

        def integer(value: object) -> bool:
            return isinstance(value, numbers.Integral) and not isinstance(value, bool)

        for key, value, what in (("q", q, "the task DFA's state"),
                                 ("hypothesis", hypothesis, "P2's hypothesis as its index into "
                                  "the world's hypotheses"),
                                 ("step", step, "the number of steps taken so far")):
            if not integer(value):
                raise InputError("move()", key, f"expected {what} (an integer), got {value!r}")
        if step < 0:
            raise InputError("move()", "step", f"must be at least 0, got {step}")
        for key, value, seen in (("q", q, {k[1] for k in self.table}),
                                 ("hypothesis", hypothesis,
                                  {k[2].hypothesis for k in self.table})):
            if seen and value not in seen:
                raise InputError("move()", key, f"{value} is not among the values the strategy "
                                 f"has records for: {listing([str(x) for x in sorted(seen)], 5)}")

    def _check_entries(self, observed: list[tuple[int, ...]]) -> None:
        """InputError (key window) when the window's entries lack P2's action played and the
        strategy's windows record it (a Bayesian observer's), or the other way round."""
        lengths = {len(o) for key in self.table for o in key[2].window}
        given = {len(o) for o in observed}
        if len(lengths) == 1 and given and given != lengths:
            shape = ("(state, action, standing, countdown, played)" if lengths == {3}
                     else "(state, action, standing, countdown), without the action played")
            recorded = "record" if lengths == {3} else "do not record"
            raise InputError("move()", "window", f"expected entries {shape}: the strategy's "
                             f"windows {recorded} the action P2 played")

    def move(self, state: str, q: int, hypothesis: int, window: Iterable[tuple] = (),
             standing: str | None = None, countdown: int | None = None, step: int = 0) -> str:
        """P1's action (its name) when the arena state is `state` (a name), the task DFA is in
        `q` (after reading the state's label), P2 holds `hypothesis` and remembers `window`:
        (state, action) pairs, oldest first. With delay > 0, `standing` (the name of P2's
        standing action) and `countdown` give P2's standing action, and each window entry is
        (state, action, standing, countdown). For the Bayesian observer each entry is (state,
        action, standing, countdown, played), `played` the name of P2's action in force
        (standing and countdown None when delay is 0), and `hypothesis` the window's MAP
        hypothesis. A window entry may also be given as strategy.json writes it, a dict with
        the keys state, action (and standing, countdown, played); `move_of` takes a record.
        `step` is the number of steps taken so far: the action of a step-bounded
        strategy (records with a ``schedule``) depends on it, from the bound on it stays the
        last step's; the other strategies ignore it.
        Raises InputError (file "move()") for an argument that names nothing in the world (a
        state, action or standing action the world does not have; key: the argument) and for
        a hypergame state the strategy has no record of (key "state"; the fallback is not
        used), saying whether the strategy never reaches the arena state at all or reaches it
        only with other task states and memories of P2."""
        if self.ts is None:
            raise ValueError("move() needs the strategy's transition system")
        ts = self.ts

        self._check_indices(q, hypothesis, step)
        v = _named_ts_state(ts, state, standing, countdown)
        observed = _window_observations(ts, window)
        key = (v, int(q), Memory(int(hypothesis), tuple(observed)))
        if key not in self.table:
            self._check_entries(observed)
            raise InputError("move()", "state", self._no_record(key))
        schedule = self._schedule(key)
        if schedule:
            last = max(int(run[1]) for run in schedule)
            for first, end, move in schedule:
                if int(first) <= min(step, last) <= int(end):
                    return str(move)
        return ts.action_names(v)[self.table[key]]

    def _no_record(self, key: tuple[int, int, Memory]) -> str:
        """Why `move` has no answer at `key`: the strategy has no record at its arena state at
        all, or records there only in other hypergame states."""
        ts = self.ts
        place = ts.decode(key[0])[0]
        name = ts.arena.states[place]
        there = [other for other in self.table if ts.decode(other[0])[0] == place]
        if not there:
            reached = sorted({ts.decode(other[0])[0] for other in self.table})
            return (f"the strategy has no record at {name}: P1 does not move from there when "
                    "P2 behaves as modelled (never reached, or the task is done or failed "
                    f"there); it has records at {len(reached)} of the world's "
                    f"{len(ts.arena.states)} states, e.g. "
                    f"{listing([ts.arena.states[p] for p in reached], 5)}")
        return (f"no record for {self.describe(*key)}: the strategy has records at {name} only "
                f"in {len(there)} other hypergame state{'s' if len(there) > 1 else ''} (task "
                f"state, P2's hypothesis and window), e.g. {self.describe(*min(there, key=_order))}")

    def move_of(self, record: Mapping, step: int = 0) -> str:
        """`move` in the hypergame state a strategy.json record names (its keys MOVE_KEYS; the
        record may come from another strategy of the world, e.g. a robust one's)."""
        if not isinstance(record, Mapping):
            raise InputError("move_of()", "record", f"expected a strategy.json record (a "
                             f"dict), got {type(record).__name__}")
        missing = [key for key in ("state", "q", "hypothesis") if key not in record]
        if missing:
            raise InputError("move_of()", "record", f"the record has no {', '.join(missing)}")
        return self.move(**{key: record[key] for key in MOVE_KEYS if key in record}, step=step)

    def record(self, ts_state: int, q: int, memory: Memory) -> Mapping | None:
        """The record (strategy.json's) of the hypergame state, None when there is none (or
        the strategy was not read from records)."""
        if not self.records:
            return None
        if self._rows is None and len(self.table) == len(self.records):
            # one record per state (as written): the table holds the states in record order
            self._rows = {key: i for i, key in enumerate(self.table)}
        row = self._record_rows().get((ts_state, q, memory))
        return None if row is None else self.records[row]

    def _schedule(self, key: tuple[int, int, Memory]) -> list | None:
        """The ``schedule`` of the record of `key` (step-bounded strategies), else None."""
        if not self.records or "schedule" not in self.records[0]:
            return None
        return self.records[self._record_rows()[key]]["schedule"]

    def _record_rows(self) -> dict:
        """Table key -> the index of its first record; records of one state must agree on
        their schedule."""
        if self._rows is None:      # built when first asked
            rows: dict[tuple[int, int, Memory], int] = {}
            for i, record in enumerate(self.records):
                where = f"strategy record {i}"
                first = rows.setdefault(_record_key(self.ts, record, where), i)
                if self.records[first].get("schedule") != record.get("schedule"):
                    raise StrategyError(f"{where}: another schedule for the state of "
                                        f"strategy record {first}")
            self._rows = rows
        return self._rows

    def describe(self, ts_state: int, q: int, memory: Memory) -> str:
        if self.ts is None:
            return f"(ts_state={ts_state}, q={q}, {memory})"

        ts = self.ts

        def where(state: int) -> str:
            d = ts.describe_state(state)
            text = d["state"]
            if d["standing"] is not None:
                text += f" standing {d['standing']} countdown {d['countdown']}"
            return text

        window = ", ".join(f"{where(o[0])} {ts.action_names(o[0])[o[1]]}"
                           + (f" played {ts.a2_names[o[2]]}" if len(o) > 2 else "")
                           for o in memory.window)
        return f"{where(ts_state)}, q={q}, hypothesis={memory.hypothesis}, window=[{window}]"
