"""Atomic output files: write to a temporary file in the same folder, then rename."""

from __future__ import annotations

import csv
import io
import json
import os
import re
import shutil
import tempfile
import time
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from hg2prism.errors import COMMAND_LINE, InputError, listing
from hg2prism.progress import say, warn


_UMASK = os.umask(0)
os.umask(_UMASK)


def write_text(path: Path, text: str) -> None:
    write_bytes(path, text.encode())


def write_json(path: Path, data: object) -> None:
    write_text(path, json.dumps(data, indent=2) + "\n")


def csv_text(header: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """hg2prism's CSV: the header, then one line per row ("\\n" line ends, quoted where
    needed); a float as repr (every digit), None as an empty cell, anything else as str."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows([repr(float(cell)) if isinstance(cell, float) else cell for cell in row]
                     for row in rows)      # float(): numpy's repr is np.float64(0.5)
    return buffer.getvalue()


def write_csv(path: Path, header: Sequence[str], rows: Iterable[Sequence[object]]) -> None:
    """A CSV file (`csv_text`), written atomically."""
    write_text(path, csv_text(header, rows))


def write_bytes(path: Path, data: bytes) -> None:
    write_chunks(path, [data])


def write_chunks(path: Path, chunks: Iterable[bytes]) -> None:
    """The file made of `chunks` one after another, each written as it comes (a large export
    is never held whole in memory), atomically like every output."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            for chunk in chunks:
                handle.write(chunk)
        os.chmod(tmp, 0o666 & ~_UMASK)   # mkstemp makes files private; outputs are not
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


# What each command owns in its output folder. When a command finishes, the items it owns but
# did not write this time are stale (emit after run: the old strategy.json, results.json and
# world.png would describe another model) and are removed. Commands with different outputs share
# a folder (`make world2`: run, then sweep, then detect), so only the command's own kinds go.
# The sweep's pattern is built from its parameter table: experiments.sweep.owned_pattern().
_MODEL = (r"hypergame\.(prism|props)|strategy\.json|results\.json|table\.md"
          r"|(world|belief|completion)\.(png|svg|pdf)|replay\.gif|explorer\.html"
          r"|task\.(hoa|dot|svg)|hypothesis_\d+\.(hoa|dot|svg)|induced\.(tra|sta|lab|drn)|goal\.props"
          r"|symmetric\.(prism|props)|perceptual_\d+\.(prism|props)"
          # a world with P2's types (adaptive deception, docs/semantics.md §16)
          r"|adaptive(_pomdp)?\.(prism|props)|adaptive_belief\.(png|svg|pdf)|type\d+")
OWNED = {
    "emit": _MODEL, "check": _MODEL, "run": _MODEL,
    "detect": r"detection\.(json|png|svg|pdf)",
    "robust": r"robust\.(json|csv|png|svg)|robust_[0-9][0-9.e+-]*",
}


def check_writable(out: Path, what: str = "--out", staged: bool = True) -> None:
    """InputError unless `out` is (or can be created as) a folder this process can write, so
    that a command fails before its work rather than after it; `staged`: a command's output
    folder, whose staging folder beside it (`staged`) must have a name the file system takes
    (not for the folder of an output file)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(COMMAND_LINE, what, f"{out} exists and is not a folder")
    if staged:
        _short_enough(out, what)
    existing = out
    while not existing.exists():
        if existing.parent == existing:
            break
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(COMMAND_LINE, what, f"{existing} is not a folder, so {out} cannot be made")
    try:    # os.access says yes to root on read-only file systems: try it
        tempfile.TemporaryDirectory(dir=existing, prefix=".hg2prism-probe-").cleanup()
    except OSError as err:
        made = "" if existing == out else f", so {out} cannot be made"
        raise InputError(COMMAND_LINE, what, f"cannot write in {existing} "
                         f"({err.strerror or err}){made}") from None


# What a staging folder's name adds to OUT's (`staged`: ".OUT.staging-" and mkdtemp's 8)
_STAGING_EXTRA = len("..staging-") + 8


def _short_enough(out: Path, what: str) -> None:
    """InputError where the staging folder beside `out` would have a name longer than its
    file system allows (it would fail after the work, naming a hidden folder)."""
    existing = out.absolute().parent
    while not existing.exists() and existing.parent != existing:
        existing = existing.parent
    try:
        most = os.pathconf(existing, "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):
        return
    length = len(os.fsencode(out.name))
    if length + _STAGING_EXTRA > most:
        shown = out.name if len(out.name) <= 40 else out.name[:40] + "..."
        raise InputError(COMMAND_LINE, what, f"the folder name {shown} is {length} "
                         f"bytes long; at most {most - _STAGING_EXTRA} here (hg2prism stages "
                         f"its outputs in a folder beside it whose name is {_STAGING_EXTRA} "
                         f"bytes longer)")


def _join_pool_workers(timeout: float = 10.0) -> None:
    """Wait (at most `timeout` seconds) for this process's thread-pool workers. A signal that
    stops a command while its main thread joins a pool's workers (the exports are written in
    parallel) interrupts that join: a worker still writing would then recreate the staging
    folder after it was removed."""
    import threading

    deadline = time.monotonic() + timeout
    for thread in threading.enumerate():
        if thread is not threading.current_thread() and \
                thread.name.startswith("ThreadPoolExecutor"):
            while True:     # the signal may have come while the pool was starting this one
                try:
                    thread.join(max(0.0, deadline - time.monotonic()))
                    break
                except RuntimeError:        # not started yet: it will be in a moment
                    if time.monotonic() >= deadline:
                        break
                    time.sleep(0.001)


# The record files whose "world" names the world a folder's outputs are of, and the models
# whose header gives its digest (`emit` writes no record).
_RECORDS = ("results.json", "robust.json", "detection.json", "sweep.json")
_MODELS = ("hypergame.prism", "adaptive.prism")
_DIGEST_LINE = re.compile(r"// digest {7}(sha256:[0-9a-f]+)$")


def _model_digest(path: Path) -> str | None:
    """The world digest in the header of a model hg2prism wrote (its first lines)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as handle:
            for _, line in zip(range(12), handle):
                found = _DIGEST_LINE.match(line.rstrip("\n"))
                if found:
                    return found.group(1)
    except OSError:
        pass
    return None


