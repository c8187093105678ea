"""The numbers of README.md and docs/*.md that the tool computes, rendered from the outputs of the
showcase worlds (`make docs`), so that the documentation cannot go stale.

A document marks what is generated:

* a block, `<!-- generated: NAME -->` ... `<!-- /generated -->`: NAME is one of `BLOCKS`
  (a table rendered from the outputs);
* a value inline, `<!-- value: SOURCE PATH FORMAT -->0.9498<!-- /value -->`: SOURCE is
  `CASE/FILE` (`world1/results.json`; `CASE` alone means its `results.json`), PATH the keys of
  the value in that JSON file joined by dots (an integer indexes a list), FORMAT a Python format
  specification (`.4f`, `.1%`, `d`).

The outputs are read from `docs/data/CASE/FILE`: the showcase worlds' JSON outputs and tables
(`SOURCES`), as `collect` copies them from `models/CASE/` after `make world1 world2 world3
mir100`, without what varies between runs (timings, the version, the world file's path). The
files are committed, so that `render` needs no run; tests/test_docs.py runs the fast showcase
worlds afresh and compares their outputs with `docs/data`, and `docs/data` with the documents.

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
    "world1": ("results.json", "table.md", "strategy.json"),
    "world2": ("results.json", "table.md", "sweep.json", "detection.json", "robust.json"),
    "world3": ("results.json", "table.md"),
    "world3_bayes": ("results.json",),
    "mir100": ("results.json", "strategy.json"),
    "mir100_sweep": ("sweep.json",),
    "world1_robust": ("robust.json",),      # make docs-all
}
VOLATILE = {"timings", "seconds", "hg2prism_version", "world_file"}
# a marker quoted in a code span (a backtick before it) is text, not a marker
MARK = re.compile(r"(?<!`)<!-- (generated|value): (.*?) -->(.*?)<!-- /\1 -->", re.DOTALL)


def documents(root: Path = ROOT) -> list[Path]:
    """README.md and every Markdown file of docs/."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


# ---- the data: outputs without what varies between runs ----

def stable(value: object) -> object:
    """`value` (parsed JSON) without timings, the version and the world file's path, its
    numbers rounded to 10 decimals."""
    if isinstance(value, dict):
        return {k: stable(v) for k, v in value.items() if k not in VOLATILE}
    if isinstance(value, list):
        return [stable(v) for v in value]
    if isinstance(value, float):
        return round(value, 10)         # the last bits differ between machines
    return value


def extract(name: str, text: str) -> str:
    """What docs/data keeps of the output file `name`: JSON without its volatile keys (of
    strategy.json only the initial state's record), other files as they are."""
    if not name.endswith(".json"):
        return text
    data = stable(json.loads(text))
    if name == "strategy.json":
        data = [record for record in data if record.get("initial")]
    return json.dumps(data, indent=1, ensure_ascii=False) + "\n"


def collect(models: Path, data: Path) -> list[str]:
    """Copy the sources present under `models` (models/CASE/FILE) into `data`; the copied."""
    copied = []
    for case, names in SOURCES.items():
        for name in names:
            source = models / case / name
            if source.is_file():
                write_text(data / case / name, extract(name, source.read_text()))
                copied.append(f"{case}/{name}")
    return copied


@dataclass
class Outputs:
    """The data the documents are rendered from (docs/data), read once each."""
    data: Path
    cache: dict[str, object] = field(default_factory=dict)

    def read(self, source: str) -> object:
        if "/" not in source:
            source += "/results.json"
        if source not in self.cache:
            text = (self.data / source).read_text()
            self.cache[source] = json.loads(text) if source.endswith(".json") else text
        return self.cache[source]

    def get(self, source: str, path: str) -> object:
        value = self.read(source)
        for key in path.split("."):
            value = value[int(key)] if isinstance(value, list) else value[key]
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
        share += f" ({deceptive['p2_switches_mean']:.1f} changes per episode)"
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
                     f"{d['p2_switches_mean']:.2f}", _f(d["rate"])])
    return _table(["world3 against", "V_static", "V_naive", "deceptive value",
                   "value of deception", "P2 changes her mind", "changes per episode",
                   "simulated completion"], rows)


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
            ("V_naive", r["v_naive"], "P1 plays the leader game against P2's inference"),
            ("V_lead", r["v_lead"], "P2 knows the task and commits first each step"),
            ("V_NE", r["v_ne"], "P2 knows the task; both players mix"),
            ("value of deception", r["value_of_deception"], "deceptive value − V_naive")]
    return _table(["value", "world1", "meaning"], [[n, _f(v), m] for n, v, m in rows])


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
    for name in collect(args.models, data):
        print(f"docs/data/{name}")
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
