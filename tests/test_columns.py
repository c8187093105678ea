"""The column-wise text writer (hg2prism.strategy.columns) against Python's own formatting, on
random columns, with blocks small enough that every text spans many blocks and threads."""

from __future__ import annotations

import numpy as np
import pytest

from hg2prism.strategy import columns
from hg2prism.strategy.columns import (Field, Lines, Texts, Vocabulary, grouped_chunks, integers,
                                       literal, tokens)


def render_grouped(heads: Lines, items: Lines, starts: np.ndarray, before: bytes = b"") -> bytes:
    """`before`, then each row of `heads` followed by its rows of `items`,
    starts[i]..starts[i + 1] - 1 (`starts` ascending, from 0 to items.n)."""
    return b"".join(grouped_chunks(heads, items, starts, before))


@pytest.fixture(autouse=True)
def small_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(columns, "BLOCK_BYTES", 97)


@pytest.mark.parametrize("seed", range(5))
def test_lines_equal_python_formatting(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 400))
    big = rng.integers(-10**12, 10**12, n)
    small = rng.integers(-3, 4, n)
    floats = rng.choice([0.1, 0.7999999999999999, 1e-05, 1 / 3, 0.0, 1.0, 2.5e-300], n)
    words = ["N", "E", "S", "W", "absorbing"]
    word = rng.integers(-1, len(words), n)          # -1: nothing
    shown = rng.random(n) < 0.5
    text = Lines([literal("<"), integers(big), literal(","), integers(small), literal(" "),
                  tokens(floats), Field(Vocabulary.of(words), word),
                  literal("|").where(shown), literal(">\n")], n).render(b"head\n", b"tail")
    expected = "head\n" + "".join(
        f"<{b},{s} {f!r}{words[w] if w >= 0 else ''}{'|' if h else ''}>\n"
        for b, s, f, w, h in zip(big.tolist(), small.tolist(), floats.tolist(), word.tolist(),
                                 shown.tolist())) + "tail"
    assert text == expected.encode()


def test_numbers_cover_every_width() -> None:
    vocabulary = Vocabulary.numbers(-10_001, 10_001)
    text = Lines([Field(vocabulary, np.arange(20_003)), literal(" ")], 20_003).render()
    assert text.decode().split() == [str(v) for v in range(-10_001, 10_002)]


@pytest.mark.parametrize("seed", range(4))
def test_grouped_rows_follow_their_head(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_heads = int(rng.integers(1, 60))
    counts = rng.integers(0, 6, n_heads)            # a head may have no items
    starts = np.r_[0, np.cumsum(counts)]
    target = rng.integers(0, 10**6, int(starts[-1]))
    heads = Lines([literal("state "), integers(np.arange(n_heads)), literal("\n")], n_heads)
    items = Lines([literal("\t"), integers(target), literal("\n")], len(target))
    expected = "".join(f"state {i}\n" + "".join(f"\t{t}\n" for t in
                                                target[starts[i]:starts[i + 1]].tolist())
                       for i in range(n_heads))
    assert render_grouped(heads, items, starts, b"@model\n") == b"@model\n" + expected.encode()


def test_nul_bytes_are_refused() -> None:
    with pytest.raises(ValueError, match="NUL"):
        Vocabulary.of(["a\0b"])


@pytest.mark.parametrize("distinct", [3, 5000])
def test_tokens_spell_every_value(distinct: int) -> None:
    """Few distinct values are found from a sample, many by sorting: the same text."""
    rng = np.random.default_rng(distinct)
    values = rng.choice(rng.random(distinct), 20_000)
    text = Lines([tokens(values), literal(";")], len(values)).render()
    assert text.decode().split(";")[:-1] == [repr(v) for v in values.tolist()]


def test_texts_column_spans_blocks() -> None:
    rng = np.random.default_rng(7)
    strings = ["x" * int(k) for k in rng.integers(0, 40, 300)]
    text = Lines([integers(np.arange(300)), Texts(strings), literal("\n")], 300).render()
    assert text.decode() == "".join(f"{i}{t}\n" for i, t in enumerate(strings))


def test_chunks_stream_the_rendered_text_block_by_block(tmp_path) -> None:
    """Lines.chunks gives render's text in pieces of about BLOCK_BYTES (97 here), formatted
    as they are consumed, and outputs.write_chunks writes exactly their concatenation,
    atomically: a failure half-way leaves neither the file nor a temporary beside it."""
    from hg2prism.outputs import write_chunks

    n = 1000
    lines = Lines([integers(np.arange(n)), literal("\n")], n)
    pieces = list(lines.chunks(b"[", b"]"))
    assert pieces[0] == b"[" and pieces[-1] == b"]" and len(pieces) > 40
    assert max(len(p) for p in pieces) <= 97
    expected = "[" + "".join(f"{i}\n" for i in range(n)) + "]"
    assert b"".join(pieces) == lines.render(b"[", b"]") == expected.encode()
    path = tmp_path / "out.txt"
    write_chunks(path, lines.chunks(b"[", b"]"))
    assert path.read_bytes() == expected.encode()

    def failing():
        yield b"partial"
        raise RuntimeError("disk full")
    with pytest.raises(RuntimeError):
        write_chunks(tmp_path / "other.txt", failing())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]
