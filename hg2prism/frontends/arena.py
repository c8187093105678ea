"""Arena worlds (docs/semantics.md §15): the `[arena]` table of a world file read into a
`model.arena.Arena`, and any world (grid or arena) written back as an arena world file.

Reading (`read`, called by worldfile/loader.py, which reads the other tables as for grids):

  [arena]
  states = ["out", "web", ...]     S in this order (the state numbering); identifiers, distinct,
                                   at least one; `trapped` is reserved (the TS's trap state)
  initial = "out"                  s0
  propositions = ["crown", ...]    optional AP, in this order. Default: the propositions of
                                   [arena.labels] in order of first occurrence (its states as
                                   written, each list left to right)
  [arena.labels]                   optional: state = [propositions] (a state not listed: none)
  [arena.positions]                optional, for figures: state = [x, y], every state
  [[arena.transition]]             at least one entry
  state = "out"; action = "phish"  P1's action at the state (an identifier)
  p2 = "watch" or ["a", "b"]       optional (general P2 actions only): the P2 actions it is for
  to = { mail = 0.6, out = 0.4 }   P(s' | s, a1, a2): >= 0, summing to 1 within 1e-9

  [adversary] (beside hypotheses and initial_hypothesis, as for grids), either
    actions = ["idle", ...]        general P2 actions A2 (identifiers, distinct), with
    initial_action = "idle"        required when delay > 0 (with delay 0 optional: what a sweep
                                   over delay starts from, as initial_traps)
  or
    traps = l                      l-subsets of the candidates, the grid's trap rule, with
    trap_candidates = [states]     distinct states, at least l of them, and
    initial_traps = [states]       l distinct candidates, required when delay > 0 (with delay
                                   0 optional, checked alike, [] naming none: what a sweep
                                   over delay starts from, as a grid's)
  delay = k                        optional, default 0

Names (states, P1's and P2's actions) are identifiers ([A-Za-z_][A-Za-z0-9_]*). A proposition
is an identifier that Spot reads back as that very atomic proposition, unquoted: not F G M R
U W X, true, false (any case), nor names Spot splits into operators (`Fa` is F a) or must quote
(`X1`, `GF`). Formulas may use only AP.

The Arena built: `states`, `initial`, `propositions` and `labels` as written; P1's actions at
each state in order of first appearance among its entries (a state without entries is
terminal); `dest/prob [S, A1max, J, K]` with J = |A2| when some entry has `p2`, else 1; the
outcomes of an entry in the order of its `to`, zero-probability ones dropped, padded to K with
the state itself and probability 0 (so are missing action slots); `p2_actions` = A2 (general)
or () (traps); `trap_candidates` the candidates' state numbers in the order written;
`positions` when given. The World's fields from here: `traps` (l, 0 for general actions),
`delay`, `initial_standing` (the index into A2 of initial_action, or of the sorted initial trap
set among the l-subsets in itertools.combinations order; with delay 0 what a sweep over delay
starts from, 0 when the file names none) and
`front` (the arena itself).

Writing (`to_toml`, `hg2prism convert`): a world's arena (a grid world compiled by
frontends/grid.py) with every other setting, as a world file that reads back to the same
transition system: each action's outcomes merged (equal successors add up, in outcome order;
zero probabilities dropped); for general P2 actions, one entry without `p2` for the
distribution most P2 actions share (the first of a tie) and one entry per other distribution
with the P2 actions it is for. Numbers are written as Python's repr, which reads back exactly.
"""

from __future__ import annotations

import math
import re

import numpy as np

from hg2prism.errors import did_you_mean, listing
from hg2prism.model.arena import TRAPS_BEYOND, Arena
from hg2prism.model.dynamics import trap_set_index
from hg2prism.model.validation import DELAY_0_STANDING

IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
RESERVED_STATES = ("trapped",)
PROBABILITY_TOLERANCE = 1e-9

ARENA_KEYS = {"states": True, "initial": True, "propositions": False, "labels": False,
              "positions": False, "transition": True}
TRANSITION_KEYS = {"state": True, "action": True, "p2": False, "to": True}
ADVERSARY_KEYS = {"actions": False, "initial_action": False, "traps": False,
                  "trap_candidates": False, "initial_traps": False, "delay": False,
                  "hypotheses": True, "initial_hypothesis": False, "tie_break": False}
