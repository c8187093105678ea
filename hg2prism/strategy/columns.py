"""Text files built column-wise with numpy, for the exports of million-state models
(strategy.json, induced.tra/.sta/.drn).

A line is a sequence of fields; each field is a column of codes into a `Vocabulary`, a small
table of byte strings padded with zero bytes. The rows of a block of lines are laid out side by
side in a byte matrix, field after field, and its non-zero bytes are the text in reading order.
Formatting a row in Python costs about a microsecond per field; this costs nanoseconds per byte
(blocks are formatted on two threads: numpy releases the GIL while it copies), so the 2.5 GB
the 4.2-million-state benchmark world writes take seconds rather than minutes. The text is what
Python's formatting gives: integers as `str(int)`, other values as the caller spells them
(`repr` of a float, a JSON fragment).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

BLOCK_BYTES = 1 << 23      # the byte matrix of one block of rows: 8 MB (a few are formatted at once)
THREADS = min(2, os.cpu_count() or 1)
SAMPLE = 4096              # values sampled to find a column's few distinct ones
T = TypeVar("T")


@dataclass(frozen=True, eq=False)
class Vocabulary:
    """Byte strings addressed by code: string k is row k of `table` without its trailing zero
    bytes. The last row is the empty string, so that code -1 writes nothing."""

    table: np.ndarray       # [strings + 1, width] uint8

    @classmethod
    def of(cls, strings: Sequence[str]) -> Vocabulary:
        """The vocabulary of `strings` (code k is strings[k])."""
        encoded = [s.encode() for s in strings] + [b""]
        if any(b"\0" in e for e in encoded):
            raise ValueError("a vocabulary string holds a NUL byte (0 marks unused bytes)")
        length = np.fromiter(map(len, encoded), dtype=np.int64, count=len(encoded))
        table = np.zeros((len(encoded), max(int(length.max()), 1)), dtype=np.uint8)
        table[np.arange(table.shape[1]) < length[:, None]] = np.frombuffer(b"".join(encoded),
                                                                             dtype=np.uint8)
        return cls(table)

    @classmethod
    def numbers(cls, low: int, high: int) -> Vocabulary:
        """str(v) for v = low..high: the code of v is v - low."""
        value = np.arange(low, high + 1, dtype=np.int64)
        negative = (value < 0).astype(np.int64)
        magnitude = np.abs(value)
        digits = np.ones(len(value), dtype=np.int64)
        power = 10
        while power <= max(abs(low), abs(high)):
            digits += magnitude >= power
            power *= 10
        width = int((digits + negative).max(initial=1))
        table = np.zeros((len(value) + 1, width), dtype=np.uint8)
        for column in range(width):          # a sign, then the digits, most significant first
            position = column - negative     # of the digit in this column
            exponent = np.clip(digits - 1 - position, 0, None)
            digit = ord("0") + (magnitude // 10 ** exponent) % 10
            table[:-1, column] = np.where(position < 0, ord("-"),
                                          np.where(position < digits, digit, 0))
        return cls(table)

    @property
    def width(self) -> int:
        return self.table.shape[1]


@dataclass(frozen=True, eq=False)
class Field:
    """One column of a line: the code of each row (-1: nothing), or one code for every row."""

    vocabulary: Vocabulary
    codes: np.ndarray | int

    def __post_init__(self) -> None:
        # codes in the narrowest integer type that holds -1 .. the vocabulary's size: the
        # fields of a file are held together while it is written (a byte or two per row for
        # most columns, not eight)
        if isinstance(self.codes, np.ndarray) and self.codes.dtype.kind in "iu":
            size = len(self.vocabulary.table)
            narrow = next(np.dtype(t) for t in (np.int8, np.int16, np.int32, np.int64)
                          if np.iinfo(t).max >= size)
            if narrow.itemsize < self.codes.dtype.itemsize:
                object.__setattr__(self, "codes", self.codes.astype(narrow))

    @property
    def width(self) -> int:
        return self.vocabulary.width

    def where(self, present: np.ndarray) -> Field:
        """This field on the rows where `present` holds, nothing elsewhere."""
        codes = np.broadcast_to(self.codes, present.shape)
        return Field(self.vocabulary, np.where(present, codes, -1))


class Texts:
    """A column of one string per row, spelled by the caller (long and mostly distinct
    strings): each block of rows gets a vocabulary of its own strings, so that no table holds
    them all."""

    def __init__(self, strings: Sequence[str]) -> None:
        self.strings = strings
        self.width = max(1, max((len(t.encode()) for t in strings), default=0))


def literal(text: str) -> Field:
    """A field holding `text` on every row."""
    return Field(Vocabulary.of([text]), 0)


def tokens(values: np.ndarray, spell: Callable[[object], str] = repr) -> Field:
    """A field of arbitrary values (floats, say) written as `spell(value)`: each distinct value
    is spelled once."""
    values = np.asarray(values).reshape(-1)
    distinct, code = _distinct(values)
    return Field(Vocabulary.of([spell(v) for v in distinct.tolist()]), code)


def _distinct(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The sorted distinct values and each value's index among them. A column of a few
    distinct values (the probabilities of a transition table) is looked up in those of a sample
    rather than sorted whole, when the sample has them all."""
    sample = np.unique(values[::max(1, len(values) // SAMPLE)])
    if 0 < len(sample) <= SAMPLE // 8:
        code = np.minimum(np.searchsorted(sample, values), len(sample) - 1)
        if np.array_equal(sample[code], values):
            return sample, code
    order = np.argsort(values, kind="stable")
    ordered = values[order]
    new = np.r_[True, ordered[1:] != ordered[:-1]] if len(values) else np.zeros(0, dtype=bool)
    code = np.empty(len(values), dtype=np.int64)
    code[order] = np.cumsum(new) - 1
    return ordered[new], code


def integers(values: np.ndarray) -> Field:
    """A field of integers, written as str(v): by a table of every number in their range
    when it is not much larger than the column, else by their distinct values."""
    values = np.asarray(values, dtype=np.int64)
    low, high = int(values.min(initial=0)), int(values.max(initial=0))
    if high - low > 2 * len(values) + 1024:
        return tokens(values, str)
    return Field(Vocabulary.numbers(low, high), values - low)


class Lines:
    """Rows of text, each the concatenation of `fields` (every array of codes has `n` rows)."""

    def __init__(self, fields: Sequence[Field | Texts], n: int) -> None:
        self.fields = list(fields)
        self.n = n
        self.width = sum(f.width for f in self.fields)

    def block(self, start: int, stop: int) -> np.ndarray:
        """Rows start..stop-1 as a byte matrix, the unused bytes 0."""
        text = np.empty((stop - start, self.width), dtype=np.uint8)
        offset = 0
        for field in self.fields:
            if isinstance(field, Texts):
                table = Vocabulary.of(field.strings[start:stop]).table[:-1]
                text[:, offset:offset + field.width] = 0
                text[:, offset:offset + table.shape[1]] = table
            else:
                codes = field.codes if np.isscalar(field.codes) else field.codes[start:stop]
                text[:, offset:offset + field.width] = field.vocabulary.table[codes]
            offset += field.width
        return text

    def render(self, before: bytes = b"", after: bytes = b"") -> bytes:
        """`before`, all rows' text one after another, then `after`."""
        return b"".join(self.chunks(before, after))

    def chunks(self, before: bytes = b"", after: bytes = b"") -> Iterator[bytes]:
        """The text of `render` in pieces of about BLOCK_BYTES, formatted THREADS at a time as
        they are consumed (outputs.write_chunks): a file of gigabytes never sits in memory."""
        step = max(1, BLOCK_BYTES // max(self.width, 1))
        starts = range(0, self.n, step)
        yield before
        yield from _in_threads(lambda start: _packed(self.block(start, min(self.n, start + step))),
                               starts)
        yield after


def grouped_chunks(heads: Lines, items: Lines, starts: np.ndarray, before: bytes = b""
                   ) -> Iterator[bytes]:
    """`before`, then each row of `heads` followed by its rows of `items`,
    starts[i]..starts[i + 1] - 1 (`starts` ascending, from 0 to items.n): the text in pieces,
    formatted as they are consumed (`Lines.chunks`)."""
    per_block = max(1, BLOCK_BYTES // max(heads.width, items.width, 1))
    blocks = []
    head = 0
    while head < heads.n:       # the heads whose items fit in a block (at least one head)
        last_fitting = int(np.searchsorted(starts, starts[head] + per_block, side="right")) - 1
        stop = min(heads.n, max(head + 1, last_fitting))
        blocks.append((head, stop))
        head = stop

    def render_block(block: tuple[int, int]) -> bytes:
        head, stop = block
        first, last = int(starts[head]), int(starts[stop])
        text = np.zeros(((stop - head) + (last - first), max(heads.width, items.width)),
                        dtype=np.uint8)
        head_row = (starts[head:stop] - first) + np.arange(stop - head)
        owner = np.repeat(np.arange(stop - head), np.diff(starts[head:stop + 1]))
        text[head_row, :heads.width] = heads.block(head, stop)
        text[np.arange(last - first) + owner + 1, :items.width] = items.block(first, last)
        return _packed(text)

    yield before
    yield from _in_threads(render_block, blocks)


def _packed(text: np.ndarray) -> bytes:
    """The bytes of a block in reading order, without the unused (0) ones."""
    return text[text != 0].tobytes()


def _in_threads(work: Callable[[T], bytes], items: Sequence[T]) -> Iterator[bytes]:
    """work(item) for each item, in order, on up to THREADS threads: numpy releases the GIL
    while it copies and packs bytes, so blocks are formatted side by side, THREADS at a time
    (only those are held until they are consumed)."""
    if len(items) < 2:
        yield from (work(item) for item in items)
        return
    with ThreadPoolExecutor(max_workers=THREADS) as pool:
        for first in range(0, len(items), THREADS):
            yield from pool.map(work, items[first:first + THREADS])