def _of_another_world(out: Path, world: str, digest: str | None = None,
                      placed: set[str] | frozenset[str] = frozenset()) -> bool:
    """Whether `out` holds outputs of a world other than `world` (its name) or than the world
    of `digest` (World.digest: the same name, its file edited), by what its record files say
    (read before the new outputs move in; a record without a digest is judged by name). Only
    the records hg2prism placed there (`placed`, MANIFEST's list) count: one it has no record
    of placing is never removed, so it would make every later command remove the others'."""
    for name in _RECORDS:
        if name not in placed:
            continue
        path = out / name
        if not path.is_file():
            continue
        try:
            record = json.loads(path.read_text())
            named, digested = record.get("world"), record.get("world_digest")
        except (OSError, ValueError, AttributeError):
            continue
        if isinstance(named, str) and named != world:
            return True
        if digest is not None and isinstance(digested, str) and digested != digest:
            return True
    if digest is not None:
        return any(_model_digest(out / name) not in (None, digest)
                   for name in _MODELS if name in placed)
    return False


# The hidden file in an output folder that lists what hg2prism placed there: only those items
# are ever removed as stale (a file or folder of the user's whose name looks like an output,
# such as notes/ in a sweep's folder or a table.md of their own, is never touched). A folder
# without it (new, or written before it existed) has nothing removed.
MANIFEST = ".hg2prism-outputs.json"


def _placed(out: Path) -> set[str]:
    """The names MANIFEST lists in `out` (none when it is missing or unreadable)."""
    try:
        items = json.loads((out / MANIFEST).read_text())["items"]
    except (OSError, ValueError, KeyError, TypeError):
        return set()
    return {name for name in items if isinstance(name, str)} if isinstance(items, list) else set()


