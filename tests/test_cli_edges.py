"""Command-line edges: each error is one line, a non-zero exit, no traceback, nothing written;
options every solving command shares; output folders that never mix fresh and stale outputs;
extreme values that run in bounded time or are refused up front.

The CLI runs as a subprocess, so a traceback reaching the terminal would be seen.
"""

from __future__ import annotations

import json
import re
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from conftest import MODELS, ROOT, names_in
from hg2prism import __version__
from hg2prism.errors import InputError
from hg2prism.outputs import MANIFEST
from hg2prism.numeric import bounded_reach
from hg2prism.worldfile import load_world

WORLD1 = str(MODELS / "world1.toml")


def run_cli(args: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "hg2prism", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def assert_one_line_error(proc: subprocess.CompletedProcess, *words: str) -> str:
    assert proc.returncode != 0, (proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("hg2prism: error: "), proc.stderr
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


def only(folder: Path, *names: str) -> None:
    """`folder` holds exactly `names` (no staging folder, no probe left behind)."""
    assert names_in(folder) == sorted(names)


def small_world(tmp_path: Path, extra: dict[str, str] | None = None) -> Path:
    """world1 with some lines replaced."""
    text = (MODELS / "world1.toml").read_text()
    for old, new in (extra or {}).items():
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / "w.toml"
    path.write_text(text)
    return path


# ------------------------------------------------------------------------------- output folders

def test_out_is_an_existing_file(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("mine")
    proc = run_cli(["emit", WORLD1, "--out", str(tmp_path / "file")], tmp_path)
    assert_one_line_error(proc, "--out", "not a folder")
    only(tmp_path, "file")
    assert (tmp_path / "file").read_text() == "mine"


def test_out_below_a_file(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("mine")
    proc = run_cli(["check", WORLD1, "--out", str(tmp_path / "file" / "sub")], tmp_path)
    assert_one_line_error(proc, "--out", "not a folder")
    only(tmp_path, "file")


def test_an_empty_out_is_refused(tmp_path: Path, capsys, monkeypatch) -> None:
    """--out "" is refused as the API's out="" is (check wrote into the default folder next to
    the world file; convert said that "." is a folder). Run from tmp_path: a regression that
    took "" for the current folder would write there, not into the repository."""
    from hg2prism.cli import main

    monkeypatch.chdir(tmp_path)
    world = tmp_path / "world1.toml"
    world.write_text((MODELS / "world1.toml").read_text())
    for command in ("check", "convert"):
        assert main([command, str(world), "--out", ""]) == 2
        (line,) = capsys.readouterr().err.splitlines()
        assert line.startswith("hg2prism: error: command line: --out: an empty path"), line
    only(tmp_path, "world1.toml")


@pytest.mark.skipif(not Path("/proc/self").exists(), reason="needs /proc (a folder nobody can write)")
def test_out_in_a_folder_that_cannot_be_written(tmp_path: Path) -> None:
    # /proc refuses new entries even to root, for whom permission bits would not do
    proc = run_cli(["run", WORLD1, "--out", "/proc/hg2prism-out"], tmp_path)
    assert_one_line_error(proc, "--out", "cannot write in /proc (", "cannot be made")


def test_version(tmp_path: Path) -> None:
    proc = run_cli(["--version"], tmp_path)
    assert proc.returncode == 0 and proc.stdout.strip() == f"hg2prism {__version__}"


def test_emit_after_run_leaves_no_stale_outputs(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert run_cli(["run", WORLD1, "--out", str(out), "--episodes", "50"], tmp_path).returncode == 0
    assert {"strategy.json", "results.json", "world.png", "table.md", "symmetric.prism",
            "goal.props"} <= {
        p.name for p in out.iterdir()}
    (out / "notes.txt").write_text("mine")      # not hg2prism's: kept
    proc = run_cli(["emit", WORLD1, "--out", str(out)], tmp_path)
    assert proc.returncode == 0, proc.stderr
    only(out, "hypergame.prism", "hypergame.props", "notes.txt")
    only(tmp_path, "out")


# ---------------------------------------------------------------------------- shared options

def test_sweep_and_detect_refuse_a_world_above_max_states(tmp_path: Path) -> None:
    for command in (["sweep", WORLD1, "--param", "window", "--values", "1", "2"],
                    ["detect", WORLD1]):
        proc = run_cli(command + ["--out", str(tmp_path / "out"), "--max-states", "100"], tmp_path)
        assert_one_line_error(proc, WORLD1, "size", "limit of 100")
        assert not (tmp_path / "out").exists()


def test_a_sweep_reports_a_refused_point_and_solves_the_others(tmp_path: Path) -> None:
    # window 1 fits in 2,000 states, window 3 does not: window 1 is solved and written, window 3
    # is reported with its parameter (exit status 1); docs/semantics.md §7, Sweeps
    proc = run_cli(["sweep", WORLD1, "--param", "window", "--values", "1", "3", "--out",
                    str(tmp_path / "out"), "--max-states", "2000", "--workers", "1"], tmp_path)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("hg2prism: error: ")]
    assert len(errors) == 1 and "sweep point window=3: size:" in errors[0]
    assert "window 3" in errors[0]
    only(tmp_path / "out", "sweep.csv", "sweep.json", "sweep.png", "sweep.svg", "window_1")
    summary = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert [row["window"] for row in summary["rows"]] == [1]
    assert [point["window"] for point in summary["failed"]] == [3]


def test_fast_method_is_flagged(tmp_path: Path) -> None:
    proc = run_cli(["check", WORLD1, "--out", str(tmp_path / "c"), "--storm-method", "fast"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "not sound" in proc.stdout and "not sound" in proc.stderr
    results = json.loads((tmp_path / "c" / "results.json").read_text())
    assert results["storm_method"] == "fast" and results["sound"] is False
    proc = run_cli(["check", WORLD1, "--out", str(tmp_path / "s")], tmp_path)
    assert "not sound" not in proc.stdout + proc.stderr
    assert json.loads((tmp_path / "s" / "results.json").read_text())["sound"] is True


def test_sweep_delay_without_initial_traps_and_with_a_storm_method(tmp_path: Path) -> None:
    """world1 writes `initial_traps = []`: a delay sweep falls back to the first candidate, as
    sweep.json's rule says, and --storm-method reaches every point."""
    proc = run_cli(["sweep", WORLD1, "--param", "delay", "--values", "0", "1", "--out",
                    str(tmp_path / "out"), "--storm-method", "sound-ovi", "--workers", "1"],
                   tmp_path)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert summary["storm_method"] == "sound-ovi" and summary["sound"] is True
    first_candidate = "x1_y4"       # world1's candidates, top row first: (1,4) (3,4) (2,2) (3,2)
    assert [row["standing"] for row in summary["rows"]] == [None, first_candidate]
    for row in summary["rows"]:
        low, high = row["v_ne_bounds"]
        assert 0 <= low <= row["v_ne"] <= high <= 1


def test_simulation_progress_names_the_simulation(tmp_path: Path) -> None:
    proc = run_cli(["run", WORLD1, "--out", str(tmp_path / "out"), "--episodes", "50"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if "episodes in" in line]
    assert [line.split(":")[0] for line in lines] == [
        "simulate deceptive", "simulate nash", "simulate leader", "simulate static",
        "simulate naive"], lines


# ----------------------------------------------------------------------------- extreme values

def test_huge_window_is_refused_up_front(tmp_path: Path) -> None:
    world = small_world(tmp_path, {"window = 2": "window = 1000000"})
    start = time.monotonic()
    proc = run_cli(["run", str(world), "--out", str(tmp_path / "out")], tmp_path, timeout=60)
    assert time.monotonic() - start < 30
    assert_one_line_error(proc, str(world), "size", "more than 10^18", "window 1000000",
                          "limit of 6,291,456")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("key,line", [("simulation.horizon", "horizon = 1000000000"),
                                      ("simulation.episodes", "episodes = 1000000000"),
                                      ("simulation.seed", "seed = 4611686018427387905")])
def test_huge_simulation_is_refused_by_the_validator(tmp_path: Path, key: str, line: str) -> None:
    world = small_world(tmp_path)
    world.write_text(world.read_text() + f"\n[simulation]\n{line}\n")
    proc = run_cli(["validate", str(world)], tmp_path)
    assert_one_line_error(proc, str(world), key, "<= ")


def test_huge_horizon_on_the_command_line_is_refused(tmp_path: Path) -> None:
    proc = run_cli(["run", WORLD1, "--out", str(tmp_path / "o"), "--horizon", "1000000000"], tmp_path)
    assert_one_line_error(proc, "--horizon", "must be <= 100,000")
    assert not (tmp_path / "o").exists()


def test_a_seed_beyond_what_a_world_file_holds_is_refused(tmp_path: Path) -> None:
    """--seed and --episode seed=N at most 2**62, as a world file's seed (both were accepted:
    their seed sets would not fit a world file's 64-bit integers)."""
    for option in (["--seed", str(2**62 + 1)], ["--episode", f"seed={2**62 + 1}"]):
        proc = run_cli(["run", WORLD1, "--out", str(tmp_path / "o"), *option], tmp_path)
        assert_one_line_error(proc, option[0], "4,611,686,018,427,387,904")
    assert not (tmp_path / "o").exists()


def test_largest_horizon_runs_in_bounded_time(tmp_path: Path) -> None:
    """At the largest horizon the exact within-horizon numbers stop once converged: they equal
    the unbounded values, and the run takes seconds, not 10^5 sweeps per number."""
    out = tmp_path / "out"
    proc = run_cli(["run", WORLD1, "--out", str(out), "--episodes", "50", "--horizon", "100000"],
                   tmp_path, timeout=240)
    assert proc.returncode == 0, proc.stderr
    results = json.loads((out / "results.json").read_text())
    simulated = results["simulation"]
    assert abs(simulated["deceptive"]["exact_within_horizon"] - results["deceptive_value"]) < 1e-9
    assert abs(simulated["leader"]["exact_within_horizon"] - results["v_lead"]) < 1e-9


def test_bounded_reach_equals_step_by_step_iteration() -> None:
    """The converged stop changes nothing that step-by-step iteration would give (to 1e-12)."""
    rng = np.random.default_rng(5)
    n = 60
    for trial in range(20):
        dense = rng.random((n, n)) * (rng.random((n, n)) < 0.08)
        dense[np.arange(n), rng.integers(0, n, n)] += 0.01
        dense /= dense.sum(axis=1, keepdims=True)
        goal = np.zeros(n, dtype=bool)
        goal[:2] = True
        stop = goal.copy()
        stop[2:4] = True
        matrix = sp.diags((~stop).astype(float)) @ sp.csr_matrix(dense)
        for horizon in (1, 7, 50, 10_000):
            reach = goal.astype(float)
            for _ in range(horizon):
                reach = np.where(stop, goal.astype(float), matrix @ reach)
            assert abs(bounded_reach(matrix, goal, stop, 10, horizon) - reach[10]) <= 1e-12


def test_sigterm_stops_a_long_simulation_within_seconds(tmp_path: Path) -> None:
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    command = [sys.executable, "-m", "hg2prism", "run", WORLD1, "--out", str(out),
               "--episodes", "1000000", "--horizon", "100000"]
    proc = subprocess.Popen(command, cwd=tmp_path, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not any(tmp_path.glob(".out.staging-*/strategy.json")):   # simulating from then on
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
        time.sleep(0.05)
    time.sleep(1.0)
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=60)
    assert time.monotonic() - sent < 5, "SIGTERM took more than 5 s to stop the run"
    assert proc.returncode == 143, stderr
    assert "Traceback" not in stderr
    only(tmp_path)


def test_an_internal_strategy_error_is_one_line(tmp_path: Path, monkeypatch, capsys) -> None:
    """A strategy without a move where an episode went (an internal error) is said in one line
    naming the world and the strategy, not as a traceback, and nothing is written."""
    from hg2prism import cli, pipeline
    from hg2prism.strategy.records import StrategyError

    def broken(*args, **kwargs):
        raise StrategyError("episode 3, step 2: no record for state x1_y1")

    monkeypatch.setattr(pipeline, "run", broken)
    out = tmp_path / "out"
    assert cli.main(["run", WORLD1, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.splitlines() == [f"hg2prism: error: {WORLD1}: strategy: episode 3, step 2: "
                                "no record for state x1_y1"]
    assert not out.exists()


def test_bench_refuses_an_unwritable_folder_first(tmp_path: Path) -> None:
    """`bench` checks --out before solving any world, as every command does: one line, no
    traceback (it wrote the first world's row, then failed with a FileNotFoundError)."""
    blocker = tmp_path / "file"
    blocker.write_text("")
    for out in ("/proc/x", str(blocker)):
        proc = run_cli(["bench", "--quick", "--out", out], tmp_path, timeout=60)
        assert proc.returncode == 2
        assert_one_line_error(proc, "--out")


@pytest.mark.parametrize("hypotheses,said", [('["!obs U A"]', "1 hypothesis)"),
                                             ('["!obs U A", "!obs U B"]', "2 hypotheses)")])
def test_validate_counts_the_hypotheses(tmp_path: Path, hypotheses: str, said: str) -> None:
    world = small_world(tmp_path, {'hypotheses = ["!obs U A", "!obs U B", "!obs U C"]':
                                   f"hypotheses = {hypotheses}"})
    proc = run_cli(["validate", str(world)], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[0].endswith(said), proc.stdout


def test_a_rounding_level_difference_is_printed_as_zero() -> None:
    """The adaptivity table's differences (V_adapt 0.7999999999999999 against a V_commit of
    0.8 printed -0.000000)."""
    from hg2prism.experiments.adaptive import _difference

    assert [_difference(x) for x in (-1.1e-16, 0.0, 4e-7, -4e-7, -6e-7, 0.1234565)] == [
        "0.000000", "0.000000", "0.000000", "0.000000", "-0.000001", "0.123456"]


@pytest.mark.parametrize("args, words", [
    (["run", WORLD1, "--episodes", "abc"], ["--episodes", "invalid int value"]),
    (["run", WORLD1, "--objective", "bogus"], ["--objective", "invalid choice"]),
    (["run", WORLD1, "--bogus"], ["unrecognized arguments: --bogus"]),
    (["robust", "--deltas", "0", "0.05", WORLD1], ["required: world", "hg2prism robust --help"]),
    ([], ["required: command", "hg2prism --help"]),
])
def test_what_argparse_refuses_is_one_line_too(tmp_path: Path, args, words) -> None:
    """Mistakes argparse itself catches (a type, a choice, an unknown flag, a missing
    argument) are one line naming the command line and where to find the options, status 2,
    not argparse's usage block (an edge-case stress test)."""
    proc = run_cli(args, tmp_path, timeout=60)
    line = assert_one_line_error(proc, "command line", *words)
    assert proc.returncode == 2 and "usage:" not in line


def test_sigterm_stops_storm_while_it_computes(tmp_path: Path) -> None:
    """SIGTERM and Ctrl-C reach the command while Storm computes (its calls run on a worker
    thread, engines/storm.py): world1 with slip 0.49999999 defeats the certified check, and
    Storm's sound solver then ran for 13 minutes, deaf to both (found by an edge-case stress
    test; `timeout` could not stop it, and SIGKILL left staging folders behind). Stopped
    during that solve, the command exits at once with 128 + the signal, one line, nothing
    written and no staging folder left."""
    world = tmp_path / "slippery.toml"
    world.write_text((MODELS / "world1.toml").read_text().replace("slip = 0.1", "slip = 0.49999999"))
    for signum, status in ((signal.SIGTERM, 143), (signal.SIGINT, 130)):
        out = tmp_path / f"out_{signum}"
        proc = subprocess.Popen(
            [sys.executable, "-m", "hg2prism", "check", str(world), "--out", str(out)],
            cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(ROOT)), text=True,
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        lines = []
        while not any("Storm's sound solver" in line for line in lines):
            line = proc.stderr.readline()
            assert line, ("the check ended before Storm's sound solver", lines)
            lines.append(line)
        time.sleep(1.0)                         # well inside the sound solve
        proc.send_signal(signum)
        start = time.perf_counter()
        try:
            proc.wait(timeout=20)
        finally:
            proc.kill()
        assert time.perf_counter() - start < 10 and proc.returncode == status
        rest = proc.stderr.read().strip().splitlines()
        assert len(rest) == 1 and "Traceback" not in rest[0], rest
        assert not out.exists()
        assert not [p for p in tmp_path.iterdir() if "staging" in p.name]


BIG_GAMES = """name = "big"
[grid]
map = \"\"\"
#########
#@......#
#ttttttt#
#ttttttt#
#ttttttt#
#tttt..A#
#.......#
#########
\"\"\"
[robot]
slip = 0.1
[task]
formula = "F A"
[adversary]
traps = 3
delay = 1
initial_traps = [[1, 5], [2, 5], [3, 5]]
hypotheses = ["F A"]
[inference]
window = 1
threshold = 1.5
rationality = 1.0
"""


def test_validate_builds_nothing_the_size_guard_refuses(tmp_path: Path, monkeypatch,
                                                         capsys) -> None:
    """A world whose games `check` refuses (2,300 trap sets with delay 1: about 1,430 GiB):
    validate says so, and does not build its transition system to see whether a play
    completes the task (it tried, and ran out of memory)."""
    from hg2prism import pipeline
    from hg2prism.cli import main

    def refused(*args, **kwargs):
        raise AssertionError("validate built the transition system")

    monkeypatch.setattr(pipeline, "transition_system", refused)
    path = tmp_path / "big.toml"
    path.write_text(BIG_GAMES)
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr().out
    assert "; P2's games would need about 1,430 GiB, above the size guard's memory limit: the " \
           "solving commands refuse it unless --max-states allows it" in out, out
    assert main(["check", str(path), "--out", str(tmp_path / "out")]) == 2
    assert "P2's perceptual games would need about 1,430 GiB" in capsys.readouterr().err


def test_a_sweep_refused_for_its_games_names_the_largest_point(tmp_path: Path) -> None:
    """The games' refusal carries the --max-states it asks for too (it was counted as none,
    and the first point's was given); values the world refuses ask for none: the first."""
    from hg2prism.experiments import sweep
    from hg2prism.model import sizeguard

    path = tmp_path / "big.toml"
    path.write_text(BIG_GAMES)
    world = load_world(path)
    asked = {}
    for delay in (1, 3):
        with pytest.raises(InputError) as caught:
            sizeguard.check_games_size(world.replace(delay=delay))
        asked[delay] = caught.value.estimate
    assert asked[1] < asked[3]
    with pytest.raises(InputError) as caught:
        sweep.guard_points(world, [{"delay": 1}, {"delay": 3}], None)
    assert caught.value.reason.startswith("every point is refused; the largest, delay=3: P2's "
                                          "perceptual games would need about ")
    assert f"--max-states {asked[3]}" in caught.value.reason
    with pytest.raises(InputError) as caught:
        sweep.guard_points(world, [{"rationality": 1e200}, {"rationality": 1e300}], None)
    assert caught.value.reason == "rationality must be at most 1e+100, got 1e+200"


def test_validate_counts_one_trap_candidate(tmp_path: Path) -> None:
    world = tmp_path / "one.toml"
    world.write_text('name = "one"\n[grid]\nmap = """\n#####\n#@tA#\n#####\n"""\n[robot]\n'
                     'slip = 0.1\n[task]\nformula = "F A"\n[adversary]\ntraps = 1\n'
                     'hypotheses = ["F A"]\n[inference]\nwindow = 1\nthreshold = 1.0\n'
                     'rationality = 1.0\n')
    proc = run_cli(["validate", str(world)], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "5x3 grid, 1 trap candidate, 1 hypothesis)" in proc.stdout, proc.stdout
    # its one candidate always holds the trap: no play completes the task, which validate
    # says as check does (it said only "ok"); world1 gets no such line
    assert proc.stderr.startswith("warning: no play completes the task 'F A' from the start")
    assert proc.stderr.count("\n") == 1
    proc = run_cli(["validate", WORLD1], tmp_path)
    assert proc.returncode == 0 and "no play completes" not in proc.stderr, proc.stderr


def test_validate_says_the_observer_and_whether_the_size_guard_refuses(tmp_path: Path) -> None:
    """validate's second line names P2's observer, traps and delay, and the size guard's bound,
    which is check's: where check refuses the world as too large, validate says so (it said
    'ok' and nothing more to a world every solving command refused)."""
    from hg2prism.model import sizeguard

    for window, refused in ((2, False), (12, True)):
        text = (MODELS / "world1.toml").read_text().replace("\nwindow = 2\n",
                                                            f"\nwindow = {window}\n")
        world = tmp_path / f"w{window}.toml"
        world.write_text(text)
        proc = run_cli(["validate", str(world)], tmp_path)
        assert proc.returncode == 0, proc.stderr
        first, second = proc.stdout.splitlines()
        bound = sizeguard.estimate_states(load_world(world))
        assert second == (f"  P2's observer: cusum, window {window}, rationality 10, threshold "
                          f"1.5; 1 trap, delay 0; hypergame: at most {bound:,} canonical states "
                          "(the size guard's bound from the world alone)"
                          + ("; above the size guard's limit of 6,291,456: the solving commands "
                             "refuse it unless --max-states allows it" if refused else ""))
        check = run_cli(["check", str(world), "--out", str(tmp_path / f"o{window}")], tmp_path)
        assert (check.returncode == 2 and "size" in check.stderr) == refused, check.stderr
    # P2's tie break when it is not the rule's (docs/semantics.md §4)
    last = tmp_path / "last.toml"
    last.write_text((MODELS / "world1.toml").read_text().replace(
        "[adversary]\n", '[adversary]\ntie_break = "last"\n', 1))
    proc = run_cli(["validate", str(last)], tmp_path)
    assert "; 1 trap, delay 0, ties to the last; hypergame: " in proc.stdout, proc.stdout


def test_a_folder_holds_one_worlds_outputs(tmp_path: Path) -> None:
    """The commands of one world share an output folder (`make world2`: run, sweep, detect),
    but a command on another world removes what the folder held of the first (found by an
    edge-case stress test: check of world B left world A's detection and robust outputs beside
    B's results)."""
    from hg2prism.cli import main
    from hg2prism.outputs import staged
    from hg2prism.progress import quiet

    out = tmp_path / "out"
    other = tmp_path / "one.toml"
    other.write_text('name = "one"\n[grid]\nmap = """\n#####\n#@tA#\n#####\n"""\n[robot]\n'
                     'slip = 0.1\n[task]\nformula = "F A"\n[adversary]\ntraps = 1\n'
                     'hypotheses = ["F A"]\n[inference]\nwindow = 1\nthreshold = 1.0\n'
                     'rationality = 1.0\n')
    with quiet():
        assert main(["check", WORLD1, "--out", str(out)]) == 0
        # what detect and robust of world1 leave there (their record names the world), placed
        # as a command places its outputs
        with staged(out) as stage:
            (stage / "detection.json").write_text(json.dumps({"world": "world1"}))
            (stage / "detection.png").write_bytes(b"")
            (stage / "robust_0.1").mkdir()
        (out / "mine.txt").write_text("not hg2prism's")
        assert main(["check", WORLD1, "--out", str(out)]) == 0          # the same world: kept
        assert {"detection.json", "detection.png", "robust_0.1"} <= {p.name for p in out.iterdir()}
        assert main(["check", str(other), "--out", str(out)]) == 0      # another: removed
    names = {p.name for p in out.iterdir()}
    assert not names & {"detection.json", "detection.png", "robust_0.1"}
    assert "mine.txt" in names and "hypothesis_1.hoa" not in names     # world1's had three
    assert json.loads((out / "results.json").read_text())["world"] == "one"


ONE = ('name = "one"\n[grid]\nmap = """\n#####\n#@tA#\n#####\n"""\n[robot]\nslip = 0.1\n'
       '[task]\nformula = "F A"\n[adversary]\ntraps = 1\nhypotheses = ["F A"]\n[inference]\n'
       'window = 1\nthreshold = 1.0\nrationality = 1.0\n')


def test_a_command_never_removes_what_it_did_not_write(tmp_path: Path) -> None:
    """Files and folders of the user's own whose names look like outputs (a table.md, world.png,
    type0/, a sweep-like delay_notes/, robust_0.5/, sweep.json) stay where a command writes,
    whatever world it solves (found by a review: `check --out .` in a folder of notes deleted
    them without a word); what hg2prism placed there and does not write again goes."""
    from hg2prism.cli import main
    from hg2prism.outputs import MANIFEST
    from hg2prism.progress import quiet

    out = tmp_path / "notes"
    out.mkdir()
    mine = {"table.md": "my table", "world.png": "my picture", "replay.gif": "mine",
            "type0/data.txt": "mine", "delay_notes/a.txt": "mine", "robust_0.5/keep.txt": "mine",
            "traps_2023/b.txt": "mine"}
    for name, text in mine.items():
        (out / name).parent.mkdir(exist_ok=True)
        (out / name).write_text(text)
    one = tmp_path / "one.toml"
    one.write_text(ONE)
    two = tmp_path / "two.toml"
    two.write_text(ONE.replace('name = "one"', 'name = "two"').replace("slip = 0.1", "slip = 0.2"))
    with quiet():
        assert main(["check", str(one), "--out", str(out)]) == 0
        assert main(["sweep", str(one), "--param", "window", "--values", "1", "--out", str(out),
                     "--workers", "1"]) == 0
        assert (out / "window_1").is_dir()
        assert main(["check", str(two), "--out", str(out)]) == 0     # another world
    for name, text in mine.items():
        assert (out / name).read_text() == text, name
    names = {p.name for p in out.iterdir()}
    assert not names & {"window_1", "sweep.json", "sweep.csv"}    # one's sweep: removed
    assert json.loads((out / "results.json").read_text())["world"] == "two"
    placed = set(json.loads((out / MANIFEST).read_text())["items"])
    assert placed == names - {name.split("/")[0] for name in mine} - {MANIFEST}


def test_a_folder_holds_one_version_of_a_world_file(tmp_path: Path, capsys) -> None:
    """The same world file edited between two commands is another world: its outputs do not
    stay beside the old version's (the folder kept world1's detection outputs when `check`
    ran on an edited world1; records now carry World.digest()). The other commands' outputs
    removed are named in one line on stderr (they went in silence); with none, the line says
    the outputs were replaced."""
    from hg2prism.cli import main
    from hg2prism.outputs import staged
    from hg2prism.progress import quiet

    out = tmp_path / "out"
    world = small_world(tmp_path)
    with quiet():
        assert main(["check", str(world), "--out", str(out)]) == 0
    digest = json.loads((out / "results.json").read_text())["world_digest"]
    assert digest == load_world(world).digest()
    with staged(out) as stage:       # what detect leaves there, placed as a command does
        (stage / "detection.json").write_text(json.dumps({"world": "world1",
                                                          "world_digest": digest}))
        (stage / "detection.png").write_bytes(b"")
    removal = "held the outputs of another world"
    capsys.readouterr()
    assert main(["check", str(world), "--out", str(out)]) == 0         # unchanged: kept
    assert (out / "detection.png").exists()
    assert removal not in capsys.readouterr().err
    world.write_text(world.read_text().replace("window = 2", "window = 1"))
    assert main(["check", str(world), "--out", str(out)]) == 0         # edited: removed
    assert not (out / "detection.json").exists() and not (out / "detection.png").exists()
    (line,) = [x for x in capsys.readouterr().err.splitlines() if removal in x]
    assert line == (f"outputs: {out} held the outputs of another world (or of this world file "
                    f"before an edit); removed those of other commands too: detection.json, "
                    f"detection.png"), line
    assert json.loads((out / "results.json").read_text())["world_digest"] != digest
    # only its own kind's outputs to replace: said too (it went in silence)
    world.write_text(world.read_text().replace("window = 1", "window = 2"))
    assert main(["check", str(world), "--out", str(out)]) == 0
    (line,) = [x for x in capsys.readouterr().err.splitlines() if removal in x]
    assert line == (f"outputs: {out} held the outputs of another world (or of this world file "
                    f"before an edit); replaced them"), line
    # the same world: `emit` after `check` removes check's results, strategy and exports,
    # which went in silence (a PRISM user's review)
    assert main(["emit", str(world), "--out", str(out)]) == 0
    (line,) = [x for x in capsys.readouterr().err.splitlines() if "removed" in x]
    assert line.startswith("outputs: removed results.json, strategy.json, goal.props, ") and line.endswith(
        f" from {out}, which an earlier command wrote there and this one does not write"), line
    assert not (out / "results.json").exists() and (out / "hypergame.prism").exists()
    assert main(["emit", str(world), "--out", str(out)]) == 0          # nothing stale: silent
    assert "removed" not in capsys.readouterr().err


def test_emits_model_is_judged_by_the_digest_in_its_header(tmp_path: Path) -> None:
    """`emit` writes no record, only the model: its header's digest says whose it is. A sweep of
    another world into the folder left the emitted model beside its own outputs (analysis
    stress test); now it removes it, and keeps the model of the same world."""
    from hg2prism.cli import main
    from hg2prism.progress import quiet

    world = small_world(tmp_path, {"window = 2": "window = 1"})
    for out, other in ((tmp_path / "same", WORLD1), (tmp_path / "other", str(world))):
        with quiet():
            assert main(["emit", WORLD1, "--out", str(out)]) == 0
            assert main(["sweep", other, "--param", "rationality", "--values", "1",
                         "--out", str(out)]) == 0
        names = {p.name for p in out.iterdir()}
        assert "sweep.json" in names
        assert ("hypergame.prism" in names) == (other == WORLD1), (other, names)
    assert f"// digest       {load_world(WORLD1).digest()}\n" in (
        tmp_path / "same" / "hypergame.prism").read_text()


def test_the_digest_is_the_worlds_content() -> None:
    """World.digest(): equal for equal worlds (another path, a list for a tuple, numpy's
    numbers), different for any change (a setting, the map, an arena's table)."""
    import dataclasses

    import hg2prism

    world1 = load_world(MODELS / "world1.toml")
    same = dataclasses.replace(world1, path=Path("elsewhere.toml"))
    assert same.digest() == world1.digest() == world1.replace(window=np.int64(2)).digest()
    changed = [world1.replace(window=1), world1.replace(slip=0.2),
               world1.replace(hypotheses=list(world1.hypotheses[::-1])),
               world1.replace(simulation=dataclasses.replace(world1.simulation, seed=1))]
    assert len({w.digest() for w in changed} | {world1.digest()}) == len(changed) + 1
    arena = hg2prism.world_from_toml(
        (MODELS / "mir100.toml").read_text(), name=str(MODELS / "mir100.toml"))
    assert arena.digest() == load_world(MODELS / "mir100.toml").digest()
    prob = arena.arena.prob.copy()
    rows = prob.reshape(-1, prob.shape[-1])
    split = np.flatnonzero((rows > 0.01).sum(axis=1) == 2)[0]          # a move of two outcomes
    first, second = np.flatnonzero(rows[split] > 0.01)
    rows[split, first] += 0.005
    rows[split, second] -= 0.005
    moved = dataclasses.replace(arena, front=dataclasses.replace(arena.arena, prob=prob))
    assert moved.digest() != arena.digest()
    assert dataclasses.replace(moved, front=arena.arena).digest() == arena.digest()


def _many_trap_sets_world(candidates: int) -> object:
    """A 40-node attack graph, `candidates` trap candidates, 3 traps, delay 1 (a stress test's:
    with 25 candidates, 2,300 trap sets, `emit` was killed by the kernel at 22 GB)."""
    import random

    import networkx as nx

    import hg2prism

    rng, graph = random.Random(4), nx.DiGraph()
    for v in range(1, 38):
        for w in rng.sample(range(v + 1, min(40, v + 6) + 1), 2):
            graph.add_edge(v, w, p=rng.choice([0.5, 0.8]))
    target = max(v for v in graph if graph.out_degree(v) == 0)
    chosen = list(range(3, 3 + candidates))
    return hg2prism.world_from_graph(graph, entries=[1, 2], task=f"F asset{target}",
                                     trap_candidates=chosen, traps=3, delay=1,
                                     initial_traps=chosen[:3], name="many_sets")


def test_games_too_large_for_memory_are_refused_up_front(tmp_path: Path) -> None:
    """The size guard bounds P2's perceptual games too (their tables over TS state x P1's action
    x P2's action x outcome), not only the hypergame: one line naming `size`, before any work,
    nothing written; --max-states raises that bound with the other."""
    from hg2prism.frontends.arena import to_toml
    from hg2prism.model import sizeguard

    world = _many_trap_sets_world(25)
    assert sizeguard.estimate_states(world) < sizeguard.DEFAULT_LIMIT     # the hypergame fits
    path = tmp_path / "many_sets.toml"
    path.write_text(to_toml(world))
    start = time.monotonic()
    proc = run_cli(["emit", str(path), "--out", str(tmp_path / "o")], tmp_path, timeout=120)
    assert time.monotonic() - start < 30
    line = assert_one_line_error(proc, "size", "P2's perceptual games", "GiB", "--max-states")
    assert not (tmp_path / "o").exists()
    enough = int(line.rsplit("--max-states ", 1)[1].split()[0])
    assert sizeguard.check_games_size(world, enough) == sizeguard.game_table_bytes(world)
    with pytest.raises(InputError):
        sizeguard.check_games_size(world, enough - 1)
    # a --max-states below the default lowers the hypergame's bound only
    assert sizeguard.check_games_size(_many_trap_sets_world(10), 100) > 100 * 4096
    # one that fits: 10 candidates (120 trap sets) took a peak of 1.3 GB, the bound says more
    assert 1.3e9 < sizeguard.check_games_size(_many_trap_sets_world(10)) < 2e9


@pytest.mark.parametrize("old, new, key", [
    ('name = "world1"', 'name = "world\\none"', "name"),
    ('description = "', 'description = "first line\\nsecond line ', "description"),
    ('"!obs U B"', '"!obs U\\nB"', "adversary.hypotheses"),
    ('formula = "', 'formula = "\\n', "task.formula"),
])
def test_a_line_break_in_a_text_the_models_show_is_refused(tmp_path: Path, old, new, key) -> None:
    """A name, description or formula with a line break validated, then broke the generated
    model (its header comment ended at the break and Storm read the rest as the model: a
    multi-line error naming the staging folder). One line from validate, naming the key."""
    world = small_world(tmp_path, {old: new})
    proc = run_cli(["validate", str(world)], tmp_path)
    assert_one_line_error(proc, str(world), key, "one line")


def test_long_games_say_how_they_go(monkeypatch, caplog) -> None:
    """Games on large TS tables print a line as each is solved (a world whose games took a
    minute printed nothing meanwhile); small ones print only the stage's summary."""
    import logging

    from hg2prism import pipeline

    world = load_world(MODELS / "world1.toml")
    with caplog.at_level(logging.INFO, logger="hg2prism"):
        pipeline.analyse(world)
    assert not [r for r in caplog.messages if "solved (" in r and " of " in r]
    caplog.clear()
    monkeypatch.setattr(pipeline, "LONG_GAMES", 0)
    with caplog.at_level(logging.INFO, logger="hg2prism"):
        pipeline.analyse(world)
    lines = [r for r in caplog.messages if r.startswith("games: ")]
    assert lines[0].startswith("games: solving 4 games on ")
    solved = sorted(line.split(" solved (")[0] for line in lines[1:5])
    assert solved == sorted(["games: the leader game"] +
                            [f"games: the game of hypothesis x{i}" for i in range(3)])
    assert lines[5].startswith("games: 3 perceptual game(s) and the leader game solved")


def test_the_csv_writer_writes_every_digit_of_python_and_numpy_floats() -> None:
    """outputs.csv_text, the one CSV writer (bench, robust, sweep, the adaptive weight sweep): a
    float as repr, numpy's as Python's (numpy 2 reprs np.float64(0.5)), None empty, text
    quoted where needed."""
    import numpy as np

    from hg2prism.outputs import csv_text

    text = csv_text(["a", "b", "c", "d"], [[0.1, np.float64(1 / 3), None, "x,y"], [1, 2, 3, 4]])
    assert text == 'a,b,c,d\n0.1,0.3333333333333333,,"x,y"\n1,2,3,4\n'


def test_a_terminal_that_cannot_print_pi_gets_the_tables_with_a_replacement(tmp_path: Path
                                                                            ) -> None:
    """PYTHONIOENCODING=latin-1: `run` wrote every file, then ended with a UnicodeEncodeError
    traceback printing its table (π); the streams now replace what they cannot encode."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONIOENCODING="latin-1")
    proc = subprocess.run([sys.executable, "-m", "hg2prism", "run", str(MODELS / "world3.toml"),
                           "--episodes", "20", "--out", str(tmp_path / "o")], env=env,
                          capture_output=True, timeout=300)
    assert proc.returncode == 0 and b"Traceback" not in proc.stderr, proc.stderr
    assert b"deceptive ?1*" in proc.stdout and (tmp_path / "o" / "results.json").exists()


def test_every_record_says_what_software_computed_it(tmp_path: Path) -> None:
    """results.json, sweep.json (and robust.json, detection.json, the adaptive results, through
    results.provenance) carry `software`: hg2prism, Python, numpy, scipy, Spot and the model
    checker's versions (reproducibility check: "0.1.0" alone named no code, and no Storm or
    library version was kept), and hg2prism's git commit where it runs from a checkout."""
    import platform

    import numpy as np
    import scipy
    import spot

    from hg2prism.cli import main
    from hg2prism.progress import quiet

    with quiet():
        assert main(["check", WORLD1, "--out", str(tmp_path / "c")]) == 0
        assert main(["sweep", WORLD1, "--param", "window", "--values", "1",
                     "--out", str(tmp_path / "s")]) == 0
    for record in (tmp_path / "c" / "results.json", tmp_path / "s" / "sweep.json"):
        software = json.loads(record.read_text())["software"]
        assert {k: software[k] for k in ("python", "numpy", "scipy", "spot")} == {
            "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "spot": spot.version()}
        checker = software["model_checker"]
        assert checker.startswith("Storm ") and "stormpy" in checker
        if (ROOT / ".git").exists():
            assert re.fullmatch(r"[0-9a-f]{40}(\+edits)?", software["hg2prism_commit"])


def test_a_closed_stdout_ends_the_command_quietly(tmp_path: Path) -> None:
    """`hg2prism validate world | true`: the reader of stdout is gone before the command
    prints; it stops without a word on stderr (it said 'error: world.toml: Broken pipe',
    naming the world file as if it were at fault) and with SIGPIPE's status, 141."""
    import os
    import subprocess
    import sys

    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-m", "hg2prism", "validate", WORLD1],
                              stdout=write, stderr=subprocess.PIPE, text=True, timeout=120,
                              cwd=tmp_path)
    finally:
        os.close(write)
    assert (done.returncode, done.stderr) == (141, "")


def test_a_second_stop_waits_for_the_staging_folder_to_go(tmp_path: Path, monkeypatch) -> None:
    """A stopped command removes its staging folder; a second Ctrl-C during that removal
    stopped it halfway and left the folder (a carried leftover). The second stop now waits
    until the folder is gone, then takes effect."""
    from hg2prism import outputs

    removals = []
    remove = outputs.shutil.rmtree

    def interrupted_removal(path, *args, **kwargs):     # Ctrl-C the moment removal starts
        removals.append(path)
        os.kill(os.getpid(), signal.SIGINT)
        return remove(path, *args, **kwargs)

    monkeypatch.setattr(outputs.shutil, "rmtree", interrupted_removal)
    with pytest.raises(KeyboardInterrupt):
        with outputs.staged(tmp_path / "out") as stage:
            (stage / "strategy.json").write_text("[]")
            raise KeyboardInterrupt                      # the first stop
    assert removals == [stage] and not stage.exists() and not (tmp_path / "out").exists()


def test_an_abandoned_staging_folder_is_removed_by_the_next_command(tmp_path: Path,
                                                                     monkeypatch) -> None:
    """A command killed (SIGKILL), or stopped a second time while removing its staging folder,
    left `.OUT.staging-*` beside OUT for good. The next command to OUT removes such a folder
    once no process holds it and it has not changed for ABANDONED_AFTER; one a running command
    holds (here a process holding it as `staged` does), a young one, one holding an item of OUT
    set aside while outputs moved in, and a folder whose name mkdtemp does not make stay."""
    import fcntl
    import time

    from hg2prism import outputs
    from hg2prism.cli import main
    from hg2prism.outputs import ABANDONED_AFTER
    from hg2prism.progress import quiet

    out = tmp_path / "out"
    free_while_placing = []
    place = outputs._place

    def placing(stage_folder, *args):            # is the command's own stage held meanwhile?
        fd = os.open(stage_folder, os.O_RDONLY)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            free_while_placing.append(True)
        except BlockingIOError:
            free_while_placing.append(False)
        finally:
            os.close(fd)
        return place(stage_folder, *args)

    monkeypatch.setattr(outputs, "_place", placing)

    def stage(name: str, age: float) -> Path:
        folder = tmp_path / f".out.staging-{name:_<8}"          # mkdtemp's 8 characters
        (folder / "strategy.json").parent.mkdir()
        (folder / "strategy.json").write_text("[]")
        then = time.time() - age
        os.utime(folder, (then, then))
        return folder

    abandoned = stage("abandond", ABANDONED_AFTER + 5)
    young = stage("young", ABANDONED_AFTER - 30)
    held = stage("held", ABANDONED_AFTER + 5)
    aside = stage("aside", ABANDONED_AFTER + 5)          # killed while the outputs moved in
    (aside / ".replaced-results.json").write_text("{}")
    os.utime(aside, (0, 0))
    named = tmp_path / ".out.staging-x.toml"             # no stage's name: a user's file
    named.mkdir()
    os.utime(named, (0, 0))
    other = tmp_path / ".other.staging-x"            # another OUT's: not this command's to judge
    other.mkdir()
    os.utime(other, (0, 0))
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, os, sys, time\n"
         f"fd = os.open({str(held)!r}, os.O_RDONLY)\n"
         "fcntl.flock(fd, fcntl.LOCK_SH)\nprint('held', flush=True)\ntime.sleep(60)\n"],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with quiet():
            assert main(["emit", WORLD1, "--out", str(out)]) == 0
    finally:
        holder.kill()
        holder.wait()
    assert not abandoned.exists()
    assert young.exists() and held.exists() and other.exists()
    assert (out / "hypergame.prism").exists()
    # the command's own staging folder is gone, and it held it while it ran
    assert free_while_placing == [False]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [".other.staging-x", ".out.staging-young___", ".out.staging-held____",
         ".out.staging-aside___", ".out.staging-x.toml", "out"])
    fd = os.open(held, os.O_RDONLY)                  # the holder gone, it is free
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    os.close(fd)


def test_a_folder_name_too_long_for_the_staging_folder_is_refused(tmp_path: Path,
                                                                   capsys) -> None:
    """A valid --out whose staging folder's name would be too long for the file system was
    accepted, and the command failed after its work naming the hidden staging folder (exit 1,
    a stress test); it is now refused before any work, naming the user's folder (exit 2). A
    name that leaves room passes."""
    import os

    from hg2prism.cli import main

    most = os.pathconf(tmp_path, "PC_NAME_MAX")
    long = tmp_path / ("o" * (most - 10))
    assert main(["emit", WORLD1, "--out", str(long)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("hg2prism: error: command line: --out: the folder name ooo"), line
    assert f"is {most - 10} bytes long; at most {most - 18} here" in line, line
    only(tmp_path)
    fits = tmp_path / ("o" * (most - 18))
    from hg2prism.progress import quiet

    with quiet():
        assert main(["emit", WORLD1, "--out", str(fits)]) == 0
        # a file's folder has no staging folder beside it: its name may be as long as any
        long.mkdir()
        assert main(["convert", WORLD1, "--out", str(long / "arena.toml")]) == 0
    assert (fits / "hypergame.prism").exists() and (long / "arena.toml").exists()


def test_a_stop_while_outputs_move_in_waits_for_them(tmp_path: Path, monkeypatch,
                                                      capsys) -> None:
    """SIGTERM (or Ctrl-C) while a command's outputs move into OUT used to stop it between two
    items: some new, some of the old world's, the manifest not updated, and "nothing was
    written" said (a stress test slowed each rename to hit it). The stop now waits until OUT
    is whole, then takes effect: status 143 and a line saying the outputs were placed."""
    import signal

    from hg2prism import outputs
    from hg2prism.cli import main
    from hg2prism.progress import quiet

    out = tmp_path / "out"
    other = small_world(tmp_path, {"slip = 0.1": "slip = 0.15"})
    with quiet():
        assert main(["check", str(other), "--out", str(out)]) == 0
    replace, calls = os.replace, []

    def stopped_midway(source, target):
        if Path(target).parent == out:
            calls.append(target)
        if len(calls) == 3 and Path(target).parent == out:    # the third item placed: stop
            os.kill(os.getpid(), signal.SIGTERM)
        return replace(source, target)

    monkeypatch.setattr(outputs.os, "replace", stopped_midway)
    capsys.readouterr()
    with pytest.raises(SystemExit) as stop:
        main(["check", WORLD1, "--out", str(out)])
    assert stop.value.code == 143
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == f"hg2prism: stopped by signal 15 after placing its outputs in {out}", err
    results = json.loads((out / "results.json").read_text())
    assert results["world_digest"] == load_world(WORLD1).digest()
    assert f"// digest       {load_world(WORLD1).digest()}\n" in (
        out / "hypergame.prism").read_text()
    placed = set(json.loads((out / MANIFEST).read_text())["items"])
    assert placed == set(names_in(out)) - {MANIFEST}
    assert not [p for p in tmp_path.iterdir() if "staging" in p.name]

    # the next command of the same process, stopped before its outputs move in, says nothing
    # was written (the placement above is not its own: a code review)
    def interrupted(source, target):
        raise KeyboardInterrupt

    monkeypatch.setattr(outputs.os, "replace", interrupted)
    assert main(["emit", WORLD1, "--out", str(tmp_path / "later")]) == 130
    assert capsys.readouterr().err.strip().splitlines()[-1] == "hg2prism: interrupted"
    assert not (tmp_path / "later").exists()


def test_a_failure_while_outputs_move_in_is_said_and_the_next_command_cleans_up(
        tmp_path: Path, monkeypatch, capsys) -> None:
    """A full disk as the manifest is written, after the outputs moved in (a stress test,
    through a plugin): the command said only the error, as if nothing had been placed, and the
    manifest kept the old list, so a later command left the unrecorded robust_0.1/ beside its
    own robust_0.2/. The manifest is now written first with the old and new items, the error
    says OUT may hold some of each, and the next command removes what is stale."""
    import errno

    from hg2prism import outputs
    from hg2prism.cli import main
    from hg2prism.progress import quiet

    out = tmp_path / "out"
    world = small_world(tmp_path)
    with quiet():
        assert main(["robust", str(world), "--deltas", "0", "--out", str(out)]) == 0
    record = outputs._record_placed

    def full(folder, names):
        raise OSError(errno.ENOSPC, "No space left on device", str(folder / MANIFEST))

    monkeypatch.setattr(outputs, "_record_placed", full)
    capsys.readouterr()
    with quiet():
        assert main(["robust", str(world), "--deltas", "0.1", "--out", str(out)]) == 1
    (line,) = [x for x in capsys.readouterr().err.splitlines() if "error" in x]
    assert line == (f"hg2prism: error: {out / MANIFEST}: No space left on device; {out} may "
                    f"hold some of the new outputs beside old ones (its {MANIFEST} lists both, "
                    f"so the next command into it removes the stale ones)"), line
    assert "robust_0.1" in json.loads((out / MANIFEST).read_text())["items"]
    monkeypatch.setattr(outputs, "_record_placed", record)
    with quiet():
        assert main(["robust", str(world), "--deltas", "0.2", "--out", str(out)]) == 0
    assert {p.name for p in out.iterdir() if p.name.startswith("robust_")} == {"robust_0.2"}

    # SIGTERM while placing, then the full disk: the error is what is said (it was replaced
    # by "stopped by signal 15; nothing was written": a code review)
    import signal

    def stopped_then_full(folder, names):
        os.kill(os.getpid(), signal.SIGTERM)
        full(folder, names)

    monkeypatch.setattr(outputs, "_record_placed", stopped_then_full)
    capsys.readouterr()
    with quiet():
        assert main(["robust", str(world), "--deltas", "0.1", "--out", str(out)]) == 1
    (line,) = [x for x in capsys.readouterr().err.splitlines() if "error" in x or "signal" in x]
    assert "No space left on device" in line and f"{out} may hold some" in line, line


def test_the_program_exits_without_tearing_down_an_abandoned_storm_thread(monkeypatch) -> None:
    """Stopped while Storm computed on its worker thread (engines/storm.py), `robust` ended
    with SIGABRT ("terminate called without an active exception") in 3 of 8 tries instead of
    status 143: Python's exit tore the interpreter down under the ending thread (a stress
    test). `cli.entry` then leaves by os._exit with the command's status; otherwise it returns
    it."""
    import threading

    from hg2prism import cli

    exits = []

    def stopped(argv=None):
        raise SystemExit(143)

    monkeypatch.setattr(cli, "main", stopped)
    monkeypatch.setattr(cli.os, "_exit", exits.append)
    assert cli.entry() == 143 and exits == []          # no Storm thread: a normal exit
    release = threading.Event()
    worker = threading.Thread(target=release.wait, name="storm", daemon=True)
    worker.start()
    try:
        cli.entry()
    finally:
        release.set()
        worker.join()
    assert exits == [143]
    # both ways of starting the program go through it
    assert 'hg2prism = "hg2prism.program:entry"' in (ROOT / "pyproject.toml").read_text()
    assert "from hg2prism.program import entry" in (ROOT / "hg2prism" / "__main__.py").read_text()
    assert "raise SystemExit(entry())" in (ROOT / "hg2prism" / "__main__.py").read_text()


def test_a_ctrl_c_while_python_imports_the_program_is_one_line(monkeypatch, capsys) -> None:
    """Ctrl-C in the first second of a command, while Python still imported hg2prism and its
    libraries, printed a KeyboardInterrupt traceback of the imports (an atomicity review):
    the program (`hg2prism.program.entry`, which imports nothing heavy) says
    `hg2prism: interrupted` and returns 130, as every other Ctrl-C does."""
    import importlib.abc

    from hg2prism import program

    class Interrupted(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name == "hg2prism.cli":
                raise KeyboardInterrupt
            return None

    monkeypatch.delitem(sys.modules, "hg2prism.cli", raising=False)
    monkeypatch.setattr(sys, "meta_path", [Interrupted(), *sys.meta_path])
    capsys.readouterr()
    assert program.entry() == 130
    assert capsys.readouterr().err == "hg2prism: interrupted\n"
    # importing the package and the program loads none of the pipeline
    code = ("import sys, hg2prism.program; "
            "print(sorted(m for m in sys.modules if m.startswith(('numpy', 'hg2prism.'))))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True).stdout
    # (and hg2prism.reproducible, which pins OpenBLAS's kernels with os, platform and sys)
    assert loaded.strip() == "['hg2prism.program', 'hg2prism.reproducible']", loaded
    # the package as it was once asked for anything: its modules too (a code review: after a
    # bare `import hg2prism`, hg2prism.errors and hg2prism.opponent.registry were no names)
    code = ("import hg2prism; print(hg2prism.errors.InputError.__name__, "
            "hg2prism.opponent.registry.configure.__name__, hg2prism.solve.__module__, "
            "sorted(set(hg2prism.__all__) - set(dir(hg2prism))))")
    said = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout
    assert said.strip() == "InputError configure hg2prism.api []", said


def test_a_sweep_stopped_while_its_dask_cluster_starts_ends_in_one_line(tmp_path) -> None:
    """Ctrl-C while a sweep's LocalCluster started printed Dask's exit-hook traceback
    (AssertionError: Status.init) and its shutdown logs after "hg2prism: interrupted" (an
    atomicity review). The sweep now closes the clusters it started itself, quietly, and keeps
    Dask's exit hook off them: one line, status 130, no worker process left."""
    script = tmp_path / "stop.py"
    script.write_text(
        "import os, sys\n"
        "import distributed, distributed.deploy.local as local\n"
        "started = local.LocalCluster.__init__\n"
        "def stop(self, *args, **kwargs):\n"
        "    started(self, *args, **kwargs)\n"
        "    raise KeyboardInterrupt          # Ctrl-C as the cluster's start returns\n"
        "local.LocalCluster.__init__ = stop\n"
        "from hg2prism.cli import entry\n"
        "if __name__ == '__main__':\n"
        "    status = entry()\n"
        "    print('children', len(__import__('multiprocessing').active_children()))\n"
        "    sys.exit(status)\n")
    done = subprocess.run(
        [sys.executable, str(script), "sweep", str(ROOT / "models" / "world1.toml"), "--param",
         "rationality", "--values", "1", "2", "--workers", "2", "--out", str(tmp_path / "out")],
        capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 130, done.stderr
    assert done.stderr == "hg2prism: interrupted\n", done.stderr
    assert done.stdout.strip() == "children 0", done.stdout
    assert not (tmp_path / "out").exists()


def test_a_stopped_parallel_sweep_gives_the_libraries_their_log_levels_back(monkeypatch) -> None:
    """A sweep on workers quiets Dask's, tornado's and asyncio's loggers while it runs; stopped
    or failed, it left them quiet for the rest of a notebook's session (a code review). They
    are put back however it ends (the program itself quiets them once stopped, cli.entry)."""
    import logging

    import distributed.deploy.local as local

    import hg2prism

    def stopped(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(local.LocalCluster, "__init__", stopped)
    names = ("asyncio", "distributed", "tornado", "bokeh")
    before = {name: logging.getLogger(name).level for name in names}
    world = hg2prism.load_world(ROOT / "models" / "world1.toml")
    with pytest.raises(KeyboardInterrupt):
        hg2prism.sweep(world, "threshold", [1.0, 2.0], workers=2)
    assert {name: logging.getLogger(name).level for name in names} == before


def test_a_ctrl_c_while_plugins_load_is_said(monkeypatch, capsys) -> None:
    """Ctrl-C while HG2PRISM_PLUGINS loaded (or the parser was built) ended with status 130 and
    nothing said (a code review): it says `hg2prism: interrupted` as every other stop does."""
    from hg2prism import cli, plugins

    def interrupted() -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(plugins, "load_plugins", interrupted)
    capsys.readouterr()
    assert cli.main(["validate", str(ROOT / "models" / "world1.toml")]) == 130
    assert capsys.readouterr().err == "hg2prism: interrupted\n"
