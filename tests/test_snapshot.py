"""Every file the command line writes for world1-world3, world2 at delay 2, ten generated worlds
and world2's robust and detect runs is what the code wrote when tests/snapshots/outputs.json was
taken (timings, version and paths masked): refactorings change no value, size, strategy,
figure or text (tests/snapshot.py)."""

from __future__ import annotations

import json

import pytest

import snapshot
from conftest import QUICK, share

GENERATED = share(snapshot.GENERATED)


# About a minute of both cores (its cases run in two processes of their own): `make test`
# leaves it to `make test-all`, which `.ci/run` runs after it, to stay within ten minutes.
@pytest.mark.skipif(QUICK, reason="make test-all compares the outputs with the snapshot")
def test_outputs_match_the_snapshot(tmp_path):
    stored = json.loads(snapshot.SNAPSHOT.read_text())
    left_out = set(snapshot.GENERATED) - set(GENERATED)
    stored.update({key: {case: files for case, files in stored[key].items()
                         if case not in left_out} for key in ("exact", "rounded")})
    fresh = snapshot.produce(tmp_path, generated=GENERATED)
    problems = snapshot.compare(fresh, stored)
    assert not problems, "outputs changed:\n" + "\n".join(problems)


def _taken(exact: dict, rounded: dict | None = None, machine: str = "here") -> dict:
    rounded = rounded or {c: {f: ["r4" + d, "r6" + d] for f, d in files.items()}
                          for c, files in exact.items()}
    return {"machine": machine, "exact": exact, "rounded": rounded}


def test_the_comparison_sees_a_changed_file():
    stored = _taken({"w": {"a.json": "1", "b.png": "2"}})
    assert snapshot.compare(_taken({"w": {"a.json": "1", "b.png": "2"}}), stored) == []
    assert snapshot.compare(_taken({"w": {"a.json": "x", "b.png": "2"}}, stored["rounded"]),
                            stored) == ["w/a.json: differs"]
    assert snapshot.compare(_taken({"w": {"a.json": "1"}}), stored) == ["w/b.png: not written"]
    assert snapshot.compare(_taken({}), stored) == ["w: missing from the run"]


def test_another_machine_compares_the_numbers_rounded(tmp_path):
    """On the machine the snapshot was taken on, a difference in the last bit of a number is a
    difference; on a machine whose floating-point code differs, numbers are compared rounded
    to 6 or 8 significant digits (either): a number at a rounding boundary of one precision is
    not at the other's, and a change in the first 6 digits is still seen."""
    def taken(text: str, machine: str) -> dict:
        path = tmp_path / "m.prism"
        path.write_text(text)
        exact, *rounded = snapshot.digests(path, [])
        return _taken({"w": {"m.prism": exact}}, {"w": {"m.prism": rounded}}, machine)

    # p is at a boundary of 6 digits, q at one of 8: last-bit changes of either pass
    for before, after in (("p = 0.6123454999999999; q = 0.12344;",
                           "p = 0.6123455000000001; q = 0.12344;"),
                          ("p = 0.61234; q = 0.12344444499999999;",
                           "p = 0.61234; q = 0.12344444500000001;")):
        stored = taken(before + " n = 3;", "avx512")
        assert snapshot.compare(taken(after + " n = 3;", "avx512"), stored) == [
            "w/m.prism: differs"]
        assert snapshot.compare(taken(after + " n = 3;", "avx2"), stored) == []
        for changed in (before.replace("0.6123", "0.6124") + " n = 3;",   # a value
                        before + " n = 4;"):                              # an integer
            assert snapshot.compare(taken(changed, "avx2"), stored) == [
                "w/m.prism: differs (numbers rounded to 6 and 8 digits)"], changed
    assert snapshot.rounded("v 0.1.0 x1_y2 1e-9 -2.50000001", 4) == "v 0.1.0 x1_y2 1e-09 -2.5"


def test_masking_keeps_values_and_hides_timings(tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps({"v": 0.5, "timings": {"build": 1.0}, "rows": [{"seconds": 2}]}))
    b.write_text(json.dumps({"v": 0.5, "timings": {"build": 3.0}, "rows": [{"seconds": 9}]}))
    assert snapshot.digest(a, []) == snapshot.digest(b, [])
    b.write_text(json.dumps({"v": 0.5000001, "timings": {}, "rows": [{"seconds": 9}]}))
    assert snapshot.digest(a, []) != snapshot.digest(b, [])
