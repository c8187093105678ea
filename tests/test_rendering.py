"""Tables as PRISM expressions (prism/rendering.lookup): read back by a small evaluator of the
comparison trees they are written as, against the arrays they were made from."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from hg2prism.prism.rendering import lookup


def evaluate(expression: str, variables: dict[str, int]) -> float:
    """The value of `(k<b ? left : right)` trees with numeric leaves, as PRISM reads them."""
    position = 0

    def parse() -> float:
        nonlocal position
        if expression[position] == "(":
            less = expression.index("<", position)
            then = expression.index(" ? ", less)
            name, bound = expression[position + 1:less], int(expression[less + 1:then])
            position = then + 3
            left = parse()
            assert expression[position:position + 3] == " : "
            position += 3
            right = parse()
            assert expression[position] == ")"
            position += 1
            return left if variables[name] < bound else right
        end = position
        while end < len(expression) and expression[end] not in " )":
            end += 1
        token, position = expression[position:end], end
        return float(token)

    value = parse()
    assert position == len(expression)
    return value


def random_tables(seed: int, count: int):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        shape = tuple(int(n) for n in rng.integers(1, 7, size=rng.integers(1, 4)))
        values = rng.integers(0, 3, size=shape) * (rng.random(shape) < rng.random())
        table = values.astype(float) if rng.random() < 0.5 else values
        care = rng.random(shape) < rng.random()
        keys = [(f"k{i}", int(rng.integers(-2, 3))) for i in range(len(shape))]
        yield table, care, keys


def entries(table: np.ndarray, keys: list[tuple[str, int]]):
    for index in itertools.product(*(range(n) for n in table.shape)):
        yield index, {name: i + low for i, (name, low) in zip(index, keys)}


@pytest.mark.parametrize("seed", range(4))
def test_a_table_reads_back_everywhere(seed: int) -> None:
    for table, _, keys in random_tables(seed, 100):
        expression = lookup(table, keys)
        for index, variables in entries(table, keys):
            assert evaluate(expression, variables) == table[index], (table, expression, index)


@pytest.mark.parametrize("seed", range(4))
def test_a_table_reads_back_where_cared_for(seed: int) -> None:
    for table, care, keys in random_tables(100 + seed, 100):
        expression = lookup(table, keys, care)
        for index, variables in entries(table, keys):
            if care[index]:
                assert evaluate(expression, variables) == table[index], (table, care, index)


def test_free_entries_shorten_the_table() -> None:
    """A table that is one value wherever it is cared for is that value; freedom elsewhere
    merges runs."""
    table = np.arange(24).reshape(4, 6)
    care = np.zeros_like(table, dtype=bool)
    care[2, 3] = True
    assert lookup(table, [("a", 0), ("b", 0)], care) == "15"
    assert lookup(table, [("a", 0), ("b", 0)], np.zeros_like(care)) == "0"
    care[0, 0] = True
    # the two cared entries lie in different columns, so all rows merge into one run
    assert lookup(table, [("a", 0), ("b", 0)], care) == "(b<3 ? 0 : 15)"
    assert len(lookup(table, [("a", 0), ("b", 0)])) > 200


def test_runs_split_at_their_boundaries() -> None:
    """Along a dimension the comparisons fall between runs of equal rows, not at midpoints."""
    table = np.array([0] * 10 + [1] * 3 + [0] * 7)
    expression = lookup(table, [("cell", 0)])
    assert expression == "(cell<10 ? 0 : (cell<13 ? 1 : 0))"


# ---- long lines ----

def test_long_lines_are_wrapped_between_tokens() -> None:
    """A model's code lines longer than 100 characters are broken at spaces outside quotes into
    lines of at most 100, continuations indented 4 more; the tokens stay the same and in order
    (PRISM reads a line break as a space); an end-of-line comment goes above; comment lines and
    lines of exactly 100 stay as they are."""
    from hg2prism.prism.rendering import WRAP, wrapped

    table = lookup(np.arange(64) % 7, [("place", 0)])
    long = f"  formula to_0 = {table};   // to_0: \"where\" it leads"
    exact = "x" * (WRAP - 4) + " = 1"
    comment = "// " + "word " * 40
    quoted = '  label "a b c" = ' + " | ".join(f"place={i}" for i in range(30)) + ";"
    text = "\n".join([long, exact, comment, quoted, ""])
    lines = wrapped(text).split("\n")
    assert exact in lines and comment in lines and lines[-1] == ""
    assert lines[0] == '  // to_0: "where" it leads'
    assert all(len(line) <= WRAP for line in lines if not line.lstrip().startswith("//"))
    formula = lines[1:lines.index(exact)]
    assert len(formula) > 1 and formula[0].startswith("  formula to_0 = (")
    assert all(line.startswith("      ") and not line.startswith("       ")
               for line in formula[1:])
    assert " ".join(formula).split() == f"formula to_0 = {table};".split()
    label = lines[lines.index(comment) + 1:-1]
    assert label[0].startswith('  label "a b c" =') and len(label) > 1
    assert " ".join(label).split() == quoted.split()
    assert wrapped(exact + "y") != exact + "y"          # one over: wrapped
    assert wrapped("a" * 150) == "a" * 150              # one token: nothing to break at
