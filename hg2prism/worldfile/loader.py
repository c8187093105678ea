"""World files (docs/semantics.md §1): read a TOML world, validate every key with one clear
error line (file, key, reason), and return an immutable `model.world.World`.

The loader sits above the model and the observers: which `[inference]` keys a world may have,
and how they are read, is asked of the observer registry (opponent/registry.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hg2prism.errors import InputError
from hg2prism.frontends import arena as arena_files
from hg2prism.worldfile import types as player_types
from hg2prism.model.world import (FORBIDDEN_REGION_LETTERS, Cell, DetectionSettings, Grid,
                                  SimulationSettings, World)


MAP_LEGEND = ". # o t @ A-Z"

# Keys allowed in each table: key -> required?
_TOP_KEYS = {"name": False, "description": False, "grid": True, "robot": True, "task": True,
             "adversary": True, "inference": True, "simulation": False, "detection": False}
# An arena world (docs/semantics.md §15) has [arena] instead of [grid] and [robot]
_ARENA_TOP_KEYS = {"name": False, "description": False, "arena": True, "task": True,
                   "adversary": True, "inference": True, "simulation": False,
                   "detection": False}
_TABLE_KEYS: dict[str, dict[str, bool]] = {
    "grid": {"map": True},
    "robot": {"slip": True},
    "task": {"formula": True},
    "adversary": {"traps": True, "delay": False, "initial_traps": False, "hypotheses": True,
                  "initial_hypothesis": False},
    # and the keys of the observers' kinds (`_Loader.inference` asks opponent/registry.py)
    "inference": {"kind": False, "window": True, "rationality": True},
    "simulation": {"episodes": False, "horizon": False, "seed": False},
    "detection": {"alpha": False, "epsilon": False, "deviate_after": False},
}
# Limits that keep every accepted world within bounded time and memory. Simulated episodes run
# side by side (arrays of `episodes` entries); a horizon bounds the steps of an episode that
# never ends (P1 kept away from both goal and traps), and the exact within-horizon numbers stop
# once converged. 10^5 steps x 10^6 episodes is the worst case these admit.
MAX_EPISODES = 1_000_000
MAX_HORIZON = 100_000
LIMIT_REASON = {
    "simulation.episodes": "episodes are simulated side by side in memory",
    "simulation.horizon": "an episode that never ends is simulated to the horizon",
    "--episodes": "episodes are simulated side by side in memory",
    "--horizon": "an episode that never ends is simulated to the horizon",
}

_MISSING_HINT = {
    "grid.map": "a multi-line string with the map (legend: " + MAP_LEGEND + ")",
    "robot.slip": "a number in [0, 0.5)",
    "task.formula": "a syntactically co-safe LTL formula in Spot syntax",
    "adversary.traps": "an integer >= 1",
    "adversary.hypotheses": "a non-empty array of co-safe LTL formulas",
    "inference.window": "an integer >= 1",
    "inference.rationality": "a number > 0",
    **arena_files.MISSING_HINT,
}


def _toml_type(value: object) -> str:
    import datetime

    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "float"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    if isinstance(value, dict):
        return "table"
    if isinstance(value, (datetime.datetime, datetime.date, datetime.time)):
        return "date/time"
    return type(value).__name__


def _shown(value: object) -> str:
    """The TOML type of a value, with the value itself when it is a short scalar."""
    if isinstance(value, bool):
        return f"boolean {'true' if value else 'false'}"
    if isinstance(value, (int, float)):
        return f"{_toml_type(value)} {value!r}"
    if isinstance(value, str) and len(value) <= 40:
        return f"string {value!r}"
    return _toml_type(value)


def _toml_repr(value: object) -> str:
    """A short one-line rendering of a TOML value as it would be written in the file."""
    import json

    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list):
        return "[" + ", ".join(_toml_repr(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_key_part(k)} = {_toml_repr(v)}" for k, v in value.items()) + "}"
    if isinstance(value, str):
        return json.dumps(value)
    return str(value)


def _key_part(name: str) -> str:
    """A TOML key as it would be written: bare when possible, else quoted (always one line)."""
    import json
    import re

    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else json.dumps(name)


def _one_line(text: str) -> str:
    return " ".join(text.split())


@dataclass(frozen=True)
class Vocabulary:
    """The atomic propositions formulas may use, and how an error message describes them."""

    propositions: tuple[str, ...]
    described: str


def _grid_vocabulary(grid: Grid) -> Vocabulary:
    return Vocabulary(("obs",) + grid.region_letters(),
                      "obs and the region letters of the map ("
                      + (", ".join(grid.region_letters()) or "none") + ")")


class _Loader:
    def __init__(self, path: Path, text: str | None = None, data: dict | None = None) -> None:
        self.path = path
        self.file = str(path)
        self.text = text        # the file's text when it does not come from a file
        self.data = data        # or the parsed file (a world built in Python)

    def fail(self, key: str, reason: str) -> InputError:
        return InputError(self.file, key, _one_line(reason))

    # -- reading -----------------------------------------------------------------------------

    def read(self) -> dict:
        import re
        import tomllib

        if self.data is not None:
            return self.data
        if self.text is not None:
            data = self.text.encode("utf-8", "surrogatepass")
        else:
            data = None
        try:
            data = self.path.read_bytes() if data is None else data
        except FileNotFoundError:
            raise self.fail("-", "file not found") from None
        except IsADirectoryError:
            raise self.fail("-", "is a directory, expected a world file (TOML)") from None
        except OSError as err:
            raise self.fail("-", f"cannot read the file: {err.strerror or err}") from None
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as err:
            raise self.fail("-", f"not valid TOML: not UTF-8 text (byte {err.start})") from None
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as err:
            msg = str(err)
            m = re.search(r"\(at (line \d+, column \d+|end of document)\)\s*$", msg)
            key = m.group(1) if m else "-"
            detail = msg[: m.start()].strip() if m else msg
            raise self.fail(key, f"not valid TOML: {detail}") from None

    # -- typed getters -----------------------------------------------------------------------

    def check_keys(self, table: dict, allowed: dict[str, bool], prefix: str,
                   tables: dict[str, dict[str, bool]] = _TABLE_KEYS) -> None:
        for name in table:
            if name not in allowed:
                key = f"{prefix}.{_key_part(name)}" if prefix else _key_part(name)
                what = "table" if isinstance(table[name], dict) else "key"
                where = f"in [{prefix}]" if prefix else "at the top level"
                raise self.fail(key, f"unknown {what} {where}; expected one of: "
                                     + ", ".join(allowed))
        for name, required in allowed.items():
            if required and name not in table:
                key = f"{prefix}.{name}" if prefix else name
                if not prefix and name in tables:
                    raise self.fail(key, f"missing required table [{name}] (with "
                                         + ", ".join(k for k, r in tables[name].items() if r)
                                         + ")")
                raise self.fail(key, "missing required key; expected "
                                     + _MISSING_HINT.get(key, "a value"))

    def table(self, root: dict, name: str, allowed: dict[str, bool] | None = None) -> dict:
        value = root.get(name, {})
        if not isinstance(value, dict):
            raise self.fail(name, f"must be a table [{name}], got {_toml_type(value)}")
        self.check_keys(value, _TABLE_KEYS[name] if allowed is None else allowed, name)
        return value

    def string(self, value: object, key: str) -> str:
        if not isinstance(value, str):
            raise self.fail(key, f"must be a string, got {_toml_type(value)}")
        return value

    def integer(self, value: object, key: str, minimum: int | None = None,
                maximum: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"must be an integer, got {_shown(value)}")
        name = key.rsplit(".", 1)[-1]
        if minimum is not None and value < minimum:
            raise self.fail(key, f"{name} must be >= {minimum}, got {value}")
        if maximum is not None and value > maximum:
            raise self.fail(key, f"{name} must be <= {maximum:,} ({LIMIT_REASON[key]}), got {value:,}")
        return value

    def array(self, value: object, key: str, expected: str) -> list:
        if not isinstance(value, list):
            raise self.fail(key, f"must be {expected}, got {_toml_type(value)}")
        return value

    def choice(self, value: object, key: str, what: str, options: tuple[str, ...]) -> str:
        if value not in options:
            raise self.fail(key, f"unknown {what} {_toml_repr(value)}; expected "
                                 + " or ".join(f'"{option}"' for option in options))
        return value

    def number(self, value: object, key: str) -> float:
        import math

        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(key, f"must be a number, got {_shown(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise self.fail(key, f"must be a finite number, got {value}")
        return value

    # -- sections ----------------------------------------------------------------------------

    def grid(self, grid_table: dict) -> Grid:
        key = "grid.map"
        text = self.string(grid_table["map"], key)
        text = text.replace("\r\n", "\n")
        if text.startswith("\n"):
            text = text[1:]
        rows = text.split("\n")
        while rows and rows[-1].strip() == "":
            rows.pop()
        if not rows:
            raise self.fail(key, "the map is empty; expected rows of cells (legend: "
                                 + MAP_LEGEND + ")")
        height = len(rows)
        width = len(rows[0])
        for i, row in enumerate(rows):
            if len(row) != width:
                raise self.fail(key, f"ragged rows: row {i + 1} (from the top) has {len(row)} "
                                     f"cells but row 1 has {width}; every row must be the same "
                                     "length")
        walls: set[Cell] = set()
        obstacles: set[Cell] = set()
        regions: dict[str, set[Cell]] = {}
        candidates: list[Cell] = []
        starts: list[Cell] = []
        for i, row in enumerate(rows):
            y = height - 1 - i
            for x, ch in enumerate(row):
                cell = (x, y)
                if ch == ".":
                    pass
                elif ch == "#":
                    walls.add(cell)
                elif ch == "o":
                    obstacles.add(cell)
                elif ch == "t":
                    candidates.append(cell)
                elif ch == "@":
                    starts.append(cell)
                elif "A" <= ch <= "Z":
                    if ch in FORBIDDEN_REGION_LETTERS:
                        raise self.fail(key, f"region letter {ch} at (x={x}, y={y}) is not "
                                             "allowed: F, G, M, R, U, W and X are Spot "
                                             "operators; use another letter")
                    regions.setdefault(ch, set()).add(cell)
                else:
                    raise self.fail(key, f"unknown character {ch!r} at (x={x}, y={y}) "
                                         f"(row {i + 1}, column {x + 1}); expected one of "
                                         + MAP_LEGEND)
        if not starts:
            raise self.fail(key, "no robot start '@' in the map; expected exactly one")
        if len(starts) > 1:
            where = ", ".join(f"({x}, {y})" for x, y in starts)
            raise self.fail(key, f"{len(starts)} robot starts '@' at {where}; expected exactly one")
        return Grid(
            rows=tuple(rows),
            width=width,
            height=height,
            walls=frozenset(walls),
            obstacles=frozenset(obstacles),
            regions=tuple((letter, frozenset(cells)) for letter, cells in sorted(regions.items())),
            trap_candidates=tuple(candidates),
            start=starts[0],
        )

    def formula(self, value: object, key: str, vocabulary: Vocabulary):
        """Check a co-safe LTL formula over the world's propositions; return spot.formula."""
        import spot

        text = self.string(value, key)
        if text.strip() == "":
            raise self.fail(key, "the formula is empty; expected a co-safe LTL formula in Spot "
                                 "syntax, e.g. \"!obs U A\"")
        try:
            parsed = spot.formula(text)
        except Exception as err:  # Spot raises SyntaxError with a multi-line diagnosis
            lines = [ln.strip() for ln in str(err).splitlines()]
            detail = "; ".join(ln for ln in lines
                               if ln and not ln.startswith(">>>") and set(ln) != {"^"})
            raise self.fail(key, f"formula {text!r} does not parse in Spot syntax"
                                 + (f": {detail}" if detail else "")) from None
        for ap in sorted(a.ap_name() for a in spot.atomic_prop_collect(parsed)):
            if ap not in vocabulary.propositions:
                raise self.fail(key, f"formula {text!r} uses proposition {ap!r}; only "
                                     f"{vocabulary.described} may be used")
        if not parsed.is_syntactic_guarantee():
            raise self.fail(key, f"formula {text!r} is not syntactically co-safe (Spot's "
                                 "is_syntactic_guarantee is false); expected a co-safe formula "
                                 "such as \"!obs U A\" or \"F A\"")
        return parsed

    def load(self) -> World:
        root = self.read()
        if not isinstance(root, dict):
            raise self.fail("-", "expected the tables of a world file")
        if "arena" in root:
            if "grid" in root:
                raise self.fail("arena", "a world is a grid world ([grid] and [robot]) or an "
                                         "arena world ([arena]), not both; remove one")
            return self.load_arena(root)
        if "grid" not in root:
            raise self.fail("grid", "missing required table: a world is a grid world ([grid] "
                                    "with map, and [robot]) or an arena world ([arena], "
                                    "docs/semantics.md §15)")
        self.check_keys(root, player_types.top_keys(root, _TOP_KEYS), "")
        name, description = self.header(root)
        grid = self.grid(self.table(root, "grid"))
        slip = self.number(self.table(root, "robot")["slip"], "robot.slip")
        if not 0.0 <= slip < 0.5:
            raise self.fail("robot.slip", f"slip must be in [0, 0.5), got {slip}")
        vocabulary = _grid_vocabulary(grid)
        formula = self.table(root, "task")["formula"]
        self.formula(formula, "task.formula", vocabulary)
        adv = self.table(root, "adversary")
        adversary = {**self.adversary(adv, grid), **self.guesses(adv, vocabulary)}
        observer = player_types.observer_fields(self, root, adv, adversary)
        return World(path=self.path, name=name, description=description, grid=grid, slip=slip,
                     formula=formula, **{**adversary, **observer},
                     simulation=self.simulation(self.table(root, "simulation")),
                     detection=self.detection(self.table(root, "detection")))

    def header(self, root: dict) -> tuple[str, str]:
        """The world's name (default: the file's stem) and description."""
        name = self.string(root["name"], "name") if "name" in root else self.path.stem
        if name.strip() == "":
            raise self.fail("name", "name must not be empty")
        description = (self.string(root["description"], "description")
                       if "description" in root else "")
        return name, description

    def load_arena(self, root: dict) -> World:
        """An arena world (docs/semantics.md §15; frontends/arena.py reads [arena] and P2's
        actions)."""
        tables = {**_TABLE_KEYS, "arena": arena_files.ARENA_KEYS,
                  "adversary": arena_files.ADVERSARY_KEYS}
        self.check_keys(root, player_types.top_keys(root, _ARENA_TOP_KEYS), "", tables)
        name, description = self.header(root)
        arena, p2 = arena_files.read(self, root)
        vocabulary = Vocabulary(arena.propositions, "the arena's propositions ("
                                + (", ".join(arena.propositions) or "none") + ")")
        formula = self.table(root, "task")["formula"]
        self.formula(formula, "task.formula", vocabulary)
        adv = self.table(root, "adversary", arena_files.ADVERSARY_KEYS)
        adversary = {**p2, **self.guesses(adv, vocabulary)}
        observer = player_types.observer_fields(self, root, adv, adversary)
        return World(path=self.path, name=name, description=description, grid=None, slip=0.0,
                     formula=formula, initial_traps=(), arena=arena,
                     **{**adversary, **observer},
                     simulation=self.simulation(self.table(root, "simulation")),
                     detection=self.detection(self.table(root, "detection")))

    def adversary(self, adv: dict, grid: Grid) -> dict:
        """[adversary] of a grid world: the World fields traps, delay and initial_traps."""
        traps = self.integer(adv["traps"], "adversary.traps", 1)
        n_cand = len(grid.trap_candidates)
        if traps > n_cand:
            raise self.fail("adversary.traps", f"traps = {traps} but the map has only {n_cand} "
                                               "trap candidate cells 't'; expected traps <= "
                                               "the number of 't' cells")
        delay = self.integer(adv.get("delay", 0), "adversary.delay", 0)
        initial_traps = self.initial_traps(adv, grid, traps, delay)
        return dict(traps=traps, delay=delay, initial_traps=initial_traps)

    def guesses(self, adv: dict, vocabulary: Vocabulary) -> dict:
        """[adversary]: the World fields hypotheses and initial_hypothesis (which P2's
        observer may set instead: `inference`)."""
        hypotheses = self.hypotheses(adv["hypotheses"], vocabulary)
        initial_hypothesis = self.integer(adv.get("initial_hypothesis", 0),
                                          "adversary.initial_hypothesis")
        if not 0 <= initial_hypothesis < len(hypotheses):
            raise self.fail("adversary.initial_hypothesis",
                            f"initial_hypothesis must be an index into hypotheses "
                            f"(0..{len(hypotheses) - 1}), got {initial_hypothesis}")
        return dict(hypotheses=hypotheses, initial_hypothesis=initial_hypothesis)

    def hypotheses(self, value: object, vocabulary: Vocabulary) -> tuple[str, ...]:
        """[adversary] hypotheses: distinct co-safe formulas, at least one."""
        items = self.array(value, "adversary.hypotheses", "an array of formulas")
        if not items:
            raise self.fail("adversary.hypotheses", "hypotheses is empty; expected at least one "
                                                    "co-safe LTL formula")
        seen: dict[str, int] = {}
        for i, h in enumerate(items):
            key = f"adversary.hypotheses[{i}]"
            canon = str(self.formula(h, key, vocabulary))
            if canon in seen:
                j = seen[canon]
                raise self.fail(key, f"hypothesis {h!r} is repeated: it is the same formula as "
                                     f"hypotheses[{j}] ({items[j]!r}); expected distinct "
                                     "hypotheses")
            seen[canon] = i
        return tuple(items)

    def inference(self, root: dict, adv: dict, adversary: dict) -> dict:
        """[inference]: the World fields inference (the observer's kind), window, settings
        (the kind's own keys, read by the kind: opponent/registry.py), rationality, and
        initial_hypothesis when the kind sets P2's first guess."""
        from hg2prism.opponent.registry import KINDS

        allowed = dict(_TABLE_KEYS["inference"])
        for kind in KINDS.values():
            allowed.update({key: False for key in kind.keys()})
        inf = self.table(root, "inference", allowed)
        kind = KINDS[self.choice(inf.get("kind", "cusum"), "inference.kind", "inference kind",
                                 tuple(KINDS))]
        window = self.integer(inf["window"], "inference.window", 1)
        settings = self.observer_settings(kind, inf, len(adversary["hypotheses"]))
        fields = dict(inference=kind.name, window=window, settings=tuple(settings.items()))
        if kind.first_guess is not None:
            if "initial_hypothesis" in adv:
                raise self.fail("adversary.initial_hypothesis", f"not allowed with kind = "
                                f"\"{kind.name}\": P2's first guess is {kind.first_guess_rule}")
            fields["initial_hypothesis"] = kind.first_guess(settings)
        rationality = self.number(inf["rationality"], "inference.rationality")
        if rationality <= 0:
            raise self.fail("inference.rationality", f"rationality must be > 0, got {rationality}")
        return dict(fields, rationality=rationality)

    def observer_settings(self, kind, inf: dict, n_hypotheses: int) -> dict[str, object]:
        """The keys of [inference] that belong to observer `kind`, as it reads them (a key of
        another kind refused)."""
        from hg2prism.opponent.registry import owner

        for key in inf:
            other = owner(key)
            if other is not None and key not in kind.keys():
                raise self.fail(f"inference.{key}", f"the {kind.title} observer has no {key}: "
                                f"it belongs to the {other.title} observer; remove it or set "
                                f"kind = \"{other.name}\"")
        settings = {}
        for setting in kind.settings:
            key = f"inference.{setting.key}"
            if setting.key in inf:
                settings[setting.key] = setting.read(self, inf[setting.key], n_hypotheses)
            elif setting.default is not None:
                settings[setting.key] = setting.default(n_hypotheses)
            else:
                raise self.fail(key, f"missing required key; expected {setting.expected}")
        return settings

    def simulation(self, sim: dict) -> SimulationSettings:
        d = SimulationSettings()
        return SimulationSettings(
            episodes=self.integer(sim.get("episodes", d.episodes), "simulation.episodes", 1,
                                  MAX_EPISODES),
            horizon=self.integer(sim.get("horizon", d.horizon), "simulation.horizon", 1,
                                 MAX_HORIZON),
            seed=self.integer(sim.get("seed", d.seed), "simulation.seed", 0),
        )

    def detection(self, det: dict) -> DetectionSettings:
        dd = DetectionSettings()
        alpha = self.number(det.get("alpha", dd.alpha), "detection.alpha")
        if not 0 < alpha < 1:
            raise self.fail("detection.alpha", f"alpha must be in (0, 1), got {alpha}")
        epsilon = self.number(det.get("epsilon", dd.epsilon), "detection.epsilon")
        if not 0 < epsilon < 1:
            raise self.fail("detection.epsilon", f"epsilon must be in (0, 1), got {epsilon}")
        deviate_after = self.integer(det.get("deviate_after", dd.deviate_after),
                                     "detection.deviate_after", 0)
        return DetectionSettings(alpha=alpha, epsilon=epsilon, deviate_after=deviate_after)

    def initial_traps(self, adv: dict, grid: Grid, traps: int, delay: int) -> tuple[Cell, ...]:
        """Parse [[x, y], ...]. Its shape is always checked when present; the cells only matter
        (and are only checked) when delay > 0. Returns cells sorted by candidate number."""
        key = "adversary.initial_traps"
        if "initial_traps" not in adv:
            if delay > 0:
                raise self.fail(key, f"initial_traps is required when delay > 0; expected "
                                     f"{traps} distinct trap candidate cells as [[x, y], ...]")
            return ()
        value = adv["initial_traps"]
        if not isinstance(value, list):
            raise self.fail(key, f"must be an array of [x, y] cells, got {_toml_type(value)}")
        cells: list[Cell] = []
        for i, item in enumerate(value):
            ikey = f"{key}[{i}]"
            if (not isinstance(item, list) or len(item) != 2
                    or any(isinstance(c, bool) or not isinstance(c, int) for c in item)):
                raise self.fail(ikey, f"each initial trap must be a cell [x, y] of two integers, "
                                      f"got {_toml_repr(item)}")
            cells.append((item[0], item[1]))
        if delay == 0:
            return ()
        numbering = {cell: n for n, cell in enumerate(grid.trap_candidates)}
        cand_text = ", ".join(f"[{x}, {y}]" for x, y in grid.trap_candidates)
        for i, cell in enumerate(cells):
            if cell not in numbering:
                raise self.fail(f"{key}[{i}]", f"[{cell[0]}, {cell[1]}] is not a trap candidate "
                                               f"'t' cell; candidates are {cand_text}")
        for i, cell in enumerate(cells):
            if cell in cells[:i]:
                raise self.fail(f"{key}[{i}]", f"[{cell[0]}, {cell[1]}] is repeated; initial "
                                               "traps must be distinct cells")
        if len(cells) != traps:
            raise self.fail(key, f"expected {traps} distinct trap candidate cells (traps = "
                                 f"{traps}) because delay > 0, got {len(cells)}")
        return tuple(sorted(cells, key=numbering.__getitem__))


def load_world(path: str | Path) -> World:
    """Read and validate a world file; raise InputError(file, key, reason) on any problem."""
    return _Loader(Path(path)).load()


def world_from_data(data: dict, name: str = "world") -> World:
    """Validate a world given as the tables of a world file (what tomllib reads from one;
    `name` as for world_from_toml)."""
    return _Loader(Path(name), data=data).load()


def world_from_toml(text: str, name: str = "world") -> World:
    """Validate the text of a world file (docs/semantics.md §1). `name` stands for the file in
    error messages and is the world's name when the text has none; raise InputError(name, key,
    reason) on any problem."""
    return _Loader(Path(name), text).load()
