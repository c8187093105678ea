"""Atomic output files: write to a temporary file in the same folder, then rename."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


_UMASK = os.umask(0)
os.umask(_UMASK)


def write_text(path: Path, text: str) -> None:
    write_bytes(path, text.encode())


def write_json(path: Path, data: object) -> None:
    write_text(path, json.dumps(data, indent=2) + "\n")


def write_bytes(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.chmod(tmp, 0o666 & ~_UMASK)   # mkstemp makes files private; outputs are not
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def staged(out: Path) -> Iterator[Path]:
    """A scratch folder beside `out` for a command's outputs: they move into `out` only when
    the command succeeds, so a failure leaves nothing half-written. Each item replaces its
    predecessor in one rename (a stop between two items leaves some new, some old, none
    broken); an item that cannot be placed puts its predecessor back."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.staging-"))
    os.chmod(stage, 0o777 & ~_UMASK)
    try:
        yield stage
        out.mkdir(exist_ok=True)
        for item in list(stage.iterdir()):
            target = out / item.name
            if not (item.is_dir() or target.is_dir()) or not (target.exists() or
                                                               target.is_symlink()):
                os.replace(item, target)      # a file over a file (or nothing): atomic
                continue
            # os.replace cannot put a folder over a file or replace a folder that has files
            # (a re-run's delay_1/ ...): move the old one aside into the stage, which is
            # removed below, and back if the new one cannot take its place.
            aside = stage / f".replaced-{item.name}"
            os.replace(target, aside)
            try:
                os.replace(item, target)
            except BaseException:
                os.replace(aside, target)
                raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)
