"""A plain CSV file's columns read with numpy alone: no quotes, one line per row, every line
with the header's number of fields. Each column comes as codes into its distinct values, found
without a Python step per row, so a data set of thousands of rows is read in milliseconds and
without importing pandas or pyarrow (their import takes longer than the read).

Anything else (quotes, blank lines, rows of other lengths, bytes that are not UTF-8) is left to
the csv module, which says where the file is wrong: :func:`read_plain_csv` returns None.

>>> table = read_plain_csv(b"A,B\\nyes,1\\nno,2\\nyes,1\\n", ",")
>>> table.names, table.rows
(['A', 'B'], 3)
>>> codes, values = table.column(0)
>>> codes.tolist(), values
([1, 0, 1], ['no', 'yes'])
"""

from __future__ import annotations

import codecs
from dataclasses import dataclass

import numpy as np

#: rows whose distinct values are found first; the other rows are looked up among them, and
#: only a column with a value outside them is sorted whole
SAMPLE = 1024
#: the low n bytes of a word, n = 0..8
_MASKS = np.array([(1 << (8 * n)) - 1 for n in range(9)], dtype=np.uint64)
_MIX = np.uint64(0x9E3779B97F4A7C15)


@dataclass
class PlainCsv:
    """The header's names, the number of rows, and what :meth:`column` needs: the text (16
    NUL bytes after it), each field's first byte and length (a row per column, a column per
    line)."""

    names: list[str]
    rows: int
    body: bytes
    starts: np.ndarray
    lengths: np.ndarray

    def column(self, i: int) -> tuple[np.ndarray, list[str]] | None:
        """Column ``i`` as codes into its distinct values (the values as written, the spaces
        after the delimiter skipped, as the csv module reads them); None when two values
        could not be told apart by their hash (then the csv module reads the file)."""
        starts, lengths = self.starts[i], self.lengths[i]
        key = _words(self.body, starts, lengths, 0)  # a value of up to 8 bytes: its bytes
        widest = int(lengths.max()) if len(lengths) else 0
        parts = [key]
        for k in range(8, widest, 8):  # a longer value: its 8-byte words hashed into one key
            part = _words(self.body, starts, lengths, k)
            parts.append(part)
            key = key * _MIX + (part ^ (part >> np.uint64(29)))
        distinct, first = np.unique(key[:SAMPLE], return_index=True)
        codes = np.minimum(np.searchsorted(distinct, key), len(distinct) - 1) if len(
            distinct) else np.zeros(len(key), dtype=np.intp)
        if len(key) and not np.array_equal(distinct[codes], key):
            distinct, first, codes = np.unique(key, return_index=True, return_inverse=True)
        if len(parts) > 1 and any(not np.array_equal(p[first][codes], p) for p in parts):
            return None
        try:
            values = [self.body[s:s + n].decode("utf-8").lstrip(" ")
                      for s, n in zip(starts[first].tolist(), lengths[first].tolist(),
                                      strict=True)]
        except UnicodeDecodeError:
            return None
        return codes.reshape(-1).astype(np.int64, copy=False), values


def read_plain_csv(raw: bytes, sep: str) -> PlainCsv | None:
    """``raw`` (a CSV file's bytes, ``sep`` its delimiter) split into fields, or None when it
    is not plain (see the module's docstring)."""
    body = raw[len(codecs.BOM_UTF8):] if raw.startswith(codecs.BOM_UTF8) else raw
    if not body or b'"' in body or b"\0" in body:
        return None
    if b"\r" in body:  # CRLF line ends are read as LF; a lone CR is left to the csv module
        if body.count(b"\r") != body.count(b"\r\n"):
            return None
        body = body.replace(b"\r\n", b"\n")
    if not body.endswith(b"\n"):
        body += b"\n"
    text = np.frombuffer(body, dtype=np.uint8)
    ends = np.flatnonzero((text == ord(sep)) | (text == ord("\n")))
    offsets = np.int32 if len(body) + 16 < 2**31 else np.int64
    ends = ends.astype(offsets, copy=False)
    newline = text[ends] == ord("\n")
    width = int(np.argmax(newline)) + 1  # fields of the header line
    lines = len(ends) // width
    if len(ends) % width or int(newline.sum()) != lines or not newline[width - 1::width].all():
        return None  # a line of another length, or a blank line
    starts = np.empty_like(ends)
    starts[0] = 0
    starts[1:] = ends[:-1] + 1
    try:
        names = [body[s:e].decode("utf-8").strip()
                 for s, e in zip(starts[:width].tolist(), ends[:width].tolist(), strict=True)]
    except UnicodeDecodeError:
        return None
    first = starts[width:].reshape(lines - 1, width)
    lengths = ends[width:].reshape(lines - 1, width) - first
    # a column's fields side by side in memory: the reads of each column are sequential; the
    # 8 bytes from any field's first byte can be read
    return PlainCsv(names, lines - 1, body + bytes(16), np.ascontiguousarray(first.T),
                    np.ascontiguousarray(lengths.T))


def _words(body: bytes, starts: np.ndarray, lengths: np.ndarray, k: int) -> np.ndarray:
    """The bytes ``k`` to ``k + 8`` of each field as a little-endian 8-byte word, the bytes past
    its end zeroed (a field holds no NUL, so the words tell fields apart); ``body`` ends with
    16 NUL bytes."""
    # every 8 bytes of the text, from each byte: one unaligned read per field
    at_each_byte = np.ndarray((len(body) - 7,), dtype="<u8", buffer=body, strides=(1,))
    if not k:
        return at_each_byte[starts] & _MASKS[np.minimum(lengths, 8)]
    at = np.minimum(starts + k, len(body) - 8)  # past a short field's end: masked to 0 below
    return at_each_byte[at] & _MASKS[np.clip(lengths - k, 0, 8)]