def _record_placed(out: Path, names: set[str]) -> None:
    """MANIFEST in `out`: the items of `names` that are there."""
    _write_manifest(out, names & {p.name for p in out.iterdir()})


def _write_manifest(out: Path, names: set[str]) -> None:
    write_json(out / MANIFEST, {"about": "what hg2prism placed in this folder: the only items "
                                "it ever removes as stale outputs",
                                "items": sorted(names - {MANIFEST})})


@contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """`folder` locked against another hg2prism process finishing a command there (an
    exclusive flock on the folder itself), so that two commands ending at once do not each
    write MANIFEST without the other's items. Where locks are not supported, unlocked."""
    try:
        import fcntl

        fd = os.open(folder, os.O_RDONLY)
    except (ImportError, OSError):
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:
            pass
        yield
    finally:
        os.close(fd)        # releases the lock


@contextmanager
def staged(out: Path, owns: str | None = None, world: str | None = None,
           every: str | None = None, digest: str | None = None) -> Iterator[Path]:
    """A scratch folder beside `out` for a command's outputs: they move into `out` only when
    the command succeeds, so a failure leaves nothing half-written. Each item replaces its
    predecessor in one rename, and Ctrl-C or SIGTERM waits until every item is in
    (`_signals_deferred`); a failure partway (a full disk) leaves some new, some old, none
    broken, with MANIFEST listing both; an item that cannot be placed puts its predecessor
    back. `owns` (a regular
    expression over names, see OWNED) removes the command's stale outputs afterwards; where
    `out` held outputs of another world than `world` (its record files name it) or another
    version of it (their `world_digest` is not `digest`), `every` (what any command owns)
    removes all of them: the commands of one world share a folder, two worlds (or two versions
    of one world file) do not. Only what hg2prism placed in `out` (MANIFEST lists it) is ever
    removed."""
    out = Path(out)
    _placement.update(state=None, out=None)     # this command's, not an earlier one's
    out.parent.mkdir(parents=True, exist_ok=True)
    _remove_abandoned_stages(out)
    stage = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.staging-"))
    os.chmod(stage, 0o777 & ~_UMASK)
    try:
        with _held(stage):
            try:
                yield stage
            except BaseException:
                _join_pool_workers()    # a worker may still be writing into the stage
                raise
            out.mkdir(exist_ok=True)
            with _locked(out), _signals_deferred():
                _place(stage, out, owns, world, every, digest)
    finally:
        with _signals_deferred():       # a second Ctrl-C does not leave half a stage
            shutil.rmtree(stage, ignore_errors=True)


# A staging folder unchanged for this long and held by no process is abandoned (its command
# was killed, SIGKILL): the next command writing to the same OUT removes it. The hold is a
# lock, which some network file systems keep per host; a command elsewhere that writes
# nothing at its stage's top level for this long would lose its stage there, hence an hour.
ABANDONED_AFTER = 3600.0
# mkdtemp's suffix: eight letters, digits or underscores
_STAGE_SUFFIX = re.compile(r"[a-z0-9_]{8}")


@contextmanager
def _held(stage: Path) -> Iterator[None]:
    """A shared hold (flock) on the staging folder while its command runs, which ends with the
    process however it ends: `_remove_abandoned_stages` leaves a held stage alone."""
    try:
        import fcntl

        fd = os.open(stage, os.O_RDONLY)
    except (ImportError, OSError):
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError:
            pass
        yield
    finally:
        os.close(fd)


def _remove_abandoned_stages(out: Path) -> None:
    """Removes the staging folders beside `out` that no process holds (`_held`) and that have
    not changed for ABANDONED_AFTER seconds, unless one holds an item of OUT set aside while
    the outputs moved in (`.replaced-*`: a command killed then; it is left to recover by hand).
    Where locks are not supported, none."""
    prefix = f".{out.name}.staging-"
    try:
        import fcntl

        beside = [p for p in out.parent.iterdir() if p.name.startswith(prefix)
                  and _STAGE_SUFFIX.fullmatch(p.name[len(prefix):])]
    except (ImportError, OSError):
        return
    for stage in beside:
        try:
            if (not stage.is_dir() or stage.is_symlink()
                    or time.time() - stage.stat().st_mtime < ABANDONED_AFTER
                    or any(stage.glob(".replaced-*"))):
                continue
            fd = os.open(stage, os.O_RDONLY)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)     # fails where a command holds it
        except OSError:
            os.close(fd)
            continue
        try:
            shutil.rmtree(stage, ignore_errors=True)
        finally:
            os.close(fd)


