"""Generator of small random *valid* world files for the tests (docs/semantics.md §1).

``random_world(seed)`` gives the TOML text of one small valid world; ``world_family()`` a
fixed, deterministic list of worlds covering delay 0/1/2/3, traps 1/2, window 1/2/3, slip 0 and
> 0, one and several hypotheses.  Every world's hypergame stays well below ~30,000 canonical
states (checked with tests/reference.py when the family was chosen).
"""

from __future__ import annotations

import random
from collections import deque

REGION_LETTERS = "ABCDE"          # never F G M R U W X (Spot operators)

# task templates over placeholder letters {a}, {b}, {c} (all syntactically co-safe)
TASKS = [
    ("!obs U {a}", 1),
    ("(!obs U {a}) & (!({b} | obs) U {c})", 3),
    ("F {a} & F {b}", 2),
    ("!{b} U {a}", 2),
    ("F ({a} & F {b})", 2),
    ("!obs U ({a} & F {b})", 2),
    ("(!obs U {a}) & F {b}", 2),
    ("F {a}", 1),
]
# hypothesis templates
HYPS = [
    ("!obs U {a}", 1),
    ("F {a}", 1),
    ("!{b} U {a}", 2),
    ("F ({a} & F {b})", 2),
]


def _fmt(template, letters):
    return template.format(**dict(zip("abc", letters)))


def _connected(grid, W, H, start):
    seen = {start}
    queue = deque([start])
    while queue:
        x, y = queue.popleft()
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            nx, ny = x + dx, y + dy
            if 0 <= nx < W and 0 <= ny < H and grid[ny][nx] != "#" and (nx, ny) not in seen:
                seen.add((nx, ny))
                queue.append((nx, ny))
    free = {(x, y) for y in range(H) for x in range(W) if grid[y][x] != "#"}
    return seen == free


