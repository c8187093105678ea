"""Helpers every PRISM model of hg2prism is written with: tables as expressions, numbers as
PRISM reads them, label names, and the Jinja environment of the templates (templates/*.j2;
the macros they share are in templates/common.prism.j2)."""

from __future__ import annotations

import functools
import importlib.resources
from pathlib import Path

import jinja2
import numpy as np

from hg2prism.model.dynamics import TransitionSystem


def region_label(letter: str) -> str:
    """The PRISM label of a region letter: "reg_A" for A. PRISM rejects a keyword as a label
    name even inside quotes, and A, C, E, F, G, I, P, R, S, U, W and X are keywords."""
    return f"reg_{letter}"


def region_labels(ts: TransitionSystem) -> list[tuple[str, int]]:
    """(PRISM label, label class) of each region letter (classes 0 and 1 are none and obs)."""
    return [(region_label(name), k) for k, name in enumerate(ts.label_names) if k >= 2]


def prism_number(value: float | int) -> str:
    """A number as PRISM reads it: integers plain, floats in their shortest exact decimal."""
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    text = np.format_float_positional(float(value), unique=True, trim="0")
    return text if "." in text else text + ".0"


def lookup(table: np.ndarray, keys: list[tuple[str, int]]) -> str:
    """An expression for table[k0 - lo0][k1 - lo1]...: a balanced tree of comparisons.

    keys: (expression, lowest value) per table dimension. Equal sub-blocks collapse to a constant.
    """
    def node(block: np.ndarray, dim: int, start: int) -> str:
        first = block.flat[0]
        if (block == first).all():
            return prism_number(first.item())
        if block.shape[0] == 1:
            return node(block[0], dim + 1, 0)
        expr, low = keys[dim]
        mid = block.shape[0] // 2
        left = node(block[:mid], dim, start)
        right = node(block[mid:], dim, start + mid)
        return f"({expr}<{low + start + mid} ? {left} : {right})"

    return node(np.asarray(table), 0, 0)


def cases(branches: list[tuple[str, str]], otherwise: str) -> str:
    """`t0 ? v0 : t1 ? v1 : ... : otherwise` (PRISM's conditional, right-associative):
    the first value whose test holds."""
    return "".join(f"{test} ? {value} : " for test, value in branches) + otherwise


def maximum(terms: list[str]) -> str:
    """max(t0, t1, ...), or the one term itself."""
    return terms[0] if len(terms) == 1 else f"max({', '.join(terms)})"


def _template_source(name: str) -> str:
    """Templates ship as the package `hg2prism.templates` (the repository's templates/ folder);
    running from a checkout without installing reads that folder directly."""
    try:
        folder = importlib.resources.files("hg2prism.templates")
    except ModuleNotFoundError:
        folder = Path(__file__).resolve().parents[2] / "templates"
    return folder.joinpath(name).read_text()


def upper(count: int) -> int:
    """The upper bound of a variable [0..upper] taking `count` values (0 .. count-1). PRISM
    rejects a range of one value ("Invalid range (0-0)"), so a variable that only ever holds 0
    (one trap set, one hypothesis, a one-state DFA) is declared [0..1]; 1 is never reached."""
    return max(count - 1, 1)


@functools.cache   # one environment, so each template is compiled once per process
def _environment() -> jinja2.Environment:
    environment = jinja2.Environment(
        loader=jinja2.FunctionLoader(_template_source),
        undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True,
        keep_trailing_newline=True)
    environment.globals["upper"] = upper
    return environment


def render_template(name: str, **context: object) -> str:
    return _environment().get_template(name).render(**context)


def render_macro(name: str, macro: str, **context: object) -> str:
    """The text of one macro of template `name`, the template's variables set to `context`."""
    module = _environment().get_template(name).make_module(vars=context)
    return str(getattr(module, macro)())
