"""Seeded random *arena* worlds (docs/semantics.md §15) that are not grids, for the tests.

``arena_world(seed)`` gives the TOML text of one small valid arena world; ``arena_worlds(n, seed)``
a deterministic list of n of them mixing the kinds (general P2 actions with p2-dependent
transitions or traps, delay 0-2, the CUSUM and the Bayesian observer); ``write_arena_worlds``
writes them to a folder. Every parameter of ``arena_world`` left as None is drawn from
``random.Random(seed)``.

A world: 4-12 states with identifier names (some of them PRISM keywords), 1-4 P1 actions per
state with 1-3 outcomes each (probabilities multiples of 1/20), one to three terminal states (no
transition entry) and sometimes an absorbing one (its only action loops), labels over 2-3
propositions (some states carry two; at least one state carries none), 2-3 hypotheses and a
co-safe task over the propositions. The transition entries are listed in a shuffled order, so
P1's action order at a state (the order of first appearance) is not alphabetical. The initial
state always has an action and is never a trap candidate. Like tests/worldgen.py this imports
nothing from hg2prism; tests/reference.py's ``parse_arena`` checks what it writes.
"""

from __future__ import annotations

import random
from pathlib import Path

import spot

# State names: identifiers, a few of them PRISM keywords or one letter (the package must prefix
# them); never "trapped" and never a proposition.
STATE_NAMES = ["lobby", "hall", "vault", "dock", "lab", "yard", "gate", "roof", "cellar",
               "attic", "tower", "bridge", "den", "camp", "s1", "s_2", "init", "module", "label",
               "formula", "min", "max", "C", "E", "x", "rate", "const", "endmodule"]
# Propositions: identifiers Spot reads as atomic propositions (never F G M R U V W X, true,
# false), some of them PRISM keywords.
PROPOSITIONS = ["crown", "gold", "alarm", "key", "data", "obs", "A", "B", "P", "S", "I"]
P1_ACTIONS = ["go", "sneak", "wait", "hop", "left", "right", "up", "down", "push", "climb",
              "N", "E", "S", "W", "module"]
P2_ACTIONS = ["idle", "watch", "scan", "guard", "patrol", "block", "label", "P"]

# co-safe templates over placeholders {a}, {b}, {c} (the number of distinct ones needed)
TASKS = [
    ("F {a}", 1),
    ("!{b} U {a}", 2),
    ("F ({a} & F {b})", 2),
    ("F {a} & F {b}", 2),
    ("F ({a} & {b})", 2),
    ("!{c} U ({a} | {b})", 3),
    ("(!{b} U {a}) & F {c}", 3),
    ("X F {a}", 1),
    ("{a} | X (!{b} U {a})", 2),
]
HYPOTHESES = [
    ("F {a}", 1),
    ("!{b} U {a}", 2),
    ("F ({a} & F {b})", 2),
    ("F ({a} & {b})", 2),
    ("F {a} | F {b}", 2),
]


def _fmt(template: str, props: list[str]) -> str:
    return template.format(**dict(zip("abc", props)))


def _probabilities(rng: random.Random, k: int) -> list[float]:
    """k positive multiples of 1/20 summing to 1."""
    cuts = sorted(rng.sample(range(1, 20), k - 1))
    parts = [b - a for a, b in zip([0] + cuts, cuts + [20])]
    return [p / 20 for p in parts]


