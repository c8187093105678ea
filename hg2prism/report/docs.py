"""The numbers of README.md and docs/*.md that the tool computes, rendered from the outputs of the
showcase worlds (`make docs`), so that the documentation cannot go stale.

A document marks what is generated:

* a block, `<!-- generated: NAME -->` ... `<!-- /generated -->`: NAME is one of `BLOCKS`
  (a table rendered from the outputs);
* a value inline, `<!-- value: SOURCE PATH FORMAT -->0.9498<!-- /value -->`: SOURCE is
  `CASE/FILE` (`world1/results.json`; `CASE` alone means its `results.json`), PATH the keys of
  the value in that JSON file joined by dots (an integer indexes a list, any other key picks
  the list's row of that `name`), FORMAT a Python format specification (`.4f`, `.1%`, `d`).

The outputs are read from `docs/data/CASE/FILE`: the showcase worlds' JSON outputs and tables
(`SOURCES`), as `collect` copies them from `models/CASE/` after `make world1 world2 world3
world4 mir100`, without what varies between runs (timings, the version, the world file's
path), and the benchmark's `bench/results.json` after `make bench` (its timings are what it
measures: kept). The files are committed, so that `render` needs no run; tests/test_docs.py
runs the fast showcase worlds afresh and compares their outputs with `docs/data`, and
`docs/data` with the documents.

    python -m hg2prism.report.docs             # copy models/*/ outputs (where present), render
    python -m hg2prism.report.docs --check     # exit 1 when a document differs from its render
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from hg2prism.outputs import write_text

ROOT = Path(__file__).resolve().parent.parent.parent

# case -> the files of models/CASE/ the documents are rendered from
SOURCES: dict[str, tuple[str, ...]] = {
    "world1": ("results.json", "table.md", "strategy.json", "explorer.html"),
    "world2": ("results.json", "table.md", "sweep.json", "detection.json", "robust.json"),
    "world3": ("results.json", "table.md", "explorer.html"),
    "world3_bayes": ("results.json",),
    "mir100": ("results.json", "strategy.json", "explorer.html"),
    "mir100_sweep": ("sweep.json",),
    "world1_robust": ("robust.json",),      # make docs-all
    "world1_bayes": ("sweep.json",),        # world1 against the Bayesian observer (map, sample)
    "world1_ties": ("sweep.json",),         # world1 with P2's ties broken either way
    "world2_bayes": ("sweep.json",),        # the same on world2 (make world2)
    "world2_replan_02": ("detection.json",),        # make world2: re-planning, budget 0.2
    "world2_replan_leader": ("detection.json",),    # and to the leader-game strategy
    "mir100_guess": ("sweep.json",),        # MIR100 over P2's first guess x delay, V_naive
    "world4": ("results.json", "table.md", "strategy.json"),
    "world4_weight": ("sweep.json",),       # world4 over the prior weight of its first type
    "bench": ("results.json",),             # make bench (bench/results.json), slow: committed
}
# where a case's files are, under the repository's root, when not under models/
ORIGIN = {"bench": "bench"}
# The showcase figures the documents show, docs/<name> copied from models/<source> (the
# explorer's screenshot, docs/world3_explorer.png, is taken by hand in a browser).
FIGURES: dict[str, str] = {
    "world1.png": "world1/world.png", "world1.svg": "world1/world.svg",
    "world1_belief.png": "world1/belief.png", "world1_completion.png": "world1/completion.png",
    "world1_replay.gif": "world1/replay.gif",
    "world2_sweep.png": "world2/sweep.png", "world2_sweep.svg": "world2/sweep.svg",
    "world2_detection.png": "world2/detection.png", "world2_detection.svg": "world2/detection.svg",
    "world2_robust.png": "world2/robust.png", "world2_robust.svg": "world2/robust.svg",
    "world3.png": "world3/world.png", "world3_belief.png": "world3/belief.png",
    "world3_bayes_belief.png": "world3_bayes/belief.png",
    "mir100.png": "mir100/world.png",
    "world4_adaptive_belief.png": "world4/adaptive_belief.png",
}
# and the benchmark's plot, from the repository's bench/ (make bench)
ROOT_FIGURES: dict[str, str] = {"scaling.png": "bench/scaling.png"}
VOLATILE = {"timings", "seconds", "hg2prism_version", "software", "world_file", "world_digest"}
# the explorer's candidate episodes docs/data keeps step by step, besides the drawn one (each
# candidate's path is kept): hand-picked examples the documents describe
EXPLORER_SEEDS = {"world3": (44,)}
# a marker quoted in a code span (a backtick before it) is text, not a marker
MARK = re.compile(r"(?<!`)<!-- (generated|value): (.*?) -->(.*?)<!-- /\1 -->", re.DOTALL)


def documents(root: Path = ROOT) -> list[Path]:
    """README.md and every Markdown file of docs/."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


