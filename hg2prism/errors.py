"""The one error type users see: a bad input, reported as file, key and reason."""

from __future__ import annotations


class InputError(Exception):
    """Bad user input. The CLI prints it as one line and exits with status 2."""

    def __init__(self, file: str, key: str, reason: str) -> None:
        super().__init__(f"{file}: {key}: {reason}")
        self.file = file
        self.key = key
        self.reason = reason


class SolverError(RuntimeError):
    """A numerical solver did not reach the precision SPEC §10 requires."""


class StormError(RuntimeError):
    """Storm refused or failed on a generated model."""
