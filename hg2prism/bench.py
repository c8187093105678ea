"""Scaling benchmark (`hg2prism bench`): a family of generated worlds of growing size, each run
through every stage with its time, Storm's sizes and the peak memory."""

from __future__ import annotations

import random

REGIONS = "ABCDE"
HYPOTHESIS_POOL = ("!obs U A", "!obs U B", "!obs U C", "!obs U D", "!obs U E")


def bench_world(side: int, window: int, hypotheses: int, traps: int, seed: int = 0,
                candidates: int = 6) -> str:
    """TOML text of a side x side open grid (plus border) with scattered walls and obstacles,
    regions A-E, `candidates` trap cells, the paper's task and `hypotheses` subgoal hypotheses."""
    rng = random.Random(seed * 1000 + side)
    grid = [["." for _ in range(side)] for _ in range(side)]
    free = [(r, c) for r in range(side) for c in range(side)]
    rng.shuffle(free)
    start = free.pop()
    grid[start[0]][start[1]] = "@"
    for letter in REGIONS:
        r, c = free.pop()
        grid[r][c] = letter
    for _ in range(candidates):
        r, c = free.pop()
        grid[r][c] = "t"
    for _ in range(side * side // 12):
        r, c = free.pop()
        grid[r][c] = "#"
    for _ in range(side * side // 25):
        r, c = free.pop()
        grid[r][c] = "o"
    rows = ["#" * (side + 2)] + ["#" + "".join(row) + "#" for row in grid] + ["#" * (side + 2)]
    hyps = ", ".join(f'"{h}"' for h in HYPOTHESIS_POOL[:hypotheses])
    return f'''name = "bench_s{side}_w{window}_x{hypotheses}_t{traps}"
description = "benchmark world: {side}x{side}, window {window}, {hypotheses} hypotheses, {traps} trap(s)"

[grid]
map = """
{chr(10).join(rows)}
"""

[robot]
slip = 0.1

[task]
formula = "(!obs U A) & (!(B | obs) U C)"

[adversary]
traps = {traps}
hypotheses = [{hyps}]

[inference]
window = {window}
threshold = 1.5
rationality = 5.0
'''
