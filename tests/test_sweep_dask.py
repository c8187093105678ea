"""Sweeps over a grid of parameters on Dask (docs/semantics.md §7, Sweeps): a 2-worker
LocalCluster gives byte-identical outputs (timings aside) to the serial run, every solved point equals the
independent reference (tests/reference.py) on the world rewritten by hand, the points the size
guard refuses are reported with their parameters while the others complete, no worker process
outlives the sweep and nothing but the progress lines reaches stderr.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import re
import sys
from pathlib import Path

import psutil
import pytest

import reference
import worldgen
from conftest import names_in
from gridview import initial_trap_cells
from hg2prism import cli
from hg2prism.errors import InputError
from hg2prism.experiments import sweep
from hg2prism.model.sizeguard import estimate_states
from hg2prism.worldfile import load_world

TOL = 1e-6
GRID = [("delay", [0, 1]), ("traps", [1, 2]), ("slip", [0.0, 0.1]), ("window", [1, 2])]
LIMIT = 500     # refuses the largest points of GRID (delay 1, slip 0.1, window 2) and no other


def tiny_world_text() -> str:
    # a 3x3 interior with three trap candidates, delay 0 and no initial traps in the file
    return worldgen.make_world(3, delay=0, traps=1, window=1, slip=0.1, nhyp=2, size=(3, 3),
                               ncand=3, name="tiny")


def candidates_in_reading_order(text: str) -> list[list[int]]:
    """The `t` cells, top row first, left to right; y counts rows from the bottom."""
    rows = text.split('map = """\n', 1)[1].split('"""', 1)[0].splitlines()
    height = len(rows)
    return [[x, height - 1 - r] for r, row in enumerate(rows) for x, ch in enumerate(row)
            if ch == "t"]


def rewritten(text: str, point: dict) -> str:
    """The world file of one point, written by hand: each swept key replaced, and with a
    positive delay the first `traps` candidates standing (the file gives no initial traps)."""
    standing = candidates_in_reading_order(text)[:point["traps"]] if point["delay"] > 0 else []
    replacements = {
        r"^slip = .*$": f"slip = {point['slip']!r}",
        r"^traps = .*$": f"traps = {point['traps']}",
        r"^delay = .*$": f"delay = {point['delay']}",
        r"^window = .*$": f"window = {point['window']}",
        r"^initial_traps = .*$": "initial_traps = [" + ", ".join(f"[{x}, {y}]"
                                                                 for x, y in standing) + "]",
    }
    for pattern, line in replacements.items():
        text, count = re.subn(pattern, line, text, flags=re.M)
        assert count == 1, pattern
    return text


def folder_of(point: dict) -> str:
    """`delay_1__traps_2__slip_0.1__window_1`, as docs/semantics.md §7 names a point's folder."""
    return "__".join(f"{k}_{v:g}" if isinstance(v, float) else f"{k}_{v}" for k, v in point.items())


def without_timings(text: str) -> str:
    return re.sub(r'"seconds": [0-9.e+-]+', '"seconds": T', text)


def children() -> list[psutil.Process]:
    """This process's children, less multiprocessing's resource tracker (one per process that
    ever started a child by spawning, alive until this process ends; it runs no work)."""
    return [p for p in psutil.Process().children(recursive=True)
            if "multiprocessing.resource_tracker" not in " ".join(p.cmdline())]


@contextlib.contextmanager
def stderr_to(path: Path):
    """sys.stderr and file descriptor 2 (which the worker processes inherit) appended to `path`."""
    sys.stderr.flush()
    saved = os.dup(2)
    with open(path, "a") as handle:
        os.dup2(handle.fileno(), 2)
        try:
            with contextlib.redirect_stderr(handle):
                yield
        finally:
            handle.flush()
            os.dup2(saved, 2)
            os.close(saved)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory):
    """The grid swept serially and on a 2-worker LocalCluster (stderr of the Dask run kept)."""
    base = tmp_path_factory.mktemp("sweep_dask")
    path = base / "tiny.toml"
    path.write_text(tiny_world_text())
    world = load_world(path)
    before = children()
    serial = sweep.sweep_grid(world, GRID, base / "serial", show_progress=False,
                              max_states=LIMIT)
    log = base / "stderr.txt"
    with stderr_to(log):
        dask = sweep.sweep_grid(world, GRID, base / "dask", show_progress=True, workers=2,
                                max_states=LIMIT)
    after = children()
    return path, world, serial, dask, base, log.read_text(), before, after


