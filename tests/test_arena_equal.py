"""A grid world and its converted arena form give the same results (issue 23, docs/semantics.md
§15): for world1, world2 at delays 0-3, world3, world3_bayes and the 50 generated worlds
(tests/worldgen.py), the grid world file and the arena world file `hg2prism convert` writes for
it (frontends.arena.to_toml, read back by load_world) give, through `pipeline.check`, the same
deceptive value, V_lead, canonical and Storm sizes and strategy.json records; and through the
stages `pipeline.run` uses (`_nash_stage`, `_deception_stage`) the same V_NE, V_static and
V_naive.

"The same": sizes, record fields and P1's actions exactly; numbers within 1e-12, except the
values of P1's moves in strategy.json records (within 1e-11). The converted file merges each
action's equal successors (their probabilities add up) and drops zero probabilities, so the
PRISM model, and the floating-point order of Storm's sums, differ slightly: the largest
differences seen are 8e-14 on a deceptive value and 1.2e-12 on a move's value (fam00).

Runtime: the baselines (V_NE, V_static, V_naive) cost about as much as the checks, so they are
compared on the model worlds and every fifth generated world (fam00, fam05, ..., fam45); the
check and V_lead on all 50 (about 35 s on one core; with the baselines on all 50 the file takes
about 70 s, and it passed so).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

import worldgen
from conftest import MODELS, QUICK, share
from hg2prism import pipeline, progress
from hg2prism.frontends.arena import to_toml
from hg2prism.worldfile import load_world

TOL = 1e-12
MOVE_TOL = 1e-11
SIZES = ("states", "transitions", "storm_states", "storm_transitions", "storm_choices")


def _model_worlds() -> list[tuple[str, str]]:
    worlds = [(name, (MODELS / f"{name}.toml").read_text())
              for name in ("world1", "world3", "world3_bayes")]
    world2 = (MODELS / "world2.toml").read_text()
    assert world2.count("delay = 0") == 1
    # `make test`: delays 0 and 2 (1 and 3 under `make test-all`)
    return worlds + [(f"world2_delay{k}", world2.replace("delay = 0", f"delay = {k}"))
                     for k in ((0, 2) if QUICK else range(4))]


FAMILY = worldgen.world_family()
CASES = ([(name, text, True) for name, text in _model_worlds()]
         + share([(name, text, i % 5 == 0) for i, (name, text) in enumerate(FAMILY)]))


def _results(world, out: Path, baselines: bool) -> dict:
    with progress.quiet():
        checked = pipeline.check(world, out)
        values = {"deceptive_value": checked.results.deceptive_value,
                  "v_lead": checked.results.v_lead}
        if baselines:
            nash = pipeline._nash_stage(checked.analysis)
            worth = pipeline._deception_stage(checked)
            values.update(v_ne=nash.v_ne, v_static=worth.v_static, v_naive=worth.v_naive)
    sizes = {key: getattr(checked.results, key) for key in SIZES}
    return {"values": values, "sizes": sizes,
            "records": json.loads((out / "strategy.json").read_text())}


@pytest.mark.parametrize("name,text,baselines", CASES, ids=[c[0] for c in CASES])
def test_a_grid_world_and_its_converted_arena_file_agree(tmp_path: Path, name: str, text: str,
                                                          baselines: bool) -> None:
    grid_file = tmp_path / f"{name}.toml"
    grid_file.write_text(text)
    grid = load_world(grid_file)
    arena_file = tmp_path / f"{name}_arena.toml"
    arena_file.write_text(to_toml(grid))
    arena = load_world(arena_file)
    assert grid.grid is not None and arena.grid is None and arena.arena is not None

    g = _results(grid, tmp_path / "grid", baselines)
    a = _results(arena, tmp_path / "arena", baselines)
    assert a["sizes"] == g["sizes"]
    assert a["values"].keys() == g["values"].keys()
    for key, value in g["values"].items():
        assert math.isclose(a["values"][key], value, rel_tol=0.0, abs_tol=TOL), (
            key, value, a["values"][key])
    assert len(a["records"]) == len(g["records"])
    for at, (rg, ra) in enumerate(zip(g["records"], a["records"])):
        moves_g, moves_a = rg.pop("values"), ra.pop("values")
        assert ra == rg, at                  # state, standing, countdown, q, ..., P1's action
        assert list(moves_a) == list(moves_g), at
        for action, value in moves_g.items():
            assert math.isclose(moves_a[action], value, rel_tol=0.0, abs_tol=MOVE_TOL), (
                at, action, value, moves_a[action])
