"""Snapshot of every file the command line writes, for refactorings that must not change outputs.

`produce(root)` runs `hg2prism run` on world1, world2 (delay 0 and 2), world3, world3_bayes and
ten generated worlds, plus `hg2prism robust` and `hg2prism detect` on world2, in two processes of
its own, and returns {case: {file: digest}}. A digest is the SHA-256 of the file with what
legitimately varies masked: timings (`timings`, `seconds`, in JSON and CSV), the package version and the
software versions (`software`), and the path of
the world file and of the output folder (written into headers and results.json).

tests/snapshots/outputs.json holds the digests the code produced when the snapshot was taken;
tests/test_snapshot.py compares a fresh run with it. On a machine whose floating-point code
differs (numpy and OpenBLAS pick their kernels for the CPU at run time: exp and log with AVX-512
differ from AVX2's in the last bit, and so did world1's inference tables in hypergame.prism;
`import hg2prism` pins both on x86-64 processors with AVX2, hg2prism/reproducible.py), the
exact digests cannot match; there the text files are compared with every number rounded to 6
and, failing that, to 8 significant digits (a number at a rounding boundary of one precision
is not at the other's), so that the snapshot still sees any change of structure or strategy,
and of a value in its first 6 significant digits. `machine()` names the floating-point code; the snapshot records it.
After a change that is *meant* to alter outputs, rewrite it with

    .venv/bin/python tests/snapshot.py --write

and say in the commit why the outputs changed.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import platform
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SNAPSHOT = Path(__file__).resolve().parent / "snapshots" / "outputs.json"
sys.path.insert(0, str(Path(__file__).resolve().parent))

import worldgen  # noqa: E402
from hg2prism.outputs import MANIFEST  # noqa: E402  (bookkeeping, not an output)

# Ten generated worlds: delay 0-3, one and two traps, windows 1-3, one to four hypotheses.
GENERATED = ["fam00_d0_l1_w1_x2", "fam02_d2_l1_w1_x4", "fam05_d2_l1_w2_x3",
             "fam09_d0_l2_w1_x3", "fam13_d1_l2_w2_x2", "fam24_d0_l1_w3_x3",
             "fam36_eq_d0_w2", "fam40_tx_d0_l1_w2", "fam46_d3_l1_w1_x3", "fam48_d3_l1_w2_x2"]
MASKED_KEYS = {"timings", "seconds", "hg2prism_version", "software"}


def _world_files(folder: Path, generated: list[str]) -> dict[str, Path]:
    """case name -> world file, written into `folder`: the shipped worlds, world2 at delay 2
    and the generated worlds `generated`."""
    files = {}
    for name in ("world1", "world2", "world3", "world3_bayes"):
        files[name] = folder / f"{name}.toml"
        files[name].write_text((ROOT / "models" / f"{name}.toml").read_text())
    text = (ROOT / "models" / "world2.toml").read_text()
    files["world2_d2"] = folder / "world2_d2.toml"
    files["world2_d2"].write_text(text.replace("\ndelay = 0\n", "\ndelay = 2\n", 1)
                                  .replace('name = "world2"', 'name = "world2_d2"', 1))
    family = dict(worldgen.world_family())
    for name in generated:
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


def machine() -> str:
    """What decides the last bits of the numbers computed here: the processor's architecture,
    the SIMD groups numpy dispatches to and OpenBLAS's kernels (hg2prism/reproducible.py pins
    the last two on x86-64 processors with AVX2: "x86_64:X86_V3:Haswell" on all of them)."""
    from hg2prism.reproducible import kernels

    found = kernels()
    return f"{platform.machine()}:{found['numpy_simd']}:{found['blas_kernels']}"


# a number with a fraction or an exponent (not an integer: counts, indices and names stay)
NUMBER = re.compile(r"(?<![\w.])-?\d+(?:\.\d+(?:[eE][-+]?\d+)?|[eE][-+]?\d+)")
ROUNDINGS = (6, 8)       # significant digits of the comparison across machines


def rounded(text: str, digits: int) -> str:
    """`text` with every number rounded to `digits` significant digits."""
    return NUMBER.sub(lambda m: format(float(m.group()), f".{digits}g"), text)


def digests(path: Path, masks: list[tuple[str, str]]) -> tuple[str, ...]:
    """The file's exact digest (`digest`), then its digests with numbers `rounded` to each of
    ROUNDINGS (images: the exact one again)."""
    text = _normalised(path, masks)
    if text is None:
        return (hashlib.sha256(path.read_bytes()).hexdigest(),) * (1 + len(ROUNDINGS))
    return tuple(hashlib.sha256(t.encode()).hexdigest()
                 for t in (text, *(rounded(text, d) for d in ROUNDINGS)))


def digest(path: Path, masks: list[tuple[str, str]]) -> str:
    return digests(path, masks)[0]


def _normalised(path: Path, masks: list[tuple[str, str]]) -> str | None:
    """The file's text with what legitimately varies masked (None for an image)."""
    data = path.read_bytes()
    if path.suffix in {".png", ".gif"}:
        return None
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
    return text