def arena_world(seed: int, *, mode: str | None = None, delay: int | None = None,
                observer: str | None = None, n_states: int | None = None,
                window: int | None = None, name: str | None = None) -> str:
    """One valid arena world (TOML text). ``mode``: "general" or "traps"; ``observer``:
    "cusum", "bayes" (decision "map") or "sample" (Bayesian, decision "sample")."""
    rng = random.Random(seed)
    mode = mode or rng.choice(["general", "traps"])
    delay = rng.choice([0, 0, 1, 2]) if delay is None else delay
    observer = observer or rng.choice(["cusum", "cusum", "bayes", "sample"])
    window = rng.choice([1, 2, 2, 3]) if window is None else window
    n_hyp = rng.choice([2, 2, 3])
    traps = 1 if mode == "general" else rng.choice([1, 1, 1, 2])
    # keep the hypergame small: it grows with the window, the delay, the traps and |X|
    budget = (window - 1) + delay + (traps - 1) + (n_hyp - 2) + (observer == "sample")
    if n_states is None:
        n_states = rng.randint(4, 12 if budget <= 1 else 8 if budget <= 3 else 6)

    states = rng.sample(STATE_NAMES, n_states)
    initial = states[0]
    props = rng.sample(PROPOSITIONS, rng.choice([2, 2, 3]))

    # labels: none, one proposition or (sometimes) two; one state (`blank`) carries none, and
    # every proposition holds somewhere unless `propositions` is written and leaves one out
    explicit = rng.random() < 0.5
    nowhere = props[-1] if explicit and len(props) == 3 and rng.random() < 0.4 else None
    present = [p for p in props if p != nowhere]
    blank = initial if rng.random() < 0.75 else rng.choice(states)
    labels: dict[str, list[str]] = {}
    for s in states:
        r = rng.random()
        if s != blank and r >= 0.35:
            labels[s] = rng.sample(present, 2 if r > 0.85 and len(present) > 1 else 1)
    for p in present:
        if not any(p in lab for lab in labels.values()):
            room = [s for s in states if s != blank and len(labels.get(s, [])) < 2]
            if room:
                s = rng.choice(room)
                labels[s] = labels.get(s, []) + [p]
            else:   # every other state carries two propositions, each also held elsewhere
                labels[rng.choice([s for s in states if s != blank])] = [p]
    labels = {s: sorted(lab, key=props.index) for s, lab in labels.items()}

    # terminal and absorbing states (never the initial one)
    others = states[1:]
    rng.shuffle(others)
    n_terminal = rng.choice([1, 1, 2, 3]) if n_states >= 6 else 1
    terminal = set(others[:n_terminal])
    absorbing = {others[n_terminal]} if n_states >= 6 and rng.random() < 0.4 else set()
    active = [s for s in states if s not in terminal]

    # P1's actions and their outcomes; then every state made reachable where possible
    acts: dict[str, dict[str, list[str]]] = {}
    for s in active:
        if s in absorbing:
            acts[s] = {rng.choice(P1_ACTIONS): [s]}
            continue
        acts[s] = {a: rng.sample(states, rng.choice([1, 1, 2, 2, 3]))
                   for a in rng.sample(P1_ACTIONS, rng.choice([1, 2, 2, 3, 3, 4]))}
    order = [initial] + [s for s in states if s != initial]
    for i, s in enumerate(order[1:], 1):
        hosts = [t for t in order[:i] if t in acts and t not in absorbing
                 and _reachable(initial, acts, t)]
        if not hosts or _reachable(initial, acts, s):
            continue
        host = rng.choice(hosts)
        slots = [a for a, out in acts[host].items() if len(out) < 3 and s not in out]
        if slots:
            acts[host][rng.choice(slots)].append(s)
        elif len(acts[host]) < 4:
            acts[host][rng.choice([a for a in P1_ACTIONS if a not in acts[host]])] = [s]

    # P2's actions
    adversary = []
    entries = []
    if mode == "general":
        a2 = rng.sample(P2_ACTIONS, rng.choice([2, 2, 3]))
        adversary.append("actions = [" + ", ".join(f'"{b}"' for b in a2) + "]")
        if delay > 0:
            adversary.append(f'initial_action = "{rng.choice(a2)}"')
    else:
        # candidates: preferably labelled states and the states leading to them
        near = {s for s in states[1:] if s in labels} | {
            s for s in acts if s != initial and any(t in labels for out in acts[s].values()
                                                    for t in out)}
        pool = sorted(near, key=states.index) if len(near) >= 2 else states[1:]
        candidates = rng.sample(pool, min(len(pool), rng.randint(2, 4)))
        traps = min(traps, len(candidates))
        adversary.append(f"traps = {traps}")
        adversary.append("trap_candidates = [" + ", ".join(f'"{c}"' for c in candidates) + "]")
        if delay > 0:
            init = rng.sample(candidates, traps)
            adversary.append("initial_traps = [" + ", ".join(f'"{c}"' for c in init) + "]")
    adversary.append(f"delay = {delay}")

    for s in active:
        for a, out in acts[s].items():
            dist = dict(zip(out, _probabilities(rng, len(out))))
            if mode == "general" and s not in absorbing and rng.random() < 0.5:
                # p2-dependent: some P2 actions get their own outcomes (one entry naming
                # them, a name or a list, or one entry each); sometimes all of them, then there
                # is no entry without p2 and the first entry keeps the outcomes drawn above
                named = rng.sample(a2, rng.randint(1, len(a2)))
                everyone = len(named) == len(a2)
                if everyone:
                    cut = rng.randint(1, len(named) - 1)
                    groups = [named[:cut], named[cut:]]
                else:
                    groups = [named] if rng.random() < 0.5 else [[b] for b in named]
                for k, group in enumerate(groups):
                    p2 = f'"{group[0]}"' if len(group) == 1 and rng.random() < 0.6 else \
                        "[" + ", ".join(f'"{b}"' for b in group) + "]"
                    if everyone and k == 0:
                        alt = dist
                    elif rng.random() < 0.6:    # P2 blocks the move: P1 stays, or worse
                        out = list(dict.fromkeys(
                            [s] + rng.sample(sorted(terminal - set(labels)) or [s], 1)))
                        alt = dict(zip(out, _probabilities(rng, len(out))))
                    else:
                        out = rng.sample(states, rng.choice([1, 2, 3]))
                        alt = dict(zip(out, _probabilities(rng, len(out))))
                    entries.append((s, a, p2, alt))
                if not everyone:
                    entries.append((s, a, None, dist))
            else:
                entries.append((s, a, None, dist))
    rng.shuffle(entries)

    # task and hypotheses over the propositions that hold somewhere
    used = [p for p in props if any(p in lab for lab in labels.values())]
    task = _fmt(*_template(rng, TASKS, used, labels))
    hyps: list[str] = []
    for _ in range(100):
        if len(hyps) == n_hyp:
            break
        h = _fmt(*_template(rng, HYPOTHESES, used, labels))
        # distinct languages, as the world file asks ("F (a & b)" and "F (b & a)" are one)
        if not any(spot.are_equivalent(h, other) for other in hyps):
            hyps.append(h)
    if nowhere and rng.random() < 0.5:
        hyps[-1] = f"F {nowhere}"               # a hypothesis nothing can satisfy
    if len(set(hyps)) != len(hyps):
        hyps = list(dict.fromkeys(hyps))

    # observer
    inference = [f"window = {window}", f"rationality = {round(rng.uniform(1.0, 10.0), 1)!r}"]
    if observer == "cusum":
        inference.append(f"threshold = {round(rng.uniform(0.3, 3.0), 2)!r}")
        adversary.append(f"initial_hypothesis = {rng.randrange(len(hyps))}")
    else:
        inference.insert(0, 'kind = "bayes"')
        inference.append(f'decision = "{"sample" if observer == "sample" else "map"}"')
        if rng.random() < 0.5:
            inference.append("prior = [" + ", ".join(
                str(rng.choice([1, 1, 2, 3])) for _ in hyps) + "]")

    lines = [f'name = "{name or f"arena{seed}"}"',
             f'description = "generated by tests/arenagen.py (seed {seed})"', "", "[arena]",
             "states = [" + ", ".join(f'"{s}"' for s in states) + "]",
             f'initial = "{initial}"']
    if explicit:
        lines.append("propositions = [" + ", ".join(f'"{p}"' for p in props) + "]")
    lines.append("")
    if labels:
        lines.append("[arena.labels]")
        lines += [f"{s} = [" + ", ".join(f'"{p}"' for p in labels[s]) + "]"
                  for s in states if s in labels]
        lines.append("")
    for s, a, p2, dist in entries:
        lines += ["[[arena.transition]]", f'state = "{s}"', f'action = "{a}"']
        if p2 is not None:
            lines.append(f"p2 = {p2}")
        lines += ["to = { " + ", ".join(f"{t} = {p!r}" for t, p in dist.items()) + " }", ""]
    lines += ["[task]", f'formula = "{task}"', "", "[adversary]", *adversary,
              "hypotheses = [" + ", ".join(f'"{h}"' for h in hyps) + "]", "",
              "[inference]", *inference, ""]
    return "\n".join(lines)