def make_world(seed, *, delay=None, traps=None, window=None, slip=None, nhyp=None,
               size=None, ncand=None, nregions=None, task=None, hyps=None, name=None,
               compact=False):
    """One valid world; every parameter left as None is drawn from ``random.Random(seed)``.

    ``size`` = (interior width, interior height); ``task``/``hyps`` are templates (index
    into TASKS / HYPS) or literal formulas over the letters A.. (then the letters are used
    as written and forced to exist in the map).  ``compact`` shrinks the grid further for
    the largest combinations (window 3 with delay > 0)."""
    rng = random.Random(seed)
    if delay is None:
        delay = rng.choice([0, 0, 1, 2])
    if traps is None:
        traps = rng.choice([1, 1, 2])
    if window is None:
        window = rng.choice([1, 2, 2, 3])
    if slip is None:
        slip = rng.choice([0.0, 0.05, 0.1, 0.1, 0.2])
    if nhyp is None:
        nhyp = rng.choice([1, 2, 2, 3, 3, 4])
    # keep the hypergame small: the product grows with window, delay, traps and |X|
    budget = (window - 1) + delay + (traps - 1) + (1 if nhyp >= 3 else 0)
    if size is None:
        if compact and window >= 3 and delay > 0:
            size = rng.choice([(3, 3), (4, 3), (3, 4)]) if nhyp <= 2 and traps == 1 else (3, 3)
        elif budget >= 4:
            size = rng.choice([(3, 3), (4, 3), (3, 4)])
        elif budget >= 2:
            size = rng.choice([(3, 3), (4, 3), (3, 4), (4, 4)])
        else:
            size = rng.choice([(4, 4), (5, 4), (4, 5), (5, 5)])
    iw, ih = size
    if ncand is None:
        hi = 3 if (delay > 0 and traps == 2) or budget >= 4 else 4 if delay > 0 else 5
        ncand = rng.randint(max(2, traps), max(max(2, traps), hi))
    if nregions is None:
        nregions = rng.randint(2, 4)
    # capacity: '@' + one cell per region + candidates + one spare cell
    ncand = max(max(2, traps), min(ncand, iw * ih - 2 - nregions))
    nregions = min(nregions, iw * ih - 2 - ncand)

    # formulas
    letters = rng.sample(REGION_LETTERS, nregions)
    if isinstance(task, str):
        task_f = task
        forced = [c for c in REGION_LETTERS if c in task_f.replace("obs", "")]
    else:
        tpl, k = TASKS[task] if task is not None else rng.choice(
            [t for t in TASKS if t[1] <= nregions])
        if k > nregions:
            raise ValueError("not enough regions for the task template")
        task_f = _fmt(tpl, rng.sample(letters, k))
        forced = []
    hyp_list = []
    if hyps is not None:
        for h in hyps:
            if isinstance(h, str):
                hyp_list.append(h)
                forced += [c for c in REGION_LETTERS if c in h.replace("obs", "")]
            else:
                tpl, k = HYPS[h]
                hyp_list.append(_fmt(tpl, rng.sample(letters, k)))
    else:
        tries = 0
        while len(hyp_list) < nhyp and tries < 200:
            tries += 1
            tpl, k = rng.choice([t for t in HYPS if t[1] <= nregions])
            h = _fmt(tpl, rng.sample(letters, k))
            if h not in hyp_list:
                hyp_list.append(h)
    if forced:
        forced = list(dict.fromkeys(forced))
        others = [c for c in letters if c not in forced]
        letters = forced + others[:max(0, nregions - len(forced))]

    # grid (interior iw x ih, '#' border); retry until every free cell is connected
    for attempt in range(1000):
        W, H = iw + 2, ih + 2
        grid = [["#"] * W for _ in range(H)]          # grid[y][x], y from the bottom
        interior = [(x, y) for x in range(1, W - 1) for y in range(1, H - 1)]
        rng.shuffle(interior)
        start = interior.pop()
        grid[start[1]][start[0]] = "@"
        # regions preferably far from the start
        interior.sort(key=lambda c: abs(c[0] - start[0]) + abs(c[1] - start[1])
                      + rng.uniform(0, 2.5), reverse=True)
        spare = len(interior) - ncand - len(letters) - 1   # keep one cell free
        for letter in letters:
            count = rng.choice([1, 1, 2])
            if count == 2 and spare <= 0:
                count = 1
            spare -= count - 1
            for _ in range(count):
                x, y = interior.pop(0)
                grid[y][x] = letter
        # trap candidates preferably next to region cells (so that traps matter)
        def near_region(c):
            return any(grid[c[1] + dy][c[0] + dx] in letters
                       for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)))
        rng.shuffle(interior)
        interior.sort(key=lambda c: 0 if near_region(c) and rng.random() < 0.5 else 1)
        for _ in range(ncand):
            x, y = interior.pop(0)
            grid[y][x] = "t"
        rng.shuffle(interior)
        it = iter(interior)
        rest = list(it)
        nobs = min(rng.choice([0, 1, 1, 2]), len(rest))
        for x, y in rest[:nobs]:
            grid[y][x] = "o"
        rest = rest[nobs:]
        nwall = min(rng.choice([0, 1, 1, 2]), max(0, len(rest) - 1))
        for x, y in rest[:nwall]:
            grid[y][x] = "#"
        for x, y in rest[nwall:]:
            grid[y][x] = "."
        if _connected(grid, W, H, start):
            break
    else:
        raise RuntimeError("could not generate a connected grid")

    cands = [(x, y) for y in range(H - 1, -1, -1) for x in range(W) if grid[y][x] == "t"]
    init_traps = [list(c) for c in rng.sample(cands, traps)] if delay > 0 else []
    threshold = round(rng.uniform(0.5, 3.0), 2)
    rationality = round(rng.uniform(1.0, 10.0), 1)
    h0 = rng.randrange(len(hyp_list))
    rows = ["".join(grid[y]) for y in range(H - 1, -1, -1)]
    name = name or f"rand{seed}"

    def q(s):
        return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'

    lines = [
        f"name = {q(name)}",
        f"description = {q(f'generated by tests/worldgen.py (seed {seed})')}",
        "",
        "[grid]",
        'map = """',
        *rows,
        '"""',
        "",
        "[robot]",
        f"slip = {slip!r}",
        "",
        "[task]",
        f"formula = {q(task_f)}",
        "",
        "[adversary]",
        f"traps = {traps}",
        f"delay = {delay}",
        "initial_traps = [" + ", ".join(f"[{x}, {y}]" for x, y in init_traps) + "]",
        "hypotheses = [" + ", ".join(q(h) for h in hyp_list) + "]",
        f"initial_hypothesis = {h0}",
        "",
        "[inference]",
        f"window = {window}",
        f"threshold = {threshold!r}",
        f"rationality = {rationality!r}",
        "",
    ]
    return "\n".join(lines)


