"""Scaling benchmark (`hg2prism bench`, `make bench`): a family of generated worlds of growing
size, each run through every stage of `hg2prism check` in its own process, with the time of each
stage, Storm's sizes and the peak memory. Writes OUT/results.csv and OUT/scaling.{png,svg}.

The worlds share one 12 x 12 core — the regions A-E, eight trap candidates next to them and a
few walls and obstacles, fixed — in the top right corner of a side x side field of open cells
with scattered walls and obstacles; the robot starts in the opposite corner. The core is where
the game is decided, so the values do not depend on the field: with one trap, deceptive value
0.7103 for window 3 at every side (0.64-0.70 for windows 1-2) against v_lead 0 — knowing the
task P2 would catch P1 for sure, and her inference switches between the hypotheses A, B and C
— and 0 with two traps. The field makes the hypergame grow: its canonical size is about
(free cells) x (hypotheses P2 adopts) x (windows of P1's last moves), up to about 1e6 states.
A few 12 x 12 worlds add delay (traps starting on the first candidates): 0.9 against v_lead 0.64
with one trap and delay 1 or 2, 0.576 against 0 with two traps and delay 1.

Two arena rows (docs/semantics.md §15) follow: the largest window-3 grid world of about 1e6
canonical states in its arena form (the file `hg2prism convert` writes), measured right after its
grid row, the summary giving the ratio of time per canonical state (arena form / grid); and a
seeded random attack-graph-like arena (`random_arena_world`) of about 1e6 canonical states.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import random
import resource
import signal
import sys
import time
import traceback
from pathlib import Path

from hg2prism.frontends.grid_worlds import bench_world, world_name

STAGES = ("games", "generate", "parse", "build", "check", "export")

# (side, window, hypotheses, traps): small worlds with windows 1 and 2, varied hypotheses and
# traps, then window 3 with a growing field up to about 1e6 canonical states.
DEFAULT_SIZES: tuple[tuple[int, ...], ...] = (
    (12, 1, 3, 1),
    (24, 1, 5, 1),
    (12, 2, 2, 1),
    (12, 2, 3, 2),
    (12, 2, 3, 1),
    (20, 2, 4, 1),
    (32, 2, 3, 1),
    (12, 3, 3, 1),
    (12, 3, 5, 2),
    (16, 3, 3, 1),
    (20, 3, 4, 1),
    (24, 3, 3, 1),
    (28, 3, 3, 1),
    (31, 3, 3, 1),
    (64, 3, 3, 1),      # 4.2 million canonical states, about 10 GB at peak
    # delay (the fifth number): one trap with delay 1 to 3 (deceptive value 0.9 against v_lead
    # 0.64), two traps with delay 1 and 2 (0.576 against 0; without delay two traps give 0), and
    # window 3 with delay 1 and 2 (0.9), to compare with the delay-0 worlds of the same grid
    (12, 1, 3, 1, 1),
    (12, 1, 3, 1, 2),
    (12, 1, 3, 1, 3),
    (12, 2, 3, 2, 1),
    (12, 2, 3, 2, 2),
    (12, 3, 3, 1, 1),
    (12, 3, 3, 1, 2),
)

# Grid sizes whose arena form is measured right after the grid row, and the random arenas
# (number of non-target states) measured after the grids.
DEFAULT_ARENA_FORMS: tuple[tuple[int, ...], ...] = ((31, 3, 3, 1),)
DEFAULT_RANDOM_ARENAS: tuple[int, ...] = (16000,)    # about 1e6 canonical states
QUICK_ARENA_FORMS: tuple[tuple[int, ...], ...] = ((12, 3, 3, 1),)
QUICK_RANDOM_ARENAS: tuple[int, ...] = (1000,)
# Bayesian worlds (docs/semantics.md §12) on the map of a CUSUM grid world of the list above,
# (side, window, hypotheses, traps, decision): window 3 on the 16 x 16 map holds about 1.1e6
# canonical states (the Bayesian window keeps w observations, CUSUM's w - 1), measured after
# the grids; the summary compares their time per canonical state with the CUSUM world of the
# same side (s16 w3: 265k states).
DEFAULT_BAYES: tuple[tuple, ...] = ((16, 3, 3, 1, "map"), (16, 3, 3, 1, "sample"))
QUICK_BAYES: tuple[tuple, ...] = ((12, 2, 3, 1, "map"), (12, 2, 3, 1, "sample"))
# `make bench-huge` (`hg2prism bench --huge`): one grid world of about 1e7 canonical states,
# alone (about 14 GB at peak and ten minutes on this machine)
HUGE_SIZES: tuple[tuple[int, ...], ...] = ((100, 3, 3, 1),)
HUGE_TIMEOUT = 3600

SLOPE_RANGE = (1e4, math.inf)     # from 1e4 states to the largest world, delay 0 (below)
WORLD_TIMEOUT = 900          # seconds one world may take before it is abandoned

COLUMNS = ("name", "form", "inference", "side", "window", "hypotheses", "traps", "delay", "storm_method",
           "cells", "estimate",
           "states",
           "transitions", "storm_states", "storm_transitions", "storm_choices",
           "deceptive_value", "v_lead") + tuple(f"time_{s}" for s in STAGES) + (
           "time_write", "time_total", "time_python", "peak_mb", "error")


RANDOM_TARGETS = ("asset_a", "asset_b", "asset_c")
RANDOM_WIDTH = 40      # states per layer of the random arena
RANDOM_CANDIDATES = 12   # trap candidates, evenly spread (P2's actions: one per candidate)


def random_arena_name(states: int, seed: int = 0) -> str:
    return f"arena_random_n{states}" + (f"_seed{seed}" if seed else "")


def _random_transitions(states: int, rng: random.Random) -> list[str]:
    """[[arena.transition]] entries: at state i (layer i // RANDOM_WIDTH) 1-4 exploits, each
    succeeding with probability 0.3-0.95 towards a state of the previous, same or next layer
    (beyond layer 2 one in 20 towards a target), failing back to i."""
    entries = []
    for i in range(states):
        layer = i // RANDOM_WIDTH
        for a in range(rng.randint(1, 4)):
            if layer > 2 and rng.random() < 0.05:
                succ = "t_" + rng.choice(RANDOM_TARGETS)
            else:
                top = min(states, (layer + 2) * RANDOM_WIDTH)
                succ = f"s{rng.randrange(max(0, i - RANDOM_WIDTH), top)}"
            p = round(rng.uniform(0.3, 0.95), 3)
            to = (f"{{ s{i} = 1.0 }}" if succ == f"s{i}"
                  else f"{{ {succ} = {p!r}, s{i} = {round(1 - p, 3)!r} }}")
            entries.append(f'[[arena.transition]]\nstate = "s{i}"\naction = "x{a}"\nto = {to}\n')
    return entries


def random_arena_world(states: int, seed: int = 0, window: int = 3, traps: int = 1) -> str:
    """TOML text of a seeded random attack-graph-like arena world: states s0 .. s{n-1} in
    layers of RANDOM_WIDTH (s0 the initial state), three absorbing targets t_asset_a/b/c
    labelled with their proposition, P1's exploits as `_random_transitions`, one trap (P2's
    honeypot) among RANDOM_CANDIDATES states spread evenly, P1's task F asset_a, P2's
    hypotheses F asset_a/b/c, CUSUM observer with the given window. About 65 canonical states
    per arena state with window 3 (16,000 states: about 1e6). Few trap candidates on purpose:
    the perceptual games are solved per trap set, so their time grows with states x candidates."""
    rng = random.Random(seed)
    names = [f"s{i}" for i in range(states)] + [f"t_{t}" for t in RANDOM_TARGETS]
    quoted = ", ".join(f'"{n}"' for n in names)
    labels = "\n".join(f't_{t} = ["{t}"]' for t in RANDOM_TARGETS)
    candidates = ", ".join(f'"s{1 + k * (states // RANDOM_CANDIDATES)}"'
                           for k in range(RANDOM_CANDIDATES))
    hyps = ", ".join(f'"F {t}"' for t in RANDOM_TARGETS)
    props = ", ".join(f'"{t}"' for t in RANDOM_TARGETS)
    transitions = "\n".join(_random_transitions(states, rng))
    return f'''name = "{random_arena_name(states, seed)}"
description = "benchmark arena: random layered attack graph, {states} states, seed {seed}"

[arena]
states = [{quoted}]
initial = "s0"
propositions = [{props}]

[arena.labels]
{labels}

{transitions}
[task]
formula = "F {RANDOM_TARGETS[0]}"

[adversary]
traps = {traps}
trap_candidates = [{candidates}]
hypotheses = [{hyps}]

[inference]
kind = "cusum"
window = {window}
threshold = 1.5
rationality = 5.0
'''


def bayes_name(side: int, window: int, hypotheses: int, traps: int, decision: str) -> str:
    return f"{world_name(side, window, hypotheses, traps)}_bayes_{decision}"


def bayes_world(side: int, window: int, hypotheses: int, traps: int, decision: str) -> str:
    """The benchmark grid world of these parameters (`bench_world`, the same map) with P2's
    Bayesian observer instead of CUSUM: window `window`, rationality 5 as the CUSUM worlds'
    softmax, uniform prior, decision "map" or "sample"."""
    text = bench_world(side, window, hypotheses, traps)
    head, found, _ = text.partition("[inference]\n")     # the last table of the file
    if not found:
        raise ValueError("bench_world wrote no [inference] table")
    name = world_name(side, window, hypotheses, traps)
    renamed = bayes_name(side, window, hypotheses, traps, decision)
    return (head.replace(f'name = "{name}"', f'name = "{renamed}"', 1) + f'[inference]\nkind = "bayes"\nwindow = {window}\nrationality = 5.0\n'
            f'decision = "{decision}"\n')


def _write_arena_form(grid_path: str, arena_path: str) -> None:
    from hg2prism.frontends.arena import to_toml
    from hg2prism.outputs import write_text
    from hg2prism.worldfile import load_world

    write_text(Path(arena_path), to_toml(load_world(Path(grid_path))))


def write_arena_form(grid_path: Path, arena_path: Path) -> None:
    """`hg2prism convert grid_path --out arena_path`, in a forked child (keeps this process
    free of the pipeline's imports, so that every world's peak memory is its own)."""
    process = multiprocessing.get_context("fork").Process(
        target=_write_arena_form, args=(str(grid_path), str(arena_path)))
    process.start()
    process.join()
    if process.exitcode != 0:
        raise RuntimeError(f"converting {grid_path} failed (exit code {process.exitcode})")


# ---------------------------------------------------------------------------------------------
# one world, in its own process
# ---------------------------------------------------------------------------------------------

def _measure(world_path: Path, out: Path, storm_method: str = "sound") -> dict:
    """Runs `pipeline.check` on one world (in the calling process) and returns its row."""
    from hg2prism import pipeline
    from hg2prism.model import sizeguard
    from hg2prism.worldfile import load_world
    from hg2prism.results import TIMING_DIGITS

    world = load_world(world_path)
    estimate = sizeguard.estimate_states(world)
    start = time.perf_counter()
    result = pipeline.check(world, out, storm_method)
    total = time.perf_counter() - start
    res = result.results
    row = {
        "cells": result.analysis.ts.n_places,
        "estimate": estimate,
        "states": res.states, "transitions": res.transitions,
        "storm_states": res.storm_states, "storm_transitions": res.storm_transitions,
        "storm_choices": res.storm_choices,
        "deceptive_value": res.deceptive_value, "v_lead": res.v_lead,
        "time_total": total,
    }
    for stage in STAGES:    # as results.json has them, rounded to 0.1 ms
        row[f"time_{stage}"] = round(float(res.timings.get(stage, 0.0)), TIMING_DIGITS)
    # Whatever check() spends outside its timed stages (writing the JSON outputs).
    row["time_write"] = max(0.0, total - sum(row[f"time_{s}"] for s in STAGES))
    row["time_python"] = sum(row[f"time_{s}"] for s in ("games", "generate", "export", "write"))
    row["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return row


def _child(world_path: str, out: str, storm_method: str, connection, quiet: bool) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_DFL)   # the parent's handler is not for a world
    from hg2prism import memory

    memory.release_large_arrays()
    try:
        if quiet:
            devnull = open(os.devnull, "w")
            os.dup2(devnull.fileno(), 2)
            sys.stderr = devnull
        connection.send(("ok", _measure(Path(world_path), Path(out), storm_method)))
    except BaseException as err:  # reported in the row, the benchmark goes on
        connection.send(("error", f"{type(err).__name__}: {err}\n{traceback.format_exc()}"))
    finally:
        connection.close()


def measure_world(world_path: Path, out: Path, storm_method: str = "sound",
                  timeout: float = WORLD_TIMEOUT, quiet: bool = True) -> dict:
    """`_measure` in a forked child process, so that the peak memory is this world's alone."""
    context = multiprocessing.get_context("fork")
    receive, send = context.Pipe(duplex=False)
    process = context.Process(target=_child,
                              args=(str(world_path), str(out), storm_method, send, quiet))
    process.start()
    send.close()
    status, payload = "error", f"no result within {timeout:.0f} s"
    try:
        if receive.poll(timeout):
            try:
                status, payload = receive.recv()
            except EOFError:
                status, payload = "error", "the process ended without a result (out of memory?)"
        process.join(5)
    finally:   # also when the benchmark itself is interrupted: never leave a world running
        if process.is_alive():
            process.kill()
            process.join()
    if status == "error":
        return {"error": str(payload).strip().splitlines()[-1] if payload else "failed",
                "traceback": payload}
    return payload