def _template(rng: random.Random, templates, used: list[str], labels) -> tuple[str, list[str]]:
    """A template that needs at most len(used) propositions, and the propositions filled in
    (for "F ({a} & {b})" preferably two that some state carries together)."""
    tpl, k = rng.choice([t for t in templates if t[1] <= len(used)])
    if "{a} & {b})" in tpl:
        pairs = [lab for lab in labels.values() if len(lab) == 2 and set(lab) <= set(used)]
        if pairs and rng.random() < 0.8:
            return tpl, rng.sample(rng.choice(pairs), 2)
    return tpl, rng.sample(used, k)


def _reachable(initial: str, acts: dict, target: str) -> bool:
    seen, stack = {initial}, [initial]
    while stack:
        s = stack.pop()
        for out in acts.get(s, {}).values():
            for t in out:
                if t not in seen:
                    seen.add(t)
                    stack.append(t)
    return target in seen


def arena_worlds(n: int, seed: int = 0) -> list[str]:
    """n arena worlds (TOML texts), deterministic in `seed`, cycling through the kinds:
    general / traps x CUSUM / Bayesian ("map", and "sample" every fourth Bayesian world), the
    delays 0, 1, 2 and the windows 1, 2, 3 in turn."""
    worlds = []
    for i in range(n):
        s = seed * 100_003 + i
        mode = ("general", "traps")[i % 2]
        observer = ("cusum", "bayes", "cusum", "sample" if i % 8 == 7 else "bayes")[(i // 2) % 4]
        worlds.append(arena_world(s, mode=mode, observer=observer, delay=(i // 3) % 3,
                                  window=1 + (i // 5) % 3, name=f"arena{seed}_{i}"))
    return worlds


def write_arena_worlds(n: int, seed: int, folder) -> list[Path]:
    """arena_worlds(n, seed) written to folder/arena<seed>_<i>.toml; the paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, text in enumerate(arena_worlds(n, seed)):
        path = folder / f"arena{seed}_{i}.toml"
        path.write_text(text)
        paths.append(path)
    return paths
