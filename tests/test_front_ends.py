"""The front-end registry (frontends/__init__.py): a third kind of world, the corridor of
tests/frontend_line.py, defined there alone and registered from the test, loads, validates and
solves with no edit to the package, and gives what its arena form (the same world written as an
arena world file by `hg2prism convert`'s writer) gives.
"""

from __future__ import annotations

import json

import pytest

import hg2prism
from hg2prism import cli, frontends
from hg2prism.errors import InputError
from conftest import MODELS
from hg2prism.frontends.arena import to_toml

TEXT = """
name = "corridor"
[line]
cells = ["B", "", "", "", "", "A"]
start = 2
advance = 0.8
[task]
formula = "F A"
[adversary]
traps = 1
candidates = [1, 4]
hypotheses = ["F A", "F B"]
initial_hypothesis = 1
[inference]
window = 1
threshold = 0.5
rationality = 4.0
"""


@pytest.fixture
def corridors(monkeypatch):
    """The corridor kind registered: one line, as a kind of the package is."""
    monkeypatch.setitem(frontends.FRONT_ENDS, "line", "frontend_line")


def test_a_kind_unregistered_is_no_world() -> None:
    with pytest.raises(InputError) as caught:
        hg2prism.world_from_toml(TEXT, "corridor.toml")
    assert caught.value.key == "grid" and "missing required table" in str(caught.value)


def test_a_registered_kind_loads_and_is_described(corridors, tmp_path, capsys) -> None:
    world = hg2prism.world_from_toml(TEXT, "corridor.toml")
    assert world.front.kind == "line" and world.grid is None and world.arena is None
    assert world.atomic_propositions() == ("A", "B")
    assert frontends.describe(world) == "corridor of 6 cells"
    assert frontends.parameters(world) == {"advance": 0.8}
    path = tmp_path / "corridor.toml"
    path.write_text(TEXT)
    assert cli.main(["validate", str(path)]) == 0
    assert "corridor of 6 cells" in capsys.readouterr().out
    # its own settings through World.replace, checked by its own rule; others' refused
    assert world.replace(advance=0.5).front.advance == 0.5
    assert world.replace(advance=0.5).digest() != world.digest()
    with pytest.raises(InputError) as caught:
        world.replace(advance=1.5)
    assert caught.value.key == "line.advance" and "(0, 1]" in str(caught.value)
    with pytest.raises(InputError) as caught:
        world.replace(slip=0.1)
    assert caught.value.key == "slip"


@pytest.mark.parametrize("change, key, words", [
    (("advance = 0.8", "advance = 2.0"), "line.advance", "(0, 1]"),
    (('cells = ["B", "", "", "", "", "A"]', 'cells = ["A"]'), "line.cells", "at least two"),
    (("candidates = [1, 4]\n", ""), "adversary.candidates", "missing required key"),
    (("traps = 1", "traps = 3"), "adversary.traps", "only 2 candidates"),
    (('formula = "F A"', 'formula = "F C"'), "task.formula", "the corridor's letters (A, B)"),
    (("[line]", "[grid]\nmap = '.'\n[robot]\nslip = 0.0\n[line]"), "line",
     "a grid world ([grid] and [robot]), an arena world ([arena]) or a corridor world ([line]), "
     "only one of them; remove one"),
])
def test_its_files_get_one_line_errors(corridors, change, key, words) -> None:
    with pytest.raises(InputError) as caught:
        hg2prism.world_from_toml(TEXT.replace(*change), "corridor.toml")
    assert caught.value.key == key and words in str(caught.value), str(caught.value)
    assert caught.value.file == "corridor.toml" and "\n" not in str(caught.value)