# ---------------------------------------------------------------------------------------------
# the family
# ---------------------------------------------------------------------------------------------

def loglog_slope(rows: list[dict], low: float = SLOPE_RANGE[0], high: float = SLOPE_RANGE[1],
                 column: str = "time_total") -> float | None:
    """Least-squares slope of log(time) against log(states) over rows with low <= states <= high."""
    points = [(math.log(r["states"]), math.log(r[column])) for r in rows
              if not r.get("error") and low <= r["states"] <= high and r.get(column, 0) > 0]
    if len(points) < 2:
        return None
    mx = sum(x for x, _ in points) / len(points)
    my = sum(y for _, y in points) / len(points)
    sxx = sum((x - mx) ** 2 for x, _ in points)
    if sxx == 0:
        return None
    return sum((x - mx) * (y - my) for x, y in points) / sxx


def _line(row: dict) -> str:
    if row.get("error"):
        return f"{row['name']:<24} FAILED: {row['error']}"
    stages = " ".join(f"{s} {row[f'time_{s}']:6.2f}" for s in STAGES)
    return (f"{row['name']:<24} {row['states']:>9,} states (estimate {row['estimate']:>9,}) "
            f"value {row['deceptive_value']:.4f} | {stages} write {row['time_write']:6.2f} | "
            f"total {row['time_total']:7.2f} s, python {row['time_python']:6.2f} s, "
            f"peak {row['peak_mb']:6.0f} MB")