def points() -> list[dict]:
    names = [name for name, _ in GRID]
    return [dict(zip(names, values)) for values in itertools.product(*(v for _, v in GRID))]


def test_dask_outputs_equal_the_serial_ones_byte_for_byte(runs) -> None:
    _, _, serial, dask, base, _, _, _ = runs
    assert [{k: v for k, v in r.items() if k != "seconds"} for r in dask.rows] == \
           [{k: v for k, v in r.items() if k != "seconds"} for r in serial.rows]
    assert dask.failed == serial.failed
    s, d = base / "serial", base / "dask"
    assert without_timings((s / "sweep.json").read_text()) == \
           without_timings((d / "sweep.json").read_text())
    strip_seconds = lambda p: [line.rsplit(",", 1)[0] for line in p.read_text().splitlines()]
    assert strip_seconds(s / "sweep.csv") == strip_seconds(d / "sweep.csv")
    folders = sorted(p.name for p in s.iterdir() if p.is_dir())
    assert folders == sorted(p.name for p in d.iterdir() if p.is_dir())
    assert len(folders) == len(serial.rows)
    for folder in folders:
        for name in ("hypergame.prism", "hypergame.props", "strategy.json"):
            assert (s / folder / name).read_bytes() == (d / folder / name).read_bytes()
        rs, rd = (json.loads((x / folder / "results.json").read_text()) for x in (s, d))
        rs.pop("timings"), rd.pop("timings")
        assert rs == rd


def test_every_point_is_solved_or_reported_and_solved_points_equal_the_reference(runs) -> None:
    path, world, _, dask, base, _, _, _ = runs
    text = path.read_text()
    summary = json.loads((base / "dask" / "sweep.json").read_text())
    assert summary["parameters"] == [name for name, _ in GRID]
    assert summary["grid"] == {name: values for name, values in GRID}
    assert "parameter" not in summary and "values" not in summary
    rows = iter(dask.rows)
    failed = iter(dask.failed)
    refused = 0
    for n, point in enumerate(points()):
        variant = base / f"point{n}.toml"
        variant.write_text(rewritten(text, point))
        if estimate_states(load_world(variant)) > LIMIT:
            refused += 1
            report = next(failed)
            assert {k: v for k, v in report.items() if k != "error"} == point
            assert report["error"].startswith("size: ") and f"limit of {LIMIT}" in report["error"]
            assert not (base / "dask" / folder_of(point)).exists()
            continue
        assert (base / "dask" / folder_of(point) / "results.json").exists()
        row = next(rows)
        assert {k: row[k] for k in point} == point
        expected = reference.solve(variant)
        assert abs(row["deceptive_value"] - expected.value) <= TOL, point
        assert abs(row["v_lead"] - expected.v_lead) <= TOL, point
        assert (row["states"], row["transitions"]) == (expected.states, expected.transitions)
        standing = candidates_in_reading_order(text)[:point["traps"]] if point["delay"] else []
        assert row["standing"] == ("+".join(f"x{x}_y{y}" for x, y in standing) or None)
    assert next(rows, None) is None and next(failed, None) is None
    assert refused == 2 and summary["failed"] == [dict(f) for f in dask.failed]


def test_progress_counts_points_and_workers_leave_no_noise_or_process(runs) -> None:
    _, _, _, dask, _, err, before, after = runs
    lines = err.splitlines()
    total = len(points())
    assert len(lines) == total
    assert all(line.startswith("sweep ") for line in lines), err     # no Dask log lines
    assert [int(re.search(r"\((\d+)/%d\)" % total, line).group(1)) for line in lines] == \
           list(range(1, total + 1))
    assert sum("failed: size: " in line for line in lines) == len(dask.failed) == 2
    # the LocalCluster's workers and nannies are gone once the sweep returns
    assert {p.pid for p in after} <= {p.pid for p in before}