MISSING_HINT = {
    "arena.states": "an array of state names",
    "arena.initial": "the name of the initial state",
    "arena.transition": "[[arena.transition]] entries (state, action, to)",
    "adversary.trap_candidates": "an array of state names (P2 may set traps on them)",
}


def toml_key(name: str) -> str:
    """A TOML key: bare when possible, else a quoted string."""
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else toml_string(name)


def toml_string(text: str) -> str:
    """A TOML basic string (control characters escaped, other characters as they are)."""
    out = []
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def toml_value(value: object) -> str:
    """A TOML value on one line; floats as repr (exact), integers as they are."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"no TOML form for {type(value).__name__}")


def proposition_problem(name: str) -> str | None:
    """Why `name` cannot be an atomic proposition (None when it can)."""
    import spot

    if not IDENTIFIER.fullmatch(name):
        return "is not an identifier (letters, digits and _, not starting with a digit)"
    try:
        parsed = spot.formula(name)
    except Exception:       # F, G, M, R, U, W, X, V
        return "is a Spot operator"
    if parsed.kind() != spot.op_ap or parsed.ap_name() != name or str(parsed) != name:
        return (f"is not a plain atomic proposition for Spot (it reads it as {str(parsed)}: "
                "a constant, operators applied to a name, or a name it must quote); choose "
                "another name")
    try:        # alone it may read as a name, and beside others as an operator (xor)
        inside = spot.formula(f"({name} | {name}) U (X {name})")
        names = {str(ap) for ap in spot.atomic_prop_collect(inside)}
    except Exception:
        names = set()
    if names != {name}:
        return "is a Spot operator inside a formula; choose another name"
    return None


def _listing(names) -> str:
    return listing(names, 12, empty="none")


# ---------------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------------

class _Reader:
    """Reads [arena] and the arena part of [adversary] with the world loader `ld` (its
    typed getters and `fail`, which makes the InputError naming file, key and reason)."""

    def __init__(self, ld) -> None:
        self.ld = ld
        self.fail = ld.fail
        self.states: tuple[str, ...] = ()
        self.number: dict[str, int] = {}

    def identifier(self, value: object, key: str, what: str) -> str:
        name = self.ld.string(value, key)
        if not IDENTIFIER.fullmatch(name):
            raise self.fail(key, f"{what} {name!r} is not an identifier (letters, digits and _, "
                                 "not starting with a digit)")
        return name

    def names(self, value: object, key: str, what: str, empty_ok: bool = False) -> list[str]:
        items = self.ld.array(value, key, f"an array of {what} names")
        if not items and not empty_ok:
            raise self.fail(key, f"is empty; expected at least one {what}")
        names: list[str] = []
        for i, item in enumerate(items):
            name = self.identifier(item, f"{key}[{i}]", what)
            if name in names:
                raise self.fail(f"{key}[{i}]", f"{what} {name!r} is repeated; expected distinct "
                                               f"names")
            names.append(name)
        return names

    def state(self, value: object, key: str) -> int:
        name = self.ld.string(value, key)
        if name not in self.number:
            raise self.unknown(key, "state", name, self.states, "states are ")
        return self.number[name]

    def unknown(self, key: str, what: str, name: str, names, known: str,
                more: str = "") -> Exception:
        """The error of a name that names no `what` ("state", "P2 action"): the close ones,
        then the known ones after `known` ("states are "), then `more`."""
        return self.fail(key, f"unknown {what} {name!r}{did_you_mean(name, names)}; {known}"
                         + _listing(names) + more)

    def read_states(self, table: dict) -> None:
        names = self.names(table["states"], "arena.states", "state")
        for i, name in enumerate(names):
            if name in RESERVED_STATES:
                raise self.fail(f"arena.states[{i}]", f"state name {name!r} is reserved (the "
                                                      "transition system's trap state)")
        self.states = tuple(names)
        self.number = {name: i for i, name in enumerate(names)}

    def proposition(self, value: object, key: str) -> str:
        name = self.ld.string(value, key)
        problem = proposition_problem(name)
        if problem:
            raise self.fail(key, f"proposition {name!r} {problem}")
        return name

    def labels(self, table: dict) -> tuple[tuple[str, ...], tuple[frozenset[str], ...]]:
        """(AP, the label of every state)."""
        given = None
        if "propositions" in table:
            key = "arena.propositions"
            items = self.ld.array(table["propositions"], key, "an array of proposition names")
            given = []
            for i, item in enumerate(items):
                name = self.proposition(item, f"{key}[{i}]")
                if name in given:
                    raise self.fail(f"{key}[{i}]", f"proposition {name!r} is repeated")
                given.append(name)
        labels_table = table.get("labels", {})
        if not isinstance(labels_table, dict):
            raise self.fail("arena.labels", "must be a table [arena.labels] (state = "
                                            "[propositions])")
        found: list[str] = []
        labels = [frozenset()] * len(self.states)
        for state, value in labels_table.items():
            key = f"arena.labels.{toml_key(state)}"
            if state not in self.number:
                raise self.unknown(key, "state", state, self.states, "states are ")
            items = self.ld.array(value, key, "an array of propositions")
            props: list[str] = []
            for i, item in enumerate(items):
                name = self.proposition(item, f"{key}[{i}]")
                if given is not None and name not in given:
                    raise self.fail(f"{key}[{i}]", f"unknown proposition {name!r}; "
                                    "arena.propositions are " + _listing(given))
                if name in props:
                    raise self.fail(f"{key}[{i}]", f"proposition {name!r} is repeated")
                props.append(name)
                if name not in found:
                    found.append(name)
            labels[self.number[state]] = frozenset(props)
        return tuple(given if given is not None else found), tuple(labels)

    def positions(self, table: dict) -> tuple[tuple[float, float], ...] | None:
        if "positions" not in table:
            return None
        value = table["positions"]
        if not isinstance(value, dict):
            raise self.fail("arena.positions", "must be a table [arena.positions] (state = "
                                               "[x, y])")
        where: dict[int, tuple[float, float]] = {}
        for state, xy in value.items():
            key = f"arena.positions.{toml_key(state)}"
            if state not in self.number:
                raise self.unknown(key, "state", state, self.states, "states are ")
            if not isinstance(xy, list) or len(xy) != 2:
                raise self.fail(key, "a position is [x, y], two numbers")
            where[self.number[state]] = (self.ld.number(xy[0], f"{key}[0]"),
                                         self.ld.number(xy[1], f"{key}[1]"))
        missing = [s for i, s in enumerate(self.states) if i not in where]
        if missing:
            raise self.fail("arena.positions", "every state needs a position when "
                                               "[arena.positions] is given; missing "
                            + _listing(missing))
        return tuple(where[i] for i in range(len(self.states)))

    # -- P2 --------------------------------------------------------------------------------

    def adversary(self, adv: dict) -> dict:
        """P2's actions: dict(p2_actions, trap_candidates, traps, delay, initial_standing)."""
        general, trapping = "actions" in adv, "traps" in adv
        if general and trapping:
            raise self.fail("adversary.traps", "P2 has general actions (actions) or sets traps "
                                               "(traps), not both; remove one")
        if not general and not trapping:
            raise self.fail("adversary", "missing P2's actions; expected actions = [...] "
                                         "(general P2 actions) or traps = l with "
                                         "trap_candidates = [states]")
        delay = self.ld.delay(adv.get("delay", 0))
        unused = (("trap_candidates", "initial_traps") if general else ("initial_action",))
        for name in unused:
            if name in adv:
                raise self.fail(f"adversary.{name}", "only with traps (adversary.traps), not "
                                "with general P2 actions" if general else "only with general "
                                "P2 actions (adversary.actions); with traps give initial_traps")
        if general:
            return self.general(adv, delay)
        return self.trapping(adv, delay)

    def general(self, adv: dict, delay: int) -> dict:
        actions = self.names(adv["actions"], "adversary.actions", "P2 action")
        key = "adversary.initial_action"
        filed = None        # the action the file names, also with delay 0 (sweeps over delay)
        if "initial_action" in adv:
            name = self.ld.string(adv["initial_action"], key)
            if name not in actions:
                raise self.unknown(key, "P2 action", name, actions, "adversary.actions are ",
                                   "" if delay else DELAY_0_STANDING)
            filed = actions.index(name)
        elif delay > 0:
            raise self.fail(key, "initial_action is required when delay > 0; expected the P2 "
                                 "action standing at the start, one of " + _listing(actions))
        return dict(p2_actions=tuple(actions), trap_candidates=(), traps=0, delay=delay,
                    initial_standing=filed or 0)

    def trapping(self, adv: dict, delay: int) -> dict:
        traps = self.ld.integer(adv["traps"], "adversary.traps", 1)
        key = "adversary.trap_candidates"
        if "trap_candidates" not in adv:
            raise self.fail(key, "missing required key with traps; expected "
                            + MISSING_HINT[key])
        candidates = self.state_list(adv["trap_candidates"], key, "trap candidate")
        self.ld.traps(traps, len(candidates), TRAPS_BEYOND)
        filed = None        # the set the file names, also with delay 0 (sweeps over delay)
        key = "adversary.initial_traps"
        if "initial_traps" in adv and delay == 0 and adv["initial_traps"] == []:
            pass                # what a world written with delay 0 may hold: none named
        elif "initial_traps" in adv:
            why = "" if delay else DELAY_0_STANDING
            chosen = self.state_list(adv["initial_traps"], key, "initial trap", empty_ok=True)
            for i, s in enumerate(chosen):
                if s not in candidates:
                    raise self.fail(f"{key}[{i}]", f"{self.states[s]!r} is not a trap "
                                    "candidate; trap_candidates are "
                                    + _listing(self.states[c] for c in candidates) + why)
            if len(chosen) != traps:
                raise self.fail(key, f"expected {traps} distinct trap candidates (traps = "
                                     f"{traps}), got {len(chosen)}{why}")
            filed = trap_set_index(len(candidates), [candidates.index(s) for s in chosen])
        elif delay > 0:
            raise self.fail(key, f"initial_traps is required when delay > 0; expected {traps} "
                                 "distinct trap candidates (state names)")
        return dict(p2_actions=(), trap_candidates=tuple(candidates), traps=traps, delay=delay,
                    initial_standing=filed or 0)

    def state_list(self, value: object, key: str, what: str, empty_ok: bool = False) -> list[int]:
        items = self.ld.array(value, key, "an array of state names")
        if not items and not empty_ok:
            raise self.fail(key, f"is empty; expected at least one {what} state")
        found: list[int] = []
        for i, item in enumerate(items):
            s = self.state(item, f"{key}[{i}]")
            if s in found:
                raise self.fail(f"{key}[{i}]", f"{self.states[s]!r} is repeated; expected "
                                               "distinct states")
            found.append(s)
        return found

    # -- P1's transitions ------------------------------------------------------------------

    def entry(self, item: object, i: int, a2: tuple[str, ...]) -> tuple:
        """One [[arena.transition]]: (state, action, the P2 actions it is for or None,
        {successor: probability})."""
        prefix = f"arena.transition[{i}]"
        if not isinstance(item, dict):
            raise self.fail(prefix, "must be a table (state, action, to)")
        self.ld.check_keys(item, TRANSITION_KEYS, prefix)
        state = self.state(item["state"], f"{prefix}.state")
        action = self.identifier(item["action"], f"{prefix}.action", "action")
        p2 = None
        if "p2" in item:
            p2 = self.p2(item["p2"], f"{prefix}.p2", a2)
        return state, action, p2, self.distribution(item["to"], f"{prefix}.to")

    def p2(self, value: object, key: str, a2: tuple[str, ...]) -> tuple[int, ...]:
        if not a2:
            raise self.fail(key, "p2 is only allowed with general P2 actions "
                                 "(adversary.actions); with traps the trap rule decides")
        items = [value] if isinstance(value, str) else self.ld.array(
            value, key, "a P2 action or an array of them")
        if not items:
            raise self.fail(key, "is empty; expected a P2 action or an array of them")
        found: list[int] = []
        for i, item in enumerate(items):
            ikey = key if isinstance(value, str) else f"{key}[{i}]"
            name = self.ld.string(item, ikey)
            if name not in a2:
                raise self.unknown(ikey, "P2 action", name, a2, "adversary.actions are ")
            if a2.index(name) in found:
                raise self.fail(ikey, f"P2 action {name!r} is repeated")
            found.append(a2.index(name))
        return tuple(found)

    def distribution(self, value: object, key: str) -> dict[int, float]:
        if not isinstance(value, dict):
            raise self.fail(key, "must be a table { state = probability, ... }, got "
                            + type(value).__name__)
        if not value:
            raise self.fail(key, "is empty; expected { state = probability, ... } summing to 1")
        dist: dict[int, float] = {}
        for name, p in value.items():
            pkey = f"{key}.{toml_key(name)}"
            if name not in self.number:
                raise self.unknown(pkey, "state", name, self.states, "states are ")
            p = self.ld.number(p, pkey)
            if p < 0:
                raise self.fail(pkey, f"probability {p!r} is negative")
            if p > 1:       # before the sum, which numbers near 1e308 would overflow
                raise self.fail(pkey, f"probability {p!r} is above 1")
            if p > 0:
                dist[self.number[name]] = p
        total = math.fsum(value.values())
        if abs(total - 1.0) > PROBABILITY_TOLERANCE:
            raise self.fail(key, f"probabilities sum to {total!r}; expected 1 (within 1e-9)")
        return dist

    def transitions(self, value: object, a2: tuple[str, ...]):
        """P1's actions per state and the dest/prob tables (docs/semantics.md §15)."""
        if not isinstance(value, list) or not value:
            raise self.fail("arena.transition", "expected [[arena.transition]] entries (an "
                                                "array of tables: state, action, to)")
        entries = [self.entry(item, i, a2) for i, item in enumerate(value)]
        actions: list[list[str]] = [[] for _ in self.states]
        for state, action, _, _ in entries:
            if action not in actions[state]:
                actions[state].append(action)
        n_p2 = len(a2) if any(p2 is not None for _, _, p2, _ in entries) else 1
        cover = self.coverage(entries, a2, n_p2)
        n_actions = max(len(a) for a in actions)
        k = max(len(dist) for *_, dist in entries)
        dest = np.broadcast_to(np.arange(len(self.states))[:, None, None, None],
                               (len(self.states), n_actions, n_p2, k)).copy()
        prob = np.zeros(dest.shape)
        for (state, action, j), i in cover.items():
            slot = actions[state].index(action)
            for o, (target, p) in enumerate(entries[i][3].items()):
                dest[state, slot, j, o], prob[state, slot, j, o] = target, p
        return tuple(tuple(a) for a in actions), dest, prob

    def coverage(self, entries: list, a2: tuple[str, ...], n_p2: int) -> dict:
        """(state, action, j) -> the entry giving its distribution; every one covered once."""
        default: dict[tuple[int, str], int] = {}
        named: dict[tuple[int, str, int], int] = {}
        for i, (state, action, p2, _) in enumerate(entries):
            where = f"action {action!r} at state {self.states[state]!r}"
            if p2 is None:
                if (state, action) in default:
                    raise self.fail(f"arena.transition[{i}]", f"a second entry without p2 for "
                                    f"{where} (the first is arena.transition"
                                    f"[{default[state, action]}]); give p2 to all but one")
                default[state, action] = i
                continue
            for j in p2:
                if (state, action, j) in named:
                    raise self.fail(f"arena.transition[{i}].p2", f"P2 action {a2[j]!r} is "
                                    f"named again for {where} (already by arena.transition"
                                    f"[{named[state, action, j]}])")
                named[state, action, j] = i
        cover = {}
        first = {}
        for i, (state, action, _, _) in enumerate(entries):
            first.setdefault((state, action), i)
        for (state, action), i in first.items():
            missing = [a2[j] for j in range(n_p2)
                       if (state, action, j) not in named and (state, action) not in default]
            if missing:
                raise self.fail(f"arena.transition[{i}]", f"action {action!r} at state "
                                f"{self.states[state]!r} has no entry for P2 action(s) "
                                f"{_listing(missing)} and no entry without p2; every (state, "
                                "action, P2 action) must be covered")
            if (state, action) in default and all((state, action, j) in named
                                                   for j in range(n_p2)):
                raise self.fail(f"arena.transition[{default[state, action]}]", "the entry "
                                f"without p2 for action {action!r} at state "
                                f"{self.states[state]!r} covers no P2 action (each has its own "
                                "entry); remove it or give p2 to fewer entries")
            for j in range(n_p2):
                cover[state, action, j] = named.get((state, action, j), default.get((state, action)))
        return cover