def _format(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.6g}" if abs(value) < 1e-3 or abs(value) >= 1e6 else f"{value:.4f}"
    return "" if value is None else str(value)


def write_csv(rows: list[dict], path: Path) -> None:
    from hg2prism import outputs

    outputs.write_csv(path, COLUMNS, ([_format(row.get(c)) for c in COLUMNS] for row in rows))


def grids(rows: list[dict]) -> list[dict]:
    """The grid worlds (rows without a form are grid rows)."""
    return [r for r in rows if r.get("form", "grid") == "grid"]


def undelayed(rows: list[dict]) -> list[dict]:
    """The grid worlds without delay: the growth curve (the delayed ones and the arenas are
    compared with them)."""
    return [r for r in grids(rows) if not r.get("delay")]


def arena_costs(rows: list[dict]) -> list[tuple[str, float, float, float]]:
    """Per arena-form row, (name, total time per canonical state against its grid row, the
    same for Storm's parse + build, the same for the Python stages)."""
    base = {r["name"]: r for r in grids(rows)}
    costs = []
    for row in rows:
        grid = base.get(row["name"].removesuffix("_arena"))
        if row.get("form") == "arena form" and grid is not None:
            def ratio(key) -> float:
                return (key(row) / row["states"]) / (key(grid) / grid["states"])
            costs.append((row["name"], ratio(lambda r: r["time_total"]),
                          ratio(lambda r: r["time_parse"] + r["time_build"]),
                          ratio(lambda r: r["time_python"])))
    return costs


