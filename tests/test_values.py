"""The one parser of command-line value lists (hg2prism/experiments/values.py): `sweep --values`,
`robust --deltas`, `sweep --param weight --values` and `detect --fallback-delta` each give their
one-line errors through it, with the hint to separate values with spaces where a list was typed
with commas."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import MODELS
from hg2prism.cli import main
from hg2prism.errors import InputError
from hg2prism.experiments import adaptive, detect, robust, sweep
from hg2prism.experiments.values import ValueList, number, parse_values


def reason(parse, *args) -> tuple[str, str]:
    with pytest.raises(InputError) as caught:
        parse(*args)
    assert caught.value.file == "command line"
    return caught.value.key, caught.value.reason


@pytest.mark.parametrize("parse, values, key, expected", [
    # sweep --values, in the sweep's words
    (lambda v: sweep.parse_sweep_values("window", v), ["1,4"], "--values",
     "window value '1,4' is not an integer >= 1; separate the values with spaces "
     "(--values 1 4)"),
    # the hint where the parts have a value's form, in range or not ("1,0")
    (lambda v: sweep.parse_sweep_values("window", v), ["1,0"], "--values",
     "window value '1,0' is not an integer >= 1; separate the values with spaces "
     "(--values 1 0)"),
    # no hint where a part is no value either ("1,x"): the value is wrong, not its commas
    (lambda v: sweep.parse_sweep_values("window", v), ["1,x"], "--values",
     "window value '1,x' is not an integer >= 1"),
    (lambda v: sweep.parse_sweep_values("prior", v), ["1,x"], "--values",
     "prior value '1,x' is not comma-separated positive numbers, one per hypothesis"),
    (lambda v: sweep.parse_sweep_values("window", v), ["0"], "--values",
     "window value 0 must be an integer >= 1"),
    (lambda v: sweep.parse_sweep_values("window", v), [], "--values",
     "expected at least one value of window (an integer >= 1)"),
    (lambda v: sweep.parse_sweep_values("window", v), ["2", 2], "--values",
     "window value 2 is repeated; expected distinct values"),
    # a bad value is reported before a repeated one, wherever it stands
    (lambda v: sweep.parse_sweep_values("window", v), ["2", "2", "x"], "--values",
     "window value 'x' is not an integer >= 1"),
    # robust --deltas, in robust's words, now with the same hint
    (robust.parse_deltas, ["0.1,0.2"], "--deltas",
     "'0.1,0.2' is not a deviation budget in [0, 1); separate the values with spaces "
     "(--deltas 0.1 0.2)"),
    (robust.parse_deltas, ["1"], "--deltas", "'1' is not a deviation budget in [0, 1)"),
    (robust.parse_deltas, [True], "--deltas", "True is not a deviation budget in [0, 1)"),
    (robust.parse_deltas, ["nan"], "--deltas", "'nan' is not a deviation budget in [0, 1)"),
    (robust.parse_deltas, [], "--deltas", "expected at least one deviation budget in [0, 1)"),
    (robust.parse_deltas, "0.1", "--deltas", "expected at least one deviation budget in [0, 1)"),
    (robust.parse_deltas, ["0.1", "0.10"], "--deltas", "0.10 is repeated; expected distinct "
                                                       "budgets"),
    (robust.parse_deltas, ["0.1", "0.1", "2"], "--deltas",
     "'2' is not a deviation budget in [0, 1)"),
    # --param weight --values
    (adaptive.parse_weights, ["1.5"], "--values", "a weight is a number in [0, 1], got '1.5'"),
    (adaptive.parse_weights, ["0.5,1"], "--values", "a weight is a number in [0, 1], got "
                                                    "'0.5,1'; separate the values with spaces "
                                                    "(--values 0.5 1)"),
    # --fallback-delta is one value: its key, robust's words, no hint about lists
    (lambda v: detect.parse_fallback("robust", v), "0.1,0.2", "--fallback-delta",
     "'0.1,0.2' is not a deviation budget in [0, 1)"),
])
def test_one_line_errors(parse, values, key, expected) -> None:
    assert reason(parse, values) == (key, expected)


def test_what_parses() -> None:
    assert robust.parse_deltas(["0", "0.05", 0.5, np.float64(0.25)]) == [0.0, 0.05, 0.5, 0.25]
    assert adaptive.parse_weights(["0", "1", "1"]) == [0.0, 1.0, 1.0]   # weights may repeat
    assert sweep.parse_sweep_values("delay", ["0", 3, np.int64(2)]) == [0, 3, 2]
    assert detect.parse_fallback("robust", "0.2") == ("robust", 0.2)
    whole = number(int, 1)
    assert [whole(v) for v in ("1", " 7 ", 9)] == [1, 7, 9]
    for bad, why in ((1.0, "must be"), ("1.5", "is not"), (True, "must be"), (0, "must be"),
                     (None, "must be")):
        with pytest.raises(ValueError, match=why):
            whole(bad)
    unit = number(float, 0.0, exclusive=True, maximum=1.0)
    assert unit("1") == 1.0
    for bad in ("0", "1.0001"):
        with pytest.raises(ValueError, match="must be"):
            unit(bad)
    for bad in ("inf", float("nan"), "1e309"):      # said apart: "must be" read wrong for 1e309
        with pytest.raises(ValueError, match="finite"):
            unit(bad)


def test_an_option_of_its_own_words() -> None:
    spec = ValueList("--sizes", "size", "an integer >= 1", number(int, 1))
    assert parse_values(spec, ["3", "4"]) == [3, 4]
    assert reason(parse_values, spec, ["3,4"]) == (
        "--sizes", "size '3,4' is not an integer >= 1; separate the values with spaces "
                   "(--sizes 3 4)")
    assert reason(parse_values, spec, []) == ("--sizes",
                                              "expected at least one size (an integer >= 1)")


def test_the_command_line_says_it_in_one_line(tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    assert main(["robust", str(MODELS / "world2.toml"), "--deltas", "0,0.1",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["hg2prism: error: command line: --deltas: '0,0.1' is not a deviation budget "
                   "in [0, 1); separate the values with spaces (--deltas 0 0.1)"]
    assert not out.exists()