# ---- the data: outputs without what varies between runs ----

def stable(value: object) -> object:
    """`value` (parsed JSON) without timings, the version, the world file's path and the
    world's digest (bookkeeping, which a change of the World's fields changes), its numbers
    rounded to 10 decimals."""
    if isinstance(value, dict):
        return {k: stable(v) for k, v in value.items() if k not in VOLATILE}
    if isinstance(value, list):
        return [stable(v) for v in value]
    if isinstance(value, float):
        return round(value, 10)         # the last bits differ between machines
    return value


def data_name(name: str) -> str:
    """The name docs/data keeps the output file `name` under (explorer.html's data as JSON)."""
    return "explorer.json" if name == "explorer.html" else name


def _state_names(data: dict) -> list[str]:
    """The explorer's states as the documents name them: on a map of cells (the grid's) by
    the position the world's drawer gives them, as the documents write cells; else by name."""
    if data["map"].get("kind") != "grid":
        return list(data["states"])
    return [f"({x:g},{y:g})" for x, y in data["positions"]]


def _episode(data: dict, episode: dict, steps: bool) -> dict:
    """One episode of explorer.html's data: its path (states by name), and with `steps` each
    step with the record of its state (strategy.json's values), P2's traps and her belief."""
    names, records = _state_names(data), data["records"]
    kept = {"name": "drawn" if episode["drawn"] else f"seed{episode['seed']}",
            "seed": episode["seed"], "outcome": episode["outcome"],
            "path": " ".join(names[s["place"]] for s in episode["states"])}
    if steps:
        kept["steps"] = [{
            "n": step["n"], "at": names[step["start"]],
            "landing": names[step["landing"]] if not step["trapped"] else "trapped",
            "believes": data["hypotheses"][state["belief"]["hypothesis"]],
            "traps": [names[t] for t in step["traps"]],
            "values": records[state["record"]]["values"] if state.get("record") is not None
            else None,
            "plays": step["action"], "realised": step["realised"],
            "belief_after": after["belief"]["belief"],
            "believes_after": data["hypotheses"][after["belief"]["hypothesis"]]}
            for step, state, after in zip(episode["steps"], episode["states"],
                                          episode["states"][1:])]
        beliefs = [s["belief_after"] for s in kept["steps"] if s["belief_after"] is not None]
        kept["peak_belief"] = [max(column) for column in zip(*beliefs)] if beliefs else None
    return kept


def explorer_extract(text: str, seeds: tuple[int, ...] = ()) -> dict:
    """What docs/data keeps of explorer.html: the hypotheses, a grid's regions (their cells),
    every candidate episode's path (its states, space-separated), and step by step the drawn
    episode and those of `seeds`."""
    start = text.index('{"world":')
    data, _ = json.JSONDecoder().raw_decode(text[start:])     # its escapes are JSON's
    regions: dict[str, list[str]] = {}
    for cell in data["map"].get("cells", ()):
        if cell.get("kind") == "region":
            regions.setdefault(cell["text"], []).append(f"({cell['x']},{cell['y']})")
    return {"world": data["world"], "hypotheses": data["hypotheses"],
            "chosen_as": data["chosen_as"], "regions": regions,
            "episodes": [_episode(data, e, e["drawn"] or e["seed"] in seeds)
                         for e in data["episodes"]]}