def read(ld, root: dict) -> Arena:
    """The arena of an arena world file. `ld` is the world loader (worldfile/loader.py): its
    typed getters and `fail`."""
    reader = _Reader(ld)
    table = ld.table(root, "arena", ARENA_KEYS)
    reader.read_states(table)
    initial = reader.state(table["initial"], "arena.initial")
    propositions, labels = reader.labels(table)
    positions = reader.positions(table)
    p2 = reader.adversary(ld.table(root, "adversary", ADVERSARY_KEYS))
    actions, dest, prob = reader.transitions(table["transition"], p2["p2_actions"])
    return Arena(states=reader.states, initial=initial, propositions=propositions,
                 labels=labels, actions=actions, dest=dest, prob=prob,
                 p2_actions=p2["p2_actions"], trap_candidates=p2["trap_candidates"],
                 positions=positions)


def read_adversary(ld, adv: dict, arena: Arena) -> dict:
    """The World fields traps, delay and initial_standing of an arena world's [adversary]
    (`read` checked it, reading P2's actions)."""
    reader = _Reader(ld)
    reader.states, reader.number = arena.states, {name: i for i, name in enumerate(arena.states)}
    p2 = reader.adversary(adv)
    return dict(traps=p2["traps"], delay=p2["delay"], initial_standing=p2["initial_standing"])


