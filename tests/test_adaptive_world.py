"""Worlds with P2's types (docs/semantics.md §16): `[[type]]` read and validated with one line
per problem, for grid and arena worlds; `world_of_type` is each type's ordinary world."""

from __future__ import annotations

import pytest

from hg2prism.errors import InputError
from hg2prism.worldfile.loader import world_from_toml
from hg2prism.worldfile.types import weights, world_of_type
from conftest import names_in

HEAD = '''name = "typed"
[grid]
map = """
#######
#..#..#
#At@tB#
#t....#
#######
"""
[robot]
slip = 0.2
[task]
formula = "!obs U A"
[adversary]
traps = 1
hypotheses = ["!obs U A", "!obs U B"]
'''

JUMPY = '''[[type]]
name = "jumpy"
weight = 1
initial_hypothesis = 1
[type.inference]
window = 1
threshold = 0.3
rationality = 10.0
'''

STUBBORN = '''[[type]]
name = "stubborn"
weight = 3
[type.inference]
kind = "bayes"
window = 2
rationality = 5.0
'''

ARENA_HEAD = '''name = "typed-arena"
[arena]
states = ["s", "m", "g", "d"]
initial = "s"
propositions = ["goal", "decoy"]
[arena.labels]
g = ["goal"]
d = ["decoy"]
[[arena.transition]]
state = "s"
action = "go"
to = { m = 1.0 }
[[arena.transition]]
state = "m"
action = "left"
to = { g = 1.0 }
[[arena.transition]]
state = "m"
action = "right"
to = { d = 1.0 }
[task]
formula = "F goal"
[adversary]
traps = 1
trap_candidates = ["g", "d"]
hypotheses = ["F goal", "F decoy"]
'''


def load(text: str):
    return world_from_toml(text, "typed.toml")


def error(text: str) -> str:
    with pytest.raises(InputError) as caught:
        load(text)
    message = str(caught.value)
    assert "\n" not in message
    return message


def test_types_read_and_normalised():
    world = load(HEAD + JUMPY + STUBBORN)
    assert [t.name for t in world.types] == ["jumpy", "stubborn"]
    assert weights(world) == (0.25, 0.75)
    jumpy, stubborn = world.types
    assert (jumpy.inference, jumpy.window, jumpy.initial_hypothesis) == ("cusum", 1, 1)
    assert dict(jumpy.settings) == {"threshold": 0.3}
    assert (stubborn.inference, stubborn.rationality) == ("bayes", 5.0)
    assert dict(stubborn.settings) == {"prior": (0.5, 0.5), "decision": "map"}
    # the world's own observer is its first type's; each type's world is an ordinary one
    assert (world.inference, world.window, world.initial_hypothesis) == ("cusum", 1, 1)
    one = world_of_type(world, 1)
    assert one.types == () and one.inference == "bayes" and one.window == 2
    assert one.rationality == 5.0 and one.initial_hypothesis == 0
    assert one.hypotheses == world.hypotheses and one.grid == world.grid


def test_types_in_an_arena_world():
    world = load(ARENA_HEAD + JUMPY + STUBBORN)
    assert world.arena is not None and len(world.types) == 2
    assert world_of_type(world, 0).threshold == 0.3


def test_zero_weight_and_identical_types_are_allowed():
    world = load(HEAD + JUMPY + JUMPY.replace("jumpy", "twin").replace("weight = 1", "weight = 0"))
    assert weights(world) == (1.0, 0.0)


