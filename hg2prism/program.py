"""The program `hg2prism` (and `python -m hg2prism`): `cli.entry`, imported here so that a
Ctrl-C while Python still loads hg2prism and its libraries (about a second) ends as every
other Ctrl-C does, in one line and exit status 130, not in a traceback of the imports."""

from __future__ import annotations

import sys


def entry() -> int:
    try:
        from hg2prism.cli import entry as program
    except KeyboardInterrupt:
        print("hg2prism: interrupted", file=sys.stderr)
        return 130
    return program()