# ---------------------------------------------------------------------------------------------
# The front end (frontends/__init__.py): an arena world's value is its arena
# ---------------------------------------------------------------------------------------------

KIND = Arena.kind
FILE_TABLES = {"arena": True}
TABLE_KEYS = {"arena": ARENA_KEYS}
DESCRIBED = "an arena world ([arena])"
SETTINGS = ()
STANDING_RULE = ("delay > 0: the world's standing action ([adversary] initial_action or "
                 "initial_traps), else the one its file names, else the first action or the "
                 "first `traps` candidates")


def to_arena(world) -> Arena:
    return world.front


def describe(world) -> str:
    from hg2prism.frontends import counted

    arena = world.front
    p2 = (counted(len(arena.trap_candidates), "trap candidate") if arena.traps_mode
          else counted(len(arena.p2_actions), "P2 action"))
    return f"arena of {arena.n_states} states, {p2}"


def outcome_name(action: str, outcome: int) -> str:
    return f"outcome {outcome}"


def standing_candidates(world) -> tuple[int, ...]:
    """In trap mode, the trap candidates standing at the start when the world is re-solved with
    a positive delay (a sweep): its standing set, which a world with delay 0 keeps as its file
    names it (the first `traps` candidates when it names none); with general P2 actions none."""
    from hg2prism.model.dynamics import a2_actions

    if not world.front.traps_mode:
        return ()
    return tuple(a2_actions(world.front, world.traps)[1][world.initial_standing])


