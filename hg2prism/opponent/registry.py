"""The kinds of P2's observer, by the world file's `[inference] kind` (docs/semantics.md §§5, 12).

The world loader (which kinds exist, which keys each accepts), the pipeline (building P2's
observer), the hypergame model (its PRISM part), detection (P2's variants), sweeps (which
parameters apply to which kind) and the size guard (how big her memory is) ask this registry,
never the kind's name. A new observer is a module defining its observer and its `ObserverKind`
(opponent/observer.py) with its PRISM renderer (or a renderer and template beside the others),
and one `register` line below.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from hg2prism.errors import InputError, MissingSetting
from hg2prism.model import validation
from hg2prism.model.world import World
from hg2prism.opponent import bayes, inference
from hg2prism.opponent.observer import Observer, ObserverKind
from hg2prism.opponent.perceptual_games import PerceptualGame
from hg2prism.prism.observers import render_bayes, render_cusum

__all__ = ["KINDS", "register", "run_time_kinds", "observer_kind", "build_observer", "owner",
           "configure", "mismatches"]

KINDS: dict[str, ObserverKind] = {}


def register(kind: ObserverKind, render: Callable[..., object] | None = None) -> ObserverKind:
    """Make `kind` known under `kind.name` (replacing a kind of that name), with `render`, its
    part of the PRISM model (prism/observers.py), when the kind does not carry one."""
    if render is not None:
        kind = replace(kind, render=render)
    if kind.render is None:
        raise ValueError(f"observer kind {kind.name!r} has no PRISM renderer")
    KINDS[kind.name] = kind
    return kind


register(inference.KIND, render_cusum)
register(bayes.KIND, render_bayes)
_BUILT_IN = dict(KINDS)


def run_time_kinds() -> tuple[ObserverKind, ...]:
    """The kinds registered since the package was imported (a new name, or a built-in one
    registered again): what another process importing the package lacks (a parallel sweep's
    workers, experiments/sweep.py)."""
    return tuple(kind for name, kind in KINDS.items() if _BUILT_IN.get(name) is not kind)


def _same(read: object, held: object) -> bool:
    """Whether a setting as its kind reads it equals the value a World holds (numbers within
    rounding: a normalised prior normalises to itself up to the last bits)."""
    import math

    if isinstance(read, tuple) and isinstance(held, tuple):
        return len(read) == len(held) and all(map(_same, read, held))
    if isinstance(read, float) and isinstance(held, (int, float)) and not isinstance(held, bool):
        return math.isclose(read, held, rel_tol=1e-12, abs_tol=0.0)
    return read == held


def check_observer(checks: validation.Checks, world: World) -> None:
    """A World's [inference] kind and the kind's settings, as its kind reads them from a world
    file, and P2's first guess when her kind sets it (model/validation.py calls this for every
    World)."""
    kind = KINDS[checks.choice(world.inference, "inference.kind", "inference kind", tuple(KINDS))]
    held = dict(world.settings) if isinstance(world.settings, tuple) else None
    if held is None or len(held) != len(world.settings):
        raise checks.fail("inference", "settings must be a tuple of (key, value) pairs")
    for key in held:
        if key not in kind.keys():
            raise checks.fail(f"inference.{key}", f"the {kind.title} observer has no {key}")
    for setting in kind.settings:
        key = f"inference.{setting.key}"
        if setting.key not in held:
            raise checks.fail(key, f"missing; expected {setting.expected}")
        value = held[setting.key]
        read = setting.read(checks, list(value) if isinstance(value, tuple) else value,
                            len(world.hypotheses))
        if not _same(read, value):
            raise checks.fail(key, f"{setting.key} = {value!r} is not as the {kind.title} "
                                   f"observer reads it ({read!r}); use registry.configure")
    if kind.first_guess is not None:
        first = kind.first_guess(held)
        if world.initial_hypothesis != first:
            raise checks.fail("adversary.initial_hypothesis", f"with kind = \"{kind.name}\" "
                              f"P2's first guess is {kind.first_guess_rule} ({first}), got "
                              f"{world.initial_hypothesis}")


validation.set_observer_check(check_observer)


def observer_kind(name: str) -> ObserverKind:
    """The kind registered as `name` (KeyError when there is none)."""
    return KINDS[name]


def build_observer(world: World, games: list[PerceptualGame]) -> Observer:
    """P2's inference as the world file sets it (`[inference] kind`)."""
    return KINDS[world.inference].build(world, games)


def owner(key: str) -> ObserverKind | None:
    """The first registered kind that has the [inference] key `key`, if any."""
    return next((kind for kind in KINDS.values() if key in kind.keys()), None)


def configure(world: World, name: str | None = None, **settings: object) -> World:
    """The world with P2's observer of kind `name` (default: the world's) and the given
    settings, the others kept when the kind stays and defaulted when it changes; P2's first
    guess follows when her kind sets it. MissingSetting (an InputError) names a required
    setting not given; InputError a bad value, as in a world file, an unknown kind or a setting the kind does not
    have."""
    if (name or world.inference) not in KINDS:
        raise InputError(str(world.path), "inference.kind", f"no observer of kind {name!r} "
                         f"(registered: {', '.join(sorted(KINDS))})")
    kind = KINDS[name or world.inference]
    keys = [setting.key for setting in kind.settings]
    for key in settings:
        if key not in keys:
            raise InputError(str(world.path), f"inference.{key}",
                             f"not a setting of the {kind.name} observer (its settings: "
                             f"{', '.join(keys) or 'none'})")
    n = len(world.hypotheses)
    values = dict(world.settings) if kind.name == world.inference else {}
    checks = validation.Checks(str(world.path))
    for setting in kind.settings:
        if setting.key in settings:     # read as from a world file (a prior normalised)
            value = settings[setting.key]
            read = setting.read(checks, list(value) if isinstance(value, tuple) else value, n)
            values[setting.key] = value if _same(read, value) else read
        elif setting.key not in values:
            if setting.default is None:
                raise MissingSetting(str(world.path), kind.name, setting.key)
            values[setting.key] = setting.default(n)
    first = world.initial_hypothesis if kind.first_guess is None else kind.first_guess(values)
    return replace(world, inference=kind.name, initial_hypothesis=first,
                   settings=tuple((s.key, values[s.key]) for s in kind.settings))


def mismatches(world: World, max_score: float) -> list:
    """P2's variants for the detection experiment (ObserverKind.mismatches), `max_score` the
    largest score P2 reached when following the model."""
    return KINDS[world.inference].mismatches(world, max_score, configure)