def delay_costs(rows: list[dict]) -> list[tuple[str, float]]:
    """Per delayed world, Storm's parse + build time per Storm state against the same world
    (grid, window, hypotheses, traps) without delay."""
    base = {(r["side"], r["window"], r["hypotheses"], r["traps"]): r for r in undelayed(rows)}
    costs = []
    for row in grids(rows):
        same = base.get((row["side"], row["window"], row["hypotheses"], row["traps"]))
        if row.get("delay") and same is not None:
            def per_state(r: dict) -> float:
                return (r["time_parse"] + r["time_build"]) / r["storm_states"]
            costs.append((row["name"], per_state(row) / per_state(same)))
    return costs


# Issue 27's targets, which the summary checks (`target_table`, `missed_targets`).
GAMES_PER_BUILD = 0.5           # P2's games at most half of Storm's build, on every world
DELAY_PER_STATE = 1.5           # a delayed world's total per canonical state against its twin
PEAK_PER_STATE = 1600           # bytes of peak memory per canonical state, on the largest worlds
LARGEST = 1e6                   # "the largest worlds": this many canonical states or more
BAYES_STATES = 1e6              # the Bayesian worlds the benchmark must hold ...
BAYES_PER_STATE = 1.5           # ... within this of the CUSUM world of the same map, per state
HUGE_STATES = 1e7               # `make bench-huge`
FOUR_MILLION = (4e6, 150.0)     # the world of about 4.2e6 states in at most 150 s (idle machine;
                                # not the ten-million one of make bench-huge)


