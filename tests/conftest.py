"""Shared fixtures: worlds from files or generated text, and cached pipeline runs."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from hg2prism.reproducible import pin_kernels

pin_kernels()    # before any test imports numpy (importing hg2prism does it too)

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

# `make test` (HG2PRISM_CASES=quick) takes every fourth case of the long families of generated
# worlds and random mazes (`share`), to stay under ten minutes on a 2-core machine; `make
# test-all`, and pytest run by hand, take every case. `.ci/run` runs both.
QUICK = os.environ.get("HG2PRISM_CASES") == "quick"

# PRISM's JVM with one garbage-collector thread: about 0.6 s of CPU less per short PRISM run
# and 5 % less on test_prism.py's long ones, the same answers (PRISM's launcher reads it).
os.environ.setdefault("PRISM_JAVA_PARAMS", "-XX:+UseSerialGC")


def share(cases) -> list:
    """The cases of a long family this run takes: the first, fifth, ninth, ... under `make
    test`, all of them otherwise."""
    return list(cases)[::4] if QUICK else list(cases)

MODELS = ROOT / "models"

# The files that take longest, longest first (from the durations of a full run). With
# `--dist loadfile --no-loadscope-reorder` (pytest-xdist 3.8, `make test`) xdist hands whole
# files to its two processes in the order collected, so a long file no longer starts last and
# runs alone at the end (by default xdist orders files by their number of tests, and the
# snapshot's one long test came near the end: 12 s of a 13-minute run). The other files
# follow in their usual order.
LONGEST_FIRST = ("test_snapshot.py", "test_docs.py", "test_prism.py", "test_packaging.py",
                 "test_robust.py", "test_core.py", "test_mazes.py", "test_cli_edges.py",
                 "test_arena_equal.py")


def names_in(folder: Path) -> list[str]:
    """The names in an output folder, sorted, but hg2prism's record of what it placed there
    (outputs.MANIFEST)."""
    from hg2prism.outputs import MANIFEST

    return sorted(p.name for p in Path(folder).iterdir() if p.name != MANIFEST)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    rank = {name: at for at, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))      # stable


@pytest.fixture(scope="session")
def world_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("worlds")


def window_sweep_table():
    """A SweepTable of two points of `window` (deceptive 0.7 and 0.8, V_lead 0.5, V_NE 0.2),
    made by hand for the figure tests."""
    import hg2prism

    rows = (hg2prism.SweepRow(point=(("window", w),), deceptive_value=v, v_lead=0.5, v_ne=0.2,
                              v_ne_p1_guaranteed=0.2, v_ne_bounds=(0.2, 0.2), states=1,
                              transitions=1, row={"window": w, "deceptive_value": v,
                                                  "v_lead": 0.5, "v_ne": 0.2})
            for w, v in ((1, 0.7), (2, 0.8)))
    return hg2prism.SweepTable(("window",), tuple(rows), ())
