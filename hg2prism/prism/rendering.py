"""Helpers every PRISM model of hg2prism is written with: tables as expressions, numbers as
PRISM reads them, and the Jinja environment of the templates (templates/*.j2;
the macros they share are in templates/common.prism.j2)."""

from __future__ import annotations

import functools
import itertools
import importlib.resources
import math
import re
from pathlib import Path

import jinja2
import numpy as np


# A written number is snapped to the shortest decimal of at most this many significant digits
# within SNAP_ULPS units in its last place (short_decimal).
SNAP_DIGITS = 12
SNAP_ULPS = 2


def short_decimal(value: float) -> float:
    """`value`, or the shortest decimal of at most 12 significant digits within 2 units in the
    last place of it. The world's probabilities are short decimals (a grid's 0.8 and 0.1);
    the model checker hands some back a unit in the last place off (it converts the rational
    4/5 to a double by truncation: 0.7999999999999999), and so do sums of them (0.9 as
    0.8999999999999999). Every writer of a probability writes this value (`prism_number`,
    `probability_text`), so an exported model reads 0.8; it differs from the computed value
    by at most 2 units in the last place (about 4e-16 for a probability)."""
    value = float(value)
    if not math.isfinite(value) or value == 0:
        return value
    text = repr(value)
    if len(text.lstrip("-0.").replace(".", "").split("e")[0]) <= SNAP_DIGITS:
        return value                # already short: nothing to snap
    slack = SNAP_ULPS * math.ulp(value)
    for digits in range(1, SNAP_DIGITS + 1):
        near = float(f"{value:.{digits}g}")
        if abs(near - value) <= slack:
            return near
    return value


def probability_text(value: float) -> str:
    """A probability as the exports write it (Python's repr of its short decimal: 0.8)."""
    return repr(short_decimal(value))


def prism_number(value: float | int) -> str:
    """A number as PRISM reads it: integers plain, floats in their shortest exact decimal
    (of `short_decimal`: 0.8, not 0.7999999999999999)."""
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    text = np.format_float_positional(short_decimal(value), unique=True, trim="0")
    return text if "." in text else text + ".0"


def lookup(table: np.ndarray, keys: list[tuple[str, int]], care: np.ndarray | None = None) -> str:
    """An expression for table[k0 - lo0][k1 - lo1]...: a tree of comparisons.

    keys: (expression, lowest value) per table dimension. Along each dimension the indices are
    grouped into runs whose sub-tables agree, and the tree bisects the runs, so a table that is
    mostly one value costs little text and Storm few comparisons. `care` (a bool array of the
    table's shape, default all True) marks the entries the model can reach; the others may take
    any value, which lengthens the runs (a table over TS states need only be right on the TS
    states P1 can reach).
    """
    table = np.asarray(table)
    care = np.ones(table.shape, dtype=bool) if care is None else np.broadcast_to(care, table.shape)
    if not care.any():
        return prism_number(table.flat[0].item())

    def node(block: np.ndarray, mask: np.ndarray, dim: int, start: int) -> str:
        cared = block[mask]
        if (cared == cared[0]).all():
            return prism_number(cared[0].item())
        return bisect(_runs(block, mask), dim, start)

    def bisect(runs: list[tuple[int, np.ndarray, np.ndarray]], dim: int, start: int) -> str:
        if len(runs) == 1:
            _, row, mask = runs[0]
            return node(row, mask, dim + 1, 0)
        expr, low = keys[dim]
        mid = len(runs) // 2
        left = bisect(runs[:mid], dim, start)
        right = bisect(runs[mid:], dim, start)
        return f"({expr}<{low + start + runs[mid][0]} ? {left} : {right})"

    return node(table, np.asarray(care, dtype=bool), 0, 0)


