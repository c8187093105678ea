"""World files (docs/semantics.md §1): every kind of bad input gives one clear line, exit status 2, no output.

Each bad world is the valid BASE world (models/world1.toml's content, inlined) with one edit.
The CLI runs as a subprocess for a tenth of the cases, so a traceback reaching the terminal
would be seen, and in process (cli.main) for the others.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import names_in
from gridview import initial_trap_cells
from hg2prism.errors import InputError
from hg2prism.worldfile import load_world

REPO = Path(__file__).resolve().parent.parent
MODELS = REPO / "models"

BASE = '''name = "world1"
description = "the paper's world_1 rebuilt from its text"

[grid]
map = """
########
#......#
#.#A...#
#t@t..B#
#...o.##
#Ctt#.##
#..#...#
########
"""

[robot]
slip = 0.1

[task]
formula = "(!obs U A) & (!(B | obs) U C)"

[adversary]
traps = 1
delay = 0
initial_traps = []
hypotheses = ["!obs U A", "!obs U B", "!obs U C"]
initial_hypothesis = 0

[inference]
window = 2
threshold = 1.5
rationality = 10.0
'''


MAP_BLOCK = BASE[BASE.index('map = """'):BASE.index('"""\n\n[robot]') + 3]


def edit(*pairs: tuple[str, str]) -> str:
    """BASE with each (old, new) replaced exactly once (old must occur in BASE)."""
    text = BASE
    for old, new in pairs:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return text


def append(extra: str) -> str:
    return BASE + "\n" + extra


def _line_of(text: str, line: str) -> int:
    return text.splitlines().index(line) + 1


# (id, world text, expected key, a word of the expected reason)
CASES = [
    # --- TOML itself
    ("invalid-toml", edit(("slip = 0.1", "slip = = 0.1")),
     f"line {_line_of(BASE, 'slip = 0.1')}, column 8", "TOML"),
    # --- the map
    ("map-unknown-character", edit(("#......#", "#..?...#")), "grid.map", "unknown character"),
    ("map-lowercase-letter", edit(("#......#", "#..a...#")), "grid.map", "unknown character"),
    ("map-ragged-rows", edit(("#......#", "#.......#")), "grid.map", "ragged"),
    ("map-empty", edit((MAP_BLOCK, 'map = """\n\n  \n"""')), "grid.map", "empty"),
    ("map-no-start", edit(("#t@t..B#", "#t.t..B#")), "grid.map", "no robot start"),
    ("map-two-starts", edit(("#......#", "#...@..#")), "grid.map", "exactly one"),
    ("map-forbidden-region-letter", edit(("#......#", "#...F..#")), "grid.map", "not allowed"),
    # V is Spot's release operator: accepted, it made every formula using it fail to parse
    ("map-region-letter-v", edit(("#......#", "#...V..#")), "grid.map", "not allowed"),
    ("map-not-a-string", edit((MAP_BLOCK, "map = 3")), "grid.map", "string"),
    # --- robot
    ("slip-too-large", edit(("slip = 0.1", "slip = 0.5")), "robot.slip", "[0, 0.5)"),
    ("slip-negative", edit(("slip = 0.1", "slip = -0.1")), "robot.slip", "[0, 0.5)"),
    ("slip-not-finite", edit(("slip = 0.1", "slip = nan")), "robot.slip", "finite"),
    ("slip-bad-type-string", edit(("slip = 0.1", 'slip = "0.1"')), "robot.slip", "number"),
    ("slip-bad-type-bool", edit(("slip = 0.1", "slip = false")), "robot.slip", "number"),
    # --- task formula
    ("formula-does-not-parse", edit(('formula = "(!obs U A) &', 'formula = "((!obs U A) &')),
     "task.formula", "parse"),
    ("formula-not-co-safe", edit(('formula = "(!obs U A) & (!(B | obs) U C)"',
                                  'formula = "G !obs & F A"')), "task.formula", "co-safe"),
    ("formula-unknown-proposition", edit(('formula = "(!obs U A) & (!(B | obs) U C)"',
                                          'formula = "!obs U D"')), "task.formula", "proposition"),
    ("formula-empty", edit(('formula = "(!obs U A) & (!(B | obs) U C)"', 'formula = ""')),
     "task.formula", "empty"),
    # --- unknown keys / tables, missing keys / tables, table types
    ("unknown-key-in-table", edit(("slip = 0.1", "slip = 0.1\nspeed = 2")), "robot.speed",
     "unknown key in [robot]; expected one of: slip"),       # nothing close
    ("unknown-top-level-key", edit(('name = "world1"', 'nmae = "world1"')), "nmae",
     "unknown key at the top level; did you mean 'name'?; expected one of: "),
    ("unknown-table", append("[extras]\nx = 1\n"), "extras", "unknown"),
    ("unknown-subtable", append("[inference.extra]\nx = 1\n"), "inference.extra", "unknown"),
    ("missing-required-key", edit(("window = 2\n", "")), "inference.window", "missing"),
    ("missing-required-table", edit(('[task]\nformula = "(!obs U A) & (!(B | obs) U C)"\n', "")),
     "task", "missing"),
    ("table-not-a-table", edit(("[robot]\nslip = 0.1\n", ""), ('name = "world1"',
                                                             'name = "world1"\nrobot = 3')),
     "robot", "table"),
    # --- name / description
    ("name-empty", edit(('name = "world1"', 'name = ""')), "name", "empty"),
    ("name-bad-type", edit(('name = "world1"', "name = 1")), "name", "string"),
    # --- adversary
    ("traps-bad-type-bool", edit(("traps = 1", "traps = true")), "adversary.traps", "integer"),
    ("traps-bad-type-float", edit(("traps = 1", "traps = 1.0")), "adversary.traps", "integer"),
    ("traps-below-one", edit(("traps = 1", "traps = 0")), "adversary.traps", ">= 1"),
    ("fewer-candidates-than-traps", edit(("traps = 1", "traps = 5")), "adversary.traps", "only"),
    ("delay-negative", edit(("delay = 0", "delay = -1")), "adversary.delay", ">= 0"),
    ("initial-traps-wrong-count", edit(("delay = 0", "delay = 1")),
     "adversary.initial_traps", "expected"),
    ("initial-traps-missing", edit(("delay = 0", "delay = 2"), ("initial_traps = []\n", "")),
     "adversary.initial_traps", "required"),
    ("initial-traps-not-candidate", edit(("delay = 0", "delay = 1"),
                                         ("initial_traps = []", "initial_traps = [[2, 4]]")),
     "adversary.initial_traps[0]", "candidate"),
    ("initial-traps-repeated", edit(("traps = 1", "traps = 2"), ("delay = 0", "delay = 1"),
                                    ("initial_traps = []", "initial_traps = [[1, 4], [1, 4]]")),
     "adversary.initial_traps[1]", "distinct"),
    ("initial-traps-bad-item", edit(("delay = 0", "delay = 1"),
                                    ("initial_traps = []", "initial_traps = [[1, true]]")),
     "adversary.initial_traps[0]", "integers"),
    ("initial-traps-not-candidate-delay-0", edit(("initial_traps = []",
                                                  "initial_traps = [[2, 4]]")),
     "adversary.initial_traps[0]", "candidate"),
    ("initial-traps-wrong-count-delay-0", edit(("initial_traps = []",
                                                "initial_traps = [[1, 4], [3, 4]]")),
     "adversary.initial_traps", "what a sweep over delay starts from"),
    ("initial-traps-bad-type", edit(("initial_traps = []", 'initial_traps = "1,4"')),
     "adversary.initial_traps", "array"),
    ("hypotheses-empty", edit(('hypotheses = ["!obs U A", "!obs U B", "!obs U C"]',
                               "hypotheses = []")), "adversary.hypotheses", "empty"),
    ("hypotheses-repeated", edit(('hypotheses = ["!obs U A", "!obs U B", "!obs U C"]',
                                  'hypotheses = ["F (A & B)", "!obs U C", "F(B&A)"]')),
     "adversary.hypotheses[2]", "repeated"),
    ("hypotheses-equivalent", edit(('hypotheses = ["!obs U A", "!obs U B", "!obs U C"]',
                                    'hypotheses = ["F A", "!obs U C", "true U A"]')),
     "adversary.hypotheses[2]", "equivalent to hypotheses[0]"),
    ("hypothesis-not-co-safe", edit(('"!obs U C"]', '"G !obs"]')), "adversary.hypotheses[2]",
     "co-safe"),
    ("hypothesis-unknown-proposition", edit(('"!obs U C"]', '"!obs U goal"]')),
     "adversary.hypotheses[2]", "proposition"),
    ("hypothesis-not-a-string", edit(('"!obs U C"]', "3]")), "adversary.hypotheses[2]",
     "string"),
    ("initial-hypothesis-out-of-range", edit(("initial_hypothesis = 0", "initial_hypothesis = 3")),
     "adversary.initial_hypothesis", "index"),
    ("tie-break-unknown", edit(("initial_hypothesis = 0", 'initial_hypothesis = 0\ntie_break = "worst"')),
     "adversary.tie_break", 'expected "first" or "last"'),
    # --- inference
    ("window-below-one", edit(("window = 2", "window = 0")), "inference.window", ">= 1"),
    ("threshold-not-positive", edit(("threshold = 1.5", "threshold = 0")),
     "inference.threshold", "> 0"),
    ("threshold-infinite", edit(("threshold = 1.5", "threshold = inf")),
     "inference.threshold", "finite"),
    ("rationality-not-positive", edit(("rationality = 10.0", "rationality = -1.0")),
     "inference.rationality", "> 0"),
    # --- simulation
    ("episodes-below-one", append("[simulation]\nepisodes = 0\n"), "simulation.episodes", ">= 1"),
    ("horizon-below-one", append("[simulation]\nhorizon = 0\n"), "simulation.horizon", ">= 1"),
    ("seed-not-int", append("[simulation]\nseed = 1.5\n"), "simulation.seed", "integer"),
    ("seed-negative", append("[simulation]\nseed = -1\n"), "simulation.seed", ">= 0"),
    # --- detection
    ("alpha-outside-0-1", append("[detection]\nalpha = 1.0\n"), "detection.alpha", "(0, 1)"),
    ("epsilon-outside-0-1", append("[detection]\nepsilon = 0\n"), "detection.epsilon", "(0, 1)"),
    ("deviate-after-negative", append("[detection]\ndeviate_after = -1\n"),
     "detection.deviate_after", ">= 0"),
]


def run_cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "hg2prism", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=60)


def assert_one_error(proc: subprocess.CompletedProcess, file: str, key: str, word: str) -> None:
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    line = lines[0]
    assert line.startswith(f"hg2prism: error: {file}: "), line
    if key == "-":      # the whole file: no key shown ("nope.toml: file not found")
        assert ": -: " not in line and word in line.removeprefix(f"hg2prism: error: {file}: ")
        return
    assert f": {key}: " in line, line
    assert word in line.split(f": {key}: ", 1)[1], line


# The cases run through the CLI as a subprocess (a traceback reaching the terminal would be
# seen, and the exit status is the process's); the others call it in process (cli.main, whose
# status and stderr are the same), which is what makes this file fast.
SUBPROCESS_CASES = {case[0] for case in CASES[::10]}


def _cli(name: str, args: list[str], cwd: Path, capsys) -> subprocess.CompletedProcess:
    if name in SUBPROCESS_CASES:
        return run_cli(args, cwd)
    from hg2prism.cli import main

    capsys.readouterr()
    status = main(args)
    captured = capsys.readouterr()
    return subprocess.CompletedProcess(args, status, captured.out, captured.err)


@pytest.mark.parametrize("name,text,key,word", CASES, ids=[c[0] for c in CASES])
def test_bad_world(tmp_path: Path, capsys, name: str, text: str, key: str, word: str) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    out = tmp_path / "out"
    proc = _cli(name, ["run", str(bad), "--out", str(out)], tmp_path, capsys)
    assert_one_error(proc, str(bad), key, word)
    assert not out.exists() or not any(out.iterdir())
    # the default output folder (next to the world file) is not created either
    assert not (tmp_path / "bad").exists()

    proc = _cli(name, ["validate", str(bad)], tmp_path, capsys)
    assert_one_error(proc, str(bad), key, word)
    assert proc.stdout == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]

    with pytest.raises(InputError) as err:
        load_world(bad)
    assert (err.value.file, err.value.key) == (str(bad), key)
    assert word in err.value.reason and "\n" not in err.value.reason


def test_missing_file(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = run_cli(["run", "nope.toml", "--out", str(out)], tmp_path)
    assert_one_error(proc, "nope.toml", "-", "not found")
    assert not out.exists()


def test_not_utf8(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_bytes(BASE.encode() + b'\nx = "\xff"\n')
    proc = run_cli(["validate", str(bad)], tmp_path)
    assert_one_error(proc, str(bad), "-", "TOML")


def test_every_case_is_distinct() -> None:
    assert len({c[0] for c in CASES}) == len(CASES)
    assert len({c[1] for c in CASES}) == len(CASES)


# --------------------------------------------------------------------------------------------
# Valid worlds
# --------------------------------------------------------------------------------------------

def test_base_is_valid(tmp_path: Path) -> None:
    good = tmp_path / "good.toml"
    good.write_text(BASE)
    proc = run_cli(["validate", str(good)], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""


def test_world1_loads() -> None:
    w = load_world(MODELS / "world1.toml")
    # Derived by hand from the map (8 rows, so the top row is y = 7 and the last row y = 0):
    #   y=7 ########
    #   y=6 #......#
    #   y=5 #.#A...#     A at (3, 5); wall at (2, 5)
    #   y=4 #t@t..B#     start (2, 4); candidates (1, 4), (3, 4); B at (6, 4)
    #   y=3 #...o.##     obstacle (4, 3)
    #   y=2 #Ctt#.##     C at (1, 2); candidates (2, 2), (3, 2)
    #   y=1 #..#...#
    #   y=0 ########
    assert w.name == "world1"
    assert (w.grid.width, w.grid.height) == (8, 8)
    assert w.grid.start == (2, 4)
    assert w.grid.trap_candidates == ((1, 4), (3, 4), (2, 2), (3, 2))
    assert w.grid.regions == (("A", frozenset({(3, 5)})), ("B", frozenset({(6, 4)})),
                              ("C", frozenset({(1, 2)})))
    assert w.grid.obstacles == frozenset({(4, 3)})
    assert (2, 5) in w.grid.walls and (0, 0) in w.grid.walls and (7, 7) in w.grid.walls
    assert (3, 1) in w.grid.walls and (6, 3) in w.grid.walls and (4, 2) in w.grid.walls
    assert len(w.grid.walls) == 8 + 8 + 6 * 2 + 1 + 1 + 2 + 1  # borders, (2,5), (6,3), (4,2) (6,2), (3,1)
    assert w.grid.rows[0] == "########" and w.grid.rows[3] == "#t@t..B#"
    assert w.atomic_propositions() == ("obs", "A", "B", "C")
    assert w.formula == "(!obs U A) & (!(B | obs) U C)"
    assert w.hypotheses == ("!obs U A", "!obs U B", "!obs U C")
    assert (w.grid.slip, w.traps, w.delay, w.initial_standing, w.initial_hypothesis) == (0.1, 1, 0, 0, 0)
    assert initial_trap_cells(w) == ()
    assert (w.window, w.threshold, w.rationality) == (2, 1.5, 10.0)
    assert (w.simulation.episodes, w.simulation.horizon, w.simulation.seed) == (10000, 200, 0)
    assert (w.detection.alpha, w.detection.epsilon, w.detection.deviate_after) == (0.05, 0.01, 4)


def test_world2_loads() -> None:
    w = load_world(MODELS / "world2.toml")
    # Derived by hand from the map:
    #   y=7 ########
    #   y=6 ##.....#
    #   y=5 #.t.BA##     candidate (2, 5); B at (4, 5); A at (5, 5)
    #   y=4 #o@....#     obstacle (1, 4); start (2, 4)
    #   y=3 #..t.t.#     candidates (3, 3), (5, 3)
    #   y=2 #o.oC..#     obstacles (1, 2), (3, 2); C at (4, 2)
    #   y=1 #.....##
    #   y=0 ########
    assert w.grid.start == (2, 4)
    assert w.grid.trap_candidates == ((2, 5), (3, 3), (5, 3))
    assert w.grid.regions == (("A", frozenset({(5, 5)})), ("B", frozenset({(4, 5)})),
                              ("C", frozenset({(4, 2)})))
    assert w.grid.obstacles == frozenset({(1, 4), (1, 2), (3, 2)})
    # delay = 0: the listed initial_traps are ignored
    assert w.delay == 0 and initial_trap_cells(w) == () and w.initial_standing == 0


def test_world2_with_delay_keeps_initial_traps(tmp_path: Path) -> None:
    text = (MODELS / "world2.toml").read_text().replace("delay = 0", "delay = 2")
    path = tmp_path / "w2k2.toml"
    path.write_text(text)
    w = load_world(path)
    assert w.delay == 2 and initial_trap_cells(w) == ((2, 5),)


def test_initial_traps_sorted_by_candidate_number(tmp_path: Path) -> None:
    path = tmp_path / "w.toml"
    path.write_text(edit(("traps = 1", "traps = 2"), ("delay = 0", "delay = 1"),
                         ("initial_traps = []", "initial_traps = [[3, 2], [1, 4]]")))
    world = load_world(path)
    assert initial_trap_cells(world) == ((1, 4), (3, 2))
    # the standing action: the index of candidates {0, 3} among the 2-subsets of the four
    # candidates (1, 4), (3, 4), (2, 2), (3, 2) in combinations order: (0,1), (0,2), (0,3)
    assert world.initial_standing == 2


def test_no_obstacle_and_defaults(tmp_path: Path) -> None:
    # no 'o' in the map (obs is false everywhere but may still appear in formulas), no optional
    # keys, ints where floats are expected, one hypothesis
    text = '''
[grid]
map = """
#####
#@tA#
#####
"""
[robot]
slip = 0
[task]
formula = "!obs U A"
[adversary]
traps = 1
hypotheses = ["F A"]
[inference]
window = 1
threshold = 2
rationality = 1
'''
    path = tmp_path / "plain.toml"
    path.write_text(text)
    w = load_world(path)
    assert w.name == "plain" and w.description == ""
    assert w.grid.obstacles == frozenset()
    assert w.grid.start == (1, 1) and w.grid.trap_candidates == ((2, 1),)
    assert w.grid.regions == (("A", frozenset({(3, 1)})),)
    assert (w.grid.slip, w.threshold, w.rationality) == (0.0, 2.0, 1.0)
    assert isinstance(w.threshold, float) and isinstance(w.grid.slip, float)
    assert (w.delay, w.initial_standing, w.initial_hypothesis) == (0, 0, 0)
    assert w.simulation.episodes == 10000 and w.detection.deviate_after == 4


def test_optional_tables(tmp_path: Path) -> None:
    path = tmp_path / "w.toml"
    path.write_text(append("[simulation]\nepisodes = 5\nhorizon = 7\nseed = 3\n"
                           "[detection]\nalpha = 0.1\nepsilon = 0.2\ndeviate_after = 0\n"))
    w = load_world(path)
    assert (w.simulation.episodes, w.simulation.horizon, w.simulation.seed) == (5, 7, 3)
    assert (w.detection.alpha, w.detection.epsilon, w.detection.deviate_after) == (0.1, 0.2, 0)


@pytest.mark.parametrize("signal_name,status", [("SIGTERM", 143), ("SIGINT", 130)])
def test_stopped_run_leaves_nothing_half_written(tmp_path: Path, signal_name: str,
                                                 status: int) -> None:
    """A run stopped by SIGTERM or Ctrl-C while it simulates removes its staging folder."""
    import signal
    import time

    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    command = [sys.executable, "-m", "hg2prism", "run", str(MODELS / "world1.toml"),
               "--out", str(out), "--episodes", "1000000"]
    # A shell's background job inherits SIGINT ignored (and Python then keeps ignoring it), so
    # the child gets the default disposition back, as a command typed in a terminal has.
    proc = subprocess.Popen(command, cwd=tmp_path, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    # Wait until the model is checked (strategy.json staged): the simulations run from then on.
    while not any(tmp_path.glob(".out.staging-*/strategy.json")):
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
        time.sleep(0.05)
    proc.send_signal(getattr(signal, signal_name))
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == status, stderr
    assert "Traceback" not in stderr
    assert not list(tmp_path.glob(".out.staging-*"))
    assert not out.exists()


def test_staged_outputs_replace_earlier_ones(tmp_path: Path) -> None:
    """A re-run replaces the files and folders of the previous one (a sweep's delay_1/ ...) and
    keeps what it does not write."""
    from hg2prism.outputs import MANIFEST, staged

    out = tmp_path / "out"
    for run, files in enumerate((["a.txt", "sub/old.txt", "sub/both.txt", "kept.txt"],
                                 ["a.txt", "sub/both.txt", "sub/new.txt"])):
        with staged(out) as stage:
            for name in files:
                (stage / name).parent.mkdir(parents=True, exist_ok=True)
                (stage / name).write_text(f"run {run}")
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")
                  if p.is_file() and p.name != MANIFEST) == [
        "a.txt", "kept.txt", "sub/both.txt", "sub/new.txt"]
    assert (out / "sub" / "both.txt").read_text() == "run 1"
    assert (out / "kept.txt").read_text() == "run 0"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_a_record_hg2prism_did_not_place_is_not_read(tmp_path: Path) -> None:
    """A results.json or robust.json naming another world that hg2prism has no record of
    placing (an older version's, a copy without the manifest) does not make the folder
    another world's: it would never be removed, so every later command would remove the
    other commands' outputs (a review: check and detect wiped each other's in turn)."""
    from hg2prism.outputs import OWNED, staged

    out = tmp_path / "out"
    out.mkdir()
    (out / "robust.json").write_text('{"world": "old"}')
    every = "|".join(f"(?:{p})" for p in OWNED.values())
    for command, name in (("check", "results.json"), ("detect", "detection.json"),
                          ("check", "results.json")):
        with staged(out, owns=OWNED[command], world="one", every=every) as stage:
            (stage / name).write_text('{"world": "one"}')
    assert names_in(out) == ["detection.json", "results.json", "robust.json"]


def test_replacing_an_item_hg2prism_did_not_write_is_warned_about(tmp_path: Path,
                                                                  caplog) -> None:
    """What a command writes replaces the item of the same name; where hg2prism has no record
    of writing that one (the user's), a warning names it, once."""
    import logging

    from hg2prism.outputs import staged

    out = tmp_path / "out"
    (out / "table.md").parent.mkdir()
    (out / "table.md").write_text("mine")
    for run in range(2):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="hg2prism"):
            with staged(out) as stage:
                (stage / "table.md").write_text(f"run {run}")
                (stage / "other.md").write_text(f"run {run}")
        said = [r.getMessage() for r in caplog.records]
        assert said == ([f"warning: outputs: replaced table.md in {out}, which hg2prism has no "
                         "record of writing there (.hg2prism-outputs.json lists what it wrote)"]
                        if run == 0 else []), said
    assert (out / "table.md").read_text() == "run 1"


def test_two_commands_ending_at_once_both_enter_the_manifest(tmp_path: Path,
                                                            monkeypatch) -> None:
    """Two commands finishing in one folder at the same time: each reads the manifest, places
    its items and writes the manifest under a lock, so neither drops the other's items (a
    review paused one between its read and its write: the other's file was left unlisted)."""
    import threading

    from hg2prism import outputs

    out = tmp_path / "out"
    out.mkdir()
    read = outputs._placed
    inside = threading.Event()

    def slow_read(folder):
        found = read(folder)
        if threading.current_thread().name == "first":
            inside.set()
            time.sleep(0.5)         # the second command finishes meanwhile, if it can
        return found

    monkeypatch.setattr(outputs, "_placed", slow_read)

    def command(name: str) -> None:
        with outputs.staged(out) as stage:
            (stage / f"{name}.txt").write_text(name)

    first = threading.Thread(target=command, args=("first",), name="first")
    first.start()
    assert inside.wait(10)
    command("second")
    first.join()
    listed = json.loads((out / outputs.MANIFEST).read_text())["items"]
    assert listed == ["first.txt", "second.txt"]


def test_staged_outputs_replace_files_by_folders_and_back(tmp_path: Path) -> None:
    from hg2prism.outputs import staged

    out = tmp_path / "out"
    for run, folder in enumerate((False, True, False)):
        with staged(out) as stage:
            if folder:
                (stage / "x").mkdir()
                (stage / "x" / "inner.txt").write_text(f"run {run}")
            else:
                (stage / "x").write_text(f"run {run}")
        assert (out / "x").is_dir() == folder
        assert ((out / "x" / "inner.txt") if folder else (out / "x")).read_text() == f"run {run}"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


# --------------------------------------------------------------------------------------------
# Arena worlds (docs/semantics.md §15)
# --------------------------------------------------------------------------------------------

ARENA_BASE = '''name = "lateral"

[arena]
states = ["out", "web", "mail", "db", "hr"]
initial = "out"
propositions = ["crown", "payroll"]

[arena.labels]
db = ["crown"]
hr = ["payroll"]

[[arena.transition]]
state = "out"
action = "phish"
to = { mail = 0.6, out = 0.4 }

[[arena.transition]]
state = "web"
action = "scan"
to = { db = 0.5, web = 0.5 }

[[arena.transition]]
state = "mail"
action = "pivot_db"
p2 = "watch_db"
to = { mail = 1.0 }

[[arena.transition]]
state = "mail"
action = "pivot_db"
to = { db = 0.5, mail = 0.5 }

[task]
formula = "F crown"

[adversary]
actions = ["idle", "watch_db", "watch_hr"]
delay = 0
hypotheses = ["F crown", "F payroll"]

[inference]
window = 2
threshold = 0.6
rationality = 1.0
'''

P2_ENTRY = '''[[arena.transition]]
state = "mail"
action = "pivot_db"
p2 = "watch_db"
to = { mail = 1.0 }

'''
GENERAL = 'actions = ["idle", "watch_db", "watch_hr"]'
TRAPS = 'traps = 1\ntrap_candidates = ["web", "mail"]'


def arena_edit(*pairs: tuple[str, str], base: str = ARENA_BASE) -> str:
    text = base
    for old, new in pairs:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return text


TRAPS_BASE = arena_edit((P2_ENTRY, ""), (GENERAL, TRAPS))
PHISH = "to = { mail = 0.6, out = 0.4 }"

ARENA_CASES = [
    # --- grid or arena
    ("grid-and-arena", ARENA_BASE + '\n[grid]\nmap = """\n#@#\n"""\n', "arena", "not both"),
    ("neither-grid-nor-arena", edit(("[grid]\n" + MAP_BLOCK, "")), "grid", "arena"),
    ("robot-in-arena-world", ARENA_BASE + "\n[robot]\nslip = 0.1\n", "robot", "unknown"),
    # --- states and propositions
    ("states-empty", arena_edit(('states = ["out", "web", "mail", "db", "hr"]', "states = []")),
     "arena.states", "empty"),
    ("states-duplicate", arena_edit(('"db", "hr"]', '"db", "hr", "web"]')), "arena.states[5]",
     "repeated"),
    ("state-not-identifier", arena_edit(('"db", "hr"]', '"db", "hr", "h r"]')),
     "arena.states[5]", "identifier"),
    ("state-reserved", arena_edit(('"db", "hr"]', '"db", "hr", "trapped"]')),
     "arena.states[5]", "reserved"),
    ("initial-unknown", arena_edit(('initial = "out"', 'initial = "inside"')), "arena.initial",
     "unknown state"),
    # an episode that ends before P1 moves: an empty strategy, a value of 0 or 1 (accepted)
    ("initial-terminal", arena_edit(('initial = "out"', 'initial = "db"')), "arena.initial",
     "'db' is terminal (no [[arena.transition]] entry): the episode would end before P1 moves"),
    ("proposition-not-identifier", arena_edit(('["crown", "payroll"]', '["crown", "pay-roll"]')),
     "arena.propositions[1]", "identifier"),
    ("proposition-spot-operator", arena_edit(('["crown", "payroll"]', '["crown", "F"]')),
     "arena.propositions[1]", "Spot operator"),
    # a name alone, an operator beside others ("F (payroll | xor)" did not parse)
    ("proposition-operator-in-a-formula", arena_edit(('["crown", "payroll"]', '["crown", "xor"]')),
     "arena.propositions[1]", "Spot operator inside a formula"),
    ("proposition-true", arena_edit(('["crown", "payroll"]', '["crown", "true"]')),
     "arena.propositions[1]", "Spot"),
    ("proposition-read-as-operators", arena_edit(('["crown", "payroll"]', '["crown", "Fa"]')),
     "arena.propositions[1]", "plain atomic proposition"),
    ("proposition-quoted-by-spot", arena_edit(('["crown", "payroll"]', '["crown", "X1"]')),
     "arena.propositions[1]", "plain atomic proposition"),
    ("label-unknown-state", arena_edit(('db = ["crown"]', 'dbb = ["crown"]')), "arena.labels.dbb",
     "unknown state"),
    ("label-unknown-proposition", arena_edit(('db = ["crown"]', 'db = ["crwn"]')),
     "arena.labels.db[0]", "unknown proposition"),
    ("label-operator-without-propositions",
     arena_edit(('propositions = ["crown", "payroll"]\n', ""), ('db = ["crown"]', 'db = ["G"]')),
     "arena.labels.db[0]", "Spot operator"),
    ("formula-unknown-arena-proposition", arena_edit(('formula = "F crown"', 'formula = "F gold"')),
     "task.formula", "arena's propositions"),
    ("hypothesis-unknown-arena-proposition",
     arena_edit(('hypotheses = ["F crown", "F payroll"]', 'hypotheses = ["F crown", "F pay"]')),
     "adversary.hypotheses[1]", "proposition"),
    ("positions-missing-state", arena_edit(('hr = ["payroll"]\n', 'hr = ["payroll"]\n\n'
                                            '[arena.positions]\nout = [0, 0]\n')),
     "arena.positions", "every state"),
    # --- transitions
    ("no-transitions", TRAPS_BASE[:TRAPS_BASE.index("[[arena.transition]]")]
     + TRAPS_BASE[TRAPS_BASE.index("[task]"):], "arena.transition", "missing"),
    ("transition-unknown-key", arena_edit((PHISH, PHISH + "\nprob = 1")),
     "arena.transition[0].prob", "unknown"),
    ("transition-unknown-state", arena_edit(('state = "out"', 'state = "outt"')),
     "arena.transition[0].state", "unknown state"),
    ("action-not-identifier", arena_edit(('action = "phish"', 'action = "ph-ish"')),
     "arena.transition[0].action", "identifier"),
    ("probabilities-not-summing-to-1", arena_edit((PHISH, "to = { mail = 0.6, out = 0.3 }")),
     "arena.transition[0].to", "sum"),
    ("probability-negative", arena_edit((PHISH, "to = { out = -0.2, mail = 1.2 }")),
     "arena.transition[0].to.out", "negative"),
    # finite numbers whose sum overflows: refused one by one (a traceback before)
    ("probability-above-one", arena_edit((PHISH, "to = { mail = 1e308, out = 1e308 }")),
     "arena.transition[0].to.mail", "above 1"),
    ("probability-not-a-number", arena_edit((PHISH, 'to = { mail = "0.6", out = 0.4 }')),
     "arena.transition[0].to.mail", "number"),
    ("to-unknown-state", arena_edit((PHISH, "to = { mall = 0.6, out = 0.4 }")),
     "arena.transition[0].to.mall", "unknown state 'mall'; did you mean 'mail'?; states are "),
    ("to-unknown-state-far", arena_edit((PHISH, "to = { exfil = 0.6, out = 0.4 }")),
     "arena.transition[0].to.exfil", "unknown state 'exfil'; states are "),
    ("to-empty", arena_edit((PHISH, "to = {}")), "arena.transition[0].to", "empty"),
    ("p2-unknown-action", arena_edit(('p2 = "watch_db"', 'p2 = "watch_dv"')),
     "arena.transition[2].p2", "unknown P2 action"),
    ("p2-empty", arena_edit(('p2 = "watch_db"', "p2 = []")), "arena.transition[2].p2", "empty"),
    ("p2-with-traps", arena_edit((GENERAL, TRAPS)), "arena.transition[2].p2", "only allowed"),
    ("uncovered-p2-action", arena_edit(("to = { db = 0.5, mail = 0.5 }", "p2 = \"idle\"\n"
                                        "to = { db = 0.5, mail = 0.5 }")),
     "arena.transition[2]", "covered"),
    ("p2-action-named-twice", arena_edit(("to = { db = 0.5, mail = 0.5 }", "p2 = [\"idle\", "
                                          "\"watch_db\"]\nto = { db = 0.5, mail = 0.5 }")),
     "arena.transition[3].p2", "named again"),
    # an entry without p2 where every P2 action has its own: it was accepted, and never read
    ("entry-without-p2-covering-nothing",
     arena_edit(('p2 = "watch_db"', 'p2 = ["idle", "watch_db", "watch_hr"]')),
     "arena.transition[3]", "covers no P2 action"),
    ("two-entries-without-p2", arena_edit((P2_ENTRY, P2_ENTRY.replace('p2 = "watch_db"\n', ""))),
     "arena.transition[3]", "second entry"),
    # --- P2
    ("p2-action-not-identifier", arena_edit((GENERAL, 'actions = ["idle", "watch db"]')),
     "adversary.actions[1]", "identifier"),
    ("p2-actions-repeated", arena_edit((GENERAL, 'actions = ["idle", "watch_db", "idle"]')),
     "adversary.actions[2]", "repeated"),
    ("actions-and-traps", arena_edit((GENERAL, GENERAL + "\ntraps = 1")), "adversary.traps",
     "not both"),
    ("neither-actions-nor-traps", arena_edit((GENERAL + "\n", "")), "adversary", "missing"),
    ("initial-action-missing", arena_edit(("delay = 0", "delay = 1")),
     "adversary.initial_action", "required"),
    ("initial-action-not-in-a2", arena_edit(("delay = 0", 'delay = 1\ninitial_action = "nap"')),
     "adversary.initial_action", "unknown P2 action"),
    # with delay 0 the standing action is what a sweep over delay starts from: checked too
    # (an unknown name was accepted, and the sweep took P2's first action)
    ("initial-action-not-in-a2-delay-0", arena_edit(("delay = 0",
                                                     'delay = 0\ninitial_action = "nap"')),
     "adversary.initial_action", "unknown P2 action"),
    ("trap-candidates-with-actions", arena_edit((GENERAL, GENERAL + '\ntrap_candidates = ["web"]')),
     "adversary.trap_candidates", "only with traps"),
    ("initial-action-with-traps", arena_edit(("delay = 0", 'delay = 0\ninitial_action = "web"'),
                                             base=TRAPS_BASE),
     "adversary.initial_action", "only with general"),
    ("trap-candidate-not-a-state", arena_edit(('["web", "mail"]', '["web", "mall"]'),
                                              base=TRAPS_BASE),
     "adversary.trap_candidates[1]", "unknown state"),
    ("trap-candidates-repeated", arena_edit(('["web", "mail"]', '["web", "web"]'), base=TRAPS_BASE),
     "adversary.trap_candidates[1]", "repeated"),
    ("trap-candidates-missing", arena_edit(('\ntrap_candidates = ["web", "mail"]', ""),
                                           base=TRAPS_BASE),
     "adversary.trap_candidates", "missing"),
    ("more-traps-than-candidates", arena_edit(("traps = 1", "traps = 3"), base=TRAPS_BASE),
     "adversary.traps", "only 2"),
    ("initial-traps-missing-arena", arena_edit(("delay = 0", "delay = 1"), base=TRAPS_BASE),
     "adversary.initial_traps", "required"),
    ("initial-traps-not-a-candidate", arena_edit(("delay = 0", 'delay = 1\ninitial_traps = ["db"]'),
                                                 base=TRAPS_BASE),
     "adversary.initial_traps[0]", "not a trap candidate"),
    ("initial-traps-not-a-candidate-delay-0",
     arena_edit(("delay = 0", 'delay = 0\ninitial_traps = ["db"]'), base=TRAPS_BASE),
     "adversary.initial_traps[0]", "not a trap candidate"),
    ("initial-traps-wrong-count-delay-0",
     arena_edit(("delay = 0", 'delay = 0\ninitial_traps = ["web", "mail"]'), base=TRAPS_BASE),
     "adversary.initial_traps", "expected 1"),
    ("initial-traps-wrong-count-arena",
     arena_edit(("delay = 0", 'delay = 1\ninitial_traps = ["web", "mail"]'), base=TRAPS_BASE),
     "adversary.initial_traps", "expected 1"),
]


def test_every_arena_case_is_distinct() -> None:
    assert len({c[0] for c in ARENA_CASES}) == len(ARENA_CASES)
    assert len({c[1] for c in ARENA_CASES}) == len(ARENA_CASES)
    for text in (ARENA_BASE, TRAPS_BASE):
        assert load_world_text(text).arena is not None


def load_world_text(text: str):
    from hg2prism.worldfile import world_from_toml

    return world_from_toml(text, name="base.toml")


@pytest.mark.parametrize("text,key,word", [c[1:] for c in ARENA_CASES],
                         ids=[c[0] for c in ARENA_CASES])
def test_bad_arena_world(tmp_path: Path, capsys, text: str, key: str, word: str) -> None:
    """In process (the grid cases above show that the CLI's subprocess prints no traceback):
    load_world's error, validate's and run's one line, exit status 2, nothing written."""
    from hg2prism.cli import main

    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    with pytest.raises(InputError) as err:
        load_world(bad)
    assert (err.value.file, err.value.key) == (str(bad), key), err.value
    assert word in err.value.reason and "\n" not in err.value.reason, err.value
    for args in (["validate", str(bad)], ["run", str(bad), "--out", str(tmp_path / "out")],
                 ["convert", str(bad), "--out", str(tmp_path / "conv.toml")]):
        assert main(args) == 2
        captured = capsys.readouterr()
        assert captured.out == ""
        assert captured.err == f"hg2prism: error: {err.value}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_an_entry_s_error_says_where_the_entry_starts(tmp_path: Path) -> None:
    """Entries are counted from 0 in keys (arena.transition[2] is the third): the reason adds
    the line of the entry's [[arena.transition]] (a review searched a long file for the 17th);
    [[type]] entries alike; a key that names no entry gets no line."""
    headers = [n for n, line in enumerate(ARENA_BASE.splitlines(), 1)
               if line == "[[arena.transition]]"]
    bad = tmp_path / "bad.toml"
    bad.write_text(arena_edit(('p2 = "watch_db"', 'p2 = "watch_dv"')))
    with pytest.raises(InputError) as err:
        load_world(bad)
    assert err.value.key == "arena.transition[2].p2"
    assert err.value.reason.endswith(f"(the entry at line {headers[2]})"), err.value
    bad.write_text(arena_edit(('states = ["out", "web", "mail", "db", "hr"]',
                               'states = ["out", "web", "mail", "db", "hr", "hr"]')))
    with pytest.raises(InputError) as err:
        load_world(bad)
    assert "line" not in err.value.reason
    typed = ARENA_BASE.replace("[inference]\nwindow = 2\nthreshold = 0.6\nrationality = 1.0\n",
                               '[[type]]\nname = "a"\nweight = 1\n[type.inference]\n'
                               'window = 1\nthreshold = 0.6\nrationality = 1.0\n'
                               '\n[[type]]\nname = "b"\nweight = 1\n[type.inference]\n'
                               'window = 0\nthreshold = 0.6\nrationality = 1.0\n')
    assert typed != ARENA_BASE
    bad.write_text(typed)
    with pytest.raises(InputError) as err:
        load_world(bad)
    second = [n for n, line in enumerate(typed.splitlines(), 1) if line == "[[type]]"][1]
    assert err.value.key.startswith("type[1]") and err.value.reason.endswith(
        f"(the entry at line {second})"), err.value


def test_an_entry_table_written_with_one_bracket_is_said(tmp_path: Path) -> None:
    """[arena.transition] for [[arena.transition]]: the TOML parser's words ("Cannot declare
    ('arena', 'transition') twice") and the fix, in one line."""
    bad = tmp_path / "bad.toml"
    text = ARENA_BASE.replace("[[arena.transition]]", "[arena.transition]")
    assert text != ARENA_BASE
    bad.write_text(text)
    with pytest.raises(InputError) as err:
        load_world(bad)
    assert err.value.key.startswith("line ") and err.value.reason.startswith("not valid TOML: ")
    assert err.value.reason.endswith("; each entry of [[arena.transition]] starts with two "
                                     "brackets (a line [arena.transition] is one table)")
    for other in (ARENA_BASE.replace("[adversary]", "[adversary]]"),       # another mistake
                  text.replace('name = "lateral"', 'name = "lateral'),       # ... beside it
                  ARENA_BASE.replace('name = "lateral"', 'name = "lateral"\ndescription = '
                                     '"""\n[type]\n"""\nbad = = 1')):
        bad.write_text(other)
        with pytest.raises(InputError) as err:
            load_world(bad)
        assert "two brackets" not in err.value.reason, err.value


def test_arena_base_worlds_validate(tmp_path: Path) -> None:
    for name, text in (("general", ARENA_BASE), ("traps", TRAPS_BASE)):
        path = tmp_path / f"{name}.toml"
        path.write_text(text)
        proc = run_cli(["validate", str(path)], tmp_path)
        assert proc.returncode == 0 and proc.stderr == "", proc.stderr
        assert proc.stdout.startswith(f"{path}: ok (lateral: arena of 5 states, ")


def test_a_stop_while_a_pool_starts_a_worker_waits_for_it() -> None:
    """A signal can stop a command while a thread pool is starting a worker: the worker is then
    listed but not started, and joining it raised "cannot join thread before it is started"
    (a traceback instead of the stop's exit status; seen once in the suite). It is waited for
    instead, and joined once it runs."""
    import threading
    import time

    from hg2prism.outputs import _join_pool_workers

    worker = threading.Thread(target=lambda: time.sleep(0.02), name="ThreadPoolExecutor-test")
    run = worker._bootstrap_inner

    def late() -> None:             # the worker starts running only after a while
        time.sleep(0.05)
        run()

    worker._bootstrap_inner = late
    threading.Thread(target=worker.start).start()
    time.sleep(0.01)
    assert not worker._started.is_set()     # listed, not started: the case
    _join_pool_workers()
    assert worker._started.is_set() and not worker.is_alive()


def test_a_prism_model_given_for_a_world_file_is_said(tmp_path: Path) -> None:
    """`hg2prism check hypergame.prism` said only "not valid TOML: Invalid statement" (a PRISM
    user's review): a file named as one of hg2prism's outputs is said to be no world file. A
    world file named otherwise keeps the parser's words alone."""
    for name in ("hypergame.prism", "hypergame.props", "induced.drn"):
        model = tmp_path / name
        model.write_text("// Hypergame MDP\nmdp\n")
        with pytest.raises(InputError) as err:
            load_world(model)
        assert err.value.reason == (
            f"not valid TOML: Invalid statement; {name} is no world file: hg2prism's commands "
            f"read a world file (TOML, a .toml; docs/semantics.md §1), and write the PRISM "
            f"models and the exports"), err.value
    (tmp_path / "mine.world").write_text("// Hypergame MDP\nmdp\n")
    with pytest.raises(InputError) as err:
        load_world(tmp_path / "mine.world")
    assert err.value.reason == "not valid TOML: Invalid statement"
