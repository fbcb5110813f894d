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
import hashlib
import os
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: rows whose distinct values are found first; the other rows are looked up among them, and
#: only a column with a value outside them is sorted whole
SAMPLE = 1024
#: the low n bytes of a word, n = 0..8
_MASKS = np.array([(1 << (8 * n)) - 1 for n in range(9)], dtype=np.uint64)
_MIX = np.uint64(0x9E3779B97F4A7C15)
#: the bytes of text searched at a time for delimiters and line ends
SCAN_BLOCK = 1 << 16
#: NUL bytes after a file's text, so that 8 bytes can be read from any field's first byte
PADDING = 16
#: a plain CSV file of this many fields or more has its columns coded on several threads (at
#: most this many)
THREADED_FIELDS = 100_000
MAX_THREADS = 4


@dataclass
class PlainCsv:
    """The header's names, the number of rows, and what :meth:`column` needs: the text (16
    NUL bytes after it), each field's first byte and length (a row per column, a column per
    line)."""

    names: list[str]
    rows: int
    body: bytearray
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


@dataclass
class PlainFile:
    """A plain CSV file read whole (:func:`read_file`): its header's names, its number of rows,
    the SHA-256 of its bytes, and each column as codes into its distinct values."""

    names: list[str]
    rows: int
    sha256: str
    columns: list[tuple[np.ndarray, list[str]]]


def read_file(path: Path, threads: bool = True) -> PlainFile | None:
    """The plain CSV file at ``path`` (``.csv`` or ``.txt``, a tab-separated ``.tsv``), or None
    for any other file (or one that cannot be read: the csv module's reading then says why).
    A large file has its columns coded on several threads, unless ``threads`` is False."""
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".txt", ".tsv"):
        return None
    try:
        with path.open("rb") as file:  # into a buffer with room for the padding: no copy
            size = os.fstat(file.fileno()).st_size
            buffer = bytearray(size + PADDING)
            if file.readinto(memoryview(buffer)[:size]) != size or file.read(1):
                return None  # the file changed while it was read
    except OSError:
        return None
    raw = memoryview(buffer)[:size]
    table = read_plain_csv(buffer, "\t" if suffix == ".tsv" else ",", padded=True)
    if table is None:
        return None
    workers = min(os.cpu_count() or 1, MAX_THREADS, len(table.names))
    if threads and workers > 1 and table.rows * len(table.names) >= THREADED_FIELDS:
        # numpy lets go of the interpreter while it gathers and sorts a column, and hashlib
        # while it hashes: the columns are coded side by side, each as it would be alone
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(workers) as pool:
            digest = pool.submit(lambda: hashlib.sha256(raw).hexdigest())
            columns = list(pool.map(table.column, range(len(table.names))))
            sha256 = digest.result()
    else:
        columns = [table.column(i) for i in range(len(table.names))]
        sha256 = hashlib.sha256(raw).hexdigest()
    if any(c is None for c in columns):
        return None
    return PlainFile(table.names, table.rows, sha256, columns)  # type: ignore[arg-type]