def cusum_twin(row: dict, rows: list[dict]) -> dict | None:
    """A Bayesian world's twin: the first CUSUM grid world of the same side (the same map)."""
    return next((r for r in rows if r.get("inference", "cusum") == "cusum"
                 and r.get("side") == row.get("side") and r.get("form") == "grid"), None)


def bayes_costs(rows: list[dict]) -> list[tuple[str, float]]:
    """Per Bayesian world, its total time per canonical state against its CUSUM twin's."""
    return [(r["name"], per_state(r) / per_state(cusum_twin(r, rows))) for r in rows
            if r.get("inference") == "bayes" and cusum_twin(r, rows) is not None]


def twin(row: dict, rows: list[dict]) -> dict | None:
    """A delayed grid world's twin: the grid world of the same side, window, hypotheses and
    traps without delay (None for an undelayed world or when the twin was not run)."""
    if not row.get("delay") or row.get("form", "grid") != "grid":
        return None
    key = (row["side"], row["window"], row["hypotheses"], row["traps"])
    return next((r for r in undelayed(rows)
                 if (r["side"], r["window"], r["hypotheses"], r["traps"]) == key), None)


def per_state(row: dict) -> float:
    """Total seconds per canonical state."""
    return row["time_total"] / row["states"]


def target_table(rows: list[dict]) -> list[str]:
    """One line per measured world: games / build, total per canonical state (and against
    the no-delay twin), peak memory per canonical state."""
    good = [r for r in rows if not r.get("error")]
    lines = [f"{'world':<32} {'states':>10} {'games/build':>11} {'us/state':>9} "
             f"{'vs no delay':>11} {'peak B/state':>12}"]
    for row in good:
        other = twin(row, good)
        games = row["time_games"] / row["time_build"] if row["time_build"] > 0 else math.inf
        against = f"{per_state(row) / per_state(other):.2f}x" if other else "-"
        lines.append(f"{row['name']:<32} {row['states']:>10,} {games:>11.2f} "
                     f"{per_state(row) * 1e6:>9.1f} {against:>11} "
                     f"{row['peak_mb'] * 2 ** 20 / row['states']:>12.0f}")
    return lines


def missed_targets(rows: list[dict], huge: list[dict] | None = None) -> list[str]:
    """Issue 27's targets that these rows miss, one line each (none: every target met);
    `huge`: the rows of `make bench-huge` (HUGE_RECORD), which count for the ten million."""
    good = [r for r in rows if not r.get("error")]
    missed = []
    slow_games = [f"{r['name']} ({r['time_games'] / max(r['time_build'], 1e-9):.1f}x)"
                  for r in good if r["time_games"] > GAMES_PER_BUILD * r["time_build"]]
    if slow_games:
        missed.append(f"games above {GAMES_PER_BUILD} x Storm's build: " + ", ".join(slow_games))
    costly = [f"{r['name']} ({per_state(r) / per_state(twin(r, good)):.1f}x)" for r in good
              if twin(r, good) and per_state(r) > DELAY_PER_STATE * per_state(twin(r, good))]
    if costly:
        missed.append(f"delay above {DELAY_PER_STATE}x the no-delay twin per state: "
                      + ", ".join(costly))
    largest = [r for r in good if r["states"] >= LARGEST]
    heavy = [f"{r['name']} ({r['peak_mb'] * 2 ** 20 / r['states']:.0f} B)" for r in largest
             if r["peak_mb"] * 2 ** 20 > PEAK_PER_STATE * r["states"]]
    if heavy:
        missed.append(f"peak above {PEAK_PER_STATE} bytes per state: " + ", ".join(heavy))
    bayes = [r for r in good if r.get("inference") == "bayes" and r["states"] >= BAYES_STATES]
    if not bayes:
        missed.append(f"no Bayesian world of {BAYES_STATES:.0e} states or more")
    for row in bayes:
        cusum = cusum_twin(row, good)
        if cusum and per_state(row) > BAYES_PER_STATE * per_state(cusum):
            missed.append(f"{row['name']}: {per_state(row) / per_state(cusum):.1f}x the CUSUM "
                          f"world's time per state (target {BAYES_PER_STATE}x)")
    if not any(r["states"] >= HUGE_STATES for r in good + [r for r in huge or []
                                                           if not r.get("error")]):
        missed.append(f"no world of {HUGE_STATES:.0e} states (make bench-huge)")
    big, limit = FOUR_MILLION
    missed += [f"{r['name']}: {r['time_total']:.0f} s (target {limit:.0f} s on an idle machine)"
               for r in good if big <= r["states"] < HUGE_STATES and r["time_total"] > limit]
    return missed


