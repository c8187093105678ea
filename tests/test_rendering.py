"""Tables as PRISM expressions (prism/rendering.lookup): read back by a small evaluator of the
comparison trees they are written as, against the arrays they were made from."""

from __future__ import annotations

import itertools
import re

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

def _tokens_kept(original: str, lines: list[str]) -> bool:
    return " ".join(lines).split() == original.split()


def test_long_code_lines_are_wrapped_between_tokens() -> None:
    """A model's code lines longer than 100 characters are broken at spaces outside quotes into
    lines of at most 100, continuations indented 4 more; the tokens stay the same and in order
    (PRISM reads a line break as a space); an end-of-line comment goes above; a line of
    exactly 100 stays as it is, one of 101 is wrapped, a lone token longer than a line too."""
    from hg2prism.prism.rendering import WRAP, wrapped

    table = lookup(np.arange(64) % 7, [("place", 0)])
    long = f"  formula to_0 = {table};   // to_0: \"where\" it leads"
    exact = "x" * (WRAP - 4) + " = 1"
    quoted = '  label "a b c" = ' + " | ".join(f"place={i}" for i in range(30)) + ";"
    lines = wrapped("\n".join([long, exact, quoted, ""])).split("\n")
    assert exact in lines and lines[-1] == ""
    assert lines[0] == '  // to_0: "where" it leads'
    assert all(len(line) <= WRAP for line in lines)
    formula = lines[1:lines.index(exact)]
    assert len(formula) > 1 and formula[0].startswith("  formula to_0 = (")
    assert all(line.startswith("      ") and not line.startswith("       ")
               for line in formula[1:])
    assert _tokens_kept(f"formula to_0 = {table};", formula)
    label = lines[lines.index(exact) + 1:-1]
    assert label[0].startswith('  label "a b c" =') and len(label) > 1
    assert _tokens_kept(quoted, label)
    assert wrapped(exact + "y") != exact + "y"          # one over: wrapped
    assert wrapped("a" * 150) == "a" * 150              # one token: nothing to break at


def test_wrapping_breaks_at_the_least_nested_space() -> None:
    """Within the last half of a full line the break goes where the fewest parentheses are
    open, before `+` (between outcomes) rather than inside an outcome: `? 1 :` / `0)*0.2:` and
    `(place<16 ? 21` / `: 22)` were split."""
    from hg2prism.prism.rendering import wrapped

    outcome = "(to_{k}=TRAPPED ? 1 : 0)*0.{k}:(place'=to_{k}) & (hyp'=h_{k})"
    command = "  [a0] place!=TRAPPED -> " + " + ".join(outcome.format(k=k) for k in range(1, 7)) + ";"
    lines = wrapped(command).split("\n")
    assert _tokens_kept(command, lines) and all(len(line) <= 100 for line in lines)
    assert all(line.lstrip().startswith("+ ") for line in lines[1:]), lines
    tree = "  formula t = " + lookup(np.arange(300) % 11, [("place", 0)]) + ";"
    lines = wrapped(tree).split("\n")
    assert _tokens_kept(tree, lines)
    for line in lines:      # no comparison (x<k ? a : b) of two numbers cut in two
        assert not re.search(r"\(place<\d+ \? \d+$", line), line
        assert not re.match(r"\s*: \d+\)", line) or line.count("(") > 0, line


def test_long_comment_lines_go_on_under_their_text() -> None:
    """Comment lines longer than 100 characters go on in comment lines: a header's value under
    its value column, prose under its first word; a word longer than a line stays whole."""
    from hg2prism.prism.rendering import wrapped

    header = "// world        world2 (models/world2.toml): " + "word " * 40
    prose = "  // The arena's tables that depend on P2's action in force: " + "per hypothesis " * 8
    lines = wrapped(header + "\n" + prose).split("\n")
    assert all(len(line) <= 100 for line in lines)
    head = [line for line in lines if not line.startswith("  ")]
    assert head[0].startswith("// world        world2") and len(head) > 1
    assert all(line.startswith("//              ") and line[16] != " " for line in head[1:])
    assert _tokens_kept(header, [head[0]] + [line[2:] for line in head[1:]])
    body = [line for line in lines if line.startswith("  ")]
    assert len(body) > 1 and all(line.startswith("  // ") and line[5] != " " for line in body)
    assert _tokens_kept(prose, [body[0]] + [line[4:] for line in body[1:]])
    assert wrapped("// " + "=" * 120) == "// " + "=" * 120


def test_a_long_comment_is_reflowed_with_the_lines_that_go_on_with_it() -> None:
    """A long comment line whose sentence goes on in the comment lines under it is reflowed as
    one paragraph (the wrapped first line left a fragment, "its default", on a line of its own);
    a header line of its own, a list item and a line after a full stop are not taken in."""
    from hg2prism.prism.rendering import wrapped

    recheck = ("// Re-check:    prism hypergame.prism hypergame.props -ex -epsilon 1e-12   "
               "(PRISM's explicit engine: its default\n"
               "//              symbolic one can stall on arena worlds; docs/cli.md)\n"
               "// digest       sha256:0123")
    lines = wrapped(recheck).split("\n")
    assert lines[-1] == "// digest       sha256:0123"
    assert all(len(line) <= 100 for line in lines) and len(lines) == 3
    assert lines[1].startswith("//              ") and "its default symbolic" in " ".join(
        line[2:].strip() for line in lines)
    items = "//     0 x2_y6: " + "a0=N " * 20 + "\n//     1 x3_y6: a0=N"
    assert wrapped(items).split("\n")[-1] == "//     1 x3_y6: a0=N"
    stop = "// " + "word " * 25 + "end.\n// next sentence"
    assert wrapped(stop).split("\n")[-1] == "// next sentence"


def test_commands_are_counted_on_the_wrapped_model() -> None:
    """count_commands counts a command whose label a wrapped line left alone on its line, and
    never a continuation line."""
    from hg2prism.prism.hypergame import count_commands
    from hg2prism.prism.rendering import wrapped

    text = ("module robot\n  [a1] " + "x" * 95 + " -> true;\n  [a2] y -> true;\n"
            "  [] " + " & ".join(f"(v{i}'=w{i})" for i in range(30)) + ";\nendmodule\n")
    assert count_commands(wrapped(text)) == {"robot": 3} == count_commands(text)