def test_it_solves_as_its_arena_form(corridors, tmp_path) -> None:
    """Through the whole pipeline (the games, the PRISM model, Storm, the strategy and its
    files): the corridor and its arena-world form have the same values and strategy."""
    world = hg2prism.world_from_toml(TEXT, "corridor.toml")
    twin = hg2prism.world_from_toml(to_toml(world), "corridor_arena.toml")
    assert twin.arena is not None
    mine, theirs = hg2prism.solve(world, out=tmp_path / "line"), hg2prism.solve(twin)
    assert mine.deceptive_value > mine.v_lead       # 0.64 > 0: her first guess is B
    assert mine.deceptive_value == pytest.approx(theirs.deceptive_value, abs=1e-12)
    assert mine.v_lead == pytest.approx(theirs.v_lead, abs=1e-12)
    assert (mine.states, mine.transitions) == (theirs.states, theirs.transitions)
    assert mine.strategy.records == theirs.strategy.records
    results = json.loads((tmp_path / "line" / "results.json").read_text())
    assert results["parameters"]["advance"] == 0.8


def test_its_own_setting_is_swept(corridors, tmp_path) -> None:
    """The kind's SETTINGS are sweep parameters, though it was registered after the sweep was
    imported; refused on other kinds of world with the kind named."""
    from hg2prism.experiments import sweep

    assert "advance" in sweep.sweep_parameters()
    world = hg2prism.world_from_toml(TEXT, "corridor.toml")
    table = hg2prism.sweep(world, "advance", [0.5, 1.0])
    values = [row.deceptive_value for row in table.rows]
    assert len(values) == 2 and values[1] > values[0]       # surer steps, surer to the goal
    for advance, value in zip((0.5, 1.0), values):
        assert value == pytest.approx(hg2prism.solve(world.replace(advance=advance))
                                      .deceptive_value, abs=1e-12)
    # on worker processes too: each point's task carries the registry (it lacked the kind)
    parallel = hg2prism.sweep(world, "advance", [0.5, 1.0], workers=2)
    assert [row.deceptive_value for row in parallel.rows] == values
    grid_world = hg2prism.load_world(MODELS / "world1.toml")
    with pytest.raises(InputError) as caught:
        hg2prism.sweep(grid_world, "advance", [0.5])
    assert "applies to corridor worlds only; world1 is a grid world" in str(caught.value)


def test_its_setting_bounded_at_most_one_is_checked_by_the_sweep(corridors) -> None:
    """advance is in (0, 1]: its Setting says so (`below` inclusive, `at_most`), so the sweep's
    own parameter check accepts 1 and refuses 1.5 with the setting's one line (1.5 reached
    the world, whose own check refused it under another key); the grid's slip keeps its
    exclusive bound."""
    from hg2prism.errors import COMMAND_LINE
    from hg2prism.experiments import sweep
    from hg2prism.frontends.grid import SLIP_EXPECTED

    assert sweep.parse_sweep_values("advance", ["1", 1.0 - 1e-9]) == [1.0, 1.0 - 1e-9]
    world = hg2prism.world_from_toml(TEXT, "corridor.toml")
    assert sweep.sweep_world(world, "advance", 1).front.advance == 1.0
    for bad in ("1.5", 1.5, "1.0000001"):
        with pytest.raises(InputError) as caught:
            sweep.parse_sweep_values("advance", [bad])
        assert (caught.value.file, caught.value.key) == (COMMAND_LINE, "--values")
        assert caught.value.reason == f"advance value {bad} must be a number in (0, 1]"
    with pytest.raises(InputError) as caught:
        hg2prism.sweep(world, "advance", [0.5, 1.5])
    assert (caught.value.file, caught.value.key) == ("sweep()", "values")
    assert caught.value.reason == "advance value 1.5 must be a number in (0, 1]"
    with pytest.raises(InputError) as caught:
        sweep.parse_sweep_values("slip", ["0.5"])
    assert caught.value.reason == f"slip value 0.5 must be {SLIP_EXPECTED}"
    assert sweep.parse_sweep_values("slip", ["0.49"]) == [0.49]