def extract(name: str, text: str, case: str = "") -> str:
    """What docs/data keeps of the output file `name` of `case`: JSON without its volatile
    keys (of strategy.json only the initial state's record; of explorer.html its episodes,
    `explorer_extract`), other files as they are."""
    if name == "explorer.html":
        data = stable(explorer_extract(text, EXPLORER_SEEDS.get(case, ())))
        return json.dumps(data, indent=1, ensure_ascii=False) + "\n"
    if not name.endswith(".json"):
        return text
    data = stable(json.loads(text))
    if name == "strategy.json":
        data = (start_records(data) if data and "types" in data[0] else
                [record for record in data if record.get("initial")])
    return json.dumps(data, indent=1, ensure_ascii=False) + "\n"


def start_records(records: list[dict]) -> list[dict]:
    """Of an adaptive strategy.json (a world with P2's types), the records at the initial
    state by what P1 knows there: the consistent types and each one's hypothesis (their
    windows dropped), each once; a knowledge whose records differ in move or values is kept
    once per difference, and `start_table` refuses it."""
    first = next(record for record in records if record.get("initial"))
    at = {key: first[key] for key in ("state", "standing", "countdown", "q")}
    kept: list[dict] = []
    for record in records:
        if all(record[key] == value for key, value in at.items()):
            known = {"types": {name: type_["hypothesis"]
                               for name, type_ in record["types"].items()},
                     "action": record["action"], "values": record["values"]}
            if known not in kept:
                kept.append(known)
    return kept


def copy_figures(models: Path, docs_folder: Path, root: Path | None = None) -> list[str]:
    """Copy the FIGURES present under `models` (and, with `root`, the ROOT_FIGURES present
    under it) into `docs_folder` where they differ; the copied."""
    from hg2prism.outputs import write_bytes

    copied = []
    sources = [(name, models / source) for name, source in FIGURES.items()]
    if root is not None:
        sources += [(name, root / source) for name, source in ROOT_FIGURES.items()]
    for name, path in sources:
        target = docs_folder / name
        if path.is_file() and (not target.is_file() or target.read_bytes() != path.read_bytes()):
            write_bytes(target, path.read_bytes())
            copied.append(name)
    return copied


def collect(models: Path, data: Path, root: Path | None = None) -> list[str]:
    """Copy the sources present under `models` (models/CASE/FILE; with `root`, a case of
    ORIGIN from root/ORIGIN[case]/FILE) into `data`; the copied."""
    copied = []
    for case, names in SOURCES.items():
        if case in ORIGIN and root is None:
            continue
        folder = root / ORIGIN[case] if case in ORIGIN else models / case
        for name in names:
            source = folder / name
            if source.is_file():
                write_text(data / case / data_name(name),
                           extract(name, source.read_text(), case))
                copied.append(f"{case}/{data_name(name)}")
    return copied


@dataclass
class Outputs:
    """The data the documents are rendered from (docs/data), read once each."""
    data: Path
    cache: dict[str, object] = field(default_factory=dict)

    def read(self, source: str) -> object:
        if "/" not in source and not source.endswith(".json"):
            source += "/results.json"
        if source not in self.cache:
            text = (self.data / source).read_text()
            self.cache[source] = json.loads(text) if source.endswith(".json") else text
        return self.cache[source]

    def get(self, source: str, path: str) -> object:
        value = self.read(source)
        for key in path.split("."):
            if isinstance(value, list):     # an index, or the `name` of a row (bench's rows)
                value = (value[int(key)] if key.isdigit()
                         else next(row for row in value if row.get("name") == key))
            else:
                value = value[key]
        return value


# ---- the blocks ----

def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def completion_table(case: str) -> Callable[[Outputs], str]:
    """The table of `table.md` (the completion table `run` writes), as it is."""
    def render(out: Outputs) -> str:
        text = out.read(f"{case}/table.md")
        return "\n".join(line for line in text.splitlines() if line.startswith("|"))
    return render


def _f(value: float) -> str:
    return f"{value:.4f}"