# This process's last placement of a command's outputs (`staged`), for the messages of a
# command stopped or failing around it.
_placement: dict[str, object] = {"state": None, "out": None}


def placement() -> tuple[str | None, Path | None]:
    """(state, folder) of the last placement of a command's outputs: state None (none yet),
    "begun" (it failed partway, a full disk: some items new, some old) or "done"."""
    return _placement["state"], _placement["out"]      # type: ignore[return-value]


@contextmanager
def _signals_deferred() -> Iterator[None]:
    """Ctrl-C and SIGTERM held back while a command's outputs move into OUT (on the main
    thread, where Python runs its handlers), then delivered: a stop no longer leaves some new
    items beside some old ones; it takes effect once OUT is whole."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    kept = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(signum) is None:    # installed from C: it could not be put back
            continue
        try:
            kept[signum] = signal.signal(signum, lambda number, frame: caught.append(number))
        except (ValueError, OSError):
            pass
    try:
        yield
    except BaseException:
        # a failure while placing (a full disk) is what the command reports; a stop asked
        # meanwhile changes nothing more
        for signum, handler in kept.items():
            signal.signal(signum, handler)
        raise
    for signum, handler in kept.items():
        signal.signal(signum, handler)
    if caught:
        signal.raise_signal(caught[0])


def _place(stage: Path, out: Path, owns: str | None, world: str | None, every: str | None,
           digest: str | None) -> None:
    """staged's work once the command succeeded: the stage's items into `out`, the stale ones
    that hg2prism placed there removed, MANIFEST written."""
    new_items = list(stage.iterdir())
    placed = _placed(out)
    _placement.update(state=None, out=out)
    # MANIFEST first lists the old items and the new: whatever stops the placement (a full
    # disk), the next command still knows every item hg2prism put here (not a file of the
    # user's that a new item will replace: it is listed once replaced, at the end)
    _write_manifest(out, placed | {item.name for item in new_items
                                   if not (out / item.name).exists()
                                   and not (out / item.name).is_symlink()})
    _placement.update(state="begun")
    own = owns
    another = (world is not None and every is not None
               and _of_another_world(out, world, digest, placed))
    if another:
        owns = every
    foreign = sorted(item.name for item in new_items if item.name not in placed
                     and ((out / item.name).exists() or (out / item.name).is_symlink()))
    for item in new_items:
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
    if foreign:
        warn(f"outputs: replaced {listing(foreign, 6, count=True)} in {out}, which hg2prism "
             f"has no record of writing there ({MANIFEST} lists what it wrote)")
    written = {item.name for item in new_items}
    if owns is not None:
        pattern = re.compile(owns)
        others = []          # other commands' outputs, removed as another world's
        removed = []         # stale outputs of this kind of command
        for old in sorted(out.iterdir()):
            if old.name in placed and old.name not in written and pattern.fullmatch(old.name):
                shown = old.name + ("/" if old.is_dir() else "")
                if own is None or not re.fullmatch(own, old.name):
                    others.append(shown)
                else:
                    removed.append(shown)
                os.replace(old, stage / f".stale-{old.name}")   # removed with the stage
        if another:
            say(f"outputs: {out} held the outputs of another world (or of this world "
                f"file before an edit); " + (
                    f"removed those of other commands too: {listing(others, 6, count=True)}"
                    if others else "replaced them"))
        elif removed:       # an earlier command of this kind wrote them, this one does not
            removed.sort(key=lambda name: not name.endswith(".json"))    # the records first
            say(f"outputs: removed {listing(removed, 6, count=True)} from {out}, which an "
                f"earlier command wrote there and this one does not write")
    _record_placed(out, placed | written)
    _placement.update(state="done")
