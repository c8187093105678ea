"""Lists of values given on the command line (`sweep --values`, `robust --deltas`): the one parser
of them, and of the numbers in them.

A value's parser (:func:`number`, or a sweep parameter's own) turns a value as typed (a string)
or given in Python into the value, raising ``ValueError("is not")`` when the text is not of the
expected form, ``ValueError("must be")`` when it is but is out of range (or of the wrong
type) and ``ValueError("finite")`` when it is a number too large for a float, inf or nan.
:func:`parse_values` applies one to every value of a list and turns the first failure into one
InputError line under the option's key, in its option's wording (:class:`ValueList`), with the
hint to separate values with spaces when a value that is not of the form holds a comma.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from hg2prism.errors import COMMAND_LINE, InputError

__all__ = ["number", "ValueList", "parse_values"]

NOT_FORM = "is not"      # the ValueError of a value that is not of the expected form
OUTSIDE = "must be"      # ... of one that is, but out of range or of the wrong type
NOT_FINITE = "finite"    # ... of one that is, but overflows (1e309) or is inf or nan


def number(kind: type, minimum: float | None = None, exclusive: bool = False,
           below: float | None = None, maximum: float | None = None
           ) -> Callable[[object], int | float]:
    """A parser of ints (`kind` int) or finite floats >= minimum (> when exclusive), < below
    and <= maximum when given; a bool is not a number."""
    def parse(value: object) -> int | float:
        if isinstance(value, bool):
            raise ValueError(OUTSIDE)
        found: object
        if isinstance(value, numbers.Real):
            found = value
        elif isinstance(value, str):
            text = value.strip()
            try:
                found = int(text) if kind is int else float(text)
            except ValueError:
                raise ValueError(NOT_FORM) from None
        else:
            raise ValueError(OUTSIDE)
        if kind is int:
            if not isinstance(found, numbers.Integral):
                raise ValueError(OUTSIDE)
            result: int | float = int(found)
        else:
            result = float(found)
            if not math.isfinite(result):
                raise ValueError(NOT_FINITE)
        if minimum is not None and (result < minimum or (exclusive and result == minimum)):
            raise ValueError(OUTSIDE)
        if (below is not None and result >= below) or (maximum is not None and result > maximum):
            raise ValueError(OUTSIDE)
        return result
    return parse


@dataclass(frozen=True)
class ValueList:
    """An option taking a list of values, and its wording. The reasons are format strings with
    `name`, `expected`, `option`, `value` (as given), `shown` (a string as typed, else its
    repr) and, for `repeated`, `parsed` (the value parsed)."""

    option: str                                 # the InputError key: "--values", "--deltas"
    name: str                                   # what one value is: "delay value", "weight"
    expected: str                               # what it must be: "an integer >= 0"
    parse: Callable[[object], Any]              # a value's parser (raises NOT_FORM / OUTSIDE)
    empty: str = "expected at least one {name} ({expected})"
    not_form: str = "{name} {shown!r} is not {expected}"
    outside: str = "{name} {shown} must be {expected}"
    not_finite: str = "{name} {shown} is not a finite number; expected {expected}"
    repeated: str | None = "{name} {parsed} is repeated; expected distinct values"
    hint: bool = True               # values joined by commas: say to separate them (False:
                                    # an option of one value)


def parse_values(spec: ValueList, values: Sequence[object]) -> list:
    """Every value of `values` parsed by `spec.parse`: a non-empty list (not a string), and
    distinct values unless `spec.repeated` is None. InputError (key `spec.option`) otherwise:
    the first value that does not parse, else the first repeated one."""
    words = {"name": spec.name, "expected": spec.expected, "option": spec.option}
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or not values:
        raise InputError(COMMAND_LINE, spec.option, spec.empty.format(**words))
    parsed: list = []
    for value in values:
        shown = value if isinstance(value, str) else repr(value)
        try:
            found = spec.parse(value)
        except ValueError as err:
            if str(err) == NOT_FORM:
                # "1,4" for 1 4: the values are separate arguments (a prior's weights take
                # commas, and its parser says whether they parse); the hint shows those typed
                parts = ([part.strip() for part in value.split(",") if part.strip()]
                         if spec.hint and isinstance(value, str) and "," in value else [])
                apart = (f"; separate the values with spaces ({spec.option} {' '.join(parts)})"
                         if parts and all(_parses(spec, part) for part in parts) else "")
                reason = spec.not_form.format(value=value, shown=shown, **words) + apart
            elif str(err) == NOT_FINITE:
                reason = spec.not_finite.format(value=value, shown=shown, **words)
            else:
                reason = spec.outside.format(value=value, shown=shown, **words)
            raise InputError(COMMAND_LINE, spec.option, reason) from None
        parsed.append(found)
    for i, (value, found) in enumerate(zip(values, parsed)):     # each value checked first
        if spec.repeated is not None and found in parsed[:i]:
            shown = value if isinstance(value, str) else repr(value)
            raise InputError(COMMAND_LINE, spec.option, spec.repeated.format(
                value=value, shown=shown, parsed=found, **words))
    return parsed


def _parses(spec: ValueList, value: str) -> bool:
    """Whether `value` alone has the form of one of `spec`'s values, in range or not (a hint to
    split "1,4" or "1,0" is only given when its parts have that form: not for a prior's
    "1,x")."""
    try:
        spec.parse(value)
    except ValueError as err:
        return str(err) != NOT_FORM
    return True
