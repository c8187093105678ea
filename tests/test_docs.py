"""Documentation that cannot go stale (docs/cli.md, "Documentation that cannot go stale"):

* every document (README.md, docs/*.md) is what `make docs` renders from docs/data, and the
  commands `make docs` runs (read from the Makefile: world1, world3 and world3_bayes, world4
  and its prior sweep, mir100 and its two sweeps, world1 against the Bayesian observer), run
  afresh, give the data docs/data holds, so that `make docs` leaves the documents unchanged;
  world2's experiments, world1's robustness and the benchmark are compared from their
  committed outputs (and the benchmark's summary numbers recomputed from its rows; world4's
  bounds from PRISM are re-computed only where PRISM is installed and not under `make test`,
  which runs the commands of `make docs` but its sweeps);
* every Python block of README.md and docs/api.md runs (in order, in one namespace with
  `hg2prism` imported, from the repository's root) and prints what its comments say (when every
  `print(` line has a comment); a signature block — fenced ```` ```python signature ````, or
  any block that is not Python, such as `x = hg2prism.f(a, *, b=1)` — has the function's
  parameters, kinds and defaults; every `hg2prism` command in a code block of the documents parses, and every
  `make` target named there exists;
* tests/README.md lists every test file, docs/architecture.md every module of hg2prism/;
* examples/tour.ipynb runs.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import json
import math
import os
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

import hg2prism
from conftest import MODELS, QUICK, ROOT
from hg2prism import cli
from hg2prism.errors import InputError
from hg2prism.experiments import bench, sweep
from hg2prism.experiments.adaptive import find_prism
from hg2prism.report import docs
from hg2prism.worldfile import load_world

FENCE = re.compile(r"^```([^\n]*)\n(.*?)^```", re.MULTILINE | re.DOTALL)


def make_commands(target: str) -> dict[str, list[str]]:
    """The `hg2prism` commands the Makefile's `target` runs through its prerequisites (not
    the set-up), by the case (models/CASE/) each writes: its --out, else its world file's
    name."""
    text = (ROOT / "Makefile").read_text().replace("\\\n", " ")
    rules = {m.group(1): (m.group(2).split(), m.group(3)) for m in
             re.finditer(r"^([\w.-]+):([^\n]*)\n((?:\t[^\n]*\n?)*)", text, re.MULTILINE)}
    commands: dict[str, list[str]] = {}

    def visit(name: str) -> None:
        needs, recipe = rules.get(name, ([], ""))
        for need in needs:
            visit(need)
        for line in recipe.splitlines():
            words = shlex.split(line.strip())
            if words and words[0] == "$(BIN)/hg2prism":
                args = words[1:]
                out = args[args.index("--out") + 1] if "--out" in args else args[1][:-5]
                commands[Path(out).name] = args
    visit(target)
    return commands


FRESH = make_commands("docs")       # fast: run afresh here
# what the fixture runs: under `make test` the runs, not the sweeps (their data are compared
# under `make test-all`; sweeps are the same code whatever the world, tests/test_experiments.py)
RUN_HERE = {case: args for case, args in FRESH.items() if not QUICK or args[0] != "sweep"}


def test_make_docs_runs_the_showcase_worlds() -> None:
    assert set(FRESH) == {"world1", "world3", "world3_bayes", "world4", "world4_weight",
                          "mir100", "mir100_sweep", "mir100_guess", "world1_bayes",
                          "world1_ties"}
    assert FRESH["world1"] == ["run", "models/world1.toml"]
    assert set(FRESH) <= set(docs.SOURCES)


def test_every_document_is_its_render() -> None:
    assert [str(d.relative_to(ROOT)) for d in docs.stale()] == []


def test_a_document_differing_from_its_render_is_found(tmp_path: Path) -> None:
    """The check can fail: a changed number inside a block, and one inside a value."""
    (tmp_path / "docs").mkdir()
    readme = (ROOT / "README.md").read_text()
    assert "| deceptive value | 0.9498 |" in readme
    (tmp_path / "README.md").write_text(readme.replace("| deceptive value | 0.9498 |",
                                                       "| deceptive value | 0.9499 |"))
    results = (ROOT / "docs" / "results.md").read_text()
    changed = re.sub(r"(<!-- value: world1 v_lead \.2f -->)0\.73", r"\g<1>0.74", results)
    assert changed != results
    (tmp_path / "docs" / "results.md").write_text(changed)
    stale = docs.stale(tmp_path, ROOT / "docs" / "data")
    assert [p.name for p in stale] == ["README.md", "results.md"]
    rendered = docs.render(changed, docs.Outputs(ROOT / "docs" / "data"))
    assert rendered == results


def _close(fresh: object, kept: object, where: str) -> None:
    """The same JSON, numbers within 1e-9 (the last bits differ between machines)."""
    if isinstance(kept, dict):
        assert isinstance(fresh, dict) and fresh.keys() == kept.keys(), where
        for key in kept:
            _close(fresh[key], kept[key], f"{where}.{key}")
    elif isinstance(kept, list):
        assert isinstance(fresh, list) and len(fresh) == len(kept), where
        for i, (a, b) in enumerate(zip(fresh, kept)):
            _close(a, b, f"{where}.{i}")
    elif isinstance(kept, float) and not isinstance(kept, bool):
        assert fresh == pytest.approx(kept, abs=1e-9), where
    else:
        assert fresh == kept, where


@pytest.fixture(scope="module")
def fresh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """models/CASE/ as `make docs` writes them (the Makefile's commands, each into a
    temporary folder; sweeps in this process), in a temporary folder."""
    root = tmp_path_factory.mktemp("showcase")
    for case, args in RUN_HERE.items():
        args = [str(ROOT / a) if a.startswith("models/") and a.endswith(".toml") else a
                for a in args]
        if "--out" in args:
            at = args.index("--out")
            args = args[:at] + args[at + 2:]
        if args[0] == "sweep":
            args += ["--workers", "1"]
        # PRISM's bounds cannot be re-computed without PRISM: the committed ones. `make test`
        # takes them too (10 s; tests/test_adaptive.py runs PRISM's POMDP engine)
        without_prism = "--prism-pomdp" in args and (QUICK or find_prism() is None)
        if without_prism:
            args.remove("--prism-pomdp")
        with contextlib.redirect_stdout(io.StringIO()):
            assert cli.main(args + ["--out", str(root / case)]) == 0, args
        if without_prism:
            _committed_prism_bounds(root / case, ROOT / "docs" / "data" / case)
    return root


def _committed_prism_bounds(out: Path, data: Path) -> None:
    """Where PRISM is not installed, a fresh run's results.json and table.md take PRISM's POMDP
    bounds from the committed data (everything else is still compared)."""
    results = json.loads((out / "results.json").read_text())
    results["prism_pomdp"] = json.loads((data / "results.json").read_text())["prism_pomdp"]
    (out / "results.json").write_text(json.dumps(results, indent=1))
    row = [line for line in (data / "table.md").read_text().splitlines()
           if line.startswith("| adaptive, POMDP form (PRISM")]
    table = [line for line in (out / "table.md").read_text().splitlines()
             if not line.startswith("| adaptive, POMDP form (PRISM")]
    # after Storm's POMDP row, where the table puts PRISM's (it was put before it: this test
    # failed wherever PRISM is not installed)
    at = 1 + max(i for i, line in enumerate(table) if line.startswith("| adaptive, POMDP form"))
    (out / "table.md").write_text("\n".join(table[:at] + row + table[at:]) + "\n")


def test_a_fresh_run_gives_the_committed_data(fresh: Path) -> None:
    data = ROOT / "docs" / "data"
    for case in RUN_HERE:
        for name in docs.SOURCES[case]:
            new = docs.extract(name, (fresh / case / name).read_text(), case)
            kept = (data / case / docs.data_name(name)).read_text()
            if docs.data_name(name).endswith(".json"):
                _close(json.loads(new), json.loads(kept), f"{case}/{name}")
            else:
                assert new == kept, f"{case}/{name}"


def test_the_committed_explorer_is_a_fresh_runs(fresh: Path) -> None:
    """docs/world3_explorer.html, which README links, is what `run` writes for world3 (`make
    docs` copies it)."""
    assert (ROOT / "docs" / "world3_explorer.html").read_bytes() == \
        (fresh / "world3" / "explorer.html").read_bytes()


def test_make_docs_after_a_fresh_run_changes_no_document(fresh: Path, tmp_path: Path) -> None:
    """`make docs`: the fresh outputs copied over docs/data, every document rendered again."""
    data = tmp_path / "data"
    shutil.copytree(ROOT / "docs" / "data", data)
    copied = docs.collect(fresh, data)
    assert len(copied) == sum(len(docs.SOURCES[case]) for case in RUN_HERE)
    assert [str(d.relative_to(ROOT)) for d in docs.stale(ROOT, data)] == []


def test_the_benchmarks_summary_is_computed_from_its_rows() -> None:
    """docs/data/bench/results.json (what `make bench` writes, docs/performance.md's data):
    its slopes and its largest world are what bench computes from its rows."""
    kept = json.loads((ROOT / "docs" / "data" / "bench" / "results.json").read_text())
    rows = kept["rows"]
    plain = bench.undelayed(rows)
    assert kept["slope"] == pytest.approx(bench.loglog_slope(plain), abs=1e-9)
    for stage, slope in kept["stage_slopes"].items():
        assert slope == pytest.approx(bench.loglog_slope(plain, 1e5, math.inf, f"time_{stage}"),
                                      abs=1e-9), stage
    assert kept["largest"] == max(rows, key=lambda r: r["states"])["name"]
    named = {r["name"] for r in rows}
    assert set(kept["delay_costs"]) == {r["name"] for r in rows if r["delay"]} and \
        set(kept["delay_costs"]) <= named
    good = [r for r in rows if not r.get("error")]
    assert kept["bayes_costs"] == pytest.approx(dict(bench.bayes_costs(good)), abs=1e-9)
    huge = bench.read_huge(ROOT / "docs" / "data" / "bench_huge.json")
    assert kept["missed_targets"] == bench.missed_targets(rows, huge)
    # the keys are those bench writes
    complete = [{**r, "storm_states": r["states"]} for r in rows]
    assert set(bench.bench_results(complete, huge)) == set(kept)


def test_the_sweep_parameters_the_docs_use_refuse_what_does_not_fit() -> None:
    """`initial_hypothesis` (MIR100's first-guess table) and `decision` (the Bayesian rows)."""
    world1 = load_world(MODELS / "world1.toml")
    assert sweep.sweep_point(world1, {"initial_hypothesis": 2}).initial_hypothesis == 2
    with pytest.raises(InputError, match="initial_hypothesis value 3 must be an index"):
        sweep.sweep_point(world1, {"initial_hypothesis": 3})
    with pytest.raises(InputError, match="has no decision"):
        sweep.sweep_point(world1, {"decision": "map"})
    bayes = sweep.sweep_point(world1, {"inference": "bayes", "decision": "sample"})
    assert bayes.setting("decision") == "sample" and bayes.initial_hypothesis == 0
    with pytest.raises(InputError, match="follows her prior"):
        sweep.sweep_point(world1, {"inference": "bayes", "initial_hypothesis": 1})
    with pytest.raises(InputError, match="decision"):
        sweep.sweep_point(bayes, {"decision": "maybe"})
    with pytest.raises(InputError, match="initial_hypothesis"):
        sweep.parse_sweep_values("initial_hypothesis", ["-1"])


def _explorer(case: str) -> dict:
    return json.loads((ROOT / "docs" / "data" / case / "explorer.json").read_text())


def _named(case: str, name: str) -> dict:
    return next(e for e in _explorer(case)["episodes"] if e["name"] == name)


def test_the_episodes_the_text_tells_are_those_of_the_data() -> None:
    """docs/results.md tells world1's and world3's pictured episodes and world3's feint (seed
    44) in words, with step numbers: they are those of the explorer's data (a fresh run's,
    above); world3's 0.6 / 0.8 = 0.75 is V_static, V_naive and V_lead; world1's static row's
    interval misses its exact value, as the text says."""
    world1 = _explorer("world1")
    drawn = _named("world1", "drawn")
    path = drawn["path"].split()                 # path[n]: where step n landed
    assert drawn["seed"] == 48 and len(path) - 1 == 62
    assert set(path[:6]) == {"(2,4)", "(1,4)"} and path[6] == "(1,5)"     # steps 1-5, slip N
    assert path[10] in world1["regions"]["A"] and not any(
        c in world1["regions"]["A"] for c in path[:10])                     # A at step 10
    steps = drawn["steps"]
    at_a = steps[10:31]                          # steps 11-31: W into the wall at A 20 times,
    assert [s["n"] for s in at_a if s["plays"] != "W"] == [28]      # back at step 28
    assert sum("bumped" in s["realised"] for s in at_a) == 18       # 18 bumps,
    assert "went N (slipped)" in steps[26]["realised"]              # a slip N at step 27
    assert "went S (slipped)" in steps[30]["realised"]              # until a slip S at step 31
    assert steps[36]["at"] == "(2,3)" and steps[36]["plays"] == "N"         # step 37
    assert steps[60]["at"] == "(1,4)" and "went S (slipped)" in steps[60]["realised"]
    assert path[61] == "(1,3)" and path[62] in world1["regions"]["C"]      # step 62: C
    lengths = [len(e["path"].split()) - 1 for e in world1["episodes"]
               if e["outcome"] == "task completed"]
    assert (min(lengths), max(lengths)) == (15, 195)
    world3 = _explorer("world3")
    drawn = _named("world3", "drawn")
    steps, path = drawn["steps"], drawn["path"].split()
    assert drawn["seed"] == 33 and len(steps) == 33
    changes = [s["n"] for s in steps if s["believes_after"] != s["believes"]]
    assert changes == [2, 27] and path[2] in world3["regions"]["B"]         # feint: steps 1-2
    assert "(2,2)" not in path[:25] and path[25] == "(3,2)"                 # until step 25
    assert path[26] == "(2,2)" and path[27] == "(2,3)"                      # steps 26, 27
    assert path[-1] in world3["regions"]["A"] and steps[-1]["plays"] == "S"
    assert not any(c in world3["regions"]["A"] for c in path[:-1])
    feint = _named("world3", "seed44")["steps"]
    assert [s["plays"] for s in feint] == ["E", "E", "W", "N", "W", "N"]
    after = [s["believes_after"] for s in feint]
    assert after == ["!obs U A"] + ["!obs U B"] * 4 + ["!obs U A"]          # steps 2 and 6
    assert feint[-1]["landing"] == "(1,2)" and feint[0]["at"] == "(3,2)"
    results3 = json.loads((ROOT / "docs" / "data" / "world3" / "results.json").read_text())
    for key in ("v_static", "v_naive", "v_lead"):
        assert results3[key] == pytest.approx(0.6 / 0.8, abs=1e-9), key
    static = json.loads((ROOT / "docs" / "data" / "world1" / "results.json").read_text())[
        "simulation"]["static"]
    low, high = static["ci95"]
    assert not low <= static["exact_within_horizon"] <= high


def test_every_block_and_value_is_rendered_from_the_data() -> None:
    """Each block name is known, each value's path exists, and every block is used."""
    out = docs.Outputs(ROOT / "docs" / "data")
    used = set()
    for doc in docs.documents():
        for kind, spec, _ in docs.MARK.findall(doc.read_text()):
            if kind == "generated":
                assert spec in docs.BLOCKS, (doc.name, spec)
                used.add(spec)
            else:
                docs.value(out, spec)
    assert used == set(docs.BLOCKS)


# ---- what PRISM, Storm and Spot print (docs/cli.md, re-checking) ----

def _prism() -> str | None:
    path = os.environ.get("PRISM") or shutil.which("prism")
    return path if path and os.access(path, os.X_OK) else None


def _recheck_rows(section: str) -> list[tuple[str, str, str]]:
    """(with, command, prints) of the table in docs/cli.md's section `section`."""
    text = (ROOT / "docs" / "cli.md").read_text().split(f"## {section}\n", 1)[1].split("\n## ", 1)[0]
    rows = [[c.strip() for c in line.strip().strip("|").split("|")]
            for line in text.splitlines() if line.startswith("| ") and "---" not in line]
    return [(row[0], row[1], row[2]) for row in rows[1:]]


def _number_after(text: str, prefix: str = "") -> float:
    return float(re.search(re.escape(prefix) + r"([0-9]+\.[0-9]+)", text).group(1))


def test_prism_prints_what_the_recheck_tables_say(fresh: Path) -> None:
    """Every PRISM command of docs/cli.md's re-checking tables, run on a fresh world1, prints
    the result the table shows, as PRISM prints it."""
    prism = _prism()
    if prism is None:
        pytest.skip("PRISM is not installed (set PRISM=/path/to/prism)")
    rows = [row for section in ("Re-checking a model", "Re-checking the strategy without hg2prism")
            for row in _recheck_rows(section) if row[1].startswith("`prism ")]
    assert len(rows) == 7
    folder = fresh / "world1"
    for _, command, prints in rows:
        words = shlex.split(command.split("`")[1].replace("models/world1/", f"{folder}/"))
        done = subprocess.run([prism, *words[1:]], cwd=folder, capture_output=True, text=True,
                              timeout=300)
        shown = prints.split("`")[1]
        printed = re.search(r"^Result: (\S+)", done.stdout, re.MULTILINE)
        assert printed and f"Result: {printed.group(1)}" == shown, (command, done.stdout[-500:])
    # "As with the model, PRISM's default stopping rule stops short (`0.9497436…` without
    # `-epsilon`)": the chain's command without it
    short = re.search(r"\(`([0-9.]+)…` without `-epsilon`\)",
                      (ROOT / "docs" / "cli.md").read_text()).group(1)
    chain = next(command for _, command, _ in rows
                 if "-importtrans" in command and "-epsilon" in command)
    words = shlex.split(chain.split("`")[1])
    done = subprocess.run([prism, *words[1:words.index("-epsilon")]], cwd=folder,
                          capture_output=True, text=True, timeout=300)
    assert f"Result: {short}" in done.stdout, done.stdout[-500:]


def test_stormpy_and_spot_print_what_the_recheck_tables_say(fresh: Path) -> None:
    """The stormpy snippet of docs/cli.md, the induced chain's DRN checked the same way, and
    Spot's reading of task.hoa, on a fresh world1."""
    import spot
    import stormpy
    import stormpy.environments

    folder = fresh / "world1"
    snippet = next(block for info, block in _blocks(ROOT / "docs" / "cli.md")
                   if info == "python" and "stormpy" in block)
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(snippet.replace("models/world1/", f"{folder}/"), {})
    claimed = _number_after(snippet.split("#")[-1])
    assert float(printed.getvalue()) == pytest.approx(claimed, abs=1e-15)
    # the exact snippet after it, run in the first's namespace: the fraction it says
    namespace: dict = {}
    blocks = [block for info, block in _blocks(ROOT / "docs" / "cli.md")
              if info == "python" and "stormpy" in block]
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        for block in blocks[:2]:
            exec(block.replace("models/world1/", f"{folder}/"), namespace)
    assert "build_model[stormpy.Rational]" in blocks[1]
    assert printed.getvalue().splitlines()[-1] == blocks[1].split("# ")[-1].strip()
    rows = {with_: prints for with_, _, prints in
            _recheck_rows("Re-checking the strategy without hg2prism")}
    model = stormpy.build_model_from_drn(str(folder / "induced.drn"))
    properties = stormpy.parse_properties('P=? [F "goal"]')
    env = stormpy.environments.sound()
    env.solver().min_max().precision = stormpy.Rational("1e-10")
    env.solver().native().precision = stormpy.Rational("1e-10")
    result = stormpy.model_checking(model, properties[0], environment=env)
    assert result.get_value(model.initial_states[0]) == pytest.approx(
        _number_after(rows["stormpy"]), abs=1e-15)
    automaton = spot.automaton(str(folder / "task.hoa"))
    assert rows["Spot"] == (f"the task DFA: {automaton.num_states()} states, initial state "
                            f"{automaton.get_init_state_number()}")


# ---- code blocks ----

def _blocks(path: Path) -> list[tuple[str, str]]:
    """(info string, text) of each fenced block; the info string's first word is the language."""
    return [(m.group(1).strip(), m.group(2)) for m in FENCE.finditer(path.read_text())]


def _signature_of(block: str) -> tuple[str, inspect.Signature] | None:
    """`x = hg2prism.f(params)` read as the signature of f; None when it is not one."""
    match = re.fullmatch(r"\s*\w+ = hg2prism\.(\w+)\((.*)\)\s*", block, re.DOTALL)
    if match is None:
        return None
    namespace: dict = {}
    exec(f"def {match.group(1)}({match.group(2)}): pass", namespace)
    return match.group(1), inspect.signature(namespace[match.group(1)])


def _plain(signature: inspect.Signature) -> list[tuple[str, object, object]]:
    """Names, kinds and defaults (not annotations)."""
    return [(p.name, p.kind, p.default) for p in signature.parameters.values()]


def _claims(block: str) -> list[str] | None:
    """What the block's `print(...)  # comment` lines say they print; None when a print has
    no comment."""
    prints = [line for line in block.splitlines() if line.startswith("print(")]
    if not prints or any("#" not in line for line in prints):
        return None
    return [line.split("#", 1)[1].split(":")[0].strip() for line in prints]


@pytest.mark.parametrize("document", ["README.md", "docs/api.md"])
def test_python_blocks_run(document: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    namespace = {"hg2prism": hg2prism}
    ran = 0
    for info, block in _blocks(ROOT / document):
        if info.split()[:1] != ["python"]:
            continue
        try:
            if "signature" in info.split():
                raise SyntaxError("a signature")
            code = compile(block, document, "exec")
        except SyntaxError:
            signature = _signature_of(block)
            assert signature is not None, f"{document}: neither Python nor a signature:\n{block}"
            name, documented = signature
            assert _plain(documented) == _plain(inspect.signature(getattr(hg2prism, name))), name
            continue
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            exec(code, namespace)
        claims = _claims(block)
        if claims is not None:
            assert printed.getvalue().splitlines() == claims, block
        ran += 1
    assert ran >= 1


def test_signature_blocks_are_checked() -> None:
    """A documented signature that differs from the function's is found."""
    name, documented = _signature_of("solution = hg2prism.solve(world, out=None)")
    assert name == "solve" and _plain(documented) != _plain(inspect.signature(hg2prism.solve))
    assert _signature_of("print(1)") is None


def _commands() -> list[tuple[str, list[str]]]:
    found = []
    for doc in docs.documents():
        for _, block in _blocks(doc):
            for line in block.splitlines():
                line = line.split(" #", 1)[0].strip()
                if line.startswith(("hg2prism ", "make ")):
                    found.append((doc.name, shlex.split(line)))
    return found


def test_commands_in_the_documents_parse() -> None:
    commands = _commands()
    assert any(words[0] == "hg2prism" for _, words in commands)
    parser = cli.build_parser()
    targets = set(re.findall(r"^([\w.-]+):", (ROOT / "Makefile").read_text(), re.MULTILINE))
    for doc, words in commands:
        if words[0] == "make":
            assert set(words[1:]) <= targets, (doc, words)
            continue
        try:
            parser.parse_args(words[1:])
        except SystemExit as stop:           # --version, --help: exit 0
            assert stop.code == 0, (doc, words)


# ---- what lists what ----

def test_tests_readme_lists_every_test_file() -> None:
    text = (ROOT / "tests" / "README.md").read_text()
    missing = [p.name for p in sorted((ROOT / "tests").glob("test_*.py"))
               if f"`tests/{p.name}`" not in text]
    assert missing == []


def test_architecture_lists_every_module() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text()
    package = ROOT / "hg2prism"
    modules = [str(p.relative_to(package)) for p in sorted(package.rglob("*.py"))
               if p.name != "__init__.py" and "__pycache__" not in p.parts]
    assert [m for m in modules if m not in text] == []


def test_readme_world_file_is_world3() -> None:
    """README's world file is models/world3.toml as it is, and a valid world."""
    text = (ROOT / "README.md").read_text()
    toml = [block for info, block in _blocks(ROOT / "README.md") if info == "toml"]
    assert toml == [(MODELS / "world3.toml").read_text()]
    assert "models/world3.toml" in text


# ---- the notebook ----

def test_the_tour_notebook_runs() -> None:
    import nbclient
    import nbformat

    notebook = nbformat.read(ROOT / "examples" / "tour.ipynb", as_version=4)
    client = nbclient.NotebookClient(notebook, timeout=180, kernel_name="python3",
                                     resources={"metadata": {"path": str(ROOT / "examples")}})
    client.execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    images = [o for o in outputs if o.output_type == "display_data" and "image/png" in o.data]
    assert len(images) == 3, "the world, P2's belief and the sweep"
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert "deceptive value 0.9498" in text


def test_world4_start_table_is_the_strategy_at_the_start_by_what_p1_knows(tmp_path: Path
                                                                          ) -> None:
    """docs/adaptive.md's table of P1's moves at world4's start: one row per knowledge (the
    consistent types and their guesses), each the strategy's values there; records P1 cannot
    tell apart by that knowledge but that differ are refused, not shown as one row."""
    records = json.loads((ROOT / "docs" / "data" / "world4" / "strategy.json").read_text())
    assert records[0]["types"] == {"jumpy": 0, "stubborn": 0}       # the initial record first
    table = docs.world4_start(docs.Outputs(ROOT / "docs" / "data"))
    assert len(table.splitlines()) == 2 + len(records)
    clash = [dict(records[0]), dict(records[0], action="W")]
    (tmp_path / "world4").mkdir()
    (tmp_path / "world4" / "strategy.json").write_text(json.dumps(clash))
    with pytest.raises(ValueError, match="cannot tell apart"):
        docs.world4_start(docs.Outputs(tmp_path))
    kept = docs.start_records([
        {"initial": True, "state": "s", "standing": None, "countdown": None, "q": 0,
         "types": {"a": {"hypothesis": 1, "window": []}}, "action": "N", "values": {"N": 1.0}},
        {"state": "s", "standing": None, "countdown": None, "q": 0,
         "types": {"a": {"hypothesis": 1, "window": ["w"]}}, "action": "N", "values": {"N": 1.0}},
        {"state": "t", "standing": None, "countdown": None, "q": 0,
         "types": {"a": {"hypothesis": 0, "window": []}}, "action": "S", "values": {"N": 0.5}}])
    assert kept == [{"types": {"a": 1}, "action": "N", "values": {"N": 1.0}}]


def test_the_arena_example_of_semantics_15_is_a_valid_world() -> None:
    """semantics §15's arena tables, with a task and an observer, make a valid world (its
    [arena.positions] gave one state of five, which the loader refuses: all or none)."""
    text = (ROOT / "docs" / "semantics.md").read_text()
    (block,) = [b for info, b in _blocks(ROOT / "docs" / "semantics.md")
                if info == "toml" and "[arena.positions]" in b]
    assert block in text
    world = hg2prism.world_from_toml(block + '\n[task]\nformula = "F crown"\n[inference]\n'
                                     'window = 1\nrationality = 1.0\nthreshold = 1.0\n')
    assert len(world.arena.positions) == len(world.arena.states) == 5


def test_the_showcase_figures_are_copied_from_the_outputs(tmp_path: Path) -> None:
    """Every figure in docs/ but the explorer's screenshot and the benchmark's plot is one
    `make docs` copies from a showcase world's outputs (docs/world2_detection.png had stayed
    behind its data), and the copy replaces only what differs."""
    shown = {p.name for p in (ROOT / "docs").iterdir() if p.suffix in (".png", ".svg", ".gif")}
    assert shown - {"world3_explorer.png"} == set(docs.FIGURES) | set(docs.ROOT_FIGURES)
    models = tmp_path / "models"
    (models / "world1").mkdir(parents=True)
    (models / "world1" / "belief.png").write_bytes(b"new")
    target = tmp_path / "docs"
    target.mkdir()
    (target / "world1_belief.png").write_bytes(b"old")
    assert docs.copy_figures(models, target) == ["world1_belief.png"]
    assert (target / "world1_belief.png").read_bytes() == b"new"
    assert docs.copy_figures(models, target) == []
