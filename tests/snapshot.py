"""Snapshot of every file the command line writes, for refactorings that must not change outputs.

`produce(root)` runs `hg2prism run` on world1, world2 (delay 0 and 2), world3, world3_bayes and
ten generated worlds, plus `hg2prism robust` and `hg2prism detect` on world2, each in a process
of its own, and returns {case: {file: digest}}. A digest is the SHA-256 of the file with what
legitimately varies masked: timings (`timings`, `seconds`, in JSON and CSV), the package version and the
software versions (`software`), and the path of
the world file and of the output folder (written into headers and results.json).

tests/snapshots/outputs.json holds the digests the code produced when the snapshot was taken;
tests/test_snapshot.py compares a fresh run with it. After a change that is *meant* to alter
outputs, rewrite it with

    .venv/bin/python tests/snapshot.py --write

and say in the commit why the outputs changed.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SNAPSHOT = Path(__file__).resolve().parent / "snapshots" / "outputs.json"
sys.path.insert(0, str(Path(__file__).resolve().parent))

import worldgen  # noqa: E402

# Ten generated worlds: delay 0-3, one and two traps, windows 1-3, one to four hypotheses.
GENERATED = ["fam00_d0_l1_w1_x2", "fam02_d2_l1_w1_x4", "fam05_d2_l1_w2_x3",
             "fam09_d0_l2_w1_x3", "fam13_d1_l2_w2_x2", "fam24_d0_l1_w3_x3",
             "fam36_eq_d0_w2", "fam40_tx_d0_l1_w2", "fam46_d3_l1_w1_x3", "fam48_d3_l1_w2_x2"]
MASKED_KEYS = {"timings", "seconds", "hg2prism_version", "software"}


def _world_files(folder: Path) -> dict[str, Path]:
    """case name -> world file, written into `folder`."""
    files = {}
    for name in ("world1", "world2", "world3", "world3_bayes"):
        files[name] = folder / f"{name}.toml"
        files[name].write_text((ROOT / "models" / f"{name}.toml").read_text())
    text = (ROOT / "models" / "world2.toml").read_text()
    files["world2_d2"] = folder / "world2_d2.toml"
    files["world2_d2"].write_text(text.replace("\ndelay = 0\n", "\ndelay = 2\n", 1)
                                  .replace('name = "world2"', 'name = "world2_d2"', 1))
    family = dict(worldgen.world_family())
    for name in GENERATED:
        files[name] = folder / f"{name}.toml"
        files[name].write_text(family[name])
    return files


def _commands(files: dict[str, Path], out: Path) -> dict[str, list[str]]:
    commands = {name: ["run", str(path), "--out", str(out / name)]
                for name, path in files.items()}
    commands["world2_robust"] = ["robust", str(files["world2"]), "--deltas", "0", "0.1",
                                 "--out", str(out / "world2_robust")]
    commands["world2_detect"] = ["detect", str(files["world2"]), "--episodes", "300",
                                 "--fallback", "robust", "--out", str(out / "world2_detect")]
    return commands


def _mask_json(value: object) -> object:
    if isinstance(value, dict):
        return {k: ("<masked>" if k in MASKED_KEYS else _mask_json(v)) for k, v in value.items()}
    if isinstance(value, list):
        return [_mask_json(v) for v in value]
    return value


def digest(path: Path, masks: list[tuple[str, str]]) -> str:
    data = path.read_bytes()
    if path.suffix in {".png", ".gif"}:
        return hashlib.sha256(data).hexdigest()
    text = data.decode()
    for old, new in masks:
        text = text.replace(old, new)
    if path.suffix == ".json" and path.name != "strategy.json":
        text = json.dumps(_mask_json(json.loads(text)), indent=1, sort_keys=True)
    if path.suffix == ".csv":
        rows = list(csv.reader(io.StringIO(text)))
        masked = [i for i, name in enumerate(rows[0]) if name in MASKED_KEYS] if rows else []
        text = "\n".join(",".join("<masked>" if i in masked else cell
                                  for i, cell in enumerate(row)) for row in rows)
    return hashlib.sha256(text.encode()).hexdigest()


def produce(root: Path, python: str = sys.executable) -> dict[str, dict[str, str]]:
    """Run every case under `root` and digest what it wrote."""
    worlds = root / "worlds"
    worlds.mkdir(parents=True, exist_ok=True)
    files = _world_files(worlds)
    commands = _commands(files, root / "out")

    def one(item: tuple[str, list[str]]) -> tuple[str, dict[str, str]]:
        name, args = item
        done = subprocess.run([python, "-m", "hg2prism", *args], capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"{name}: hg2prism {' '.join(args)} failed:\n{done.stderr}")
        out = root / "out" / name
        masks = [(str(out), "<OUT>"), (str(worlds), "<WORLDS>")]
        return name, {str(p.relative_to(out)): digest(p, masks)
                      for p in sorted(out.rglob("*")) if p.is_file()}

    with ThreadPoolExecutor(max_workers=2) as pool:
        return dict(pool.map(one, commands.items()))


def compare(fresh: dict[str, dict[str, str]], stored: dict[str, dict[str, str]]) -> list[str]:
    """Every difference, one line each."""
    problems = []
    for case in sorted(set(fresh) | set(stored)):
        new, old = fresh.get(case), stored.get(case)
        if new is None or old is None:
            problems.append(f"{case}: {'missing from the run' if new is None else 'not in the snapshot'}")
            continue
        for name in sorted(set(new) | set(old)):
            if new.get(name) != old.get(name):
                what = ("not written" if name not in new else "new file" if name not in old
                        else "differs")
                problems.append(f"{case}/{name}: {what}")
    return problems


if __name__ == "__main__":
    import tempfile

    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/snapshot.py --write   (rewrites tests/snapshots/outputs.json)")
    with tempfile.TemporaryDirectory() as tmp:
        result = produce(Path(tmp))
    SNAPSHOT.parent.mkdir(exist_ok=True)
    SNAPSHOT.write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    print(f"wrote {SNAPSHOT}: {len(result)} cases, {sum(map(len, result.values()))} files")
