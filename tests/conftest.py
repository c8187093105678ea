"""Shared fixtures: worlds from files or generated text, and cached pipeline runs."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

MODELS = ROOT / "models"


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