@pytest.mark.parametrize("text, key, reason", [
    (HEAD + "[inference]\nwindow = 1\nthreshold = 1.0\nrationality = 1.0\n" + JUMPY + STUBBORN,
     "inference", "not both"),
    (HEAD.replace("traps = 1\n", "traps = 1\ninitial_hypothesis = 0\n") + JUMPY + STUBBORN,
     "adversary.initial_hypothesis", "each type sets"),
    (HEAD + JUMPY, "type", "at least two types"),
    (HEAD + JUMPY + STUBBORN.replace('kind = "bayes"', 'kind = "bayes"\ndecision = "sample"'),
     "type[1].inference.decision", "not allowed for a type"),
    (HEAD + JUMPY.replace("weight = 1", "weight = -1") + STUBBORN, "type[0].weight", ">= 0"),
    (HEAD + JUMPY.replace("weight = 1", "weight = 0") + STUBBORN.replace("weight = 3",
                                                                          "weight = 0"),
     "type", "sum to 0"),
    (HEAD + JUMPY.replace("weight = 1\n", "") + STUBBORN, "type[0].weight", "missing"),
    # finite weights whose sum overflows (a traceback: fsum's OverflowError)
    (HEAD + JUMPY.replace("weight = 1", "weight = 1e308") + STUBBORN.replace("weight = 3",
                                                                              "weight = 1e308"),
     "type", "too large to add up"),
    (HEAD + JUMPY.replace("weight = 1", 'weight = "a"') + STUBBORN, "type[0].weight",
     "must be a number"),
    (HEAD + JUMPY.replace("threshold = 0.3\n", "") + STUBBORN, "type[0].inference.threshold",
     "missing required key"),
    (HEAD + JUMPY.replace("window = 1", "window = 0") + STUBBORN, "type[0].inference.window",
     ">= 1"),
    (HEAD + JUMPY.replace("rationality = 10.0", "rationality = -1.0") + STUBBORN,
     "type[0].inference.rationality", "> 0"),
    (HEAD + JUMPY + STUBBORN.replace("rationality = 5.0", "rationality = 5.0\nthreshold = 1.0"),
     "type[1].inference.threshold", "belongs to the CUSUM"),
    (HEAD + JUMPY.replace("initial_hypothesis = 1", "initial_hypothesis = 2") + STUBBORN,
     "type[0].initial_hypothesis", "index into hypotheses"),
    (HEAD + JUMPY + STUBBORN.replace("weight = 3", "weight = 3\ninitial_hypothesis = 1"),
     "type[1].initial_hypothesis", "not allowed with kind"),
    (HEAD + JUMPY + STUBBORN.replace("weight = 3", "weight = 3\ncolour = 1"), "type[1].colour",
     "unknown key"),
    (HEAD + JUMPY + STUBBORN.replace("[type.inference]\nkind", "[type.inferenc]\nkind"),
     "type[1].inferenc", "unknown table"),
    (HEAD + JUMPY + '[[type]]\nname = "bare"\nweight = 1\n', "type[1].inference", "missing"),
    (HEAD + JUMPY + STUBBORN.replace("stubborn", "jumpy"), "type[1].name", "repeated"),
    ("type = 3\n" + HEAD, "type", "array of tables"),
    (ARENA_HEAD + JUMPY, "type", "at least two types"),
])
def test_bad_types(text, key, reason):
    message = error(text)
    assert f": {key}: " in message, message
    assert reason in message, message