def bench_results(rows: list[dict], huge: list[dict] | None = None) -> dict:
    """results.json (docs/performance.md is rendered from it): every row, and the summary's
    numbers: the log-log slope of the total time (worlds without delay, SLOPE_RANGE), each
    stage's from 1e5 states, each delayed world's Storm cost per state against its twin
    without delay, each Bayesian world's time per state against its CUSUM twin's, the largest
    grid world, and the targets missed (`missed_targets`, with `huge`: make bench-huge's rows)."""
    good = [r for r in rows if not r.get("error")]
    plain = undelayed(good)
    top = max(grids(good) or good, key=lambda r: r["states"]) if good else None
    return {"rows": rows, "slope": loglog_slope(plain),
            "stage_slopes": {stage: loglog_slope(plain, 1e5, math.inf, f"time_{stage}")
                             for stage in STAGES + ("total",)},
            "delay_costs": dict(delay_costs(good)),
            "bayes_costs": dict(bayes_costs(good)),
            "largest": None if top is None else top["name"],
            "missed_targets": missed_targets(rows, huge)}


def summary(rows: list[dict], huge: list[dict] | None = None) -> str:
    """The closing lines: slope, the largest world, Python stages against Storm's build, the
    cost of delay."""
    good = [r for r in rows if not r.get("error")]
    lines = []
    slope = loglog_slope(undelayed(good))
    lo, _ = SLOPE_RANGE
    lines.append(f"log-log slope of total time against states (worlds without delay, {lo:.0e} "
                 "states to the largest): "
                 + ("n/a (fewer than two worlds in range)" if slope is None else f"{slope:.3f}"))
    stage_slopes = [(stage, loglog_slope(undelayed(good), 1e5, math.inf, f"time_{stage}"))
                    for stage in STAGES + ("total",)]
    if any(slope is not None for _, slope in stage_slopes):
        lines.append("log-log slope per stage from 1e+05 states: " + ", ".join(
            f"{stage} {slope:.2f}" for stage, slope in stage_slopes if slope is not None))
    costs = delay_costs(good)
    if costs:
        lines.append("Storm's parse + build per Storm state against the same world without "
                     "delay: " + ", ".join(f"{name} {ratio:.2f}x" for name, ratio in costs))
    for name, total, storm, python in arena_costs(good):
        lines.append(f"{name}: time per canonical state against the grid form: total "
                     f"{total:.2f}x (Storm's parse + build {storm:.2f}x, Python stages "
                     f"{python:.2f}x)")
    for name, ratio in bayes_costs(good):
        lines.append(f"{name}: total time per canonical state {ratio:.2f}x the CUSUM world of "
                     f"the same map (target {BAYES_PER_STATE}x)")
    for row in good:
        if row.get("form") == "random arena":
            lines.append(f"{row['name']}: {row['states']:,} states in {row['time_total']:.1f} s"
                         " "
                         f"({row['time_total'] / row['states'] * 1e6:.1f} us per state), peak "
                         f"memory {row['peak_mb']:.0f} MB")
    if good:
        top = max(grids(good) or good, key=lambda r: r["states"])
        lines.append(f"largest world {top['name']}: {top['states']:,} states end to end in "
                     f"{top['time_total']:.1f} s (build {top['time_build']:.1f} s, Python stages "
                     f"{top['time_python']:.1f} s), peak memory {top['peak_mb']:.0f} MB "
                     f"({top['peak_mb'] * 2 ** 20 / top['states']:.0f} bytes per state)")
        ranged = [r for r in good if r["states"] >= lo]
        slower = [r["name"] for r in ranged if r["time_python"] > r["time_build"]]
        lines.append(f"Python stages (games + generate + export + write) within Storm's build, "
                     f"worlds of {lo:.0e} states or more: "
                     + ("all" if not slower else "not for " + ", ".join(slower)))
        slow_checks = [r["name"] for r in good if r["time_check"] > r["time_build"]]
        lines.append("check within Storm's build: "
                     + ("all worlds" if not slow_checks else "not for " + ", ".join(slow_checks)))
        ratios = [r["estimate"] / r["states"] for r in good if r["states"]]
        lines.append(f"size estimate / canonical states: {min(ratios):.2f} .. {max(ratios):.2f}")
    failed = [r["name"] for r in rows if r.get("error")]
    if failed:
        lines.append("failed: " + ", ".join(failed))
    if good:
        lines += ["per world (issue 27's targets: games/build <= "
                  f"{GAMES_PER_BUILD}, delayed <= {DELAY_PER_STATE}x the no-delay twin per "
                  f"state, peak <= {PEAK_PER_STATE} B per state from {LARGEST:.0e} states):"]
        lines += ["  " + line for line in target_table(good)]
        missed = missed_targets(good, huge)
        lines.append("targets missed: " + ("none" if not missed else ""))
        lines += ["  MISSED " + line for line in missed]
    return "\n".join(lines)