def test_two_parameters_on_the_command_line(tmp_path: Path, capsys) -> None:
    path = tmp_path / "tiny.toml"
    path.write_text(tiny_world_text())
    out = tmp_path / "out"
    code = cli.main(["sweep", str(path), "--param", "delay", "--values", "0", "1",
                     "--param", "window", "--values", "1", "2", "--out", str(out),
                     "--workers", "1", "--max-states", "300"])
    captured = capsys.readouterr()
    # delay 1 with window 2 is refused (estimate 1,046), the three others are written
    assert code == 1
    errors = [line for line in captured.err.splitlines() if line.startswith("hg2prism: error:")]
    assert len(errors) == 1 and "sweep point delay=1 window=2: size:" in errors[0]
    assert names_in(out) == [
        "delay_0__window_1", "delay_0__window_2", "delay_1__window_1",
        "sweep.csv", "sweep.json", "sweep.png", "sweep.svg"]
    header = (out / "sweep.csv").read_text().splitlines()[0]
    assert header.startswith("delay,window,standing,deceptive_value,")
    assert "| delay | window | standing at the start | deceptive value |" in captured.out
    summary = json.loads((out / "sweep.json").read_text())
    assert [(r["delay"], r["window"]) for r in summary["rows"]] == [(0, 1), (0, 2), (1, 1)]
    assert [(f["delay"], f["window"]) for f in summary["failed"]] == [(1, 2)]
    # a one-parameter sweep into the same folder leaves no stale point folder behind
    assert cli.main(["sweep", str(path), "--param", "window", "--values", "1", "--out",
                     str(out), "--workers", "1"]) == 0
    assert names_in(out) == [
        "sweep.csv", "sweep.json", "sweep.png", "sweep.svg", "window_1"]


@pytest.mark.parametrize("argv, key, fragment", [
    (["--param", "delay", "--values", "0", "--param", "window"], "--values", "own --values"),
    (["--param", "delay", "--values", "0", "--param", "delay", "--values", "1"], "--param",
     "given twice"),
    (["--param", "traps", "--values", "4"], "--values", "at most the world's 3 trap candidates"),
    (["--param", "slip", "--values", "0.5"], "--values", "slip value 0.5 must be a number in [0, 0.5)"),
    (["--param", "window", "--values", "1", "--workers", "0"], "--workers", "at least 1"),
    (["--param", "window", "--values", "1", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"],
     "--scheduler", "leave out --workers"),
])
def test_bad_sweep_arguments_are_one_line(tmp_path: Path, capsys, argv, key, fragment) -> None:
    path = tmp_path / "tiny.toml"
    path.write_text(tiny_world_text())
    code = cli.main(["sweep", str(path), "--out", str(tmp_path / "out")] + argv)
    err = capsys.readouterr().err
    assert code == 2 and len(err.splitlines()) == 1, err
    assert f"command line: {key}: " in err and fragment in err, err
    assert not (tmp_path / "out").exists()


def test_swept_traps_keep_the_worlds_standing_traps_first(tmp_path: Path) -> None:
    text = tiny_world_text().replace("delay = 0", "delay = 1")
    cands = candidates_in_reading_order(text)
    last = cands[-1]
    text = re.sub(r"^initial_traps = .*$", f"initial_traps = [[{last[0]}, {last[1]}]]", text,
                  flags=re.M)
    path = tmp_path / "standing.toml"
    path.write_text(text)
    world = load_world(path)
    # traps 2: the world's own standing trap, then the first other candidate (reading order)
    cells = initial_trap_cells
    assert [list(c) for c in cells(sweep.sweep_world(world, "traps", 2))] == [cands[0], last]
    assert [list(c) for c in cells(sweep.sweep_world(world, "traps", 1))] == [last]
    point = sweep.sweep_point(world, {"traps": 2, "delay": 0})
    # nothing stands with delay 0; the point keeps the set for a re-solve with delay
    assert cells(point) == () and point.initial_standing == sweep.sweep_point(
        world, {"traps": 2, "delay": 1}).initial_standing == 1
    with pytest.raises(InputError):
        sweep.sweep_world(world, "traps", 0)