def _runs(block: np.ndarray, mask: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """block's rows (along its first dimension) grouped into runs of consecutive rows that agree
    wherever both are cared for: (first row, the run's merged row, its mask) per run."""
    if mask.all():
        flat = block.reshape(block.shape[0], -1)
        starts = np.r_[0, np.flatnonzero((flat[1:] != flat[:-1]).any(axis=1)) + 1]
        return [(int(i), block[i], mask[i]) for i in starts]
    if block.ndim == 1:     # each free entry joins the run before it (the first, the one after)
        cared = np.flatnonzero(mask)
        filled = block[cared[np.maximum(np.searchsorted(cared, np.arange(len(block)), "right") - 1, 0)]]
        starts = np.r_[0, np.flatnonzero(filled[1:] != filled[:-1]) + 1]
        return [(int(i), filled[i], np.True_) for i in starts]
    runs = []
    row, row_mask, first = block[0], mask[0], 0
    for i in range(1, block.shape[0]):
        both = row_mask & mask[i]
        if (row[both] == block[i][both]).all():
            row = np.where(row_mask, row, block[i])
            row_mask = row_mask | mask[i]
        else:
            runs.append((first, row, row_mask))
            row, row_mask, first = block[i], mask[i], i
    runs.append((first, row, row_mask))
    return runs


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
    """The text of template `name`; a PRISM model's long lines wrapped (`wrapped`) and its
    blank lines single (the templates' optional parts left some doubled)."""
    text = _environment().get_template(name).render(**context)
    if not name.endswith(".prism.j2"):
        return text
    return re.sub(r"\n{3,}", "\n\n", wrapped(text))


# A model's lines longer than this are wrapped (formulas of tables ran to 13,642 characters on
# one line, which editors, diffs and PRISM's GUI show poorly)
WRAP = 100
CONTINUED = 4           # a code line's continuations are indented this much more


def wrapped(text: str, width: int = WRAP) -> str:
    """`text` (PRISM) with every line longer than `width` broken into lines of at most `width`
    characters where its words allow. Code is broken between tokens (at spaces outside
    "quoted" names), at the least nested break of the line's last stretch (`_broken`),
    continuations indented by CONTINUED more, a wrapped line's end-of-line comment on a line of
    its own above it; PRISM reads line breaks as spaces, so the model is the same. A comment
    goes on in comment lines whose text starts under its own (a header's value column)."""
    lines = []
    given = text.split("\n")
    n = 0
    while n < len(given):
        line = given[n]
        n += 1
        body = line.lstrip()
        indent = line[:len(line) - len(body)]
        if len(line) <= width:
            lines.append(line)
        elif body.startswith("//"):
            hang = _hang(body[2:])
            # the sentence goes on in the comment lines under it: one paragraph, reflowed
            while n < len(given) and _goes_on(given[n], indent, hang, body):
                body += " " + given[n].strip()[2:].strip()
                n += 1
            lines += _comment_broken(indent, body, width, hang)
        else:
            code, comment = _code_and_comment(body)
            if comment:
                lines += _comment_broken(indent, comment, width, _hang(comment[2:]))
            lines += _broken(code, indent, width)
    return "\n".join(lines)


def _hang(text: str) -> int:
    """Where a comment's text (after //) goes on: under its value when a run of spaces sets one
    off within its first 24 characters (`// world        world1 (...)`), else under its first
    word."""
    column = re.search(r"^ *\S+(?: \S+)*? {2,}(?=\S)", text)
    if column is not None and column.end() <= 24:
        return column.end()
    return len(text) - len(text.lstrip(" "))


def _goes_on(line: str, indent: str, hang: int, before: str) -> bool:
    """Whether comment `line` continues the sentence of the long comment line `before` (with
    `indent` and `hang`): its text starts under the hang, in lower case or with "(", it is no
    header line of its own (`// digest   ...`), and `before` does not end a sentence."""
    if not line.startswith(indent + "//") or before.rstrip().endswith((".", ":", ";")):
        return False
    text = line[len(indent) + 2:]
    if len(text) <= hang or text[:hang].strip() or text[hang] == " ":
        return False
    start = text[hang]
    return (start.islower() or start == "(") and _hang(text) == hang


def _comment_broken(indent: str, body: str, width: int, hang: int) -> list[str]:
    """A comment (`body` starts with //) in lines of at most `width` characters where its
    words allow: continuations are comment lines whose text starts at `hang` after the //."""
    text = body[2:]
    first, rest = text[:hang], text[hang:].split()
    prefix, more = indent + "//" + first, indent + "//" + " " * hang
    lines, current = [], prefix.rstrip(" ") if not rest else prefix + rest[0]
    for word in rest[1:]:
        if len(current) + 1 + len(word) > width:
            lines.append(current)
            current = more + word
        else:
            current += " " + word
    lines.append(current)
    return lines


def _code_and_comment(body: str) -> tuple[str, str]:
    """A line's code and its end-of-line comment ("" when none): the first // outside quotes."""
    quoted = False
    for i, char in enumerate(body):
        if char == '"':
            quoted = not quoted
        elif not quoted and body.startswith("//", i):
            return body[:i].rstrip(), body[i:]
    return body, ""


# operators a wrapped code line would rather begin with (between outcomes, updates, branches)
_LEADING = {"+": 0, "&": 1, "|": 1, ":": 2, "?": 3}


def _broken(code: str, indent: str, width: int) -> list[str]:
    """`code` in lines of at most `width` characters (a token longer than that alone on its
    line), breaking only at spaces outside quotes. A line is filled, then broken at the least
    nested space of its last half (parentheses counted), preferring one before `+` (between
    outcomes), then `&` or `|`, `:` and `?`, and the latest of equals: `(place<16 ? 21 : 22)`
    and an outcome's probability stay whole where the line allows."""
    if '"' not in code:              # the usual line: no quoted name to keep whole
        tokens = [token for token in code.split(" ") if token]
        depths = list(itertools.accumulate(t.count("(") - t.count(")") for t in tokens))
        return _filled(tokens, depths, indent, width)
    tokens, depths, quoted, start, depth = [], [], False, 0, 0
    for i, char in enumerate(code):
        if char == '"':
            quoted = not quoted
        elif quoted:
            continue
        elif char == " ":
            if i > start:
                tokens.append(code[start:i])
                depths.append(depth)
            start = i + 1
            continue
        if char == "(":
            depth += 1
        elif char == ")":
            depth -= 1
    tokens.append(code[start:])
    depths.append(depth)
    return _filled(tokens, depths, indent, width)


def _filled(tokens: list[str], depths: list[int], indent: str, width: int) -> list[str]:
    """The lines of `_broken`: `depths[k]` is the nesting after token k."""
    # depth before each token: the nesting a break in front of it leaves open
    before = [0] + depths[:-1]
    more = indent + " " * CONTINUED
    lines: list[str] = []
    head, line, length = indent, [0], len(indent) + len(tokens[0])   # the line being filled
    i = 1
    while i < len(tokens):
        if length + 1 + len(tokens[i]) <= width:
            line.append(i)
            length += 1 + len(tokens[i])
            i += 1
            continue
        best, key = i, None          # no break in the line's last half: break here
        half = len(head) + (width - len(head)) // 2
        upto = len(head) + len(tokens[line[0]])      # the line's length before line[pos]
        for pos in range(1, len(line)):
            k = line[pos]
            if upto >= half:
                rank = (before[k], _LEADING.get(tokens[k], 4), -k)
                if key is None or rank < key:
                    best, key = k, rank
            upto += 1 + len(tokens[k])
        kept = [m for m in line if m < best]
        lines.append(head + " ".join(tokens[m] for m in kept))
        head, line = more, [m for m in line if m >= best]
        if not line:
            line, i = [i], i + 1
        length = len(head) + sum(len(tokens[m]) for m in line) + len(line) - 1
    lines.append(head + " ".join(tokens[k] for k in line))
    return lines


def render_macro(name: str, macro: str, **context: object) -> str:
    """The text of one macro of template `name`, the template's variables set to `context`."""
    module = _environment().get_template(name).make_module(vars=context)
    return str(getattr(module, macro)())