def standing_action(world) -> int:
    """With general P2 actions, the action (its index) standing at the start when the world is
    re-solved with a positive delay: its own, which a world with delay 0 keeps as its file's
    `initial_action` names it (the first when it names none)."""
    return world.initial_standing


def parameters(world) -> dict[str, object]:
    return {}


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------

def merged(arena: Arena, s: int, i: int, j: int) -> dict[int, float]:
    """The distribution of P1's i-th action at s when P2 plays j: equal successors added up
    in outcome order, zero probabilities dropped."""
    dist: dict[int, float] = {}
    for target, p in zip(arena.dest[s, i, j].tolist(), arena.prob[s, i, j].tolist()):
        if p > 0:
            dist[target] = dist.get(target, 0.0) + p
    return dist


def _entries(arena: Arena) -> list[str]:
    """The [[arena.transition]] entries, by state, then action."""
    lines: list[str] = []
    names = arena.states
    for s, actions in enumerate(arena.actions):
        for i, action in enumerate(actions):
            groups: list[tuple[dict[int, float], list[int]]] = []
            for j in range(arena.dest.shape[2]):
                dist = merged(arena, s, i, j)
                for known, members in groups:
                    if known == dist:
                        members.append(j)
                        break
                else:
                    groups.append((dist, [j]))
            common = max(range(len(groups)), key=lambda g: (len(groups[g][1]), -g))
            order = [g for g in range(len(groups)) if g != common] + [common]
            for g in order:
                dist, members = groups[g]
                lines += ["", "[[arena.transition]]", f"state = {toml_string(names[s])}",
                          f"action = {toml_string(action)}"]
                if g != common:
                    lines.append("p2 = " + toml_value([arena.p2_actions[j] for j in members]))
                lines.append("to = " + toml_value({names[t]: p for t, p in dist.items()}))
    return lines