def test_cli(tmp_path, capsys):
    """`hg2prism check` of a world with types prints the adaptivity table; `sweep --param
    weight` sweeps the prior; the commands that do not handle types refuse it with one line
    (exit status 2, nothing written)."""
    import subprocess
    import sys
    from pathlib import Path

    world = Path(__file__).resolve().parent.parent / "models" / "world4.toml"
    hg2prism = [sys.executable, "-m", "hg2prism"]
    done = subprocess.run(hg2prism + ["check", str(world), "--out", str(tmp_path / "c")],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "V_adapt = 0.871241" in done.stdout and "value of adaptivity" in done.stdout
    assert (tmp_path / "c" / "strategy.json").exists()
    # the rest in this process (the same main() the command runs; a process each took 6 s)
    from hg2prism.cli import main

    capsys.readouterr()
    assert main(["validate", str(world)]) == 0
    assert "P2's types jumpy, stubborn" in capsys.readouterr().out
    for command, key in ((["emit"], ": type: "), (["detect"], ": type: "),
                         (["robust"], ": type: "), (["convert"], ": type: "),
                         (["run", "--episode", "bogus"], ": --episode: expected median"),
                         (["run", "--episode", "seed=3"], ": --episode: a world with P2's types"),
                         (["check", "--objective", "lexicographic"], ": type: "),
                         (["sweep", "--param", "delay", "--values", "0"], ": --param: "),
                         (["sweep", "--param", "weight", "--values", "0.5", "--param", "weight",
                           "--values", "1"], ": --param: weight is given twice"),
                         (["sweep", "--param", "weight", "--values", "1.5"], ": --values: ")):
        assert main([command[0], str(world), *command[1:], "--out", str(tmp_path / "r")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and key in err and err.startswith("hg2prism: error: "), err
        assert not (tmp_path / "r").exists()
    # the prior swept: V_adapt, V_oracle and the committed values against the weight of jumpy
    from hg2prism.progress import quiet

    with quiet():
        assert main(["sweep", str(world), "--param", "weight", "--values", "0.5", "1", "--out",
                     str(tmp_path / "s")]) == 0
    import json

    rows = json.loads((tmp_path / "s" / "sweep.json").read_text())["rows"]
    assert [row["weight"] for row in rows] == [0.5, 1.0]
    assert rows[0]["v_adapt"] == pytest.approx(0.871241, abs=1e-6)
    assert rows[1]["v_adapt"] == pytest.approx(1.0, abs=1e-9)           # jumpy alone
    assert rows[1]["v_commit"] == pytest.approx({"jumpy": 1.0, "stubborn": 0.75}, abs=1e-9)
    assert (tmp_path / "s" / "sweep.png").exists()


def test_the_size_guard_bounds_every_type_and_the_adaptive_hypergame():
    """Every type's hypergame is bounded, not only the first's: a world whose second type
    would not fit is refused up front, naming that type; and the adaptive hypergame itself
    (key `type`) is bounded, its estimate at least the bound of each type's."""
    from pathlib import Path

    from hg2prism.model import sizeguard

    text = (Path(__file__).resolve().parent.parent / "models" / "world4.toml").read_text()
    world = load(text)
    own = [sizeguard.estimate_states(world_of_type(world, k)) for k in range(2)]
    adaptive = sizeguard.estimate_adaptive(world)
    assert adaptive >= max(own)
    assert sizeguard.check_size(world) == adaptive
    with pytest.raises(InputError) as caught:          # the second type blows up
        sizeguard.check_size(load(text.replace("window = 3", "window = 60")))
    assert caught.value.key == "type[1]" and "type 'stubborn'" in str(caught.value)
    assert "Reduce type[1].inference.window" in str(caught.value)
    assert "\n" not in str(caught.value)
    with pytest.raises(InputError) as caught:          # each type fits, the product does not
        sizeguard.check_size(world, max(own))
    assert caught.value.key == "type" and "adaptive hypergame" in str(caught.value)
    assert sizeguard.check_size(world, adaptive) == adaptive      # at the limit: accepted


def test_a_refused_type_advises_the_max_states_every_part_needs():
    """A type above the limit is named, but the --max-states advised (and the refusal's
    estimate, which a sweep compares across its points) is the largest part's, here the
    adaptive hypergame's: following the advice does not meet the adaptive refusal next."""
    from pathlib import Path

    from hg2prism.model import sizeguard

    world = load((Path(__file__).resolve().parent.parent / "models" / "world4.toml").read_text())
    own = [sizeguard.estimate_states(world_of_type(world, k)) for k in range(2)]
    adaptive = sizeguard.estimate_adaptive(world)
    assert adaptive > max(own)              # else this test shows nothing
    first = next(k for k in range(2) if own[k] == max(own))
    with pytest.raises(InputError) as caught:
        sizeguard.check_size(world, max(own) - 1)
    assert caught.value.key == f"type[{first}]"
    assert f"up to {max(own):,} states" in str(caught.value)
    assert (f"To build it and every other part of the world anyway, pass --max-states "
            f"{adaptive}") in str(caught.value)
    assert caught.value.estimate == adaptive
    assert sizeguard.check_size(world, adaptive) == adaptive      # the advice lets it through


def test_a_type_too_big_is_refused_before_any_work(tmp_path):
    """`hg2prism run` refuses it with one line naming the type, writing nothing."""
    import subprocess
    import sys
    from pathlib import Path

    text = (Path(__file__).resolve().parent.parent / "models" / "world4.toml").read_text()
    world = tmp_path / "big.toml"
    world.write_text(text.replace("window = 3", "window = 60"))
    done = subprocess.run([sys.executable, "-m", "hg2prism", "run", str(world), "--out",
                           str(tmp_path / "out")], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and ": type[1]: " in done.stderr, done.stderr
    assert not (tmp_path / "out").exists()


def test_every_api_verb_on_a_world_with_types(tmp_path):
    """hg2prism.solve of a world with types gives the adaptive solution (the values and the
    strategy `hg2prism check` writes, each type's own Solution); baselines handles it (V_NE
    and V_lead do not depend on P2's inference); every other verb either takes one type's
    Solution or refuses the world or the AdaptiveSolution with one line naming `type`: none
    silently solves the first type only."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    import hg2prism

    path = Path(__file__).resolve().parent.parent / "models" / "world4.toml"
    adaptive = hg2prism.solve(path, out=tmp_path / "api")
    assert isinstance(adaptive, hg2prism.AdaptiveSolution)
    done = subprocess.run([sys.executable, "-m", "hg2prism", "check", str(path), "--out",
                           str(tmp_path / "cli")], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    cli = json.loads((tmp_path / "cli" / "results.json").read_text())
    for key in ("v_adapt", "v_oracle", "value_of_adaptivity", "cost_of_not_knowing"):
        assert getattr(adaptive, key) == cli[key], key
    assert adaptive.v_k == {t["name"]: t["deceptive_value"] for t in cli["types"]}
    assert adaptive.v_commit == {t["name"]: t["v_commit"] for t in cli["types"]}
    assert adaptive.v_adapt == pytest.approx(0.871241, abs=1e-6)
    assert list(adaptive.strategy) == json.loads((tmp_path / "cli" / "strategy.json").read_text())
    # written as every strategy.json is (a code review: its own writer used json.dumps's
    # default separators, and would have written NaN): compact, one record a line, and each
    # line the record's JSON with "values" by RecordExtras (null for a value that is none)
    lines = (tmp_path / "cli" / "strategy.json").read_text().splitlines()
    assert lines[0] == "[" and lines[-1] == "]" and len(lines) == len(adaptive.strategy) + 2
    assert lines[1] == json.dumps(adaptive.strategy[0], separators=(",", ":"), allow_nan=False) + ","
    assert adaptive.to_json()["v_adapt"] == cli["v_adapt"]
    assert (tmp_path / "api" / "adaptive.prism").exists()
    assert (tmp_path / "api" / "type1" / "strategy.json").exists()
    # each type's own Solution is that type's ordinary world solved
    world = load(path.read_text())
    for k, solution in enumerate(adaptive.types):
        assert solution.world.types == () and solution.world.window == world.types[k].window
        assert solution.deceptive_value == adaptive.v_k[world.types[k].name]
    assert adaptive.types[1].deceptive_value == pytest.approx(0.75, abs=1e-9)
    assert 0 <= hg2prism.simulate(adaptive.types[0], episodes=20).rate <= 1
    # baselines do not depend on P2's inference: the same for every type
    assert hg2prism.baselines(world) == hg2prism.baselines(world_of_type(world, 1))
    refusals = {
        "simulate": lambda: hg2prism.simulate(adaptive),
        "deception_values": lambda: hg2prism.deception_values(adaptive),
        "robust": lambda: hg2prism.robust(adaptive, [0.1]),
        "detection": lambda: hg2prism.detection(adaptive),
        "episode": lambda: hg2prism.episode(adaptive),
        "draw_world": lambda: hg2prism.draw_world(adaptive),
        "draw_belief": lambda: hg2prism.draw_belief(adaptive),
        "sweep": lambda: hg2prism.sweep(world, "rationality", [1.0]),
        "solve": lambda: hg2prism.solve(world, objective="lexicographic"),
    }
    for verb, call in refusals.items():
        with pytest.raises(InputError) as caught:
            call()
        assert caught.value.key == "type", verb
        message = str(caught.value)
        assert "\n" not in message and "[[type]]" in message, (verb, message)
        assert verb in message or verb == "solve", (verb, message)


def test_a_weight_that_fails_is_recorded_and_the_others_go_on(tmp_path, monkeypatch, capsys):
    """As `hg2prism sweep` records a point: the weight whose solve fails is listed under
    `failed` with its one-line error and printed as one line (exit status 1); the other
    weights are solved and written."""
    import json
    from pathlib import Path

    from hg2prism import cli
    from hg2prism.errors import SolverError
    from hg2prism.experiments import adaptive

    solve = adaptive.check_adaptive

    def failing_at_half(world, out, storm_method="sound", **kwargs):
        if weights(world)[0] == 0.5:
            raise SolverError("the adaptive model did not converge\nsecond line")
        return solve(world, out, storm_method, **kwargs)

    monkeypatch.setattr(adaptive, "check_adaptive", failing_at_half)
    world = Path(__file__).resolve().parent.parent / "models" / "world4.toml"
    # one worker: the points run in this process, where the failing solve is patched in
    status = cli.main(["sweep", str(world), "--param", "weight", "--values", "0.5", "1",
                       "--out", str(tmp_path / "s"), "--workers", "1"])
    assert status == 1
    err = capsys.readouterr().err.splitlines()
    assert [line for line in err if "error" in line] == [
        f"hg2prism: error: {world}: sweep point weight=0.5: solver: the adaptive model did not "
        "converge"]
    summary = json.loads((tmp_path / "s" / "sweep.json").read_text())
    assert summary["failed"] == [{"weight": 0.5,
                                  "error": "solver: the adaptive model did not converge"}]
    assert [row["weight"] for row in summary["rows"]] == [1.0]
    assert summary["values"] == [0.5, 1.0] and summary["parameters"] == ["weight"]
    assert (tmp_path / "s" / "sweep.png").exists()


def test_the_weight_sweep_runs_on_the_sweeps_driver(tmp_path, capsys):
    """`sweep --param weight` goes through experiments/sweep.py's driver: serially and on a
    2-worker Dask cluster it writes the same sweep.json (timings aside), sweep.csv and figures,
    with a progress line per weight counting the points; no folder per weight."""
    import json
    from pathlib import Path

    from hg2prism import cli

    world = Path(__file__).resolve().parent.parent / "models" / "world4.toml"
    outs = {}
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}"
        status = cli.main(["sweep", str(world), "--param", "weight", "--values", "0", "0.5",
                           "--out", str(out), "--workers", workers])
        assert status == 0
        lines = [line for line in capsys.readouterr().err.splitlines()
                 if line.startswith("sweep weight=")]
        # one line per weight as it finishes (on Dask, in any order), counting the points
        assert [line.split(" ")[2] for line in lines] == ["(1/2)", "(2/2)"], lines
        assert sorted(line.split(" ")[1] for line in lines) == ["weight=0", "weight=0.5"]
        assert any("V_adapt 0.8712, V_oracle 0.8750, V_commit(jumpy) 0.5000, "
                   "V_commit(stubborn) 0.7500" in line for line in lines), lines
        assert names_in(out) == ["sweep.csv", "sweep.json",
                                                         "sweep.png", "sweep.svg"]
        summary = json.loads((out / "sweep.json").read_text())
        summary.pop("seconds")
        outs[workers] = (summary, *((out / f).read_bytes() for f in ("sweep.csv", "sweep.svg")))
    assert outs["1"] == outs["2"]
    assert [row["weight"] for row in outs["1"][0]["rows"]] == [0.0, 0.5]


def test_the_weight_sweep_has_the_size_guard(tmp_path, capsys):
    """--max-states bounds every weight's adaptive hypergame, as it bounds a sweep's points:
    refused at every weight, the sweep is one error line (exit status 2) and writes nothing."""
    from pathlib import Path

    from hg2prism import cli
    from hg2prism.model import sizeguard
    from hg2prism.worldfile import load_world

    from hg2prism.experiments.adaptive import with_first_weight

    world = Path(__file__).resolve().parent.parent / "models" / "world4.toml"
    below = min(sizeguard.estimate_adaptive(with_first_weight(load_world(world), weight))
                for weight in (0.5, 1.0)) - 1
    status = cli.main(["sweep", str(world), "--param", "weight", "--values", "0.5", "1",
                       "--out", str(tmp_path / "s"), "--max-states", str(below)])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1, err
    assert err[0].startswith("hg2prism: error: ") and f"limit of {below:,}" in err[0], err
    assert not (tmp_path / "s").exists()


def test_the_weight_sweep_refuses_deception(tmp_path, capsys):
    """sweep --deception on a world with P2's types: one error line and nothing written (the
    flag was ignored in silence: V_static and V_naive are of a world with one [inference])."""
    from pathlib import Path

    from hg2prism import cli

    world = Path(__file__).resolve().parent.parent / "models" / "world4.toml"
    status = cli.main(["sweep", str(world), "--param", "weight", "--values", "0.5",
                       "--deception", "--out", str(tmp_path / "s")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and err == [
        "hg2prism: error: command line: --deception: V_static and V_naive are of a world with "
        "one [inference]; a world with P2's types reports V_adapt, V_oracle and each V_commit "
        "per weight (docs/adaptive.md)"], err
    assert not (tmp_path / "s").exists()


def test_a_type_name_with_a_bar_keeps_table_md_a_table(tmp_path):
    """A type's name may hold `|` (a world file's name is any one line); in table.md it is
    escaped, so that every row of the adaptivity table has its three cells (it ended a cell)."""
    import dataclasses
    import re

    from pathlib import Path

    import hg2prism

    world = hg2prism.load_world(Path(__file__).resolve().parent.parent / "models" / "world4.toml")
    jumpy, stubborn = world.types
    named = world.replace(types=(dataclasses.replace(jumpy, name="jumpy|fast"), stubborn))
    hg2prism.solve(named, out=tmp_path / "out")
    rows = [line for line in (tmp_path / "out" / "table.md").read_text().splitlines()
            if line.startswith("| ") and "V_" in line]
    assert any("jumpy\\|fast" in row for row in rows)
    assert all(len(re.findall(r"(?<!\\)\|", row)) == 4 for row in rows), rows


def test_one_type_at_a_time_from_the_command_line(tmp_path, capsys):
    """`--type NAME` (or its number) runs a command on the world where P2 is of that type: the
    commands that play one model of P2 refused a world with types, and the docs said to copy
    the type into a world file of its own (a user review). `robust --type stubborn` gives what
    the API gives for the AdaptiveSolution's stubborn type; `check --type 0` the adaptive
    check's V_k of jumpy; `sweep --type stubborn` at the type's own rationality its V_k. OUT
    defaults to <world>_type<k>/, and the records name the type (`p2_type`; a user could not
    tell from results.json which type it was of). A world without types, or a type it does not
    list, is one line."""
    import dataclasses
    import json
    import shutil
    from pathlib import Path

    import hg2prism
    import hg2prism.results
    from hg2prism.cli import main
    from hg2prism.progress import quiet

    world = tmp_path / "world4.toml"
    shutil.copy(Path(__file__).resolve().parent.parent / "models" / "world4.toml", world)
    with quiet():
        assert main(["robust", str(world), "--type", "stubborn", "--deltas", "0.1",
                     "--no-cross-check"]) == 0
        assert main(["check", str(world), "--type", "0"]) == 0
        assert main(["sweep", str(world), "--type", "stubborn", "--param", "rationality",
                     "--values", repr(hg2prism.load_world(world).types[1].rationality),
                     "--workers", "1"]) == 0
    adaptive = hg2prism.solve(world)
    (row,) = json.loads((tmp_path / "world4_type1" / "robust.json").read_text())["rows"]
    (expected,) = hg2prism.robust(adaptive.types[1], [0.1])
    assert row["robust_value"] == expected.robust_value
    assert row["nominal_worst_case"] == expected.nominal_worst_case
    results = json.loads((tmp_path / "world4_type0" / "results.json").read_text())
    assert results["deceptive_value"] == adaptive.v_k["jumpy"]
    assert results["p2_type"] == "jumpy"
    swept = json.loads((tmp_path / "world4_type1" / "sweep.json").read_text())
    assert swept["p2_type"] == "stubborn"
    assert json.loads((tmp_path / "world4_type1" / "robust.json").read_text())["p2_type"] \
        == "stubborn"
    (point,) = swept["rows"]
    assert point["deceptive_value"] == adaptive.v_k["stubborn"]
    assert adaptive.types[1].to_json()["p2_type"] == "stubborn"     # the API's records too
    # the type's name does not enter the digest (a code review: it made every world4_type<k>/
    # folder written before look like another world's), and leaves with types given back
    from hg2prism.worldfile.types import world_of_type

    loaded = hg2prism.load_world(world)
    for k in range(2):
        typed_world = world_of_type(loaded, k)
        assert typed_world.of_type == loaded.types[k].name
        assert typed_world.digest() == dataclasses.replace(typed_world, of_type="").digest()
        again = typed_world.replace(types=loaded.types)
        assert again.of_type == "" and "p2_type" not in hg2prism.results.provenance(again)
    assert "here P2 of type 'jumpy'" in (tmp_path / "world4_type0" / "hypergame.prism").read_text()
    # load_strategy reads a type's folder back for the world of that type
    loaded_strategy = hg2prism.load_strategy(tmp_path / "world4_type0")
    assert loaded_strategy.table == adaptive.types[0].strategy.table
    capsys.readouterr()
    for args, reason in (
            (["emit", str(Path(__file__).resolve().parent.parent / "models" / "world1.toml"),
              "--type", "jumpy"], "lists no [[type]] of P2"),
            (["detect", str(world), "--type", "lazy"],
             "no type 'lazy' in " + str(world) + "; expected one of 'jumpy', 'stubborn' or a "
             "number from 0 to 1"),
            (["robust", str(world), "--type", "2"], "no type '2'")):
        assert main([*args, "--out", str(tmp_path / "refused")]) == 2
        (line,) = capsys.readouterr().err.splitlines()
        assert line.startswith("hg2prism: error: command line: --type: ") and reason in line, line
    assert not (tmp_path / "refused").exists()


def test_types_given_to_a_world_bring_its_observer_from_the_first() -> None:
    """world.replace(types=(...)) on a world without types was refused, one field at a time,
    with "change a type through types=(...)", which the call did (an API review): the world's
    own observer fields now come from the first type unless the call gives them too; given and
    different, they are refused as before, the message saying what types= brings."""
    import dataclasses
    from pathlib import Path

    import hg2prism
    from hg2prism import PlayerType

    world1 = hg2prism.load_world(Path(__file__).resolve().parent.parent / "models" / "world1.toml")
    first = PlayerType(name="a", weight=0.5, initial_hypothesis=1, inference="cusum", window=1,
                       rationality=4.0, settings=(("threshold", 0.3),))
    second = dataclasses.replace(first, name="b", settings=(("threshold", 2.0),))
    typed = world1.replace(types=(first, second))
    assert (typed.inference, typed.window, typed.rationality, typed.settings,
            typed.initial_hypothesis) == ("cusum", 1, 4.0, (("threshold", 0.3),), 1)
    assert typed.replace(types=(second, first)).settings == (("threshold", 2.0),)
    for call in (lambda: world1.replace(window=2, types=(first, second)),
                 lambda: typed.replace(window=2)):
        with pytest.raises(hg2prism.InputError) as refused:
            call()
        assert refused.value.key == "type[0]" and refused.value.reason.startswith(
            "the world's own window (2) and its first type's (1) differ") and \
            "brings the first type's window when the call does not give window too" \
            in refused.value.reason
    assert typed.replace(types=()).settings == (("threshold", 0.3),)