class ReadAhead:
    """The data file at ``path`` read by :func:`read_file` on a thread, started at once, while
    the caller does other work (``bayesprog learn`` loads the program meanwhile: the reading
    is mostly numpy, which lets go of the interpreter). Learning takes it as its data, as it
    takes the path; a file that is not plain CSV is read there as any other.

    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = Path(folder) / "d.csv"
    ...     _ = path.write_text("A,B\\nyes,1\\nno,2\\n")
    ...     ahead = ReadAhead(path)
    ...     ahead.result().columns[0]
    (array([1, 0]), ['no', 'yes'])
    """

    def __init__(self, path: str | os.PathLike[str]):
        self.path = Path(path)
        self._file: PlainFile | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._read, name="bayesprog-read-ahead",
                                        daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:  # on this thread alone: the caller's thread is the other one at work
            self._file = read_file(self.path, threads=False)
        except BaseException as exc:  # raised where the result is asked for
            self._error = exc

    def result(self) -> PlainFile | None:
        """The file read (waiting for the thread), or None when it is not plain CSV; what the
        reading raised is raised here."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._file


def read_plain_csv(raw: bytes | bytearray, sep: str, padded: bool = False) -> PlainCsv | None:
    """``raw`` (a CSV file's bytes, ``sep`` its delimiter) split into fields, or None when it
    is not plain (see the module's docstring). ``padded``: ``raw`` is a bytearray whose last
    :data:`PADDING` bytes are not the file's (NUL bytes), read as it is, without a copy."""
    end = len(raw) - PADDING if padded else len(raw)
    bom = len(codecs.BOM_UTF8) if raw.startswith(codecs.BOM_UTF8) else 0
    if padded and not bom and isinstance(raw, bytearray):
        body = raw
    else:
        body = bytearray(raw[bom:end]) + bytes(PADDING)
    end -= bom
    if not end or body.find(b'"', 0, end) >= 0 or body.find(b"\0", 0, end) >= 0:
        return None
    if body.find(b"\r", 0, end) >= 0:  # CRLF line ends are read as LF; a lone CR is left to
        if body.count(b"\r", 0, end) != body.count(b"\r\n", 0, end):  # the csv module
            return None
        body = bytearray(body[:end].replace(b"\r\n", b"\n")) + bytes(PADDING)
        end = len(body) - PADDING
    if body[end - 1] != ord("\n"):
        body[end] = ord("\n")  # the padding's first byte
        end += 1
    ends, line_ends = _ends(np.frombuffer(body, dtype=np.uint8, count=end), ord(sep),
                            np.int32 if len(body) < 2**31 else np.int64)
    width = int(np.searchsorted(ends, line_ends[0])) + 1  # fields of the header line
    lines = len(line_ends)
    if len(ends) != lines * width or not np.array_equal(ends[width - 1::width], line_ends):
        return None  # a line of another length, or a blank line
    head = ends[:width].tolist()
    try:
        names = [bytes(body[s:e]).decode("utf-8").strip()
                 for s, e in zip([0] + [e + 1 for e in head[:-1]], head, strict=True)]
    except UnicodeDecodeError:
        return None
    # a column's fields side by side in memory (a row per column): the reads of each column
    # are sequential. A field starts after the one before it on its line, the first of a line
    # after the last of the line before; its length is its end less its start
    last = np.ascontiguousarray(ends[width:].reshape(lines - 1, width).T)
    starts = np.empty_like(last)
    if lines > 1:
        np.add(last[:-1], 1, out=starts[1:])
        starts[0, 0] = head[-1] + 1
        np.add(last[-1, :-1], 1, out=starts[0, 1:])
    lengths = np.subtract(last, starts, out=last)
    return PlainCsv(names, lines - 1, body, starts, lengths)


def _ends(text: np.ndarray, sep: int, dtype: type) -> tuple[np.ndarray, np.ndarray]:
    """Where each field ends (at its delimiter or its line's end), and where each line ends, as
    offsets of ``dtype``: found a block of the text at a time, so that the masks stay small
    (allocating and filling masks of the whole text costs more than the search)."""
    fields, lines = [], []
    for start in range(0, len(text), SCAN_BLOCK):
        block = text[start:start + SCAN_BLOCK]
        newline = block == ord("\n")
        lines.append(np.flatnonzero(newline).astype(dtype) + dtype(start))
        newline |= block == sep
        fields.append(np.flatnonzero(newline).astype(dtype) + dtype(start))
    return np.concatenate(fields), np.concatenate(lines)


def _words(body: bytearray, starts: np.ndarray, lengths: np.ndarray, k: int) -> np.ndarray:
    """The bytes ``k`` to ``k + 8`` of each field as a little-endian 8-byte word, the bytes past
    its end zeroed (a field holds no NUL, so the words tell fields apart); ``body`` ends with
    16 NUL bytes."""
    # every 8 bytes of the text, from each byte: one unaligned read per field
    at_each_byte = np.ndarray((len(body) - 7,), dtype="<u8", buffer=body, strides=(1,))
    if not k:
        return at_each_byte[starts] & _MASKS[np.minimum(lengths, 8)]
    at = np.minimum(starts + k, len(body) - 8)  # past a short field's end: masked to 0 below
    return at_each_byte[at] & _MASKS[np.clip(lengths - k, 0, 8)]