def _wrapped(key: str, items: list[str], width: int = 96) -> list[str]:
    """`key = [...]`, over several lines when long."""
    one = f"{key} = [" + ", ".join(items) + "]"
    if len(one) <= width:
        return [one]
    lines, line = [f"{key} = ["], "   "
    for item in items:
        if len(line) + len(item) + 2 > width:
            lines.append(line.rstrip())
            line = "   "
        line += f" {item},"
    return lines + [line.rstrip(), "]"]


def _arena_lines(arena: Arena) -> list[str]:
    names = arena.states
    lines = ["[arena]", *_wrapped("states", [toml_string(s) for s in names]),
             f"initial = {toml_string(names[arena.initial])}",
             "propositions = " + toml_value(list(arena.propositions))]
    labelled = [(s, label) for s, label in enumerate(arena.labels) if label]
    if labelled:
        lines += ["", "[arena.labels]"]
        lines += [f"{toml_key(names[s])} = "
                  + toml_value([p for p in arena.propositions if p in label]
                               + sorted(label - set(arena.propositions)))
                  for s, label in labelled]
    if arena.positions is not None:
        lines += ["", "[arena.positions]"]
        lines += [f"{toml_key(names[s])} = {toml_value([float(c) for c in point])}"
                  for s, point in enumerate(arena.positions)]
    return lines + _entries(arena)


