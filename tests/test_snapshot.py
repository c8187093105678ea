"""Every file the command line writes for world1-world3, world2 at delay 2, ten generated worlds
and world2's robust and detect runs is what the code wrote when tests/snapshots/outputs.json was
taken (timings, version and paths masked): refactorings change no value, size, strategy,
figure or text (tests/snapshot.py)."""

from __future__ import annotations

import json

import snapshot


def test_outputs_match_the_snapshot(tmp_path):
    stored = json.loads(snapshot.SNAPSHOT.read_text())
    fresh = snapshot.produce(tmp_path)
    problems = snapshot.compare(fresh, stored)
    assert not problems, "outputs changed:\n" + "\n".join(problems)


def test_the_comparison_sees_a_changed_file():
    stored = {"w": {"a.json": "1", "b.png": "2"}}
    assert snapshot.compare({"w": {"a.json": "1", "b.png": "2"}}, stored) == []
    assert snapshot.compare({"w": {"a.json": "x", "b.png": "2"}}, stored) == ["w/a.json: differs"]
    assert snapshot.compare({"w": {"a.json": "1"}}, stored) == ["w/b.png: not written"]
    assert snapshot.compare({}, stored) == ["w: missing from the run"]


def test_masking_keeps_values_and_hides_timings(tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps({"v": 0.5, "timings": {"build": 1.0}, "rows": [{"seconds": 2}]}))
    b.write_text(json.dumps({"v": 0.5, "timings": {"build": 3.0}, "rows": [{"seconds": 9}]}))
    assert snapshot.digest(a, []) == snapshot.digest(b, [])
    b.write_text(json.dumps({"v": 0.5000001, "timings": {}, "rows": [{"seconds": 9}]}))
    assert snapshot.digest(a, []) != snapshot.digest(b, [])
