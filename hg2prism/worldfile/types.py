"""P2's possible types in a world file (docs/semantics.md §16): `[[type]]` tables instead of
one `[inference]` table.

    [[type]]
    name = "jumpy"              # optional (default type<i>), distinct
    weight = 0.5                # prior probability, >= 0 (normalised over the types)
    initial_hypothesis = 0      # optional, as adversary.initial_hypothesis
    [type.inference]            # exactly the keys of [inference]
    window = 1
    ...

Each type's `[inference]` keys are read by the world loader's own `[inference]` reader (and so
by the observer registry), its messages naming `type[<i>].inference.<key>`. The world keeps its
types in `World.types` and, as its own observer, its first type's; `world_of_type` is the
ordinary world of one type, which the rest of the pipeline solves (V_k).
"""

from __future__ import annotations

import copy
import math
from dataclasses import replace

from hg2prism.model.world import PlayerType, World

__all__ = ["TYPE_KEYS", "top_keys", "observer_fields", "world_of_type", "weights"]

# Keys of a [[type]] table: key -> required?
TYPE_KEYS = {"name": False, "weight": True, "initial_hypothesis": False, "inference": True}


def top_keys(root: dict, keys: dict[str, bool]) -> dict[str, bool]:
    """The top-level keys a world may have: `type` beside the others, and `[inference]` not
    required when the world lists types."""
    keys = {**keys, "type": False}
    if "type" in root:
        keys["inference"] = False
    return keys


def _renamed(loader, prefix: str):
    """The loader whose messages name the keys of type `prefix` (type[<i>])."""
    sub = copy.copy(loader)

    def fail(key: str, reason: str):
        if key.startswith("inference"):
            key = f"{prefix}.{key}"
        elif key == "adversary.initial_hypothesis":
            key = f"{prefix}.initial_hypothesis"
        return loader.fail(key, reason)

    sub.fail = fail
    return sub


def observer_fields(loader, root: dict, adv: dict, adversary: dict) -> dict:
    """The World fields of P2's observer: `[inference]` as the loader reads it, or, with
    `[[type]]`, the first type's and `types`."""
    if "type" not in root:
        return loader.inference(root, adv, adversary)
    if "inference" in root:
        raise loader.fail("inference", "a world lists P2's types ([[type]], each with its "
                                       "[type.inference]) or has one [inference] table, not both")
    if "initial_hypothesis" in adv:
        raise loader.fail("adversary.initial_hypothesis", "not allowed with [[type]]: each "
                                                          "type sets its own initial_hypothesis")
    tables = root["type"]
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise loader.fail("type", "must be an array of tables [[type]]")
    if len(tables) < 2:
        raise loader.fail("type", f"{len(tables)} type(s); P1 adapts among at least two types "
                                  "(a world with one has [inference] instead)")
    read = [_read_type(loader, table, i, adversary) for i, table in enumerate(tables)]
    total = sum(t.weight for t in read)
    if total <= 0:
        raise loader.fail("type", "the types' weights sum to 0; expected at least one "
                                  "positive weight")
    seen: dict[str, int] = {}
    for i, t in enumerate(read):
        if t.name in seen:
            raise loader.fail(f"type[{i}].name", f"type name {t.name!r} is repeated (it is "
                                                  f"type[{seen[t.name]}]'s); expected distinct "
                                                  "names")
        seen[t.name] = i
    types = tuple(replace(t, weight=t.weight / total) for t in read)
    first = types[0]
    return dict(inference=first.inference, window=first.window, settings=first.settings,
                rationality=first.rationality, initial_hypothesis=first.initial_hypothesis,
                types=types)


def _read_type(loader, table: dict, i: int, adversary: dict) -> PlayerType:
    prefix = f"type[{i}]"
    loader.check_keys(table, TYPE_KEYS, prefix, {})
    name = loader.string(table["name"], f"{prefix}.name") if "name" in table else f"type{i}"
    if name.strip() == "":
        raise loader.fail(f"{prefix}.name", "name must not be empty")
    weight = loader.number(table["weight"], f"{prefix}.weight")
    if weight < 0 or not math.isfinite(weight):
        raise loader.fail(f"{prefix}.weight", f"weight must be >= 0, got {weight}")
    inference = table["inference"]
    if not isinstance(inference, dict):
        raise loader.fail(f"{prefix}.inference", "must be a table [type.inference], got "
                                                 + type(inference).__name__)
    sub = _renamed(loader, prefix)
    adv = {k: table[k] for k in ("initial_hypothesis",) if k in table}
    fields = sub.inference({"inference": inference}, adv, adversary)
    if dict(fields["settings"]).get("decision") == "sample":
        raise loader.fail(f"{prefix}.inference.decision", "decision \"sample\" is not allowed "
                                                         "for a type: P1's belief over the "
                                                         "types would not stay finite; use "
                                                         "\"map\"")
    first = fields.get("initial_hypothesis")
    if first is None:
        first = sub.integer(table.get("initial_hypothesis", 0), "adversary.initial_hypothesis")
        n = len(adversary["hypotheses"])
        if not 0 <= first < n:
            raise sub.fail("adversary.initial_hypothesis",
                           f"initial_hypothesis must be an index into hypotheses "
                           f"(0..{n - 1}), got {first}")
    return PlayerType(name=name, weight=weight, initial_hypothesis=first,
                      inference=fields["inference"], window=fields["window"],
                      rationality=fields["rationality"], settings=fields["settings"])


def world_of_type(world: World, k: int) -> World:
    """The ordinary world (one `[inference]`) in which P2 is of type k."""
    t = world.types[k]
    return replace(world, inference=t.inference, window=t.window, rationality=t.rationality,
                   settings=t.settings, initial_hypothesis=t.initial_hypothesis, types=())


def weights(world: World) -> tuple[float, ...]:
    """The types' prior (normalised weights)."""
    return tuple(t.weight for t in world.types)
