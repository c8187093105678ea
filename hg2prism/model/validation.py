"""The rules every value of a world obeys (docs/semantics.md §1), written once: the world loader
(worldfile/loader.py, frontends/arena.py) reads a file with them, and `World.__post_init__`
checks every World with them (`validate`), so that no World exists unvalidated, however it was
made (`world.replace(...)`, `dataclasses.replace`, the constructor).

Each rule fails with one `InputError(file, key, reason)`, the key as the world file spells it
(`inference.rationality`, `adversary.traps`). The checks are cheap (no transition system is built):
the keys that need the map or the arena (trap counts, initial traps, P2's standing action) read
the data the World carries. The observer's own keys (`[inference] kind` and its settings) are
checked by the observer registry (opponent/registry.py), which hands its check to
`set_observer_check`; the model layer does not know the kinds of observer.
"""

from __future__ import annotations

import math
from pathlib import PurePath
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hg2prism.errors import InputError

# which of P2's tied actions she takes where the standing one is not tied ([adversary]
# tie_break, docs/semantics.md §4): the first in A2's order (the rule), or the last
TIE_BREAKS = ("first", "last")
MAX_RATIONALITY = 1e100     # P2's softmax in double precision (docs/semantics.md §1)

# Limits that keep every accepted world within bounded time and memory. Simulated episodes run
# side by side (arrays of `episodes` entries); a horizon bounds the steps of an episode that
# never ends (P1 kept away from both goal and traps), and the exact within-horizon numbers stop
# once converged. 10^5 steps x 10^6 episodes is the worst case these admit.
MAX_EPISODES = 1_000_000
MAX_HORIZON = 100_000
# Seeds at most this, so that every seed derived from one (an episode's seed set, detection's
# search) is still an integer a world file (TOML: 64 bits) can hold.
MAX_SEED = 2**62
_SEED_REASON = "the seeds derived from it must fit a world file's 64-bit integers"
LIMIT_REASON = {
    "simulation.seed": _SEED_REASON, "--seed": _SEED_REASON, "seed": _SEED_REASON,
    "simulation.episodes": "episodes are simulated side by side in memory",
    "simulation.horizon": "an episode that never ends is simulated to the horizon",
    "--episodes": "episodes are simulated side by side in memory",
    "--horizon": "an episode that never ends is simulated to the horizon",
    "episodes": "episodes are simulated side by side in memory",         # the API's arguments
    "horizon": "an episode that never ends is simulated to the horizon",
}


def toml_type(value: object) -> str:
    import datetime

    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "float"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    if isinstance(value, dict):
        return "table"
    if isinstance(value, (datetime.datetime, datetime.date, datetime.time)):
        return "date/time"
    return type(value).__name__


def shown(value: object) -> str:
    """The TOML type of a value, with the value itself when it is a short scalar."""
    if isinstance(value, bool):
        return f"boolean {'true' if value else 'false'}"
    if isinstance(value, (int, float)):
        return f"{toml_type(value)} {value!r}"
    if isinstance(value, str) and len(value) <= 40:
        return f"string {value!r}"
    return toml_type(value)


def toml_repr(value: object) -> str:
    """A short one-line rendering of a TOML value as it would be written in the file."""
    import json

    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_repr(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key_part(k)} = {toml_repr(v)}" for k, v in value.items()) + "}"
    if isinstance(value, str):
        return json.dumps(value)
    return str(value)


def key_part(name: str) -> str:
    """A TOML key as it would be written: bare when possible, else quoted (always one line)."""
    import json
    import re

    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else json.dumps(name)


def one_line(text: str) -> str:
    return " ".join(text.split())


@dataclass(frozen=True)
class Vocabulary:
    """The atomic propositions formulas may use, and how an error message describes them."""

    propositions: tuple[str, ...]
    described: str


