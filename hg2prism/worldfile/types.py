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
by the observer registry), its messages naming `type[<i>].inference.<key>`; the rules of the
types themselves are model/validation.py's (`TypeChecks`), which `validate` applies to every
World. The world keeps its
types in `World.types` and, as its own observer, its first type's; `world_of_type` is the
ordinary world of one type, which the rest of the pipeline solves (V_k).
"""

from __future__ import annotations

from dataclasses import replace

from hg2prism.model.validation import TypeChecks, renamed
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
    TypeChecks.count(loader, len(tables))
    read = [_read_type(loader, table, i, adversary) for i, table in enumerate(tables)]
    total = TypeChecks.total(loader, [t.weight for t in read])
    TypeChecks.distinct(loader, [t.name for t in read])
    types = tuple(replace(t, weight=t.weight / total) for t in read)
    first = types[0]
    return dict(inference=first.inference, window=first.window, settings=first.settings,
                rationality=first.rationality, initial_hypothesis=first.initial_hypothesis,
                types=types)


def _read_type(loader, table: dict, i: int, adversary: dict) -> PlayerType:
    prefix = f"type[{i}]"
    loader.check_keys(table, TYPE_KEYS, prefix, {})
    name = TypeChecks.name(loader, table["name"], i) if "name" in table else f"type{i}"
    weight = TypeChecks.weight(loader, table["weight"], i)
    inference = table["inference"]
    if not isinstance(inference, dict):
        raise loader.fail(f"{prefix}.inference", "must be a table [type.inference], got "
                                                 + type(inference).__name__)
    sub = renamed(loader, prefix)
    adv = {k: table[k] for k in ("initial_hypothesis",) if k in table}
    fields = sub.inference({"inference": inference}, adv, adversary)
    TypeChecks.decision(loader, dict(fields["settings"]), i)
    first = fields.get("initial_hypothesis")
    if first is None:
        first = sub.initial_hypothesis(table.get("initial_hypothesis", 0),
                                       len(adversary["hypotheses"]))
    return PlayerType(name=name, weight=weight, initial_hypothesis=first,
                      inference=fields["inference"], window=fields["window"],
                      rationality=fields["rationality"], settings=fields["settings"])


def world_of_type(world: World, k: int) -> World:
    """The ordinary world (one `[inference]`) in which P2 is of type k; its description says
    so (the header of `type<k>/hypergame.prism` shows it)."""
    t = world.types[k]
    which = f"P2 of type {t.name!r} (type {k} of {len(world.types)})"
    return replace(world, inference=t.inference, window=t.window, rationality=t.rationality,
                   settings=t.settings, initial_hypothesis=t.initial_hypothesis, types=(),
                   of_type=t.name, description=f"{world.description}; here {which}" if world.description
                   else which)


def weights(world: World) -> tuple[float, ...]:
    """The types' prior (normalised weights)."""
    return tuple(t.weight for t in world.types)
