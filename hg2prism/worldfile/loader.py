"""World files (docs/semantics.md §1): read a TOML world, validate every key with one clear
error line (file, key, reason), and return an immutable `model.world.World`.

The loader sits above the model and the observers: which `[inference]` keys a world may have,
and how they are read, is asked of the observer registry (opponent/registry.py). The rules of
each value are model/validation.py's (`Checks`, which the loader extends with the file's
tables), the same rules World.__post_init__ checks every World with.
"""

from __future__ import annotations

from pathlib import Path

from hg2prism.errors import InputError, did_you_mean
from hg2prism.model.validation import Checks, Vocabulary
from hg2prism.model.validation import key_part as _key_part
from hg2prism.model.validation import toml_repr as _toml_repr
from hg2prism.model.validation import toml_type as _toml_type
from hg2prism.frontends import front_ends
from hg2prism.worldfile import types as player_types
# the registry checks every World's observer settings (model/validation.py) once imported
from hg2prism.opponent.registry import KINDS, owner
from hg2prism.model.world import DetectionSettings, SimulationSettings, World


# Keys allowed in each table: key -> required? A front end adds its files' own tables (between
# description and task) and its [adversary] keys (frontends/__init__.py).
_TOP_KEYS = {"name": False, "description": False, "task": True, "adversary": True,
             "inference": True, "simulation": False, "detection": False}
_ADVERSARY_KEYS = {"hypotheses": True, "initial_hypothesis": False, "tie_break": False}
_TABLE_KEYS: dict[str, dict[str, bool]] = {
    "task": {"formula": True},
    "adversary": _ADVERSARY_KEYS,
    # and the keys of the observers' kinds (`_Loader.inference` asks opponent/registry.py)
    "inference": {"kind": False, "window": True, "rationality": True},
    "simulation": {"episodes": False, "horizon": False, "seed": False},
    "detection": {"alpha": False, "epsilon": False, "deviate_after": False},
}
# The tables of entries ([[...]]): a TOML error in a file that writes one with one bracket says so
ARRAY_TABLES = ("arena.transition", "type")
_MISSING_HINT = {
    "task.formula": "a syntactically co-safe LTL formula in Spot syntax",
    "adversary.traps": "an integer >= 1",
    "adversary.hypotheses": "a non-empty array of co-safe LTL formulas",
    "inference.window": "an integer >= 1",
    "inference.rationality": "a number > 0",
}


def _file_keys(front) -> tuple[dict[str, bool], dict[str, dict[str, bool]]]:
    """The top-level tables and every table's keys of a world file of front end `front`."""
    top = {"name": False, "description": False, **front.FILE_TABLES, **_TOP_KEYS}
    tables = {**_TABLE_KEYS, **front.TABLE_KEYS,
              "adversary": {**front.ADVERSARY_KEYS, **_ADVERSARY_KEYS}}
    return top, tables