def run_bench(out_dir: Path, sizes=DEFAULT_SIZES, show_progress: bool = True,
              keep_outputs: bool = False, storm_method: str = "sound",
              arena_forms=(), random_arenas=(), bayes=(), huge: list[dict] = (),
              timeout: float = WORLD_TIMEOUT) -> list[dict]:
    """Runs every world of `sizes` ((side, window, hypotheses, traps[, delay]) each) through
    `pipeline.check` in its own process; prints one line per world as it goes (stdout), then
    writes out_dir/results.csv, results.json (`bench_results`) and out_dir/scaling.{png,svg}
    and prints the summary.

    The world files stay in out_dir/worlds/; each world's outputs go to out_dir/runs/<name>/
    and, unless keep_outputs, its strategy.json (hundreds of MB for the largest) is removed.
    `storm_method` is check's --storm-method: "sound" (docs/semantics.md §10), "sound-ovi" or "fast".
    Each size of `sizes` also in `arena_forms` is measured a second time right after, in its
    arena form (`hg2prism convert`); then each `random_arenas` (numbers of states) as
    `random_arena_world`, then each of `bayes` ((side, window, hypotheses, traps, decision))
    as `bayes_world`. Only grid rows enter the slope and the figure. `huge`: the rows of
    `make bench-huge` (HUGE_RECORD), for the summary's ten-million-state target."""
    from hg2prism.outputs import write_json, write_text

    out_dir = Path(out_dir)
    rows: list[dict] = []
    if show_progress:
        count = len(sizes) + len(arena_forms) + len(random_arenas)
        print(f"hg2prism bench: {count} worlds, each in its own process "
              f"with Storm method {storm_method!r} (times in seconds; 'write' is check's JSON "
              f"output outside the timed stages)",
              flush=True)
    def run(world_path: Path, row: dict) -> None:
        run_dir = out_dir / "runs" / row["name"]
        row.update(storm_method=storm_method,
                   **measure_world(world_path, run_dir, storm_method, timeout))
        if not keep_outputs:
            (run_dir / "strategy.json").unlink(missing_ok=True)
        rows.append(row)
        if show_progress:
            print(_line(row), flush=True)

    for side, window, hypotheses, traps, *rest in sizes:
        delay = rest[0] if rest else 0
        name = world_name(side, window, hypotheses, traps, delay)
        world_path = out_dir / "worlds" / f"{name}.toml"
        write_text(world_path, bench_world(side, window, hypotheses, traps, delay=delay))
        row = {"name": name, "form": "grid", "inference": "cusum", "side": side, "window": window,
               "hypotheses": hypotheses, "traps": traps, "delay": delay}
        run(world_path, row)
        if (side, window, hypotheses, traps, *rest) in arena_forms:
            arena_path = out_dir / "worlds" / f"{name}_arena.toml"
            write_arena_form(world_path, arena_path)
            run(arena_path, dict(row, name=f"{name}_arena", form="arena form"))
    for side, window, hypotheses, traps, decision in bayes:
        name = bayes_name(side, window, hypotheses, traps, decision)
        world_path = out_dir / "worlds" / f"{name}.toml"
        write_text(world_path, bayes_world(side, window, hypotheses, traps, decision))
        run(world_path, {"name": name, "form": f"bayes {decision}", "inference": "bayes",
                         "side": side, "window": window, "hypotheses": hypotheses,
                         "traps": traps, "delay": 0})
    for states in random_arenas:
        name = random_arena_name(states)
        world_path = out_dir / "worlds" / f"{name}.toml"
        write_text(world_path, random_arena_world(states))
        run(world_path, {"name": name, "form": "random arena", "inference": "cusum",
                         "window": 3, "hypotheses": 3,
                         "traps": 1, "delay": 0})
    write_csv(rows, out_dir / "results.csv")
    write_json(out_dir / "results.json", bench_results(rows, list(huge)))
    good = [r for r in rows if not r.get("error")]
    if good:
        from hg2prism.report.plots import scaling_figure   # after the children: keeps them small

        slope = loglog_slope(undelayed(good))
        title = (f"hg2prism bench (Storm method {storm_method}): log-log slope of the total "
                 f"{'n/a' if slope is None else f'{slope:.2f}'} from {SLOPE_RANGE[0]:.0e} "
                 f"states (no delay)")
        scaling_figure(grids(good) or good, STAGES + ("write",), out_dir / "scaling.png", title)
    if show_progress:
        print(summary(rows, list(huge)), flush=True)
        print(f"wrote {out_dir / 'results.csv'}, results.json and {out_dir / 'scaling.png'} "
              "(and .svg)", flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    import argparse

    from hg2prism.engines import default

    parser = argparse.ArgumentParser(prog="hg2prism bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="bench", help="output folder (default: bench)")
    parser.add_argument("--quick", action="store_true",
                        help="only the worlds below 2e5 states without delay, two small "
                             "arenas and two small Bayesian worlds (about a minute)")
    parser.add_argument("--keep-outputs", action="store_true",
                        help="keep every world's strategy.json")
    parser.add_argument("--storm-method", choices=default().methods, default="sound",
                        help="how Storm solves Pmax, as for `hg2prism check` (default: sound)")
    parser.add_argument("--huge", action="store_true",
                        help="only the world of about 1e7 canonical states (`make bench-huge`: "
                             "about 14 GB at peak, run it alone), its row also written to "
                             "OUT/huge.json")
    args = parser.parse_args(argv)
    from hg2prism.errors import InputError
    from hg2prism.outputs import check_writable

    try:    # before any world is solved, as every command checks its folder
        check_writable(Path(args.out), staged=False)
    except InputError as err:
        print(f"hg2prism: error: {err}", file=sys.stderr)
        return 2
    # SIGTERM unwinds like Ctrl-C, so that the running world's process is killed (measure_world).
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    if args.huge:
        rows = run_bench(Path(args.out), HUGE_SIZES, keep_outputs=args.keep_outputs,
                         storm_method=args.storm_method, timeout=HUGE_TIMEOUT)
        write_huge(rows, Path(args.out) / "huge.json")
        return 0
    sizes = DEFAULT_SIZES
    if args.quick:
        sizes = tuple(s for s in DEFAULT_SIZES
                      if (s[1] < 3 or s[0] <= 12) and not (len(s) > 4 and s[4]))
    arena_forms, random_arenas = ((QUICK_ARENA_FORMS, QUICK_RANDOM_ARENAS) if args.quick
                                  else (DEFAULT_ARENA_FORMS, DEFAULT_RANDOM_ARENAS))
    run_bench(Path(args.out), sizes, show_progress=True, keep_outputs=args.keep_outputs,
              storm_method=args.storm_method, arena_forms=arena_forms,
              random_arenas=random_arenas, bayes=QUICK_BAYES if args.quick else DEFAULT_BAYES,
              huge=read_huge(HUGE_RECORD))
    return 0


# The record of the last `make bench-huge` (copied there from bench-huge/huge.json), which
# `make bench` reads for the ten-million-state target and the docs for its numbers.
HUGE_RECORD = Path("docs/data/bench_huge.json")


def write_huge(rows: list[dict], path: Path) -> None:
    """The rows of a `--huge` run with the machine they ran on, as JSON."""
    from hg2prism.outputs import write_json

    machine = {"cpus": os.cpu_count(),
               "memory_gb": round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
                                  / 2 ** 30, 1)}
    write_json(path, {"measured": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                      "machine": machine,
                      "rows": [{k: v for k, v in row.items() if k != "traceback"}
                               for row in rows]})


def read_huge(path: Path) -> list[dict]:
    """The rows of HUGE_RECORD, none when it is missing."""
    import json

    return json.loads(path.read_text())["rows"] if path.is_file() else []


if __name__ == "__main__":
    sys.exit(main())