def world2_sweep(out: Outputs) -> str:
    rows = [[str(r["delay"]), _f(r["deceptive_value"]), _f(r["v_lead"]), _f(r["v_ne"]),
             str(r["states"])] for r in out.read("world2/sweep.json")["rows"]]
    return _table(["delay", "deceptive value", "V_lead", "V_NE", "hypergame states"], rows)


def _changes(results: dict) -> str:
    deceptive = results["simulation"]["deceptive"]
    share = f"{deceptive['p2_switched']:.0%}"
    if deceptive["p2_switched"] > 0:
        share += (f" ({deceptive['p2_switches_mean']:.1f} changes per episode; "
                  f"{deceptive['p2_switched_in_play']:.0%} she could act on)")
    return share


def deception_worth(out: Outputs) -> str:
    rows = []
    for case in ("world1", "world2", "world3"):
        r = out.read(case)
        rows.append([case, _f(r["v_static"]), _f(r["v_naive"]), _f(r["deceptive_value"]),
                     _f(r["value_of_deception"]), _changes(r)])
    return _table(["world", "V_static", "V_naive", "deceptive value", "value of deception",
                   "P2 changes her mind (deceptive episodes)"], rows)


def world3_observers(out: Outputs) -> str:
    rows = []
    for case, against in (("world3", "CUSUM (window 2, threshold 0.5)"),
                          ("world3_bayes", "Bayesian, `map` (window 2, uniform prior)")):
        r = out.read(case)
        d = r["simulation"]["deceptive"]
        rows.append([against, _f(r["v_static"]), _f(r["v_naive"]), _f(r["deceptive_value"]),
                     _f(r["value_of_deception"]), f"{d['p2_switched']:.0%}",
                     f"{d['p2_switched_in_play']:.0%}", f"{d['p2_switches_mean']:.2f}",
                     _f(d["rate"])])
    return _table(["world3 against", "V_static", "V_naive", "deceptive value",
                   "value of deception", "P2 changes her mind", "... that she could act on",
                   "changes per episode", "simulated completion"], rows)


def mir100_values(out: Outputs) -> str:
    r = out.read("mir100")
    sim = r["simulation"]
    rows = [("deceptive value", r["deceptive_value"]), ("V_lead", r["v_lead"]),
            ("V_NE", r["v_ne"]), ("V_static", r["v_static"]), ("V_naive", r["v_naive"]),
            ("value of deception", r["value_of_deception"]),
            ("simulated (deceptive)", sim["deceptive"]["rate"]),
            ("simulated (naive)", sim["naive"]["rate"])]
    return _table(["value", ""], [[name, _f(value)] for name, value in rows])


def world2_robust(out: Outputs) -> str:
    rows = [[f"{r['delta']:g}", _f(r["robust_value"]), _f(r["nominal_worst_case"]),
             _f(r["robust_strategy_nominal_value"]), str(r["states"])]
            for r in out.read("world2/robust.json")["rows"]]
    return _table(["δ", "robust value R_δ", "deceptive strategy, worst case",
                   "robust strategy when P2 does not deviate", "hypergame states"], rows)


def mir100_sweep(out: Outputs) -> str:
    rows = [[str(r["delay"]), str(r["traps"]), _f(r["deceptive_value"]), _f(r["v_lead"]),
             _f(r["v_ne"]), str(r["states"])] for r in out.read("mir100_sweep/sweep.json")["rows"]]
    return _table(["delay", "honeypots", "deceptive value", "V_lead", "V_NE", "hypergame states"],
                  rows)


def world1_headline(out: Outputs) -> str:
    """The values `make world1` prints, with what each means."""
    r = out.read("world1")
    rows = [("deceptive value", r["deceptive_value"], "P1 against P2's inference (Storm's Pmax)"),
            ("V_static", r["v_static"], "P2 never revises her first guess"),
            ("V_naive", r["v_naive"], "P1 plays as if P2 knew the task, against her inference"),
            ("V_lead", r["v_lead"], "P2 knows the task and commits first each step"),
            ("V_NE", r["v_ne"], "P2 knows the task; both players mix"),
            ("value of deception", r["value_of_deception"], "deceptive value − V_naive")]
    return _table(["value", "world1", "meaning"], [[n, _f(v), m] for n, v, m in rows])


