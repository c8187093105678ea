"""Extensions from outside the package: the modules named in the environment variable
HG2PRISM_PLUGINS (comma- or space-separated, importable from Python's path) are imported before
the command line is read. Each registers what it adds, as docs/architecture.md ("How to add …")
shows: an observer by `opponent.registry.register(KIND)`, a world kind by a line in
`frontends.FRONT_ENDS`. The command line then knows the new `[inference] kind`, world tables and
sweep parameters, with no edit to the package. From Python, import the module yourself."""

from __future__ import annotations

import importlib
import os
import re
from collections.abc import Mapping

from hg2prism.errors import InputError

VARIABLE = "HG2PRISM_PLUGINS"


def plugin_names(environ: Mapping[str, str] | None = None) -> tuple[str, ...]:
    """The module names HG2PRISM_PLUGINS lists, in order, each once."""
    text = (os.environ if environ is None else environ).get(VARIABLE, "")
    return tuple(dict.fromkeys(name for name in re.split(r"[,\s]+", text) if name))


def load_plugins(environ: Mapping[str, str] | None = None) -> tuple[str, ...]:
    """Import every module HG2PRISM_PLUGINS names; InputError (one line, naming the variable
    and the module) when one cannot be imported or fails while registering. Returns the
    names imported."""
    names = plugin_names(environ)
    for name in names:
        if not re.fullmatch(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*", name):
            raise InputError(VARIABLE, name, "not a module name; expected dotted Python "
                             "module names separated by commas or spaces")
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name is not None and (name == err.name or name.startswith(err.name + ".")):
                raise InputError(VARIABLE, name, "no such module on Python's path (sys.path: "
                                 "the current folder, PYTHONPATH, installed packages)") from None
            raise InputError(VARIABLE, name, f"importing it failed: {err}") from None
        except InputError:
            raise
        except Exception as err:        # the plugin's own error, said in one line
            raise InputError(VARIABLE, name, f"importing it failed: "
                             f"{type(err).__name__}: {err}") from None
    return names
