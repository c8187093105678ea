"""Small random maze worlds (issue 22, item 9): walls at random, the robot's start, one cell per
region, trap candidates on the shortest paths from the start to the regions, delay 0-2, and
either observer (sliding-window CUSUM or Bayesian, `map` decision). Deterministic in the seed.

Like tests/worldgen.py it imports nothing from hg2prism; the maps use its conventions
(`#` wall, `@` start, `t` trap candidate, letters regions; rows from the top, y from the
bottom)."""

from __future__ import annotations

import random
from collections import deque

TASKS = ["!obs U A", "F A & F B", "(!obs U A) & (!(B | obs) U C)", "!obs U (A & F B)",
         "(!obs U A) | (!obs U B)", "F (A & F C)"]
HYPOTHESES = ["F A", "!obs U B", "F C", "!obs U A", "F B & F C", "F (B & F A)"]
LETTERS = "ABC"
STEPS = ((0, 1), (1, 0), (0, -1), (-1, 0))


def _distances(free: set, start: tuple[int, int]) -> dict:
    """Breadth-first distances from `start` over the cells of `free`."""
    dist = {start: 0}
    queue = deque([start])
    while queue:
        x, y = queue.popleft()
        for dx, dy in STEPS:
            c = (x + dx, y + dy)
            if c in free and c not in dist:
                dist[c] = dist[(x, y)] + 1
                queue.append(c)
    return dist


def _on_shortest_paths(free: set, start, goal) -> set:
    """The cells on some shortest path from `start` to `goal`, both excluded."""
    there, back = _distances(free, start), _distances(free, goal)
    total = there[goal]
    return {c for c in free if c in there and c in back and there[c] + back[c] == total} \
        - {start, goal}


def _layout(rng: random.Random, width: int, height: int, regions: int):
    """(free cells, start, region cells) of a connected random maze, or None."""
    cells = [(x, y) for x in range(1, width + 1) for y in range(1, height + 1)]
    free = {c for c in cells if rng.random() > 0.3}
    if len(free) < regions + 3:
        return None
    start = rng.choice(sorted(free))
    if len(_distances(free, start)) != len(free):
        return None
    spots = sorted(free - {start})
    return free, start, rng.sample(spots, regions)


def maze_world(seed: int) -> str:
    """One small maze world as TOML text."""
    rng = random.Random(seed)
    task = rng.choice(TASKS)
    letters = sorted({c for c in task if c in LETTERS} | set(rng.sample(LETTERS, 2)))
    hypotheses = rng.sample(HYPOTHESES, rng.choice([2, 2, 3]))
    letters = sorted(set(letters) | {c for h in hypotheses for c in h if c in LETTERS})
    for _ in range(1000):
        width, height = rng.choice([(4, 2), (5, 2), (4, 3), (6, 2), (5, 3)])
        found = _layout(rng, width, height, len(letters))
        if found is None:
            continue
        free, start, region_cells = found
        candidates = set()
        for cell in region_cells:
            candidates |= _on_shortest_paths(free, start, cell)
        candidates -= set(region_cells)
        if candidates:
            break
    else:
        raise RuntimeError("no maze with trap candidates")
    traps = sorted(rng.sample(sorted(candidates), min(len(candidates), rng.choice([1, 2, 3]))))
    grid = {c: "." for c in free}
    grid[start] = "@"
    for letter, cell in zip(letters, region_cells):
        grid[cell] = letter
    for cell in traps:
        grid[cell] = "t"
    rows = ["".join(grid.get((x, y), "#") for x in range(width + 2))
            for y in range(height + 1, -1, -1)]
    delay = rng.choice([0, 1, 2])
    if rng.random() < 0.5:
        inference = {"kind": '"bayes"', "window": rng.choice([1, 2]),
                     "rationality": rng.choice([1.0, 3.0, 10.0]),
                     "prior": [rng.choice([1, 1, 2]) for _ in hypotheses], "decision": '"map"'}
        first = None
    else:
        inference = {"window": rng.choice([1, 2]), "rationality": rng.choice([1.0, 3.0]),
                     "threshold": rng.choice([0.5, 0.75, 1.5])}
        first = rng.randrange(len(hypotheses))
    return world_text(f"maze{seed}", rows, rng.choice([0.0, 0.05, 0.1]), task, delay,
                      [list(traps[0])] if delay else [], hypotheses, first, inference)


def world_text(name: str, rows: list[str], slip: float, task: str, delay: int,
               initial_traps: list, hypotheses: list[str], first: int | None,
               inference: dict) -> str:
    """A world file with one trap: `inference` maps keys to TOML values (strings quoted)."""
    lines = [f'name = "{name}"', "[grid]", 'map = """', *rows, '"""', "[robot]",
             f"slip = {slip}", "[task]", f'formula = "{task}"', "[adversary]", "traps = 1",
             f"delay = {delay}"]
    if initial_traps:
        lines.append(f"initial_traps = {initial_traps}")
    lines.append("hypotheses = [" + ", ".join(f'"{h}"' for h in hypotheses) + "]")
    if first is not None:
        lines.append(f"initial_hypothesis = {first}")
    lines += ["[inference]"] + [f"{key} = {value}" for key, value in inference.items()]
    return "\n".join(lines) + "\n"


# The world of issue 22, item 9, on which `run` stopped ("policy iteration for P1's best
# response did not converge") while `check` gave deceptive value 0.9 and V_lead 0.
ISSUE_WORLD = world_text(
    "maze", ["##########", "##....#A.#", "#.@t.C.t##", "###..#B#.#", "##########"], 0.05,
    "(!obs U A) & (!(B | obs) U C)", 2, [[3, 2]], ["F A", "!obs U B", "F C"], 2,
    {"window": 2, "rationality": 1.0, "threshold": 0.75})