def random_world(seed: int) -> str:
    """TOML text of one small valid random world."""
    return make_world(seed, compact=True)


# The family: (name, seed, parameters).  Seeds were chosen (with tests/reference.py) so
# that most worlds have a deceptive value strictly between 0 and 1 and several allow more
# than one hypothesis change; every world stays well below 30,000 canonical states.
FAMILY = [
    ('fam00_d0_l1_w1_x2', 1000, {'delay': 0, 'traps': 1, 'window': 1, 'nhyp': 2}),
    ('fam01_d1_l1_w1_x3', 2000, {'delay': 1, 'traps': 1, 'window': 1, 'nhyp': 3}),
    ('fam02_d2_l1_w1_x4', 3001, {'delay': 2, 'traps': 1, 'window': 1, 'nhyp': 4}),
    ('fam03_d0_l1_w2_x1', 4000, {'delay': 0, 'traps': 1, 'window': 2, 'nhyp': 1}),
    ('fam04_d1_l1_w2_x2', 5000, {'delay': 1, 'traps': 1, 'window': 2, 'nhyp': 2}),
    ('fam05_d2_l1_w2_x3', 6002, {'delay': 2, 'traps': 1, 'window': 2, 'nhyp': 3, 'slip': 0.0}),
    ('fam06_d0_l1_w3_x2', 7000, {'delay': 0, 'traps': 1, 'window': 3, 'nhyp': 2}),
    ('fam07_d1_l1_w3_x4', 8000, {'delay': 1, 'traps': 1, 'window': 3, 'nhyp': 4}),
    ('fam08_d2_l1_w3_x3', 9004, {'delay': 2, 'traps': 1, 'window': 3, 'nhyp': 3}),
    ('fam09_d0_l2_w1_x3', 10023, {'delay': 0, 'traps': 2, 'window': 1, 'nhyp': 3}),
    ('fam10_d1_l2_w1_x2', 11002, {'delay': 1, 'traps': 2, 'window': 1, 'nhyp': 2}),
    ('fam11_d2_l2_w1_x1', 12000, {'delay': 2, 'traps': 2, 'window': 1, 'nhyp': 1, 'slip': 0.0}),
    ('fam12_d0_l2_w2_x4', 13001, {'delay': 0, 'traps': 2, 'window': 2, 'nhyp': 4}),
    ('fam13_d1_l2_w2_x2', 14003, {'delay': 1, 'traps': 2, 'window': 2, 'nhyp': 2}),
    ('fam14_d2_l2_w2_x3', 15007, {'delay': 2, 'traps': 2, 'window': 2, 'nhyp': 3}),
    ('fam15_d0_l2_w3_x2', 16002, {'delay': 0, 'traps': 2, 'window': 3, 'nhyp': 2}),
    ('fam16_d1_l2_w3_x3', 17001, {'delay': 1, 'traps': 2, 'window': 3, 'nhyp': 3}),
    ('fam17_d2_l2_w3_x4', 18001, {'delay': 2, 'traps': 2, 'window': 3, 'nhyp': 4, 'slip': 0.0}),
    ('fam18_d0_l1_w1_x3', 19005, {'delay': 0, 'traps': 1, 'window': 1, 'nhyp': 3}),
    ('fam19_d1_l1_w1_x2', 20009, {'delay': 1, 'traps': 1, 'window': 1, 'nhyp': 2}),
    ('fam20_d2_l1_w1_x3', 21010, {'delay': 2, 'traps': 1, 'window': 1, 'nhyp': 3}),
    ('fam21_d0_l1_w2_x4', 22012, {'delay': 0, 'traps': 1, 'window': 2, 'nhyp': 4}),
    ('fam22_d1_l1_w2_x3', 23006, {'delay': 1, 'traps': 1, 'window': 2, 'nhyp': 3}),
    ('fam23_d2_l1_w2_x2', 24001, {'delay': 2, 'traps': 1, 'window': 2, 'nhyp': 2}),
    ('fam24_d0_l1_w3_x3', 25000, {'delay': 0, 'traps': 1, 'window': 3, 'nhyp': 3, 'slip': 0.0}),
    ('fam25_d1_l1_w3_x2', 26001, {'delay': 1, 'traps': 1, 'window': 3, 'nhyp': 2}),
    ('fam26_d2_l1_w3_x2', 27008, {'delay': 2, 'traps': 1, 'window': 3, 'nhyp': 2}),
    ('fam27_d0_l2_w1_x2', 28000, {'delay': 0, 'traps': 2, 'window': 1, 'nhyp': 2}),
    ('fam28_d1_l2_w1_x4', 29001, {'delay': 1, 'traps': 2, 'window': 1, 'nhyp': 4}),
    ('fam29_d2_l2_w1_x3', 30010, {'delay': 2, 'traps': 2, 'window': 1, 'nhyp': 3}),
    ('fam30_d0_l2_w2_x2', 31005, {'delay': 0, 'traps': 2, 'window': 2, 'nhyp': 2}),
    ('fam31_d1_l2_w2_x3', 32010, {'delay': 1, 'traps': 2, 'window': 2, 'nhyp': 3, 'slip': 0.0}),
    ('fam32_d2_l2_w2_x2', 33017, {'delay': 2, 'traps': 2, 'window': 2, 'nhyp': 2}),
    ('fam33_d0_l2_w3_x3', 34011, {'delay': 0, 'traps': 2, 'window': 3, 'nhyp': 3}),
    ('fam34_d1_l2_w3_x2', 35007, {'delay': 1, 'traps': 2, 'window': 3, 'nhyp': 2}),
    ('fam35_d2_l2_w3_x2', 36014, {'delay': 2, 'traps': 2, 'window': 3, 'nhyp': 2}),
    ('fam36_eq_d0_w2', 37001, {'delay': 0, 'traps': 1, 'window': 2, 'slip': 0.1, 'task': '!obs U A', 'hyps': ['!obs U A']}),
    ('fam37_eq_d1_w1', 38003, {'delay': 1, 'traps': 1, 'window': 1, 'slip': 0.1, 'task': '!obs U A', 'hyps': ['!obs U A']}),
    ('fam38_eq_d2_w2', 39001, {'delay': 2, 'traps': 1, 'window': 2, 'slip': 0.05, 'task': '!obs U A', 'hyps': ['!obs U A']}),
    ('fam39_eq_d0_w3', 40004, {'delay': 0, 'traps': 1, 'window': 3, 'slip': 0.2, 'task': '!obs U A', 'hyps': ['!obs U A']}),
    ('fam40_tx_d0_l1_w2', 41005, {'delay': 0, 'traps': 1, 'window': 2, 'task': '!obs U A', 'hyps': ['!obs U A', '!obs U B', 'F C']}),
    ('fam41_tx_d1_l1_w2', 42000, {'delay': 1, 'traps': 1, 'window': 2, 'task': '!obs U A', 'hyps': ['!obs U A', '!obs U B', 'F C']}),
    ('fam42_tx_d0_l2_w3', 43003, {'delay': 0, 'traps': 2, 'window': 3, 'task': '!obs U A', 'hyps': ['!obs U A', '!obs U B', 'F C']}),
    ('fam43_tx_d0_l1_w3', 44002, {'delay': 0, 'traps': 1, 'window': 3, 'task': '!obs U A', 'hyps': ['!obs U A', '!obs U B', 'F C']}),
    ('fam44_big_d0_l1_w3_x3', 45004, {'delay': 0, 'traps': 1, 'window': 3, 'nhyp': 3, 'size': (5, 5)}),
    ('fam45_big_d1_l1_w3_x3', 46000, {'delay': 1, 'traps': 1, 'window': 3, 'nhyp': 3, 'size': (4, 4)}),
    # delay 3 (seeds picked for a value strictly between V_lead and 1)
    ('fam46_d3_l1_w1_x3', 47005, {'delay': 3, 'traps': 1, 'window': 1, 'nhyp': 3}),
    ('fam47_d3_l2_w1_x2', 48020, {'delay': 3, 'traps': 2, 'window': 1, 'nhyp': 2}),
    ('fam48_d3_l1_w2_x2', 49001, {'delay': 3, 'traps': 1, 'window': 2, 'nhyp': 2}),
    ('fam49_d3_l1_w3_x2', 51007, {'delay': 3, 'traps': 1, 'window': 3, 'nhyp': 2}),
]


def world_family() -> list[tuple[str, str]]:
    """[(name, toml_text)], deterministic."""
    return [(name, make_world(seed, name=name, **params)) for name, seed, params in FAMILY]