def test_a_setting_named_as_another_kinds_is_one_line(corridors, monkeypatch, capsys) -> None:
    """Settings share one namespace (sweep parameters): a kind whose setting is named as the
    grid's `slip` made every command, `validate` of a grid world included, a traceback
    (ValueError while the command line was built). Now one line naming both owners, exit 2."""
    import dataclasses

    import frontend_line

    from hg2prism.cli import main

    from hg2prism.experiments import sweep

    clash = dataclasses.replace(frontend_line.SETTINGS[0], name="slip")
    monkeypatch.setattr(frontend_line, "SETTINGS", (clash,))
    monkeypatch.setattr(sweep, "_TABLES", {})      # built before, with the kind's own name
    assert main(["validate", str(MODELS / "world1.toml")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("hg2prism: error: sweep parameters: slip: defined by both front "
                               "end 'grid' (hg2prism.frontends.grid, SETTINGS) and front end "
                               "'line' (frontend_line, SETTINGS)"), lines[0]


def test_a_plugin_named_in_the_environment_registers_a_kind(monkeypatch, tmp_path,
                                                            capsys) -> None:
    """HG2PRISM_PLUGINS: the command line imports the modules it names before reading its
    arguments, so a kind that a module outside the package registers is a world kind of every
    command, its setting a sweep parameter (the command line could not load one before);
    a module that cannot be imported, or fails, is one line naming the variable."""
    from hg2prism.cli import main
    from hg2prism.experiments import sweep

    (tmp_path / "corridor_plugin.py").write_text(
        "from hg2prism import frontends\nfrontends.FRONT_ENDS['line'] = 'frontend_line'\n")
    (tmp_path / "broken_plugin.py").write_text("raise RuntimeError('no licence found')\n")
    (tmp_path / "corridor.toml").write_text(TEXT)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(frontends, "FRONT_ENDS", dict(frontends.FRONT_ENDS))   # restored after
    monkeypatch.setattr(sweep, "_TABLES", {})
    world = str(tmp_path / "corridor.toml")

    assert main(["validate", world]) == 2                     # not registered: not a world
    capsys.readouterr()
    monkeypatch.setenv("HG2PRISM_PLUGINS", "corridor_plugin")
    assert main(["validate", world]) == 0
    assert "corridor" in capsys.readouterr().out
    assert "advance" in sweep.sweep_parameters()
    for value, words in (("nope_plugin", "HG2PRISM_PLUGINS: nope_plugin: no such module"),
                         ("broken_plugin", "HG2PRISM_PLUGINS: broken_plugin: importing it "
                                           "failed: RuntimeError: no licence found"),
                         ("corridor_plugin, 3x", "HG2PRISM_PLUGINS: 3x: not a module name")):
        monkeypatch.setenv("HG2PRISM_PLUGINS", value)
        assert main(["validate", world]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"hg2prism: error: {words}"), err


def test_a_bad_adversary_table_is_one_line(corridors) -> None:
    """The kind's `read` looks at [adversary]: the loader has checked it is a table."""
    text = "adversary = 3\n" + TEXT[:TEXT.index("[adversary]")] + TEXT[TEXT.index("[inference]"):]
    with pytest.raises(InputError) as caught:
        hg2prism.world_from_toml(text, "corridor.toml")
    assert caught.value.key == "adversary" and "must be a table" in str(caught.value)


def test_a_world_of_a_kind_no_longer_registered(monkeypatch) -> None:
    monkeypatch.setitem(frontends.FRONT_ENDS, "line", "frontend_line")
    world = hg2prism.world_from_toml(TEXT, "corridor.toml")
    monkeypatch.delitem(frontends.FRONT_ENDS, "line")
    with pytest.raises(InputError) as caught:
        hg2prism.solve(world)
    assert caught.value.key == "front" and "no front end of kind 'line'" in str(caught.value)


def test_replace_checks_the_new_fronts_settings() -> None:
    """A setting of the old front given with a new one is the new one's to accept: an arena
    has no slip (it was applied to the Arena, a TypeError)."""
    world = hg2prism.load_world(MODELS / "world1.toml")
    with pytest.raises(InputError) as caught:
        world.replace(front=frontends.arena_of(world), slip=0.2)
    assert caught.value.key == "slip" and "not a setting of this world" in str(caught.value)
    assert world.replace(front=frontends.arena_of(world)).arena is not None