def _asset(formula: str) -> str:
    """A hypothesis `F target` by its target's name."""
    return re.sub(r"^F\s+", "", formula)


def mir100_guess(out: Outputs) -> str:
    """MIR100 solved with each first guess of P2, delay 0 and 1 (`make mir100`'s sweep over
    initial_hypothesis x delay with --deception)."""
    parameters = out.read("mir100")["parameters"]
    by = {(r["initial_hypothesis"], r["delay"]): r
          for r in out.read("mir100_guess/sweep.json")["rows"]}
    rows = []
    for h, formula in enumerate(parameters["hypotheses"]):
        now, later = by[(h, 0)], by[(h, 1)]
        truth = " (the truth)" if formula == parameters["formula"] else ""
        rows.append([_asset(formula) + truth, _f(now["deceptive_value"]), _f(now["v_naive"]),
                     _f(now["value_of_deception"]), _f(later["deceptive_value"]),
                     _f(later["v_naive"])])
    return _table(["P2's first guess", "deceptive value", "V_naive", "value of deception",
                   "deceptive value, delay 1", "V_naive, delay 1"], rows)


def world1_inference(out: Outputs) -> str:
    """world1 against CUSUM (its own run) and the Bayesian observer, `map` and `sample` (the
    sweep `make docs` runs: inference bayes x decision)."""
    r = out.read("world1")
    rows = [[f"CUSUM, threshold {r['parameters']['threshold']:g}", _f(r["deceptive_value"]),
             _f(r["v_lead"]), str(r["states"])]]
    rows += [[f"Bayesian, uniform prior, `{p['decision']}`", _f(p["deceptive_value"]),
              _f(p["v_lead"]), str(p["states"])]
             for p in out.read("world1_bayes/sweep.json")["rows"]]
    return _table(["P2's inference", "deceptive value", "V_lead", "canonical states"], rows)


def world4_table(out: Outputs) -> str:
    """The adaptivity table `make world4` prints (table.md without its title; a paragraph of
    several lines, one number each, as a list)."""
    paragraphs = "\n".join(out.read("world4/table.md").splitlines()[1:]).strip().split("\n\n")
    return "\n\n".join(
        "\n".join(f"- {line}" for line in text.splitlines())
        if len(text.splitlines()) > 1 and not text.startswith("|") else text
        for text in paragraphs)


def world4_start(out: Outputs) -> str:
    """P1's adaptive strategy at world4's start state, by what P1 knows there (which types are
    still consistent with P2's actions, and what each of them guesses): each move's value
    and the move played (strategy.json)."""
    records = out.read("world4/strategy.json")
    known = [tuple(sorted(r["types"].items())) for r in records]
    if len(set(known)) != len(known):
        raise ValueError("world4's strategy differs at its start between records P1 cannot "
                         "tell apart by the consistent types and their guesses")
    moves = list(records[0]["values"])
    order = sorted(range(len(records)), key=lambda i: (-len(known[i]), known[i]))
    rows = [[", ".join(name for name, _ in known[i]),
             ", ".join(f"{name}: x{x}" for name, x in known[i]),
             *(_f(records[i]["values"][m]) if records[i]["values"][m] is not None else "–"
               for m in moves), records[i]["action"]] for i in order]
    return _table(["types still consistent", "their guesses", *moves, "P1 plays"], rows)


def world4_weight(out: Outputs) -> str:
    """world4 against the prior weight of its first type (`hg2prism sweep --param weight`)."""
    sweep = out.read("world4_weight/sweep.json")
    names = list(sweep["rows"][0]["v_commit"])
    rows = [[f"{r['weight']:g}", f"{r['v_adapt']:.6f}", f"{r['v_oracle']:.6f}",
             *(f"{r['v_commit'][n]:.6f}" for n in names)] for r in sweep["rows"]]
    return _table([f"weight of {sweep['type']}", "V_adapt", "V_oracle",
                   *(f"V_commit({n})" for n in names)], rows)