def produce(root: Path, python: str = sys.executable,
            generated: list[str] = GENERATED) -> dict:
    """Run every case under `root` (of the generated worlds, those of `generated`) and digest
    what it wrote: {"machine": machine(), "exact": {case: {file: digest}}, "rounded": {case:
    {file: [digest at each of ROUNDINGS]}}}.

    The cases run in two processes of their own (`run_cases`, half of them each, one after
    another within a process): a fresh interpreter per case spent a quarter of the time
    importing, and a case whose outputs depended on what its process ran before would show
    here as a difference."""
    worlds = root / "worlds"
    worlds.mkdir(parents=True, exist_ok=True)
    files = _world_files(worlds, generated)
    names = list(_commands(files, root / "out"))

    def half(names: list[str]) -> None:
        done = subprocess.run([python, __file__, "--cases", str(root), *names],
                              capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"cases {names} failed:\n{done.stderr}")

    with ThreadPoolExecutor(max_workers=2) as pool:
        list(pool.map(half, [names[0::2], names[1::2]]))
    cases = {}
    for name in names:
        out = root / "out" / name
        masks = [(str(out), "<OUT>"), (str(worlds), "<WORLDS>")]
        cases[name] = {str(p.relative_to(out)): digests(p, masks)        # not the manifest
                       for p in sorted(out.rglob("*")) if p.is_file() and p.name != MANIFEST}
    return {"machine": machine(),
            "exact": {case: {name: d[0] for name, d in files.items()}
                      for case, files in cases.items()},
            "rounded": {case: {name: list(d[1:]) for name, d in files.items()}
                        for case, files in cases.items()}}


def run_cases(root: Path, names: list[str]) -> int:
    """Run the cases `names` of `produce(root)` one after another in this process (the world
    files are in root/worlds); 0, or 1 after printing each failed case's command and errors."""
    import contextlib

    from hg2prism import cli

    files = {path.stem: path for path in (root / "worlds").glob("*.toml")}
    commands = _commands(files, root / "out")
    failed = 0
    for name in names:
        captured = io.StringIO()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(captured):
            status = cli.main(commands[name])
        if status != 0:
            failed = 1
            print(f"{name}: hg2prism {' '.join(commands[name])} failed ({status}):\n"
                  f"{captured.getvalue()}", file=sys.stderr)
    return failed


def compare(fresh: dict, stored: dict) -> list[str]:
    """Every difference, one line each: the exact digests on the machine the snapshot was
    taken on (its floating-point code), else a file matches when, with its numbers rounded,
    it matches at one of ROUNDINGS."""
    same = fresh["machine"] == stored["machine"]
    problems = []
    for case in sorted(set(fresh["exact"]) | set(stored["exact"])):
        new, old = fresh["exact"].get(case), stored["exact"].get(case)
        if new is None or old is None:
            problems.append(f"{case}: {'missing from the run' if new is None else 'not in the snapshot'}")
            continue
        for name in sorted(set(new) | set(old)):
            if name not in new or name not in old:
                problems.append(f"{case}/{name}: {'not written' if name not in new else 'new file'}")
            elif new[name] != old[name] and (same or not any(
                    a == b for a, b in zip(fresh["rounded"][case][name],
                                           stored["rounded"][case][name]))):
                problems.append(f"{case}/{name}: differs" + ("" if same else
                                                             " (numbers rounded to 6 and 8 digits)"))
    return problems


if __name__ == "__main__":
    import tempfile

    if sys.argv[1:2] == ["--cases"] and len(sys.argv) > 3:      # produce()'s worker processes
        sys.exit(run_cases(Path(sys.argv[2]), sys.argv[3:]))
    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/snapshot.py --write   (rewrites tests/snapshots/outputs.json)")
    with tempfile.TemporaryDirectory() as tmp:
        result = produce(Path(tmp))
    SNAPSHOT.parent.mkdir(exist_ok=True)
    SNAPSHOT.write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    print(f"wrote {SNAPSHOT}: {len(result['exact'])} cases, "
          f"{sum(map(len, result['exact'].values()))} files, on {result['machine']}")