class _Loader(Checks):
    def __init__(self, path: Path, text: str | None = None, data: dict | None = None) -> None:
        super().__init__(str(path))
        self.path = path
        self.text = text        # the file's text when it does not come from a file
        self.data = data        # or the parsed file (a world built in Python)
        self.source: str | None = None      # the text parsed, once read

    def fail(self, key: str, reason: str) -> InputError:
        line = self._entry_line(key)
        if line is not None:    # entries are counted from 0: where the entry is, in the file
            reason = f"{reason} (the entry at line {line})"
        return super().fail(key, reason)

    def _entry_line(self, key: str) -> int | None:
        """The line of the `[[table]]` header that starts the entry `key` names
        ("arena.transition[16].to.plc": the 17th [[arena.transition]]), None when the key names
        no entry or the text is not known."""
        import re

        found = re.match(r"(" + "|".join(re.escape(t) for t in ARRAY_TABLES) + r")\[(\d+)\]",
                         key)
        if found is None or self.source is None:
            return None
        header = re.compile(r"[ \t]*\[\[[ \t]*" + re.escape(found.group(1)) + r"[ \t]*\]\]")
        starts = [n for n, text in enumerate(self.source.splitlines(), 1) if header.match(text)]
        index = int(found.group(2))
        return starts[index] if index < len(starts) else None

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
            parsed = tomllib.loads(text)
            self.source = text
            return parsed
        except tomllib.TOMLDecodeError as err:
            msg = str(err)
            m = re.search(r"\(at (line \d+, column \d+|end of document)\)\s*$", msg)
            key = m.group(1) if m else "-"
            detail = msg[: m.start()].strip() if m else msg
            single = re.search(r"^[ \t]*\[[ \t]*(" + "|".join(re.escape(t) for t in ARRAY_TABLES)
                               + r")[ \t]*\]", text, re.MULTILINE)
            if single and detail.startswith(("Cannot declare", "Cannot overwrite")):
                # a table of entries written as one table, declared again: said in its words
                detail += (f"; each entry of [[{single.group(1)}]] starts with two brackets "
                           f"(a line [{single.group(1)}] is one table)")
            if self.path.suffix in (".prism", ".props", ".pm", ".nm", ".drn", ".tra", ".json"):
                detail += (f"; {self.path.name} is no world file: hg2prism's commands read a "
                           f"world file (TOML, a .toml; docs/semantics.md §1), and write the "
                           f"PRISM models and the exports")
            raise self.fail(key, f"not valid TOML: {detail}") from None

    # -- typed getters -----------------------------------------------------------------------

    def check_keys(self, table: dict, allowed: dict[str, bool], prefix: str,
                   tables: dict[str, dict[str, bool]] = _TABLE_KEYS) -> None:
        for name in table:
            if name not in allowed:
                key = f"{prefix}.{_key_part(name)}" if prefix else _key_part(name)
                what = "table" if isinstance(table[name], dict) else "key"
                where = f"in [{prefix}]" if prefix else "at the top level"
                raise self.fail(key, f"unknown {what} {where}{did_you_mean(name, allowed)}; "
                                     "expected one of: " + ", ".join(allowed))
        for name, required in allowed.items():
            if required and name not in table:
                key = f"{prefix}.{name}" if prefix else name
                if not prefix and name in tables:
                    raise self.fail(key, f"missing required table [{name}] (with "
                                         + ", ".join(k for k, r in tables[name].items() if r)
                                         + ")")
                hints = {key: hint for module in front_ends()
                         for key, hint in module.MISSING_HINT.items()} | _MISSING_HINT
                raise self.fail(key, "missing required key; expected "
                                     + hints.get(key, "a value"))

    def table(self, root: dict, name: str, allowed: dict[str, bool] | None = None) -> dict:
        value = root.get(name, {})
        if not isinstance(value, dict):
            raise self.fail(name, f"must be a table [{name}], got {_toml_type(value)}")
        if allowed is None:         # a table every world has, or one of a front end's own
            allowed = _TABLE_KEYS.get(name) or next(
                module.TABLE_KEYS[name] for module in front_ends() if name in module.TABLE_KEYS)
        self.check_keys(value, allowed, name)
        return value

    @staticmethod
    def written(value: object) -> str:
        """A value as it would be written in the file (one line), for error messages."""
        return _toml_repr(value)

    # -- sections ----------------------------------------------------------------------------

    def load(self) -> World:
        root = self.read()
        if not isinstance(root, dict):
            raise self.fail("-", "expected the tables of a world file")
        front_end = self.front_end(root)
        top, tables = _file_keys(front_end)
        self.check_keys(root, player_types.top_keys(root, top), "", tables)
        name, description = self.header(root)
        if not isinstance(root["adversary"], dict):      # what a kind's `read` may look at
            self.table(root, "adversary", tables["adversary"])
        front = front_end.read(self, root)
        vocabulary = front.vocabulary()
        formula = self.table(root, "task")["formula"]
        self.formula(formula, "task.formula", vocabulary)
        adv = self.table(root, "adversary", tables["adversary"])
        adversary = {**front_end.read_adversary(self, adv, front),
                     **self.guesses(adv, vocabulary)}
        observer = player_types.observer_fields(self, root, adv, adversary)
        return World(path=self.path, name=name, description=description, front=front,
                     formula=formula, **{**adversary, **observer},
                     simulation=self.simulation(self.table(root, "simulation")),
                     detection=self.detection(self.table(root, "detection")))

    def front_end(self, root: dict):
        """The front end of the file's kind (frontends/__init__.py), by the table that marks
        it (a grid world's [grid], an arena world's [arena])."""
        modules = front_ends()
        kinds = [module for module in modules if next(iter(module.FILE_TABLES)) in root]
        named = [module.DESCRIBED for module in modules]
        described = " or ".join(filter(None, (", ".join(named[:-1]), named[-1])))
        if len(kinds) > 1:
            raise self.fail(next(iter(kinds[1].FILE_TABLES)),
                            f"a world is {described}, "
                            + ("not both" if len(modules) == 2 else "only one of them")
                            + "; remove one")
        if not kinds:
            raise self.fail(next(iter(modules[0].FILE_TABLES)),
                            f"missing required table: a world is {described} "
                            "(docs/semantics.md §§1, 15)")
        return kinds[0]

    def header(self, root: dict) -> tuple[str, str]:
        """The world's name (default: the file's stem) and description."""
        name = self.string(root["name"], "name") if "name" in root else self.path.stem
        if name.strip() == "":
            raise self.fail("name", "name must not be empty")
        description = (self.string(root["description"], "description")
                       if "description" in root else "")
        return name, description

    def guesses(self, adv: dict, vocabulary: Vocabulary) -> dict:
        """[adversary]: the World fields hypotheses, initial_hypothesis (which P2's
        observer may set instead: `inference`) and tie_break."""
        hypotheses = self.hypotheses(adv["hypotheses"], vocabulary)
        initial_hypothesis = self.initial_hypothesis(adv.get("initial_hypothesis", 0),
                                                     len(hypotheses))
        return dict(hypotheses=hypotheses, initial_hypothesis=initial_hypothesis,
                    tie_break=self.tie_break(adv.get("tie_break", "first")))

    def inference(self, root: dict, adv: dict, adversary: dict) -> dict:
        """[inference]: the World fields inference (the observer's kind), window, settings
        (the kind's own keys, read by the kind: opponent/registry.py), rationality, and
        initial_hypothesis when the kind sets P2's first guess."""
        allowed = dict(_TABLE_KEYS["inference"])
        for kind in KINDS.values():
            allowed.update({key: False for key in kind.keys()})
        inf = self.table(root, "inference", allowed)
        kind = KINDS[self.choice(inf.get("kind", "cusum"), "inference.kind", "inference kind",
                                 tuple(KINDS))]
        window = self.window(inf["window"])
        settings = self.observer_settings(kind, inf, len(adversary["hypotheses"]))
        fields = dict(inference=kind.name, window=window, settings=tuple(settings.items()))
        if kind.first_guess is not None:
            if "initial_hypothesis" in adv:
                raise self.fail("adversary.initial_hypothesis", f"not allowed with kind = "
                                f"\"{kind.name}\": P2's first guess is {kind.first_guess_rule}")
            fields["initial_hypothesis"] = kind.first_guess(settings)
        return dict(fields, rationality=self.rationality(inf["rationality"]))

    def observer_settings(self, kind, inf: dict, n_hypotheses: int) -> dict[str, object]:
        """The keys of [inference] that belong to observer `kind`, as it reads them (a key of
        another kind refused)."""
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
            episodes=self.episodes(sim.get("episodes", d.episodes)),
            horizon=self.horizon(sim.get("horizon", d.horizon)),
            seed=self.seed(sim.get("seed", d.seed)),
        )

    def detection(self, det: dict) -> DetectionSettings:
        dd = DetectionSettings()
        return DetectionSettings(alpha=self.alpha(det.get("alpha", dd.alpha)),
                                 epsilon=self.epsilon(det.get("epsilon", dd.epsilon)),
                                 deviate_after=self.deviate_after(det.get("deviate_after",
                                                                          dd.deviate_after)))


def load_world(path: str | Path) -> World:
    """Read and validate a world file; raise InputError(file, key, reason) on any problem."""
    import os

    if not isinstance(path, (str, os.PathLike)):
        raise InputError("load_world()", "path", "expected the path of a world file (a str or "
                         f"a pathlib.Path), got {type(path).__name__}")
    return _Loader(Path(path)).load()


def world_from_data(data: dict, name: str = "world") -> World:
    """Validate a world given as the tables of a world file (what tomllib reads from one;
    `name` as for world_from_toml)."""
    return _Loader(Path(name), data=data).load()


def world_from_toml(text: str, name: str = "world") -> World:
    """Validate the text of a world file (docs/semantics.md §1). `name` stands for the file in
    error messages and is the world's name when the text has none; raise InputError(name, key,
    reason) on any problem."""
    for key, value in (("text", text), ("name", name)):
        if not isinstance(value, str):
            raise InputError("world_from_toml()", key, "expected a str (" + (
                "the world file's text; bytes: decode them, or give the file to load_world"
                if key == "text" else "what stands for the file in messages")
                + f"), got {type(value).__name__}")
    return _Loader(Path(name), text).load()