def _memory(mb: float) -> str:
    return f"{mb:.0f} MB" if mb < 1000 else f"{mb / 1024:.1f} GB"


def bench_table(out: Outputs) -> str:
    """The benchmark's grid worlds (`make bench`'s bench/results.json): time per stage in
    seconds, total and peak memory."""
    stages = ("games", "generate", "parse", "build", "check", "export", "write")
    rows = [[r["name"].removeprefix("bench_").replace("_", " "), f"{r['states']:,}",
             *(f"{r[f'time_{s}']:.2f}" for s in stages), f"{r['time_total']:.1f}",
             _memory(r["peak_mb"]), f"{r['peak_mb'] * 2 ** 20 / r['states']:,.0f}"]
            for r in out.read("bench/results.json")["rows"]
            if (r.get("form") or "grid") == "grid" and not r.get("error")]
    return _table(["world", "canonical states", *stages, "total", "peak memory",
                   "bytes per state"], rows)


def bench_targets(out: Outputs) -> str:
    """The scaling targets the last `make bench` missed (bench/results.json's
    `missed_targets`, with make bench-huge's row for the ten million states), or that it met
    them all."""
    missed = out.read("bench/results.json")["missed_targets"]
    return "\n".join(f"- {line}" for line in missed) if missed else "- none: every target met"


def bench_huge(out: Outputs) -> str:
    """`make bench-huge`'s world (docs/data/bench_huge.json, written by it): its sizes, time
    per stage, peak memory per canonical state, and when and where it was measured."""
    huge = out.read("bench_huge.json")
    stages = ("games", "parse", "build", "check", "export")
    rows = [[r["name"].removeprefix("bench_").replace("_", " "), f"{r['states']:,}",
             f"{r['storm_states']:,}", f"{r['storm_transitions']:,}",
             *(f"{r[f'time_{s}']:.1f}" for s in stages), f"{r['time_total']:.1f}",
             _memory(r["peak_mb"]), f"{r['peak_mb'] * 2 ** 20 / r['states']:,.0f}"]
            for r in huge["rows"] if not r.get("error")]
    table = _table(["world", "canonical states", "Storm states", "Storm transitions", *stages,
                    "total (s)", "peak memory", "bytes per state"], rows)
    machine = huge["machine"]
    return (f"{table}\n\nMeasured {huge['measured']} on {machine['cpus']} cores and "
            f"{machine['memory_gb']:g} GB.")


def _episode_named(out: Outputs, case: str, name: str) -> dict:
    return next(e for e in out.read(f"{case}/explorer.json")["episodes"] if e["name"] == name)


def _where(cell: str, regions: dict[str, list[str]]) -> str:
    return " ".join([cell, *(name for name, cells in regions.items() if cell in cells)])


def world3_steps(out: Outputs) -> str:
    """world3's feint step by step: the candidate episode of seed EXPLORER_SEEDS["world3"]
    in world3's explorer data (strategy.json's values of each move, P2's traps and CUSUM
    scores after each step)."""
    explorer = out.read("world3/explorer.json")
    episode = _episode_named(out, "world3", f"seed{EXPLORER_SEEDS['world3'][0]}")
    rows = []
    for step in episode["steps"]:
        values = ", ".join(f"**{v:.2f}**" if move == step["plays"] else f"{v:.2f}"
                           for move, v in step["values"].items())
        rows.append([str(step["n"]), _where(step["at"], explorer["regions"]),
                     f"`{step['believes']}`", ", ".join(step["traps"]), values,
                     step["realised"],
                     ", ".join(f"{z:.2f}" for z in step["belief_after"]),
                     _where(step["landing"], explorer["regions"])])
    moves = ", ".join(episode["steps"][0]["values"])
    zs = ", ".join(f"Z_{h.split()[-1]}" for h in explorer["hypotheses"])
    return _table(["step", "robot", "P2 believes", "traps", f"value of {moves}",
                   "P1's move (the world's caption)", f"{zs} after", "lands on"], rows)


