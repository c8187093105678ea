"""Generated grid worlds: the benchmark's (`hg2prism bench`, experiments/bench.py) square worlds
around a fixed core, written as world files."""

from __future__ import annotations

import random
from collections import deque

from hg2prism.frontends.grid import world_file as grid_world_file

HYPOTHESIS_POOL = ("!obs U A", "!obs U B", "!obs U C", "!obs U D", "!obs U E")
TASK = "(!obs U A) & (!(B | obs) U C)"

# The core, top row first: P1 needs A and C (and must not touch B before C); traps stand next
# to every region, so P2 blocks whichever region she believes in.
CORE = (
    "....#Ct..#..",
    ".#..ott..o..",
    "..#..tB...#.",
    "........E...",
    "........t...",
    "..#.o.......",
    ".#..........",
    "....D....#..",
    "....t.......",
    ".....##.....",
    ".........At#",
    "...o...#t...",
)
CORE_SIZE = len(CORE)


def _reachable(grid: list[list[str]], start: tuple[int, int]) -> set[tuple[int, int]]:
    side = len(grid)
    seen, queue = {start}, deque([start])
    while queue:
        r, c = queue.popleft()
        for n in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
            if 0 <= n[0] < side and 0 <= n[1] < side and grid[n[0]][n[1]] != "#" \
                    and n not in seen:
                seen.add(n)
                queue.append(n)
    return seen


def bench_world(side: int, window: int, hypotheses: int, traps: int, seed: int = 0,
                delay: int = 0) -> str:
    """TOML text of a side x side world (plus border): the fixed core in the top right corner,
    the start in the bottom left one, 1/12 of the other cells walls and 1/25 obstacles (none
    next to the start; cells the start cannot reach are walled in).

    `hypotheses` (1-5) takes P2's candidate tasks from "!obs U A", "!obs U B", ... in that
    order; `traps` (1-2) among the core's 8 candidates (the core fixes them); with `delay` > 0
    the traps start on the first candidates in reading order."""
    if side < CORE_SIZE:
        raise ValueError(f"side must be at least {CORE_SIZE} (the core)")
    if not 1 <= hypotheses <= len(HYPOTHESIS_POOL):
        raise ValueError(f"hypotheses must be in 1..{len(HYPOTHESIS_POOL)}")
    rng = random.Random(seed * 1000 + side)
    for _ in range(10):
        grid = [["." for _ in range(side)] for _ in range(side)]
        for r, row in enumerate(CORE):
            grid[r][side - CORE_SIZE:] = list(row)
        start = (side - 1, 0)
        grid[start[0]][start[1]] = "@"
        # walls and obstacles anywhere but the core, its rim and the start's neighbourhood
        field = [(r, c) for r in range(side) for c in range(side)
                 if not (r <= CORE_SIZE and c >= side - CORE_SIZE - 1)
                 and max(abs(r - start[0]), abs(c - start[1])) > 1]
        rng.shuffle(field)
        n_field = len(field)
        for _ in range(n_field // 12):
            r, c = field.pop()
            grid[r][c] = "#"
        for _ in range(n_field // 25):
            r, c = field.pop()
            grid[r][c] = "o"
        reachable = _reachable(grid, start)
        cut_off = [(r, c) for r in range(side) for c in range(side)
                   if grid[r][c] != "#" and (r, c) not in reachable]
        if not cut_off:
            break
    # Large fields are rarely connected: wall in whatever the start cannot reach.
    for r, c in cut_off:
        grid[r][c] = "#"
    rows = ["#" * (side + 2)] + ["#" + "".join(row) + "#" for row in grid] + ["#" * (side + 2)]
    description = (f"benchmark world: {side}x{side}, window {window}, {hypotheses} hypotheses, "
                   f"{traps} trap(s)" + (f", delay {delay}" if delay else ""))
    return grid_world_file(name=world_name(side, window, hypotheses, traps, delay),
                           description=description, rows=rows, slip=0.1, formula=TASK,
                           traps=traps, delay=delay, hypotheses=HYPOTHESIS_POOL[:hypotheses],
                           inference={"window": window, "threshold": 1.5, "rationality": 5.0})


def world_name(side: int, window: int, hypotheses: int, traps: int, delay: int = 0) -> str:
    return f"bench_s{side}_w{window}_x{hypotheses}_t{traps}" + (f"_d{delay}" if delay else "")