class Checks:
    """The value rules, failing with InputError(file, key, reason). The world loader is one
    (reading a file), `validate` makes one for a World (its path as the file)."""

    file: str

    def __init__(self, file: str) -> None:
        self.file = file

    def fail(self, key: str, reason: str) -> InputError:
        return InputError(self.file, key, one_line(reason))

    # -- types -------------------------------------------------------------------------------

    def string(self, value: object, key: str) -> str:
        if not isinstance(value, str):
            raise self.fail(key, f"must be a string, got {toml_type(value)}")
        return value

    def integer(self, value: object, key: str, minimum: int | None = None,
                maximum: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"must be an integer, got {shown(value)}")
        # a world file's key is named again in the reason, an option (--episodes) is not
        name = "" if key.startswith("--") else key.rsplit(".", 1)[-1] + " "
        if minimum is not None and value < minimum:
            raise self.fail(key, f"{name}must be >= {minimum}, got {value}")
        if maximum is not None and value > maximum:
            reason = f" ({LIMIT_REASON[key]})" if key in LIMIT_REASON else ""
            raise self.fail(key, f"{name}must be <= {maximum:,}{reason}, got {value:,}")
        return value

    def array(self, value: object, key: str, expected: str) -> list:
        if not isinstance(value, list):
            raise self.fail(key, f"must be {expected}, got {toml_type(value)}")
        return value

    def choice(self, value: object, key: str, what: str, options: tuple[str, ...]) -> str:
        if value not in options:
            raise self.fail(key, f"unknown {what} {toml_repr(value)}; expected "
                                 + " or ".join(f'"{option}"' for option in options))
        return value

    def number(self, value: object, key: str) -> float:
        import numbers

        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise self.fail(key, f"must be a number, got {shown(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise self.fail(key, f"must be a finite number, got {value}")
        return value

    # -- the keys ----------------------------------------------------------------------------

    def name(self, value: object) -> str:
        if self.string(value, "name").strip() == "":
            raise self.fail("name", "name must not be empty")
        return self.one_line(value, "name")

    def one_line(self, value: str, key: str) -> str:
        """A text the generated models' comments and the figures' titles show: one line (a
        line break in a PRISM comment ends it, and Storm then read the rest as the model)."""
        if "\n" in value or "\r" in value:
            raise self.fail(key, f"{key.rsplit('.', 1)[-1]} must be one line (it heads the "
                                 f"generated models' comments), got {value!r}")
        return value

    def traps(self, value: object, candidates: int, beyond: str) -> int:
        """adversary.traps of a world whose P2 sets traps on `candidates` places (a grid's
        cells, an arena's states); `beyond` says, with {n} for `candidates`, why more are
        refused (the front end's words)."""
        traps = self.integer(value, "adversary.traps", 1)
        if traps > candidates:
            raise self.fail("adversary.traps",
                            f"traps = {traps} but " + beyond.format(n=candidates))
        return traps

    def delay(self, value: object) -> int:
        return self.integer(value, "adversary.delay", 0)

    def initial_hypothesis(self, value: object, n_hypotheses: int) -> int:
        key = "adversary.initial_hypothesis"
        index = self.integer(value, key)
        if not 0 <= index < n_hypotheses:
            raise self.fail(key, f"initial_hypothesis must be an index into hypotheses "
                                 f"(0..{n_hypotheses - 1}), got {index}")
        return index

    def window(self, value: object) -> int:
        return self.integer(value, "inference.window", 1)

    def tie_break(self, value: object) -> str:
        return self.choice(value, "adversary.tie_break", "tie break", TIE_BREAKS)

    def rationality(self, value: object) -> float:
        rationality = self.number(value, "inference.rationality")
        if rationality <= 0:
            raise self.fail("inference.rationality", f"rationality must be > 0, got {rationality}")
        if rationality > MAX_RATIONALITY:
            # beta * Q reaches 1e308 near here and P2's log-likelihood ratios overflow to
            # +-inf (world1 with 1.7e308 had 2 canonical states fewer than with 1e300)
            raise self.fail("inference.rationality", f"rationality must be at most "
                                                     f"{MAX_RATIONALITY:g}, got {rationality:g}")
        return rationality

    def episodes(self, value: object) -> int:
        return self.integer(value, "simulation.episodes", 1, MAX_EPISODES)

    def horizon(self, value: object) -> int:
        return self.integer(value, "simulation.horizon", 1, MAX_HORIZON)

    def seed(self, value: object) -> int:
        return self.integer(value, "simulation.seed", 0, MAX_SEED)

    def open_unit(self, value: object, key: str) -> float:
        number = self.number(value, key)
        if not 0 < number < 1:
            raise self.fail(key, f"{key.rsplit('.', 1)[-1]} must be in (0, 1), got {number}")
        return number

    def alpha(self, value: object) -> float:
        return self.open_unit(value, "detection.alpha")

    def epsilon(self, value: object) -> float:
        return self.open_unit(value, "detection.epsilon")

    def deviate_after(self, value: object) -> int:
        return self.integer(value, "detection.deviate_after", 0)

    def formula(self, value: object, key: str, vocabulary: Vocabulary):
        """Check a co-safe LTL formula over the world's propositions; return spot.formula."""
        import spot

        text = self.string(value, key)
        if text.strip() == "":
            raise self.fail(key, "the formula is empty; expected a co-safe LTL formula in Spot "
                                 "syntax, e.g. \"!obs U A\"")
        if "\n" in text or "\r" in text:
            raise self.fail(key, f"the formula must be one line (it heads the generated models' "
                                 f"comments), got {text!r}")
        try:
            parsed = spot.formula(text)
        except Exception as err:  # Spot raises SyntaxError with a multi-line diagnosis
            lines = [ln.strip() for ln in str(err).splitlines()]
            detail = "; ".join(ln for ln in lines
                               if ln and not ln.startswith(">>>") and set(ln) != {"^"})
            raise self.fail(key, f"formula {text!r} does not parse in Spot syntax"
                                 + (f": {detail}" if detail else "")) from None
        for ap in sorted(a.ap_name() for a in spot.atomic_prop_collect(parsed)):
            if ap not in vocabulary.propositions:
                raise self.fail(key, f"formula {text!r} uses proposition {ap!r}; only "
                                     f"{vocabulary.described} may be used")
        if not parsed.is_syntactic_guarantee():
            raise self.fail(key, f"formula {text!r} is not syntactically co-safe (Spot's "
                                 "is_syntactic_guarantee is false); expected a co-safe formula "
                                 "such as \"!obs U A\" or \"F A\"")
        return parsed

    def hypotheses(self, value: object, vocabulary: Vocabulary) -> tuple[str, ...]:
        """[adversary] hypotheses: distinct co-safe formulas, at least one."""
        items = self.array(value, "adversary.hypotheses", "an array of formulas")
        if not items:
            raise self.fail("adversary.hypotheses", "hypotheses is empty; expected at least one "
                                                    "co-safe LTL formula")
        # Distinct languages, not only distinct texts: two equivalent hypotheses ("F A" and
        # "true U A", "F (A & B)" and "F (B & A)") have the same DFA and game, and P2 could
        # never tell them apart. (Equivalence over every word: formulas that differ only on
        # letters the world never produces, two propositions on one cell, pass, as
        # docs/semantics.md §1 says; the arena is not compiled yet here.)
        import spot

        parsed: list = []
        for i, h in enumerate(items):
            key = f"adversary.hypotheses[{i}]"
            formula = self.formula(h, key, vocabulary)
            for j, other in enumerate(parsed):
                if spot.are_equivalent(formula, other):
                    raise self.fail(key, f"hypothesis {h!r} is repeated: it is equivalent to "
                                         f"hypotheses[{j}] ({items[j]!r}); expected hypotheses "
                                         "with distinct languages")
            parsed.append(formula)
        return tuple(items)


# -- P2's types (docs/semantics.md §16) ----------------------------------------------------------

def renamed(checks: Checks, prefix: str) -> Checks:
    """`checks` whose messages name the keys of type `prefix` (``type[<i>]``): ``inference.*``
    becomes ``<prefix>.inference.*`` and ``adversary.initial_hypothesis``
    ``<prefix>.initial_hypothesis`` (a type's `[type.inference]` is read by the rules of
    `[inference]`)."""
    import copy

    sub = copy.copy(checks)

    def fail(key: str, reason: str) -> InputError:
        if key.startswith("inference"):
            key = f"{prefix}.{key}"
        elif key == "adversary.initial_hypothesis":
            key = f"{prefix}.initial_hypothesis"
        return checks.fail(key, reason)

    sub.fail = fail
    return sub


class TypeChecks:
    """The rules of P2's types, for the world loader (worldfile/types.py) and `validate`."""

    @staticmethod
    def count(checks: Checks, n: int) -> None:
        if n < 2:
            raise checks.fail("type", f"{n} type(s); P1 adapts among at least two types "
                                      "(a world with one has [inference] instead)")

    @staticmethod
    def name(checks: Checks, value: object, i: int) -> str:
        key = f"type[{i}].name"
        if checks.string(value, key).strip() == "":
            raise checks.fail(key, "name must not be empty")
        return checks.one_line(value, key)

    @staticmethod
    def weight(checks: Checks, value: object, i: int) -> float:
        key = f"type[{i}].weight"
        weight = checks.number(value, key)
        if weight < 0:
            raise checks.fail(key, f"weight must be >= 0, got {weight}")
        return weight

    @staticmethod
    def total(checks: Checks, weights: list[float]) -> float:
        try:
            total = math.fsum(weights)
        except OverflowError:       # fsum raises where its partial sums overflow
            total = math.inf
        if not math.isfinite(total):
            raise checks.fail("type", "the types' weights are too large to add up; scale them "
                                      "down (they are normalised)")
        if total <= 0:
            raise checks.fail("type", "the types' weights sum to 0; expected at least one "
                                      "positive weight")
        return total

    @staticmethod
    def distinct(checks: Checks, names: list[str]) -> None:
        seen: dict[str, int] = {}
        for i, name in enumerate(names):
            if name in seen:
                raise checks.fail(f"type[{i}].name", f"type name {name!r} is repeated (it is "
                                                      f"type[{seen[name]}]'s); expected "
                                                      "distinct names")
            seen[name] = i

    @staticmethod
    def decision(checks: Checks, settings: dict, i: int) -> None:
        if settings.get("decision") == "sample":
            raise checks.fail(f"type[{i}].inference.decision", "decision \"sample\" is not "
                                                              "allowed for a type: P1's belief "
                                                              "over the types would not stay "
                                                              "finite; use \"map\"")


@dataclass(frozen=True)
class _TypeObserver:
    """A type's observer fields as the observer check reads a World's."""

    inference: object
    settings: object
    hypotheses: tuple
    initial_hypothesis: object


# The World fields that are the world's own observer: its first type's
OBSERVER_FIELDS = ("inference", "window", "rationality", "settings", "initial_hypothesis")


def _types(checks: Checks, world: Any) -> None:
    """`World.types`: at least two PlayerTypes with distinct non-empty names, weights >= 0
    normalised to sum 1 (a World holds the prior; the loader normalises a file's weights),
    each type's observer valid as an [inference] table (keys named ``type[<i>].inference.*``),
    no "sample" decision; the world's own observer is its first type's."""
    types = world.types
    if not isinstance(types, tuple):
        raise checks.fail("type", f"types must be a tuple of PlayerType, got "
                                  f"{type(types).__name__}")
    if not types:
        return
    TypeChecks.count(checks, len(types))
    for i, t in enumerate(types):
        if type(t).__name__ != "PlayerType":
            raise checks.fail(f"type[{i}]", f"must be a PlayerType, got {type(t).__name__}")
        TypeChecks.name(checks, t.name, i)
        TypeChecks.weight(checks, t.weight, i)
    total = TypeChecks.total(checks, [t.weight for t in types])
    if abs(total - 1.0) > 1e-9:
        raise checks.fail("type", f"the types' weights sum to {total!r}; a World holds the "
                                  "normalised prior (weights summing to 1)")
    TypeChecks.distinct(checks, [t.name for t in types])
    for i, t in enumerate(types):
        sub = renamed(checks, f"type[{i}]")
        sub.window(t.window)
        sub.rationality(t.rationality)
        sub.initial_hypothesis(t.initial_hypothesis, len(world.hypotheses))
        if _observer_check is not None:
            _observer_check(sub, _TypeObserver(t.inference, t.settings, world.hypotheses,
                                               t.initial_hypothesis))
        TypeChecks.decision(checks, dict(t.settings), i)
    first = types[0]
    for name in OBSERVER_FIELDS:
        if getattr(world, name) != getattr(first, name):
            mine, its = (_shown(name, getattr(w, name)) for w in (world, first))
            raise checks.fail("type[0]", f"the world's own {name} ({mine}) and its first "
                                         f"type's ({its}) differ: a world with types observes "
                                         f"as its first type; change a type through "
                                         f"World.replace(types=...), which brings the first "
                                         f"type's {name} when the call does not give {name} "
                                         f"too")


def _shown(name: str, value: object) -> str:
    """An observer field as a world file writes it: settings as `key = value` pairs."""
    if name == "settings" and isinstance(value, tuple):
        return ", ".join(f"{pair[0]} = {pair[1]!r}" for pair in value
                         if isinstance(pair, tuple) and len(pair) == 2) or "none"
    return repr(value)


# The observer registry's check of [inference] kind and the kind's settings (and of P2's first
# guess when her kind sets it): (checks, world) -> None, raising checks.fail(...).
_observer_check: Callable[[Checks, Any], None] | None = None


def set_observer_check(check: Callable[[Checks, Any], None]) -> None:
    global _observer_check
    _observer_check = check


def validate(world: Any) -> None:
    """Raise InputError(world's path, key, reason) at the first value of `world` that no world
    file could give (called by World.__post_init__)."""
    checks = Checks(str(world.path))
    if not isinstance(world.path, PurePath):
        raise checks.fail("path", "must be the world file's pathlib.Path (a world from text: "
                                  f"Path(its name)), got {type(world.path).__name__}")
    checks.name(world.name)
    checks.one_line(checks.string(world.description, "description"), "description")
    front = world.front
    if not all(callable(getattr(front, verb, None))
               for verb in ("vocabulary", "check", "count_p2_actions")):
        raise checks.fail("front", "must be a front end's value (model.world.Front: a grid "
                                   "world's frontends.grid.Grid, an arena world's "
                                   f"model.arena.Arena), got {type(front).__name__}")
    front.check(checks)                 # the front end's own values (a grid's robot)
    vocabulary = front.vocabulary()
    checks.formula(world.formula, "task.formula", vocabulary)
    if not isinstance(world.hypotheses, tuple):
        raise checks.fail("adversary.hypotheses", "must be a tuple of formulas, got "
                                                  f"{type(world.hypotheses).__name__}")
    checks.hypotheses(list(world.hypotheses), vocabulary)
    # a world with types observes as its first type: its own observer is named as type[0]'s
    observer = (renamed(checks, "type[0]") if isinstance(world.types, tuple) and world.types
                else checks)
    observer.initial_hypothesis(world.initial_hypothesis, len(world.hypotheses))
    _adversary(checks, world)
    observer.window(world.window)
    observer.rationality(world.rationality)
    sim, det = world.simulation, world.detection
    for key, value, kind in (("simulation", sim, "SimulationSettings"),
                             ("detection", det, "DetectionSettings")):
        if type(value).__name__ != kind:     # the model's dataclass (world.py imports this)
            raise checks.fail(key, f"must be a {kind} (hg2prism.model.world), such as "
                                   f"dataclasses.replace(world.{key}, ...), got "
                                   f"{type(value).__name__}")
    checks.episodes(sim.episodes), checks.horizon(sim.horizon), checks.seed(sim.seed)
    checks.alpha(det.alpha), checks.epsilon(det.epsilon), checks.deviate_after(det.deviate_after)
    if _observer_check is not None:
        _observer_check(observer, world)
    _types(checks, world)


# What a world file's refused initial_traps (or initial_action) adds when its delay is 0
# (frontends/grid.py, frontends/arena.py).
DELAY_0_STANDING = ("; with delay 0 it names what a sweep over delay starts from (without it, "
                    "the first)")


def _adversary(checks: Checks, world: Any) -> None:
    """traps, delay, and what stands at the start: P2's standing action, an index into her
    actions (the trap sets in combinations order, or an arena's P2 actions). With delay 0
    nothing stands; the index is then what a re-solve with a positive delay starts from (a
    sweep over delay: the file's initial_traps or initial_action, else 0)."""
    delay = checks.delay(world.delay)
    checks.tie_break(world.tie_break)
    n_actions, key = world.front.count_p2_actions(checks, world.traps)
    standing = checks.integer(world.initial_standing, key, 0)
    if standing >= n_actions:
        when = ("at the start" if delay > 0 else
                "a re-solve with delay > 0 starts from (delay is 0)")
        raise checks.fail(key, f"P2's standing action {when} (initial_standing = "
                               f"{standing}) must index one of her {n_actions} actions")