def world1_exits(out: Outputs) -> str:
    """How world1's candidate episodes (explorer.html: seeds 0-49) first left the pair of
    cells the strategy bounces between, (2,4) and (1,4), and which region they reached
    first."""
    explorer = out.read("world1/explorer.json")
    pair, regions = {"(2,4)", "(1,4)"}, explorer["regions"]
    exits: dict[str, int] = {}
    first: dict[str, int] = {}
    for episode in explorer["episodes"]:
        path = episode["path"].split()
        out_at = next((i for i in range(len(path) - 1)
                       if path[i] in pair and path[i + 1] not in pair), None)
        if out_at is not None:
            key = f"{path[out_at]} → {path[out_at + 1]}"
            exits[key] = exits.get(key, 0) + 1
        region = next((r for cell in path for r, cells in regions.items() if cell in cells),
                      None)
        if region is not None:
            first[region] = first.get(region, 0) + 1
    n = len(explorer["episodes"])
    rows = [[f"left (2,4)–(1,4) by {key}", f"{k} of {n}"] for key, k in
            sorted(exits.items(), key=lambda item: -item[1])]
    rows += [[f"reached {region} first", f"{k} of {n}"] for region, k in
             sorted(first.items(), key=lambda item: -item[1])]
    return _table(["candidate episodes (seeds of the explorer)", ""], rows)


BLOCKS: dict[str, Callable[[Outputs], str]] = {
    "world1-headline": world1_headline,
    "world1-table": completion_table("world1"),
    "world2-table": completion_table("world2"),
    "world3-table": completion_table("world3"),
    "world2-sweep": world2_sweep,
    "world2-robust": world2_robust,
    "deception-worth": deception_worth,
    "world3-observers": world3_observers,
    "mir100-values": mir100_values,
    "mir100-sweep": mir100_sweep,
    "mir100-guess": mir100_guess,
    "world1-inference": world1_inference,
    "world4-table": world4_table,
    "world4-weight": world4_weight,
    "world4-start": world4_start,
    "bench-table": bench_table,
    "bench-huge": bench_huge,
    "bench-targets": bench_targets,
    "world3-steps": world3_steps,
    "world1-exits": world1_exits,
}


# ---- rendering ----

def value(out: Outputs, spec: str) -> str:
    """An inline value: `SOURCE PATH FORMAT`."""
    source, path, form = spec.split()
    return format(out.get(source, path), form)


def render(text: str, out: Outputs) -> str:
    """`text` with every marked block and value rendered from `out`."""
    def one(match: re.Match) -> str:
        kind, spec, _ = match.groups()
        if kind == "generated":
            if spec not in BLOCKS:
                raise ValueError(f"unknown generated block {spec!r} (known: {', '.join(BLOCKS)})")
            body = "\n" + BLOCKS[spec](out) + "\n"
        else:
            body = value(out, spec)
        return f"<!-- {kind}: {spec} -->{body}<!-- /{kind} -->"
    return MARK.sub(one, text)


def stale(root: Path = ROOT, data: Path | None = None) -> list[Path]:
    """The documents that differ from their render."""
    out = Outputs(data or root / "docs" / "data")
    return [doc for doc in documents(root) if render(doc.read_text(), out) != doc.read_text()]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hg2prism.report.docs",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="change nothing; exit 1 when a document differs from its render")
    parser.add_argument("--models", type=Path, default=ROOT / "models",
                        help="where the showcase worlds' outputs are (default: models/)")
    args = parser.parse_args(argv)
    data = ROOT / "docs" / "data"
    if args.check:
        differ = stale(ROOT, data)
        for doc in differ:
            print(f"{doc.relative_to(ROOT)} differs from what `make docs` writes", file=sys.stderr)
        return 1 if differ else 0
    for name in collect(args.models, data, ROOT):
        print(f"docs/data/{name}")
    for name in copy_figures(args.models, ROOT / "docs", ROOT):
        print(f"copied docs/{name}")
    out = Outputs(data)
    for doc in documents(ROOT):
        text = doc.read_text()
        new = render(text, out)
        if new != text:
            write_text(doc, new)
            print(f"rewrote {doc.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
