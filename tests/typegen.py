"""Small random worlds with P2's types (docs/semantics.md §16), for the tests: a generated grid
world (tests/worldgen.py) or arena world (tests/arenagen.py) whose `[inference]` table is
replaced by two or three `[[type]]` tables (CUSUM or Bayesian "map", windows 1-2)."""

from __future__ import annotations

import random
import re

import arenagen
import worldgen


def _strip(text: str) -> str:
    """The world without its [inference] table and adversary.initial_hypothesis."""
    text = re.sub(r"^initial_hypothesis\s*=.*\n", "", text, flags=re.MULTILINE)
    return re.sub(r"\[inference\]\n(?:[^\[].*\n?)*", "", text)


def type_table(rng: random.Random, name: str, n_hyp: int, weight: float | None = None) -> str:
    kind = rng.choice(["cusum", "cusum", "bayes"])
    weight = round(rng.uniform(0.1, 1.0), 2) if weight is None else weight
    lines = ["[[type]]", f'name = "{name}"', f"weight = {weight}"]
    if kind == "cusum":
        lines.append(f"initial_hypothesis = {rng.randrange(n_hyp)}")
    lines += ["[type.inference]", f'kind = "{kind}"', f"window = {rng.choice([1, 1, 2])}",
              f"rationality = {round(rng.uniform(1.0, 10.0), 1)}"]
    if kind == "cusum":
        lines.append(f"threshold = {round(rng.uniform(0.1, 2.0), 2)}")
    else:
        prior = [round(rng.uniform(0.2, 1.0), 2) for _ in range(n_hyp)]
        lines.append(f"prior = {prior}")
    return "\n".join(lines) + "\n"


def typed_world(seed: int, arena: bool = False, n_types: int | None = None) -> str:
    """A small world with 2 or 3 types (delay 0-2)."""
    rng = random.Random(10_000 + seed)
    n_types = n_types or rng.choice([2, 2, 3])
    if arena:
        base = arenagen.arena_world(seed, observer="cusum", window=1)
    else:
        base = worldgen.make_world(seed, window=1, traps=1, nhyp=rng.choice([2, 3]),
                                   size=rng.choice([(3, 3), (4, 3)]),
                                   delay=rng.choice([0, 0, 1, 2]))
    n_hyp = len(re.search(r"^hypotheses = \[(.*)\]$", base, re.MULTILINE).group(1).split('", "'))
    text = _strip(base)
    return text + "\n" + "".join(type_table(rng, f"t{i}", n_hyp) for i in range(n_types))