def _adversary_lines(world, arena: Arena, standing: int) -> list[str]:
    from hg2prism.model.dynamics import a2_actions
    from hg2prism.opponent.registry import observer_kind

    lines = ["", "[adversary]"]
    # with delay 0, the standing action a sweep over delay starts from, when not the first
    write_standing = world.delay > 0 or standing != 0
    if arena.traps_mode:
        cands = [arena.states[c] for c in arena.trap_candidates]
        lines += [f"traps = {world.traps}", *_wrapped("trap_candidates",
                                                      [toml_string(c) for c in cands])]
        lines.append(f"delay = {world.delay}")
        if write_standing:
            _, sets = a2_actions(arena, world.traps)
            lines.append("initial_traps = " + toml_value([cands[c] for c in sets[standing]]))
    else:
        lines.append("actions = " + toml_value(list(arena.p2_actions)))
        lines.append(f"delay = {world.delay}")
        if write_standing:
            lines.append(f"initial_action = {toml_string(arena.p2_actions[standing])}")
    lines.append("hypotheses = " + toml_value(list(world.hypotheses)))
    if observer_kind(world.inference).first_guess is None:
        lines.append(f"initial_hypothesis = {world.initial_hypothesis}")
    if world.tie_break != "first":
        lines.append(f"tie_break = {toml_string(world.tie_break)}")
    return lines


def to_toml(world) -> str:
    """The world file of `world`'s arena form (docs/semantics.md §15), normalised."""
    from hg2prism import frontends

    arena = frontends.arena_of(world)
    standing = world.initial_standing
    source = f" (from {world.path.name})" if world.path is not None else ""
    lines = [f"# The arena form of world {world.name}{source}, written by hg2prism convert",
             "# (docs/semantics.md §15).",
             f"name = {toml_string(world.name)}"]
    if world.description:
        lines.append(f"description = {toml_string(world.description)}")
    lines += ["", *_arena_lines(arena), "", "[task]", f"formula = {toml_string(world.formula)}"]
    lines += _adversary_lines(world, arena, standing)
    lines += ["", "[inference]", f"kind = {toml_string(world.inference)}",
              f"window = {world.window}", f"rationality = {toml_value(world.rationality)}"]
    lines += [f"{toml_key(key)} = {toml_value(value)}" for key, value in world.settings]
    sim, det = world.simulation, world.detection
    lines += ["", "[simulation]", f"episodes = {sim.episodes}", f"horizon = {sim.horizon}",
              f"seed = {sim.seed}", "", "[detection]", f"alpha = {toml_value(det.alpha)}",
              f"epsilon = {toml_value(det.epsilon)}", f"deviate_after = {det.deviate_after}"]
    return "\n".join(lines) + "\n"
